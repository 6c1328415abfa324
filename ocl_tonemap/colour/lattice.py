"""One frame's per-pixel mapping as colour operations (``clf.py``): the lattices of an
OCIO export (``export.py``; measured in ``benchmarks/ocio_export_lut.py``, the design
and its measurements in docs/ocio_export.md).

For a global operator the per-pixel part of a frame is a fixed function of the
pixel's RGB. It is carried in two stages, each a LUT3D on a lattice of its own:

*Stage A*, the operator and the per-pixel effects: working-space cd/m^2 -> the
operator's display-linear signal before the highlight shoulder, a smooth function
that may cross zero (``FrameParams.raw`` of the models); the clamp at 0 follows as a
Range, exactly. A stage that is linear (durand00 without rods or the Purkinje
shift) is a Matrix, exact.

*Stage B*, the highlight shoulder and the clip (``models/display.apply_shoulder``):
display-linear in and out, the identity below the knee, C0 kinks above it (the
largest channel; the desaturation toward white).

Both lattices sit in log-opponent coordinates (:class:`Coordinates`): a camera log
(log2 with a linear toe, through black and below zero) of the colour with a little
of its luminance added to each channel, then (mean, r - g, b - g). Along the first
axis a colour changes intensity alone (a map homogeneous in intensity is linear
there); the chroma axes stay bounded. The LUT's output is written in the same kind
of coordinates and decoded after it, so that power-law and log-like outputs
interpolate well; stage B's output shares its input's coordinates (a cell wholly
below the knee reproduces the identity exactly). Per axis a piecewise-linear LUT1D puts the nodes
where the frame needs them: at quantiles of the frame's coordinates, evenly over
their range, evenly in the output's lightness along the neutral axis, and (stage
B) at the most common highlight colours. Stage B can also be an RGB lattice
(:func:`stage_b_rgb`: exact at 0 and in the cube below the knee, and exact on the
flat colours of a rendered frame, whose channel values become its nodes); the
export keeps whichever measures better on the frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..models.display import DISPLAY_LINEAR_MAX
from ..models.photometry import Y_WEIGHTS

#: Entries of the shapers' LUT1D (the grid the lattice nodes are snapped to; odd: a
#: range symmetric about 0 has 0 on the grid).
SHAPER_SIZE = 4097
#: Default lattice size (nodes per axis) of both stages.
LATTICE = 33
#: At most this many pixels are looked at to place the nodes.
SAMPLE = 1 << 18
#: A stage is linear when a fitted matrix reproduces it to this (relative).
LINEAR_TOL = 1e-7
LN2 = math.log(2.0)


def matrix_op(M: np.ndarray, offset=(0.0, 0.0, 0.0)) -> tuple:
    return ("matrix", np.asarray(M, np.float64), np.asarray(offset, np.float64))


def range_op(lo: float | None, hi: float | None) -> tuple:
    """A clamp to [lo, hi], either side open when None."""
    return ("range", None if lo is None else float(lo), None if hi is None else float(hi))


def lattice_points(axes) -> np.ndarray:
    """(n^3, 3) points of the lattice with node values ``axes`` = (r, g, b) arrays."""
    R, G, B = np.meshgrid(*axes, indexing="ij")
    return np.stack([R, G, B], -1).reshape(-1, 3)


def sample_rows(pixels: np.ndarray, limit: int = SAMPLE) -> np.ndarray:
    """At most ``limit`` rows of (N, 3) ``pixels``, evenly strided."""
    step = max(1, pixels.shape[0] // limit)
    return pixels[::step]


def extreme_rows(full, forward, chunk: int = 1 << 20) -> np.ndarray:
    """The rows of ``full`` (N, 3) that hold the smallest and the largest value of each
    coordinate of ``forward(rows)`` (non-finite rows aside; ``chunk`` rows at a time):
    added to a strided sample, they make the lattice's extents cover every row of
    ``full`` (a frame's most saturated pixel may lie between the sample's rows, and a
    colour beyond the lattice is clamped to its edge)."""
    best = {}
    full = np.asarray(full).reshape(-1, 3)
    for i in range(0, full.shape[0], chunk):
        rows = np.asarray(full[i:i + chunk], np.float64)
        rows = rows[np.isfinite(rows).all(axis=1)]
        if not rows.size:
            continue
        with np.errstate(all="ignore"):
            z = forward(rows)
        for j in range(z.shape[1]):
            for key, k in (((j, 0), int(np.argmin(z[:, j]))), ((j, 1), int(np.argmax(z[:, j])))):
                v = z[k, j] * (1 - 2 * key[1])          # (smaller is better, both ends)
                if key not in best or v < best[key][0]:
                    best[key] = (v, rows[k])
    return np.array([r for _, r in best.values()], np.float64).reshape(-1, 3)


def _fill(idx: np.ndarray, n: int, coord) -> np.ndarray:
    """Grid indices ``idx`` (sorted, unique) grown to ``n`` by halving the widest
    gap (in ``coord`` of the index); fewer when the grid is too fine to split."""
    idx = np.unique(idx)
    while idx.size < n:
        c = coord(idx)
        i = int(np.argmax(np.diff(c)))
        mid = (idx[i] + idx[i + 1]) // 2
        if mid <= idx[i]:
            gaps = np.diff(idx)
            i = int(np.argmax(gaps))
            if gaps[i] < 2:
                break
            mid = (idx[i] + idx[i + 1]) // 2
        idx = np.insert(idx, i + 1, mid)
    return idx


def _thin(idx: np.ndarray, n: int, keep: np.ndarray, coord) -> np.ndarray:
    """Drop nodes (never those in ``keep``) from the narrowest gaps down to ``n``."""
    idx = np.unique(idx)
    while idx.size > n:
        c = coord(idx)
        gaps = np.minimum(np.diff(c)[:-1], np.diff(c)[1:])      # around inner nodes
        gaps = np.where(np.isin(idx[1:-1], keep), np.inf, gaps)
        if not np.isfinite(gaps).any():
            break
        idx = np.delete(idx, int(np.argmin(gaps)) + 1)
    return idx


# --- coordinates ----------------------------------------------------------------

#: The opponent matrix: (mean, r - g, b - g) of the per-channel logs.
OPPONENT = np.array([[1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0], [1.0, -1.0, 0.0], [0.0, -1.0, 1.0]])


def _mul3(x: np.ndarray, M: np.ndarray) -> np.ndarray:
    """x @ M.T for (N, 3) x, elementwise."""
    return x[:, 0:1] * M[:, 0] + x[:, 1:2] * M[:, 1] + x[:, 2:3] * M[:, 2]


def camera_log(beta: float, top: float) -> tuple[float, float, float]:
    """(break, slope, offset) of y = slope log2(x) + offset above ``beta``, linear
    (C1) below it (negative x too), with y(0) = 0 and y(top) = 1."""
    k = 1.0 / (math.log2(top) - math.log2(beta) + 1.0 / LN2)
    return beta, k, k * (1.0 / LN2 - math.log2(beta))


def camera_log_forward(x, P) -> np.ndarray:
    beta, k, o = P
    x = np.asarray(x, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(x >= beta, k * np.log2(np.maximum(x, beta)) + o,
                        k / (beta * LN2) * (x - beta) + k * math.log2(beta) + o)


def camera_log_inverse(y, P) -> np.ndarray:
    beta, k, o = P
    yb = k * math.log2(beta) + o
    y = np.asarray(y, np.float64)
    with np.errstate(over="ignore"):
        return np.where(y >= yb, 2.0 ** ((np.minimum(y, 1e3) - o) / k),
                        beta + (y - yb) * beta * LN2 / k)


@dataclass(frozen=True)
class Coordinates:
    """Log-opponent coordinates z = OPPONENT camlog(D x) of RGB x, D = I + delta 1 w^T
    (each channel gets delta x the luminance: no channel of a colour is 0, so the
    chroma axes z1 = y_r - y_g, z2 = y_b - y_g stay within +-log2((1+delta)/delta) in
    the log part). camlog: log2 above ``P``'s break, linear below it (black and
    values below zero go through smoothly); z0 in [0, 1] over [0, top].
    Along z0 a colour's intensity changes alone: a map homogeneous in intensity
    (durand00) is linear there in the log part."""

    delta: float
    P: tuple

    @property
    def D(self) -> np.ndarray:
        return np.eye(3) + self.delta * np.outer(np.ones(3), Y_WEIGHTS)

    def forward(self, x) -> np.ndarray:
        return camera_log_forward(np.asarray(x, np.float64) @ self.D.T, self.P) @ OPPONENT.T

    def forward_rows(self, x) -> np.ndarray:
        """:meth:`forward` with its 3x3 products written out (the same to rounding; for
        every pixel of a frame, where a BLAS call on N x 3 rows is slow)."""
        return _mul3(camera_log_forward(_mul3(np.asarray(x, np.float64), self.D), self.P),
                     OPPONENT)

    def inverse(self, z) -> np.ndarray:
        u = camera_log_inverse(np.asarray(z, np.float64) @ np.linalg.inv(OPPONENT).T, self.P)
        return u @ np.linalg.inv(self.D).T

    def to_ops(self) -> list:
        """x -> z as colour operations (``clf.py``)."""
        return [matrix_op(self.D), ("log", self.P, False), matrix_op(OPPONENT)]

    def from_ops(self) -> list:
        """z -> x as colour operations."""
        return [matrix_op(np.linalg.inv(OPPONENT)), ("log", self.P, True),
                matrix_op(np.linalg.inv(self.D))]


# --- the lattice ---------------------------------------------------------------------

@dataclass
class Axis:
    """One lattice axis: nodes (grid indices) on a SHAPER_SIZE grid over [lo, hi]."""

    lo: float
    hi: float
    nodes: np.ndarray

    def value(self, j) -> np.ndarray:
        return self.lo + np.asarray(j, np.float64) * (self.hi - self.lo) / (SHAPER_SIZE - 1)

    def index(self, z) -> np.ndarray:
        t = (np.asarray(z, np.float64) - self.lo) / (self.hi - self.lo)
        return np.clip(np.rint(t * (SHAPER_SIZE - 1)), 0, SHAPER_SIZE - 1).astype(int)

    def column(self) -> np.ndarray:
        """The LUT1D column: node k at k / (n - 1), linear between."""
        n = self.nodes.size
        return np.interp(np.arange(SHAPER_SIZE), self.nodes, np.arange(n) / max(n - 1, 1))


def axis_nodes(z: np.ndarray, n: int, lo: float, hi: float, must=(), curve=None) -> Axis:
    """An axis over [lo, hi] with ``n`` nodes for the frame's coordinates ``z``:
    the ends, ``must`` (values), a third at quantiles of z, a third evenly between
    its 0.1th and 100th percentiles, a third evenly in ``curve`` (the output along
    the axis, a function of the grid's values: nodes where the output moves); then
    the narrowest gaps merged, the widest split."""
    ax = Axis(lo, hi, np.array([0]))
    z = z[np.isfinite(z)]
    keep = np.unique(np.concatenate([[0, SHAPER_SIZE - 1], ax.index(np.asarray(must, float))]))
    cand = np.array([], int)
    if z.size:
        m = max(n - keep.size, 3)
        zlo, zhi = float(np.quantile(z, 0.001)), float(z.max())
        q = np.quantile(z, np.linspace(0.0, 1.0, m // 3))
        e = np.linspace(zlo, zhi, m // 3)
        parts = [q, e, [z.min()]]
        if curve is not None:
            j = np.arange(ax.index(zlo), ax.index(zhi) + 1)
            c = np.maximum.accumulate(np.nan_to_num(curve(ax.value(j))))
            if c[-1] > c[0]:
                k = np.searchsorted(c, np.linspace(c[0], c[-1], m - 2 * (m // 3)))
                parts.append(ax.value(j[np.minimum(k, j.size - 1)]))
        cand = ax.index(np.concatenate(parts))
    coord = lambda j: np.asarray(j, np.float64)          # noqa: E731
    idx = _thin(np.union1d(keep, cand), n, keep, coord)
    ax.nodes = _fill(idx, n, coord)
    return ax


def shaper_ops(axes) -> list:
    """z -> lattice coordinates in [0, 1]: per axis an affine map onto the grid, then
    the piecewise-linear LUT1D through the nodes."""
    lo = np.array([a.lo for a in axes])
    span = np.array([a.hi - a.lo for a in axes])
    return [matrix_op(np.diag(1.0 / span), -lo / span),
            ("lut1d", np.stack([a.column() for a in axes], -1))]


def lattice_lut(fn, axes) -> list:
    """Shaper and LUT3D of ``fn`` (z (K, 3) -> output coordinates (K, 3)) on ``axes``."""
    pts = lattice_points([a.value(a.nodes) for a in axes])
    with np.errstate(all="ignore"):
        vals = np.nan_to_num(fn(pts), nan=0.0, posinf=1e4, neginf=-1e4)
    n = [a.nodes.size for a in axes]
    return shaper_ops(axes) + [("lut3d", vals.reshape(n[0], n[1], n[2], 3))]


def frame_axes(z: np.ndarray, n: int, hot: np.ndarray | None = None, tone=None) -> list:
    """The three axes for a frame's coordinates ``z`` (N, 3): intensity over [0, 1];
    the two chroma axes with the same nodes (the tetrahedra then split along z1 = z2,
    where the red and blue channels swap), 0 a node on each. ``hot``: coordinates of
    colours whose exact values should be nodes (most common first); ``tone``: the
    output's lightness along the neutral axis, a function of z0."""
    lam = axis_nodes(z[:, 0], n, min(0.0, float(z[:, 0].min(initial=0.0))),
                     max(1.0, float(z[:, 0].max(initial=1.0))) + 1e-6, must=[0.0], curve=tone)
    c = np.concatenate([z[:, 1], z[:, 2]])
    r = max(float(np.abs(c).max(initial=0.0)) * 1.0001, 1e-6)
    chroma = axis_nodes(c, n, -r, r, must=[0.0])
    if hot is not None and hot.size:
        lam, chroma = _with_colours(lam, chroma, hot, n)
    return [lam, chroma, Axis(chroma.lo, chroma.hi, chroma.nodes)]


def _with_colours(lam: Axis, chroma: Axis, hot: np.ndarray, n: int):
    """Nodes at the coordinates of the most common colours in ``hot`` (N, 3), a
    quarter of the budget each axis, in place of the narrowest gaps."""
    q = np.stack([lam.index(hot[:, 0]), chroma.index(hot[:, 1]), chroma.index(hot[:, 2])], -1)
    colours, counts = np.unique(q, axis=0, return_counts=True)
    order = colours[np.argsort(-counts, kind="stable")]
    add_l, add_c = [], []
    for c in order:
        if len(add_l) >= n // 4 or len(add_c) >= n // 4:
            break
        add_l.append(int(c[0]))
        add_c += [int(c[1]), int(c[2])]
    coord = lambda j: np.asarray(j, np.float64)          # noqa: E731
    out = []
    for ax, add in ((lam, add_l), (chroma, add_c)):
        keep = np.union1d([0, SHAPER_SIZE - 1], add)
        idx = _thin(np.union1d(ax.nodes, keep), n, keep, coord)
        out.append(Axis(ax.lo, ax.hi, _fill(idx, n, coord)))
    return out


# --- the two stages -----------------------------------------------------------------

#: Desaturation of the coordinates' input (``Coordinates.delta``), stages A and B.
DELTA = 0.05


@dataclass
class Stage:
    """One stage of a frame: its colour operations (``clf.py``) and what they are."""

    ops: list
    kind: str
    axes: list = field(default_factory=list)


def fit_linear(raw, pixels: np.ndarray):
    """The 3x3 matrix T with raw(x) = T x for the frame's pixels and a spread of
    other colours, or None when ``raw`` is not linear (to LINEAR_TOL)."""
    rng = np.random.default_rng(7)
    hi = float(np.max(pixels)) if pixels.size else 1.0
    hi = hi if hi > 0 else 1.0
    probe = np.concatenate([sample_rows(pixels, 512),
                            rng.uniform(0.0, 1.0, (256, 3)) * hi * 10.0 ** rng.uniform(-6, 0, (256, 1)),
                            np.eye(3) * hi])
    out = raw(probe)
    T, *_ = np.linalg.lstsq(probe, out, rcond=None)
    err = np.max(np.abs(probe @ T - out)) if out.size else 0.0
    return T.T if err <= LINEAR_TOL * max(float(np.max(np.abs(out))), 1e-30) else None


def lightness(display_linear: np.ndarray) -> np.ndarray:
    """A display lightness of display-linear RGB (for placing nodes): the sRGB curve
    of the luminance, clamped to [0, 1]."""
    Y = np.clip(np.asarray(display_linear, np.float64) @ Y_WEIGHTS,
                0.0, 1.0)
    return np.where(Y <= 0.0031308, 12.92 * Y, 1.055 * Y ** (1 / 2.4) - 0.055)


def positive_top(x: np.ndarray, floor: float) -> float:
    return max(float(np.max(x)) if x.size else 0.0, floor) * 1.0001


def _finite(x) -> np.ndarray:
    x = np.asarray(x).reshape(-1, 3)
    return x[np.isfinite(x).all(axis=1)]


def stage_a(raw, pixels: np.ndarray, n: int = LATTICE, full=None) -> Stage:
    """Stage A for ``raw`` (working cd/m^2 (K, 3) -> raw display-linear (K, 3)) on the
    frame's ``pixels`` (working cd/m^2 (N, 3), >= 0). Out: display-linear >= 0.
    ``full``: every pixel of the frame, when ``pixels`` is a sample of it: the
    lattice's extents cover them all (:func:`extreme_rows`)."""
    px = sample_rows(pixels)
    T = fit_linear(raw, px)
    if T is not None:
        return Stage([matrix_op(T), range_op(0.0, None)], "matrix")
    Y = px @ Y_WEIGHTS
    top = positive_top(px if full is None else _finite(full), 1e-30)
    pos = Y[Y > 0]
    beta = max(float(np.quantile(pos, 0.001)) if pos.size else top * 1e-6, top * 1e-12)
    cin = Coordinates(DELTA, camera_log(min(beta, top * 0.5), top))
    if full is not None:
        px = np.concatenate([px, extreme_rows(full, cin.forward_rows)])
    out = raw(px)
    Yo = out @ Y_WEIGHTS
    with np.errstate(divide="ignore", invalid="ignore"):
        dip = np.where(Yo > 0, -out.min(axis=1) / Yo, 0.0)
    delta_o = max(1.0, 1.5 * float(np.max(dip, initial=0.0)))
    otop = positive_top(out, 1.0)
    cout = Coordinates(delta_o, camera_log(2.0 ** -12, otop))
    fn = lambda z: cout.forward(raw(cin.inverse(z)))     # noqa: E731
    axes = frame_axes(cin.forward(px), n, tone=lambda z0: lightness(
        raw(cin.inverse(np.stack([z0, 0 * z0, 0 * z0], -1)))))
    return Stage(cin.to_ops() + lattice_lut(fn, axes) + cout.from_ops() + [range_op(0.0, None)],
                 f"lut3d {n}", axes)


def stage_b(white: float, knee: float, values: np.ndarray, shoulder, n: int = LATTICE,
            full=None) -> Stage:
    """Stage B: display-linear (>= 0) -> ``shoulder`` (the model's shoulder and clip)
    for a frame whose stage-A values are ``values`` (N, 3). Input and output share
    the coordinates, so the identity below the knee is reproduced exactly.
    ``full``: stage A's values of every pixel, when ``values`` are a sample's."""
    if not (0.0 < knee < 1.0):                 # no shoulder: the clip alone, exact
        return Stage([range_op(0.0, DISPLAY_LINEAR_MAX)], "clip")
    vals = sample_rows(values)
    vals = vals[np.isfinite(vals).all(axis=1)]
    top = min(positive_top(vals if full is None else _finite(full), white),
              DISPLAY_LINEAR_MAX * 1e4)
    c = Coordinates(DELTA, camera_log(2.0 ** -12 * white, top))
    if full is not None:
        vals = np.concatenate([vals, extreme_rows(full, lambda v: c.forward_rows(np.minimum(v, top)))])
    z = c.forward(np.minimum(vals, top))
    hot = z[(vals > knee * white).any(axis=1)]
    fn = lambda zz: c.forward(shoulder(np.maximum(c.inverse(zz), 0.0)))   # noqa: E731
    axes = frame_axes(z, n, hot, tone=lambda z0: lightness(
        shoulder(np.maximum(c.inverse(np.stack([z0, 0 * z0, 0 * z0], -1)), 0.0))))
    return Stage([range_op(0.0, top)] + c.to_ops() + lattice_lut(fn, axes) + c.from_ops()
                 + [range_op(0.0, DISPLAY_LINEAR_MAX)], f"lut3d {n} log-opponent", axes)


def stage_b_rgb(white: float, knee: float, values: np.ndarray, shoulder, n: int = LATTICE,
                full=None) -> Stage:
    """Stage B on an RGB lattice (the same nodes on the three axes): a camera log with
    its linear toe up to the knee (the identity there exact), nodes at 0, the knee,
    evenly above it, and at the channel values of the most common highlight colours.
    ``full``: as for :func:`stage_b` (the lattice's top is their largest value)."""
    if not (0.0 < knee < 1.0):
        return Stage([range_op(0.0, DISPLAY_LINEAR_MAX)], "clip")
    vals = sample_rows(values)
    vals = vals[np.isfinite(vals).all(axis=1)]
    top = min(positive_top(vals if full is None else _finite(full), white),
              DISPLAY_LINEAR_MAX * 1e4)
    P = camera_log(knee * white, top)
    ax = Axis(0.0, 1.0, np.array([0]))
    k_j = int(ax.index(camera_log_forward(knee * white, P)))
    fixed = np.unique([0, int(ax.index(camera_log_forward(0.5 * knee * white, P))), k_j,
                       SHAPER_SIZE - 1])
    idx = np.union1d(fixed, np.rint(np.linspace(k_j, SHAPER_SIZE - 1, max(n // 4, 2))).astype(int))
    hot = vals[(vals > knee * white).any(axis=1)]
    if hot.size:
        q = ax.index(camera_log_forward(np.minimum(hot, top), P))
        colours, counts = np.unique(q, axis=0, return_counts=True)
        for c in colours[np.argsort(-counts, kind="stable")]:
            new = np.setdiff1d(c, idx)        # all three: a bright colour's dark
            # channels are on the shoulder too (desaturated toward white)
            if idx.size + new.size > n:
                break
            idx = np.union1d(idx, new)
    ax.nodes = _fill(idx, n, lambda j: np.asarray(j, np.float64))
    x = camera_log_inverse(ax.value(ax.nodes), P)
    x[0] = 0.0
    m = ax.nodes.size
    out = shoulder(lattice_points((x, x, x))).reshape(m, m, m, 3)
    return Stage([range_op(0.0, top), ("log", P, False),
                  ("lut1d", np.repeat(ax.column()[:, None], 3, axis=1)), ("lut3d", out),
                  range_op(0.0, DISPLAY_LINEAR_MAX)], f"lut3d {n} rgb", [ax, ax, ax])
