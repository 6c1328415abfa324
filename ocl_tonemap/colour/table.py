"""The display transform baked into tables (``kernels/display.cl``): shapers, the
baked 1-D/3-D table and its self-check against OCIO, and the cache of baked tables."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import PyOpenColorIO as ocio

from ..models.display import DISPLAY_LINEAR_MAX
from ..base.resources import cache_write, user_cache_dir
from ..version import __version__
from .config import apply_processor

#: One 10-bit code value: the error bound the baked display tables are held to.
CODE_10BIT = 1.0 / 1023.0
#: ``--display-encode`` choices.
DISPLAY_ENCODE_MODES = ("auto", "table", "ocio")
#: The tables' input shapers, both ~log2(1 + |v|/eps) (eps a power of two, per table
#: form, chosen by measurement: docs/models.md):
#: "bits" (1D tables): from the float32 bits of |v| + eps = 2^e (1 + m), m in [0, 1),
#: s = sign(v) (e - log2(eps) + m (4 - m) / 3): smooth (C1), equal to log2(1 + |v|/eps)
#: at every power of two of |v| + eps and within 0.01 between them; a few integer and
#: multiply-add operations on the device, 2.5x faster than log2 on PoCL;
#: "log2" (3D tables): s = sign(v) log2(1 + |v|/eps) exactly (half the 3D error of
#: "bits" at the same lattice size: the gathers, not the log, dominate a 3D lookup).
SHAPER_EPS_1D = 2.0 ** -24
SHAPER_EPS_3D = (2.0 ** -17, 2.0 ** -14, 2.0 ** -20)
#: 1D tables: nodes per octave of |v| + eps (every node interval lies in one octave).
NODES_PER_OCTAVE_1D = 128
_MANT = float(2 ** 23)


def _eps_exponent(eps: float) -> int:
    e = math.log2(eps)
    if e != int(e) or not -126 < e < 100:
        raise ValueError(f"the shaper's eps must be a power of two (got {eps!r})")
    return int(e)


def shaper(v, eps: float, kind: str = "bits") -> np.ndarray:
    """A table input shaper (see SHAPER_EPS_1D) of float32 ``v``, in float64, as
    kernels/display.cl computes it in float32."""
    v32 = np.asarray(v, np.float32)
    if kind == "log2":
        with np.errstate(invalid="ignore"):
            s = np.log2(np.abs(v32.astype(np.float64)) + eps) - _eps_exponent(eps)
        s = np.where(np.isnan(s), np.inf, s)
    else:
        with np.errstate(invalid="ignore"):
            a = (np.abs(v32) + np.float32(eps)).astype(np.float32)
        bits = a.view(np.int32).astype(np.int64)
        m = (bits & 0x7FFFFF) / _MANT
        s = ((bits >> 23) - 127 - _eps_exponent(eps)) + m * (4.0 - m) / 3.0
    return np.where(v32 < 0, -s, s)


def shaper_inverse(s, eps: float, kind: str = "bits") -> np.ndarray:
    """v with shaper(v) = s (float64)."""
    s = np.asarray(s, np.float64)
    a = np.abs(s)
    if kind == "log2":
        return np.copysign(eps * np.expm1(a * np.log(2.0)), s)
    j = np.floor(a)
    m = 2.0 - np.sqrt(np.maximum(4.0 - 3.0 * (a - j), 0.0))
    return np.copysign(np.exp2(j + _eps_exponent(eps)) * (1.0 + m) - eps, s)


def display_probe_set(n_random: int = 100_000, seed: int = 0, vmax: float | None = None,
                      n_axis: int = 4096) -> np.ndarray:
    """(N, 3) float32 working-space RGB spread over the display-linear domain [0, vmax]:
    the grey axis, the primaries and secondaries (dense: log-spaced from 1e-10, linear
    near 0 and over the range), ``n_random`` triples with log-uniform peak in
    [1e-8, vmax] and random chromaticity (a tenth with a zero channel: saturated),
    and saturated colours (one channel at vmax/4..vmax, the others far below)."""
    vmax = float(DISPLAY_LINEAR_MAX if vmax is None else vmax)
    rng = np.random.default_rng(seed)
    v = np.concatenate([[0.0, vmax], np.logspace(-10, np.log10(vmax), n_axis),
                        np.linspace(0.0, 1e-3, n_axis // 4), np.linspace(0.0, 2.0, n_axis // 4),
                        np.linspace(0.0, vmax, n_axis // 4)])
    dirs = np.array([(1, 1, 1), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1)],
                    np.float64)
    parts = [v[:, None, None] * dirs[None]]
    peak = 2.0 ** rng.uniform(np.log2(1e-8), np.log2(vmax), n_random)
    w = rng.uniform(0.0, 1.0, (n_random, 3)) ** rng.choice([0.5, 1.0, 3.0, 8.0], (n_random, 1))
    w[rng.uniform(size=(n_random, 3)) < 0.1] = 0.0
    parts.append(w / np.maximum(w.max(axis=1, keepdims=True), 1e-300) * peak[:, None])
    n_sat = max(n_random // 10, 64)
    sat = rng.uniform(0.0, 1e-3, (n_sat, 3)) * rng.uniform(0.0, 1.0, (n_sat, 1))
    sat[np.arange(n_sat), rng.integers(0, 3, n_sat)] = rng.uniform(vmax / 4, vmax, n_sat)
    parts.append(sat)
    rgb = np.concatenate([p.reshape(-1, 3) for p in parts])
    return np.clip(rgb, 0.0, vmax).astype(np.float32)


@dataclass(frozen=True, eq=False)
class DisplayTable:
    """The forward display/view transform of a config, baked over [0, vmax]^3.

    kind : ``"identity"`` (OCIO's processor is a no-op), ``"1d"`` (per-channel
        separable: ``matrix``/``offset`` then one curve per channel) or ``"3d"``
        (a lattice of ``size``^3 RGB triples, tetrahedral interpolation).
    The table input is ``s = shaper(matrix @ rgb + offset, eps, shaper)`` per channel (3D:
    ``matrix`` is the identity), clamped to [s_lo, s_hi], sampled at ``size`` equally
    spaced points (``table`` is float64: (size, 3), or (size, size, size, 3) indexed
    [r, g, b]); values outside the baked domain read the nearest edge.
    max_error, p999_error : the bake-time self-check against OCIO's CPU processor on
    :func:`display_probe_set` (``probes`` triples), in code values (x 1023 for 10-bit).
    """

    kind: str
    matrix: np.ndarray
    offset: np.ndarray
    eps: float
    s_lo: float
    s_hi: float
    table: np.ndarray
    shaper: str = "bits"
    description: str = ""
    vmax: float = 100.0
    max_error: float = 0.0
    p999_error: float = 0.0
    probes: int = 0

    @property
    def size(self) -> int:
        return int(self.table.shape[0]) if self.kind != "identity" else 0

    @property
    def within_10bit(self) -> bool:
        """The self-check's largest error is below one 10-bit code value."""
        return self.max_error < CODE_10BIT

    def describe(self) -> str:
        if self.kind == "identity":
            return f"{self.description}: identity (no table)"
        form = (f"matrix + 3 x {self.size}-point 1D table" if self.kind == "1d"
                else f"{self.size}^3 3D table, tetrahedral")
        return (f"{self.description}: {form}, {self.shaper} shaper, eps "
                f"2^{math.log2(self.eps):g}; self-check vs OCIO on {self.probes} RGB: "
                f"max {self.max_error * 1023:.3g}, "
                f"99.9% {self.p999_error * 1023:.3g} 10-bit code values")

    def indices(self, rgb) -> np.ndarray:
        """Fractional table coordinates in [0, size - 1] of (..., 3) RGB (float64)."""
        x = np.asarray(rgb, np.float64)[..., :3]
        if self.kind == "1d":
            x = x @ self.matrix.T + self.offset
        scale = (self.size - 1) / (self.s_hi - self.s_lo)
        return np.clip((shaper(x, self.eps, self.shaper) - self.s_lo) * scale, 0.0, self.size - 1)

    def apply(self, rgb) -> np.ndarray:
        """The float64 reference of the table lookup (what kernels/display.cl computes in
        float32): (..., 3) RGB -> (..., 3) code values."""
        x = np.asarray(rgb, np.float64)[..., :3]
        if self.kind == "identity":
            return x.copy()
        f = self.indices(x)
        shape = f.shape
        f = f.reshape(-1, 3)
        i = np.minimum(np.floor(f).astype(np.int64), self.size - 2)
        t = f - i
        T = self.table
        if self.kind == "1d":
            ch = np.arange(3)
            lo, hi = T[i, ch], T[i + 1, ch]
            return (lo + t * (hi - lo)).reshape(shape)
        return _tetrahedral(T, i, t).reshape(shape)

    def error_against(self, cpu_proc, rgb) -> tuple[float, float]:
        """(max, 99.9th percentile) over ``rgb`` (N, 3) of the largest channel's |table -
        OCIO| in code values."""
        x = np.ascontiguousarray(np.asarray(rgb, np.float32).reshape(1, -1, 3))
        ref = x.copy()
        apply_processor(cpu_proc, ref)
        e = np.abs(self.apply(x[0]) - ref[0].astype(np.float64))
        e = np.where(np.isfinite(e), e, np.inf).max(axis=1)
        return float(e.max()), float(np.percentile(e, 99.9))


def _tetrahedral(T: np.ndarray, i: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Tetrahedral interpolation in the (N, N, N, 3) lattice ``T`` at cells ``i`` (M, 3),
    fractions ``t`` (M, 3) (float64; the same six tetrahedra as kernels/display.cl)."""
    r, g, b = t[:, 0:1], t[:, 1:2], t[:, 2:3]
    ir, ig, ib = i[:, 0], i[:, 1], i[:, 2]

    def c(a, bb, cc):
        return T[ir + a, ig + bb, ib + cc]
    c000, c111 = c(0, 0, 0), c(1, 1, 1)
    c100, c010, c001 = c(1, 0, 0), c(0, 1, 0), c(0, 0, 1)
    c110, c101, c011 = c(1, 1, 0), c(1, 0, 1), c(0, 1, 1)
    rg, gb, rb = r >= g, g >= b, r >= b
    out = np.where(rg & gb, c000 + r * (c100 - c000) + g * (c110 - c100) + b * (c111 - c110), 0.0)
    out = np.where(rg & ~gb & rb, c000 + r * (c100 - c000) + b * (c101 - c100)
                   + g * (c111 - c101), out)
    out = np.where(rg & ~gb & ~rb, c000 + b * (c001 - c000) + r * (c101 - c001)
                   + g * (c111 - c101), out)
    out = np.where(~rg & rb, c000 + g * (c010 - c000) + r * (c110 - c010)
                   + b * (c111 - c110), out)
    out = np.where(~rg & ~rb & gb, c000 + g * (c010 - c000) + b * (c011 - c010)
                   + r * (c111 - c011), out)
    out = np.where(~rg & ~gb, c000 + b * (c001 - c000) + g * (c011 - c001)
                   + r * (c111 - c011), out)
    return out


def _leading_matrix(proc) -> tuple[np.ndarray, np.ndarray]:
    """(M, offset) of the matrices that open OCIO's optimized transform (identity if none)."""
    M, o = np.eye(3), np.zeros(3)
    try:
        group = proc.getOptimizedProcessor(ocio.OPTIMIZATION_DEFAULT).createGroupTransform()
    except Exception:  # noqa: BLE001 -- OCIO raises its own Exception type
        return M, o
    for t in group:
        if not isinstance(t, ocio.MatrixTransform):
            break
        m = np.array(t.getMatrix(), np.float64).reshape(4, 4)[:3, :3]
        off = np.array(t.getOffset(), np.float64)[:3]
        if t.getDirection() == ocio.TRANSFORM_DIR_INVERSE:
            m = np.linalg.inv(m)
            off = -m @ off
        M, o = m @ M, m @ o + off
    if not (np.all(np.isfinite(M)) and abs(np.linalg.det(M)) > 1e-9):
        return np.eye(3), np.zeros(3)
    return M, o


def _run_ocio(cpu_proc, rgb: np.ndarray) -> np.ndarray:
    x = np.ascontiguousarray(np.asarray(rgb, np.float32).reshape(1, -1, 3))
    apply_processor(cpu_proc, x)
    return x[0].astype(np.float64)


def bake_display_table(proc, form: str = "auto", size_3d: int = 65,
                       vmax: float | None = None, description: str = "",
                       probe: np.ndarray | None = None) -> DisplayTable:
    """Bake OCIO processor ``proc`` (working -> display code values) over [0, vmax]^3.

    ``form``: ``"1d"``, ``"3d"`` or ``"auto"``: a matrix + per-channel 1D table when
    that reproduces OCIO within one 10-bit code value on the probe set (the transform
    is separable after its leading matrix: found by probing, not by the transform's
    name), else the best 3D table of the shapers tried. Every table sample comes from
    OCIO's CPU processor of ``proc``; the self-check is against it too."""
    vmax = float(DISPLAY_LINEAR_MAX if vmax is None else vmax)
    if form not in ("auto", "1d", "3d"):
        raise ValueError(f"table form must be auto, 1d or 3d (got {form!r})")
    cpu = proc.getDefaultCPUProcessor()
    if proc.isNoOp():
        return DisplayTable("identity", np.eye(3), np.zeros(3), 1.0, 0.0, 1.0,
                            np.zeros((0, 3)), "bits", description, vmax)
    if probe is None:
        probe = display_probe_set(50_000, seed=1, vmax=vmax, n_axis=2048)
    probe = np.asarray(probe, np.float32)
    best = None
    if form in ("auto", "1d"):
        M, o = _leading_matrix(proc)
        corners = np.array(np.meshgrid(*[[0.0, vmax]] * 3, indexing="ij")).reshape(3, -1).T
        post = corners @ M.T + o
        eps = SHAPER_EPS_1D
        k = NODES_PER_OCTAVE_1D
        s_lo = math.floor(float(shaper(post.min(), eps)) * k) / k
        s_hi = math.ceil(float(shaper(post.max(), eps)) * k) / k
        t = shaper_inverse(np.linspace(s_lo, s_hi, round((s_hi - s_lo) * k) + 1), eps)
        # the channel curves: OCIO at the RGB that the matrix maps to grey (t, t, t)
        x = np.linalg.solve(M, (t[:, None] - o).T).T
        tab = _run_ocio(cpu, x)
        best = _checked(DisplayTable("1d", M, o, eps, s_lo, s_hi, tab, "bits", description,
                                     vmax), cpu, probe)
        if form == "1d" or best.within_10bit:
            return best
    # 3D: the shapers in turn, then a finer lattice, until within half the bound; a
    # transform hopelessly far from any (ACES output transforms: tens of code values)
    # is not searched further
    for n in (size_3d, (size_3d - 1) * 3 // 2 + 1):
        for eps in SHAPER_EPS_3D:
            s_hi = float(shaper(vmax, eps, "log2"))
            t = shaper_inverse(np.linspace(0.0, s_hi, n), eps, "log2")
            grid = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
            tab = _run_ocio(cpu, grid).reshape(n, n, n, 3)
            cand = _checked(DisplayTable("3d", np.eye(3), np.zeros(3), eps, 0.0, s_hi, tab,
                                         "log2", description, vmax), cpu, probe)
            if best is None or cand.max_error < best.max_error:
                best = cand
            if cand.max_error > 16 * CODE_10BIT or best.max_error < CODE_10BIT / 2:
                break
        if best.max_error > 16 * CODE_10BIT or best.max_error < CODE_10BIT / 2:
            break
    return best


def cached_display_table(proc, form: str = "auto", size_3d: int = 65,
                         description: str = "") -> DisplayTable:
    """:func:`bake_display_table` kept in the user's cache (``display-tables/*.npz``):
    a bake and its self-check cost ~0.1 s of every start. Keyed by OCIO's cache ID of
    the processor (its transforms and LUT files' contents), the OCIO and project
    versions and the bake's constants; a file that cannot be read is baked again."""
    import dataclasses
    import hashlib
    import json
    ident = json.dumps([proc.getCacheID(), form, size_3d, ocio.GetVersion(), __version__,
                        DISPLAY_LINEAR_MAX, SHAPER_EPS_1D, SHAPER_EPS_3D, NODES_PER_OCTAVE_1D,
                        CODE_10BIT])
    path = user_cache_dir() / "display-tables" / \
        f"{hashlib.sha256(ident.encode()).hexdigest()[:32]}.npz"
    fields = [f.name for f in dataclasses.fields(DisplayTable)]
    try:
        with np.load(path, allow_pickle=False) as z:
            kw = {k: (z[k] if z[k].ndim else z[k].item()) for k in fields}
        kw["kind"], kw["shaper"] = str(kw["kind"]), str(kw["shaper"])
        return DisplayTable(**{**kw, "description": description})
    except (OSError, KeyError, ValueError, TypeError):
        pass
    table = bake_display_table(proc, form, size_3d, description=description)
    import io
    buf = io.BytesIO()
    np.savez(buf, **{k: getattr(table, k) for k in fields})
    cache_write(path, buf.getvalue())       # no cache: baked again next time
    return table


def _checked(table: DisplayTable, cpu, probe: np.ndarray) -> DisplayTable:
    import dataclasses
    mx, p999 = table.error_against(cpu, probe)
    return dataclasses.replace(table, max_error=mx, p999_error=p999, probes=len(probe))
