"""What the observer can see: Adrian 1989's threshold under an operator's own state.

The threshold luminance difference of a target on a background L_b (the glare veil
included, as CIE 88 adds L_seq) is Adrian's steady dL_th (``models/adrian1989.py``)
times the transient factor TAF of the observer's present adaptation
(``adrian1989.transient_factor``): each operator's response gain at L_b now
against its gain when adapted to L_b (``Operator.observer_*``). So the papers' time
courses drive the threshold, frame by frame.

Used by the ``visibility`` calculator (a step in a uniform field, :func:`trace`),
the run's ``--visibility`` planes (:func:`frame_planes`) and the benchmarks.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .backends.flare_exec import fft_size
from .models import adrian1989 as ad
from .models import cie203

#: The default target: 10 arcmin (the issue's and RP-8's small target is 7.3-10).
TARGET_ARCMIN = 10.0
#: The default observation time of a map, s (RP-8's 0.2 s fixation of a driver).
MAP_TIME_S = 0.2


@dataclass(frozen=True)
class Viewing:
    """The target and the observer: size (arcmin), age (years), observation time (s),
    field factor k."""

    size_arcmin: float = TARGET_ARCMIN
    age: float = 25.0
    time_s: float = 2.0
    k: float = ad.FIELD_FACTOR

    def check(self) -> "Viewing":
        if not (self.size_arcmin > 0 and math.isfinite(self.size_arcmin)):
            raise ValueError(f"the target size must be > 0 arcmin (got {self.size_arcmin:g})")
        if not 1.0 <= self.age <= 100.0:
            raise ValueError(f"the age must be 1..100 years (got {self.age:g})")
        if not self.time_s > 0:
            raise ValueError(f"the observation time must be > 0 s (got {self.time_s:g})")
        if not self.k > 0:
            raise ValueError(f"the field factor k must be > 0 (got {self.k:g})")
        return self

    def steady(self, L_b, polarity="positive") -> np.ndarray:
        """Adrian's dL_th (cd/m^2) of backgrounds ``L_b`` (any shape), the eye adapted
        to each; ``polarity`` "positive", "negative" or a boolean array (True:
        negative)."""
        L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
        base = ad.basic_threshold(L, self.size_arcmin)
        neg = np.asarray(polarity == "negative") if isinstance(polarity, str) \
            else np.asarray(polarity, bool)
        fcp = np.where(neg, ad.polarity_factor(L, self.size_arcmin, self.k * base), 1.0)
        tf = 1.0 if math.isinf(self.time_s) else ad.time_factor(L, self.size_arcmin,
                                                                  self.time_s)
        return self.k * base * fcp * tf * ad.age_factor(self.age)

    @property
    def media_gain(self) -> float:
        """The scene-to-retina factor of this observer's ocular media (CIE 203), the
        run's at the same age: the operators' states hold the light behind the media,
        so their responses are read at gain x L_b (Adrian's AF holds the threshold's
        own part of the media, measured on observers with their lenses)."""
        return cie203.media_gain(self.age)


def transient(op, obs: dict, L_b, gain: float = 1.0) -> np.ndarray:
    """TAF of backgrounds ``L_b`` (scene cd/m^2) for an observer in state ``obs`` of
    operator ``op`` whose media pass ``gain`` of the light (:attr:`Viewing.media_gain`)."""
    L = np.asarray(L_b, np.float64) * gain
    return ad.transient_factor(op.observer_steady_slope(L), op.observer_slope(obs, L))


@dataclass(frozen=True)
class TracePoint:
    """The observer ``t`` s after a step: adaptation luminance La, TAF, dL_th (and VL
    of a target)."""

    t: float
    L_a: float
    TAF: float
    dL_th: float
    VL: float | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def trace(op, L_from: float, seconds: float | None, L_b: float, times, view: Viewing,
          polarity: str = "positive", L_target: float | None = None) -> list[TracePoint]:
    """The observer of ``op`` adapted to a neutral field of ``L_from`` (for ``seconds``;
    None: fully), which steps to ``L_b`` at t = 0: its threshold at each of ``times``
    (s after the step, >= 0; the field held at L_b)."""
    g = view.media_gain                       # the operator sees the light behind the media
    Lg = float(L_b) * g
    obs = op.observer_preadapted(float(L_from) * g, seconds)
    steady = float(view.steady(L_b, polarity))
    s_ss = float(op.observer_steady_slope(Lg))
    out, now = [], 0.0
    for t in sorted(float(x) for x in times):
        obs = op.observer_advance(obs, Lg, t - now)
        now = t
        taf = float(ad.transient_factor(s_ss, op.observer_slope(obs, Lg)))
        dl = steady * taf
        vl = None if L_target is None else abs(L_target - L_b) / dl
        out.append(TracePoint(t, float(op.observer_level(obs)) / g, taf, dl, vl))
    return out


# --- the per-frame planes (``run --visibility``) -----------------------------------------

#: The planes of a visibility EXR, in order, with their units (the header says them).
PLANES = (("La", "cd/m^2", "the eye's (cone) adaptation luminance, from the operator's state "
          "(scene luminance: the light behind the media over their gain)"),
          ("Lveil", "cd/m^2", "the glare veil (the flare's scattered light)"),
          ("Lb", "cd/m^2", "the background: the surround's luminance plus the veil"),
          ("dLth", "cd/m^2", "Adrian 1989's threshold x the transient factor"),
          ("VL", "1", "|target - background| / dLth (CIE 140 visibility level)"))
#: The background is the surround of a target: a Gaussian of this many target sizes.
SURROUND = 3.0
#: Samples per decade of L_b of the threshold's table (linear in log-log: <= 1e-6).
TABLE_PER_DECADE = 2048
#: A cell whose midpoint the table's line misses by more than this (relative) is
#: looked up exactly (:class:`ThresholdTable`): the line's error within a cell is at
#: most twice its midpoint's.
MIDPOINT_TOL = 4e-7


def _gauss_fft(F, shape, sigma_px: float, pad: int) -> np.ndarray:
    """A Gaussian of ``sigma_px`` applied to the padded image whose rfft2 is ``F``."""
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    g = np.exp(-2.0 * (np.pi * sigma_px) ** 2 * (fy * fy + fx * fx))
    return np.fft.irfft2(F * g, s=shape)


def _gauss(Y: np.ndarray, sigma_px: float) -> np.ndarray:
    """A Gaussian of ``sigma_px`` on a reflected border (FFT, float64 inside)."""
    if sigma_px <= 0.3:
        return np.asarray(Y, np.float32)
    pad = int(min(max(Y.shape), math.ceil(3.0 * sigma_px) + 1))
    P = np.pad(Y, pad, mode="reflect" if min(Y.shape) > pad else "edge")
    # zero-filled to an FFT-friendly size beyond the reflected border (>= 3 sigma)
    P = np.pad(P, ((0, fft_size(P.shape[0]) - P.shape[0]),
                   (0, fft_size(P.shape[1]) - P.shape[1])))
    out = _gauss_fft(np.fft.rfft2(P), P.shape, sigma_px, pad)
    return out[pad:pad + Y.shape[0], pad:pad + Y.shape[1]].astype(np.float32)


def block_mean(a: np.ndarray, s: int) -> np.ndarray:
    """Means of s x s blocks (the blocks at the bottom and right edges of what pixels
    they have), float32: the whole blocks as a sum of s^2 strided slices (no
    reshaped reductions over short axes, which NumPy runs slowly)."""
    if s <= 1:
        return np.asarray(a, np.float32)
    h, w = a.shape[:2]
    hf, wf = h // s * s, w // s * s
    out = np.empty((-(-h // s), -(-w // s)) + a.shape[2:], np.float32)

    def means(part, ny, nx):
        b = part.reshape(part.shape[0] // ny, ny, part.shape[1] // nx, nx, *a.shape[2:])
        return b.sum(axis=3, dtype=np.float32).sum(axis=1) * np.float32(1.0 / (ny * nx))
    if hf and wf:
        acc = np.zeros((hf // s, wf // s) + a.shape[2:], np.float32)
        for dy in range(s):
            for dx in range(s):
                acc += a[dy:hf:s, dx:wf:s]
        acc *= np.float32(1.0 / (s * s))
        out[:hf // s, :wf // s] = acc
    if hf < h and wf:
        out[-1, :wf // s] = means(a[hf:, :wf], h - hf, s)[0]
    if wf < w and hf:
        out[:hf // s, -1] = means(a[:hf, wf:], s, w - wf)[:, 0]
    if hf < h and wf < w:
        out[-1, -1] = means(a[hf:, wf:], h - hf, w - wf)[0, 0]
    return out


def _upsample_axis(a: np.ndarray, n: int, s: int, axis: int) -> np.ndarray:
    """:func:`upsample` along one axis: output j = s k + p lies at (p + 0.5) / s - 0.5
    cells from block k's centre, the same for every k, so each phase p is one
    weighted sum of two shifted slices (the edges held by a one-cell edge pad)."""
    a = np.moveaxis(np.asarray(a, np.float32), axis, 0)
    ap = np.concatenate([a[:1], a, a[-1:]])
    out = np.empty((n,) + a.shape[1:], np.float32)
    for p in range(min(s, n)):
        off = (p + 0.5) / s - 0.5
        d = -1 if off < 0 else 0
        f = np.float32(off - d)
        c = len(range(p, n, s))
        out[p::s] = ap[d + 1:d + 1 + c] * (np.float32(1.0) - f) + ap[d + 2:d + 2 + c] * f
    return np.moveaxis(out, 0, axis)


def upsample(a: np.ndarray, shape, s: int) -> np.ndarray:
    """Bilinear from a grid s times coarser (block centres) to ``shape``, float32."""
    if s <= 1:
        return np.asarray(a, np.float32)
    return _upsample_axis(_upsample_axis(a, shape[0], s, 0), shape[1], s, 1)


def _step(sigma_px: float, h: int, w: int) -> int:
    """The coarsest grid (1, 2, 4 or 8 times) on which a Gaussian of ``sigma_px`` is
    still >= 1 cell wide (the block mean's own blur, s^2/12 of variance, then adds
    at most 1/12 of sigma^2 ... s = 8: 8 %) and the frame >= 16 cells."""
    s = 1
    while s < 8 and sigma_px / (2 * s) >= 1.0 and min(h, w) // (2 * s) >= 16:
        s *= 2
    return s


def target_and_surround(Y: np.ndarray, size_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(target, surround) luminance of every pixel, float32: Gaussians of the
    target's size (sigma = size / 2.355, the disc's FWHM) and of :data:`SURROUND`
    sizes, on a reflected border; each made on the coarsest grid that holds it a
    cell wide (block means) and brought back bilinearly (the planes are smooth at
    that scale; a 10 arcmin target at 1080p and 50 degrees: the surround on an 8x,
    the target on a 2x grid)."""
    Y = np.asarray(Y, np.float32)
    h, w = Y.shape
    out = []
    for sigma in (max(size_px / 2.355, 0.0), SURROUND * size_px / 2.355):
        s = _step(sigma, h, w)
        out.append(np.maximum(upsample(_gauss(block_mean(Y, s), sigma / s), Y.shape, s), 0.0))
    return out[0], out[1]


def _log_grid(lo: float, hi: float) -> tuple[float, int, np.ndarray]:
    """(a, n, L): the tables' uniform grid of log10 L from a cell edge at or below
    ``lo`` past ``hi``, :data:`TABLE_PER_DECADE` samples a decade."""
    a = math.floor(math.log10(max(lo, 1e-9)) * TABLE_PER_DECADE) / TABLE_PER_DECADE
    n = max(2, int(math.ceil((math.log10(max(hi, 1e-9)) - a) * TABLE_PER_DECADE)) + 2)
    return a, n, 10.0 ** (a + np.arange(n) / TABLE_PER_DECADE)


def _cells(a: float, n: int, Lb) -> tuple[np.ndarray, np.ndarray]:
    """(cell index, fraction within it) of backgrounds ``Lb`` on a :func:`_log_grid`,
    float64 from log10 on (float32 would lose 1e-3 of a cell)."""
    x = np.log10(np.asarray(Lb), dtype=np.float64)
    x -= a
    x *= TABLE_PER_DECADE
    i = x.astype(np.int32)
    np.clip(i, 0, n - 2, out=i)
    x -= i
    return i, x


class ThresholdTable:
    """Adrian's dL_th x TAF of a scalar observer state (``obs`` None: the steady dL_th,
    TAF 1) on a uniform grid of log10 L_b (:data:`TABLE_PER_DECADE`), both
    polarities; a lookup is linear between samples (<= 1e-6), and exact in the cells
    where that line misses the model (a kink or a step: Adrian's range joins, TAF
    reaching 1 or its ceiling, a threshold model's segment joins)."""

    def __init__(self, op, obs: dict, view: Viewing, lo: float, hi: float):
        self.op, self.obs, self.view = op, obs, view
        a, n, L = _log_grid(lo, hi)
        self.a, self.n = a, n
        t = self.exact(L, np.zeros(n, bool)), self.exact(L, np.ones(n, bool))
        # log2 of each sample and the step to the next: one gather each a lookup
        lg2 = np.log2(np.concatenate(t))
        self.base = lg2                  # float64: a float32 log2 near 2^4 loses 1e-6
        self.step = np.append(np.diff(lg2), 0.0)
        # cells whose midpoint the line misses by more than MIDPOINT_TOL hold a kink
        # or a step (Adrian's range joins, TAF meeting 1 or its ceiling, a TVI
        # model's segment joins): looked up exactly
        mid = 10.0 ** (a + (np.arange(n - 1) + 0.5) / TABLE_PER_DECADE)
        self.exact_cell = np.zeros(2 * n, bool)
        for half in range(2):
            lin = np.exp2((lg2[half * n:half * n + n - 1] + lg2[half * n + 1:half * n + n]) / 2)
            ex = self.exact(mid, np.full(n - 1, bool(half)))
            self.exact_cell[half * n:half * n + n - 1] = np.abs(lin / ex - 1.0) > MIDPOINT_TOL

    def exact(self, L, negative) -> np.ndarray:
        if self.obs is None:
            return self.view.steady(L, negative)
        return self.view.steady(L, negative) * transient(self.op, self.obs, L,
                                                          self.view.media_gain)

    def __call__(self, Lb: np.ndarray, negative: np.ndarray) -> np.ndarray:
        """dL_th (float32) of backgrounds ``Lb`` (float32), ``negative`` per pixel."""
        i, x = _cells(self.a, self.n, Lb)
        i += np.asarray(negative, bool).astype(np.int32) * np.int32(self.n)   # (not a
        # masked add: np.add(..., where=) took 10 ms of the lookup's 30 at 1080p)
        near = self.exact_cell[i]
        x *= self.step[i]
        x += self.base[i]
        out = np.exp2(x).astype(np.float32)
        if near.any():                       # cells across a kink: exact
            out[near] = self.exact(Lb[near].astype(np.float64), negative[near])
        return out


class SlopeTable:
    """An operator's steady response gain (``observer_steady_slope``, smooth in L) on
    the uniform log10 grid of :class:`ThresholdTable`, looked up linearly in log-log."""

    def __init__(self, op, lo: float, hi: float):
        self.a, self.n, L = _log_grid(lo, hi)
        self.table = np.log10(np.maximum(op.observer_steady_slope(L), 1e-300))

    def __call__(self, Lb: np.ndarray) -> np.ndarray:
        i, f = _cells(self.a, self.n, Lb)
        t0, t1 = self.table[i], self.table[i + 1]
        return 10.0 ** (t0 + f * (t1 - t0))


def frame_planes(op, obs: dict, Y: np.ndarray, veil: np.ndarray | None, view: Viewing,
                 px_per_arcmin: float) -> dict:
    """The visibility planes of one frame (float32, H x W): ``Y`` the scene's photopic
    luminance (cd/m^2, before the flare), ``veil`` the flare's veil (or None), ``obs``
    the operator's observer state at the frame (:meth:`Operator.observer_of`)."""
    Y = np.asarray(Y, np.float32)
    if not (np.isfinite(Y).all() and Y.min(initial=0.0) >= 0.0):    # else clean already
        Y = np.where(np.isfinite(Y), np.maximum(Y, 0.0), 0.0).astype(np.float32)
    tgt, sur = target_and_surround(Y, view.size_arcmin * px_per_arcmin)
    V = np.zeros_like(Y) if veil is None else np.maximum(np.asarray(veil, np.float32), 0.0)
    Lb = np.maximum(sur + V, np.float32(1e-6))
    dL = tgt - sur
    neg = dL < 0
    if op.observer_per_pixel:
        # the steady threshold and gain from tables of L_b, the gain now per pixel
        g = view.media_gain                  # the states hold the light behind the media
        lo, hi = float(Lb.min()), float(Lb.max())
        L64 = Lb.astype(np.float64)
        if g != 1.0:
            L64 *= g
        taf = ad.transient_factor(SlopeTable(op, lo * g, hi * g)(L64),
                                  op.observer_slope(obs, L64))
        th = ThresholdTable(op, None, view, lo, hi)(Lb, neg) * taf
        La = np.broadcast_to(op.observer_level(obs) / g, Y.shape)
    else:
        th = ThresholdTable(op, obs, view, float(Lb.min()), float(Lb.max()))(Lb, neg)
        La = np.full(Y.shape, float(op.observer_level(obs)) / view.media_gain, np.float32)
    return {"La": np.asarray(La, np.float32), "Lveil": V, "Lb": Lb,
            "dLth": th.astype(np.float32), "VL": (np.abs(dL) / th).astype(np.float32)}
