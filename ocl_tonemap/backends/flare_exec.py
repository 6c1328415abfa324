"""How the flare of ``models/spencer1995.py`` is computed on the host, float64:
the FFT convolutions (the exact method, and the fast method's f3 ring), the
fast method's pyramid (Eq. F: [1 3 3 1]/8 decimation, bilinear upsampling,
levels with margins beyond the frame) and its execution in row bands with halos
for frames that are never whole in memory. The blurs are the float64 reference
or the device's (``blur(img, taps)``); ``backends/opencl/flare.py`` runs the
same plan whole on the device and uses :func:`level_sizes`, :func:`level_margin`
and the ring's FFT from here."""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np

from ..models import spencer1995 as fl
from ..models.convolution import EDGE_ZERO, blur_reference, fft_size, gaussian_taps

# --- FFT convolution (the exact method, the fast method's ring) --------------------------

def _fft_shape(h: int, w: int) -> tuple[int, int]:
    """Circular size for a linear 'same' convolution of an (h, w) image with a
    (2h-1, 2w-1) kernel: 2h-1 is enough (the wrapped part of the full result
    never reaches the rows kept), rounded up to a fast length."""
    return fft_size(2 * h - 1), fft_size(2 * w - 1)


def fftconvolve_same(img: np.ndarray, kern: np.ndarray, kern_fft=None) -> np.ndarray:
    """Linear convolution of (H, W) with a (2H-1, 2W-1) centred kernel, cropped to (H, W)."""
    h, w = img.shape
    H, W = _fft_shape(h, w)
    KF = kern_fft if kern_fft is not None else np.fft.rfft2(kern, (H, W))
    full = np.fft.irfft2(np.fft.rfft2(img, (H, W)) * KF, (H, W))
    return full[h - 1:2 * h - 1, w - 1:2 * w - 1]


@functools.lru_cache(maxsize=8)
def ring_kernel_fft(shape: tuple[int, int], deg_per_px: float, ch: int) -> np.ndarray:
    """FFT of the normalised f3 kernel of channel ``ch`` for the fast method's ring level."""
    h, w = shape
    return np.fft.rfft2(fl.basis_kernel(fl.channel_bases(ch)[3], shape, deg_per_px),
                        _fft_shape(h, w))


@functools.lru_cache(maxsize=16)
def basis_fft(name: str, shape: tuple[int, int], deg_per_px: float) -> np.ndarray:
    """FFT of one normalised basis kernel at a frame size (kept: the mechanism plan
    convolves its proxy, the same size every frame, with a new pupil each time)."""
    return np.fft.rfft2(fl.basis_kernel(name, shape, deg_per_px), _fft_shape(*shape))


def convolve_exact_cached(src: np.ndarray, deg_per_px: float, D: float,
                          age: float | None = None) -> np.ndarray:
    """:func:`convolve_exact` from the cached basis FFTs (the PSF is linear in them:
    the same result to rounding)."""
    h, w, _ = src.shape
    wts = fl.flare_weights(D, age)
    shared = _scatter_fft((h, w), deg_per_px, wts)
    out = []
    for c in range(3):
        KF = shared + wts[3] * basis_fft(fl.channel_bases(c)[3], (h, w), deg_per_px)
        out.append(np.maximum(fftconvolve_same(src[..., c], None, KF), 0.0))
    return np.stack(out, axis=-1)


def _scatter_fft(shape: tuple[int, int], deg_per_px: float, wts) -> np.ndarray:
    """FFT of the PSF's part shared by the channels: w0 f0 + w1 f1 + w2 f2 (no halo)."""
    return sum(wi * basis_fft(b, shape, deg_per_px) for wi, b in zip(wts[:3], fl.channel_bases(0)))


def convolve_scatter_cached(src: np.ndarray, deg_per_px: float, D: float,
                            age: float | None = None) -> np.ndarray:
    """One plane ``src`` (H x W) through the PSF without the lenticular halo (f0, f1,
    f2 at their weights; the same for every channel), float64, >= 0: the light the
    disability-glare veil counts (``--visibility``'s Lveil)."""
    KF = _scatter_fft(src.shape, deg_per_px, fl.flare_weights(D, age))
    return np.maximum(fftconvolve_same(src, None, KF), 0.0)


def convolve_exact(src: np.ndarray, deg_per_px: float, D: float,
                   age: float | None = None) -> np.ndarray:
    """PSF * src, float64, exact (FFT of the full-support kernel)."""
    h, w, _ = src.shape
    K = fl.psf_kernel((h, w), deg_per_px, D, age)
    return np.stack([np.maximum(fftconvolve_same(src[..., c], K[c]), 0.0) for c in range(3)],
                    axis=-1)


# --- the pyramid --------------------------------------------------------------------------

#: Coarse levels hold this many samples beyond the frame on every side: the
#: decimation reaches one sample past the frame (light at its edge keeps its
#: place), the upsampling one more.
PYRAMID_MARGIN = 2


def level_sizes(shape: tuple[int, int], top: int) -> list:
    """(H_l, W_l) of the frame on levels 0..top (each level half the one below,
    rounded up), margins not counted."""
    s = [tuple(shape)]
    for _ in range(top):
        h, w = s[-1]
        s.append(((h + 1) // 2, (w + 1) // 2))
    return s


def level_margin(lev: int) -> int:
    """Samples a level holds beyond the frame on every side (level 0: none)."""
    return PYRAMID_MARGIN if lev else 0


def level_range(sizes: list, lev: int, axis: int) -> tuple[int, int]:
    """[first, end) of the samples level ``lev`` holds along ``axis``, margins included."""
    m = level_margin(lev)
    return -m, sizes[lev][axis] + m


def _down_axis(x: np.ndarray, axis: int, i0: int, j0: int, j1: int) -> np.ndarray:
    """Samples [j0, j1) along ``axis`` of the next coarser level, from a level
    whose samples [i0, i0 + n) are ``x`` (zero elsewhere):
    c[j] = (f[2j - 1] + 3 f[2j] + 3 f[2j + 1] + f[2j + 2]) / 8, the coarse sample
    centred between its two fine ones (the 2x2 box's cell, a smoother filter:
    the box let a source's place inside its cell leak into the flare, +-15%)."""
    x = np.moveaxis(np.asarray(x, np.float64), axis, 0)
    n, N = x.shape[0], j1 - j0
    lo = 2 * j0 - 1
    p = np.zeros((2 * N + 2,) + x.shape[1:], np.float64)
    a, b = max(lo, i0), min(lo + 2 * N + 2, i0 + n)
    if b > a:
        p[a - lo:b - lo] = x[a - i0:b - i0]
    out = p[0:2 * N:2] + p[3:2 * N + 3:2]
    out += 3.0 * (p[1:2 * N + 1:2] + p[2:2 * N + 2:2])
    out *= 0.125
    return np.moveaxis(out, 0, axis)


def _up_axis(c: np.ndarray, axis: int, c0: int, f0: int, f1: int) -> np.ndarray:
    """Samples [f0, f1) along ``axis`` of the next finer level, bilinear, from a
    level whose samples [c0, c0 + n) are ``c``: f[2j] = .75 c[j] + .25 c[j - 1],
    f[2j + 1] = .75 c[j] + .25 c[j + 1] (held at the ends of ``c``, which lie in
    the margins)."""
    i = np.arange(f0, f1)
    j = i // 2
    nb = np.where(i % 2 == 0, j - 1, j + 1)
    last = c0 + c.shape[axis] - 1
    j, nb = np.clip(j, c0, last) - c0, np.clip(nb, c0, last) - c0
    out = 0.75 * np.take(c, j, axis=axis)
    out += 0.25 * np.take(c, nb, axis=axis)
    return out


def _down2(img: np.ndarray, sizes: list, lev: int, r0: int, rows: tuple) -> np.ndarray:
    """Rows ``rows`` = [j0, j1) of level ``lev + 1`` (every column, margins too)
    from rows [r0, r0 + len(img)) of level ``lev`` (every column)."""
    c = _down_axis(img, 0, r0, *rows)
    return _down_axis(c, 1, level_range(sizes, lev, 1)[0], *level_range(sizes, lev + 1, 1))


def _up2(acc: np.ndarray, sizes: list, lev: int, r0: int, rows: tuple) -> np.ndarray:
    """Rows ``rows`` of level ``lev`` (every column) from rows [r0, r0 + len(acc))
    of level ``lev + 1``."""
    f = _up_axis(acc, 0, r0, *rows)
    return _up_axis(f, 1, level_range(sizes, lev + 1, 1)[0], *level_range(sizes, lev, 1))

# --- the plan's geometry: levels, rows and halos -------------------------------------------

@dataclass(frozen=True)
class BandedPlan(fl.FastPlan):
    """A :class:`~ocl_tonemap.models.spencer1995.FastPlan` with its pyramid's rows,
    and the level the work is cut at for frames in row bands (``split``: the
    levels from it up are computed whole; 0 for a whole frame)."""

    split: int = 0              # levels >= split are computed whole

    @property
    def sizes(self) -> list:
        """(H_l, W_l) of every level 0..top, margins not counted."""
        return level_sizes(self.shape, self.top)

    def rows(self, lev: int) -> tuple[int, int]:
        """[first, end) of the rows level ``lev`` holds (margins included)."""
        return level_range(self.sizes, lev, 0)

    def radius(self, lev: int) -> int:
        """Rows the Gaussians of level ``lev`` reach (their taps' radius)."""
        return max((len(gaussian_taps(sc)) - 1 for sc, _ in self.by_level.get(lev, [])),
                   default=0)

    def _clip(self, lev: int, a: int, b: int) -> tuple[int, int]:
        lo, hi = self.rows(lev)
        a = max(lo, a)
        return a, max(a, min(hi, b))

    def source_rows(self, lev: int, c0: int, c1: int) -> list:
        """Rows of levels 0..lev that rows [c0, c1) of level ``lev`` are made from
        (each decimation reaches one finer row beyond its pair on each side)."""
        need = [None] * (lev + 1)
        need[lev] = (c0, c1)
        for k in range(lev - 1, -1, -1):
            a, b = need[k + 1]
            need[k] = self._clip(k, 2 * a - 1, 2 * b + 1)
        return need

    def span(self, y0: int, y1: int) -> tuple[list, list]:
        """For rows [y0, y1) of the flare: (``need``: the rows of the accumulated
        flare on levels 0..split, each level's rows around the finer level's for
        the upsampling; ``made``: the rows of the source part decimated to levels
        0..split-1 the band needs, the Gaussians' halo around ``need`` and what
        coarser levels are made from, None above the finest level that needs none)."""
        L = self.split
        need = [(y0, y1)]
        for lev in range(1, L + 1):
            p0, p1 = need[-1]
            need.append(self._clip(lev, p0 // 2 - 1, (p1 - 1) // 2 + 2))
        made = [None] * max(L, 1)
        for lev in range(L - 1, -1, -1):
            r = None
            R = self.radius(lev)
            if self.by_level.get(lev) or lev == 0:
                n0, n1 = need[lev]
                r = self._clip(lev, n0 - R, n1 + R)
            if lev + 1 < L and made[lev + 1] is not None:
                a, b = made[lev + 1]
                f = self._clip(lev, 2 * a - 1, 2 * b + 1)
                r = f if r is None else (min(r[0], f[0]), max(r[1], f[1]))
            made[lev] = r
        if L == 0:
            made[0] = (y0, y1)
        return need, made


def pyramid_plan(plan: fl.FastPlan, split: int = 0) -> BandedPlan:
    """``plan`` with its pyramid's geometry, cut at level ``split``."""
    return BandedPlan(**{f.name: getattr(plan, f.name) for f in fields(fl.FastPlan)},
                      split=split)


# --- the fast method, whole frames and row bands -----------------------------------------

def _level_part(plan: BandedPlan, lev: int, img: np.ndarray, blur) -> np.ndarray | None:
    """The Gaussians (and the ring) of pyramid level ``lev`` on ``img`` (zero
    beyond it), summed in one order for whole frames and bands alike."""
    part = None
    for sc, wk in plan.by_level.get(lev, []):
        b = np.array(blur(img, gaussian_taps(sc)), np.float64)
        b *= wk                                  # (in place: the same values, less memory)
        if part is None:
            part = b
        else:
            part += b
        del b
    if lev == plan.lring:
        dl = plan.deg_per_px * 2.0 ** lev
        ring = np.stack([plan.w3 * fftconvolve_same(img[..., c], None, ring_kernel_fft(
            img.shape[:2], dl, c)) for c in range(3)], axis=-1)
        part = ring if part is None else part + ring
    return part


def _wide_part(plan: BandedPlan, lev0: int, level: np.ndarray, blur) -> np.ndarray | None:
    """The accumulated flare of levels lev0..top on level ``lev0`` (all its rows
    and margins), from the source part on that level (``level``, the same rows)."""
    sizes = plan.sizes
    levels = {lev0: np.asarray(level, np.float64)}
    for lev in range(lev0 + 1, plan.top + 1):
        levels[lev] = _down2(levels[lev - 1], sizes, lev - 1, plan.rows(lev - 1)[0],
                             plan.rows(lev))
    acc = None
    for lev in range(plan.top, lev0 - 1, -1):
        if acc is not None:
            acc = _up2(acc, sizes, lev, plan.rows(lev + 1)[0], plan.rows(lev))
        part = _level_part(plan, lev, levels.pop(lev), blur)
        if part is not None:
            acc = part if acc is None else acc + part
    return acc


def convolve_fast(src: np.ndarray, deg_per_px: float, D: float, per_octave: int = 1,
                  blur=None, age: float | None = None) -> np.ndarray:
    """PSF * src approximated on a pyramid.

    f0, f1, f2 (monotone): the fitted delta + Gaussians, each Gaussian on the
    coarsest level where it is >= ``spencer1995.PYRAMID_MIN_SIGMA`` px wide; ``blur(img, taps)``
    does the zero-edged separable blur: the device's (``DeviceBlur.blur``) or,
    by default, the float64 reference. f3 (a ring, which centred Gaussians
    cannot make): a direct FFT convolution on the coarsest level where the ring
    is still ``spencer1995.RING_MIN_PX`` wide (a few thousand pixels at video sizes). Levels
    above 0 hold PYRAMID_MARGIN samples beyond the frame, so light at the
    frame's edge stays where it is.
    """
    blur = blur or (lambda img, taps: blur_reference(img, taps, EDGE_ZERO))
    h, w, _ = src.shape
    plan = pyramid_plan(fl.fast_plan((h, w), deg_per_px, D, per_octave, age=age))
    src = np.asarray(src, np.float64)
    out = plan.a0 * src
    acc = _wide_part(plan, 0, src, blur)
    if acc is not None:
        out = out + acc
    return np.maximum(out, 0.0)


def apply_flare(rgb: np.ndarray, L_wa: float, L_waR: float, fov_deg: float,
                method: str = "fast", threshold: float = fl.DEFAULT_THRESHOLD, per_octave: int = 1,
                blur=None, lim: float | None = None,
                age: float | None = None) -> tuple[np.ndarray, dict]:
    """Add the flares of the frame's light sources (cd/m^2 in, cd/m^2 out): the
    part of each pixel above ``lim`` cd/m^2 (default: ``threshold`` x L_wa, the
    paper's test alone; ``effects/flare.py`` ``source_limit``).

    ``age``: the observer's (``spencer1995.observer_pupil``, ``flare_weights``).
    Returns the new frame and what was done: sources (pixels), pupil diameter,
    weights, the share of source energy that stayed inside the frame.
    """
    rgb = np.asarray(rgb, np.float64)
    h, w, _ = rgb.shape
    D = fl.observer_pupil(L_wa, L_waR, fov_deg, (h, w), age)
    S = fl.source_part(rgb, L_wa, threshold) if lim is None else fl.source_part(rgb, 1.0, lim)
    n_src = int(np.count_nonzero(S.any(axis=-1)))
    info = {"sources": n_src, "pupil_mm": D, "weights": list(fl.flare_weights(D, age)),
            "method": method, "threshold": threshold}
    if n_src == 0:
        return rgb, info
    deg_per_px = fov_deg / w
    if method == "exact":
        F = convolve_exact(S, deg_per_px, D, age)
    elif method == "fast":
        F = convolve_fast(S, deg_per_px, D, per_octave, blur, age)
    else:
        raise ValueError(f"unknown flare method {method!r} (fast | exact)")
    info["energy_in_frame"] = float(F.sum() / max(S.sum(), 1e-300))
    return rgb - S + F, info


# --- the fast method in row bands (frames streamed with bounded memory) ------------------

def banded_fast(shape: tuple[int, int], deg_per_px: float, D: float, per_octave: int = 1,
                max_pixels: int | None = None, age: float | None = None) -> BandedPlan:
    """:func:`convolve_fast` split for frames that are never whole in memory.

    The pyramid is cut at level ``split``, the finest whose image holds at most
    ``max_pixels`` pixels (not above the ring's level nor the coarsest level
    used): the levels from ``split`` up (the wide Gaussians and the halo ring,
    whose supports reach across the frame) are computed whole from level
    ``split`` alone (:func:`banded_coarse`), a ``2^split``-times smaller image
    built band by band (:func:`down_rows`); the delta and the Gaussians of the
    finer levels (each <= ~4 px wide on its level, so a few dozen rows reach)
    are computed per output band from the source rows around it
    (:func:`banded_rows`), and the wide part is brought up through the same
    bilinear steps. Every sample is computed as the whole frame computes it,
    from the same neighbours, so the result is :func:`convolve_fast`'s (float64
    blurs: bit for bit; device blurs: bit for bit as well), not a further
    approximation. Memory: a few float64 copies of level ``split`` plus the
    band and its halo."""
    plan = fl.fast_plan(tuple(shape), deg_per_px, D, per_octave, age=age)
    split = 0
    cap = max(1, int(max_pixels)) if max_pixels else 1
    hh, ww = shape
    while split < plan.top and hh * ww > cap and (plan.lring < 0 or split < plan.lring):
        split += 1
        hh, ww = (hh + 1) // 2, (ww + 1) // 2
    return pyramid_plan(plan, split)


def down_rows(plan: BandedPlan, S: np.ndarray, a0: int, c0: int, c1: int) -> np.ndarray:
    """Rows [c0, c1) of level ``plan.split`` (every column, margins too) from the
    source rows [a0, a0 + len(S)), which must hold ``plan.source_rows(split, c0,
    c1)[0]``: the whole frame's values of those rows."""
    need = plan.source_rows(plan.split, c0, c1)
    sizes = plan.sizes
    lv, off = np.asarray(S, np.float64), a0
    for lev in range(1, plan.split + 1):
        lv, off = _down2(lv, sizes, lev - 1, off, need[lev]), need[lev][0]
    return lv


def banded_coarse(plan: BandedPlan, level_split: np.ndarray, blur=None) -> np.ndarray | None:
    """The wide part at level ``split``: :func:`convolve_fast`'s accumulator there
    (rows ``plan.rows(split)``), from the source part on that level (the same
    rows, built band by band with :func:`down_rows`). None when no level >= split
    has anything."""
    blur = blur or (lambda img, taps: blur_reference(img, taps, EDGE_ZERO))
    return _wide_part(plan, plan.split, level_split, blur)


def banded_rows(plan: BandedPlan, y0: int, y1: int, source_rows, coarse, blur=None):
    """Rows [y0, y1) of PSF * S (:func:`convolve_fast`'s values): ``source_rows(a,
    b)`` gives rows [a, b) of the source part S (float64, H x W x 3 sliced);
    ``coarse`` is :func:`banded_coarse`'s result. Returns (F rows, S rows)."""
    blur = blur or (lambda img, taps: blur_reference(img, taps, EDGE_ZERO))
    L, sizes = plan.split, plan.sizes
    need, made = plan.span(y0, y1)
    a0, a1 = made[0]
    S = np.asarray(source_rows(a0, a1), np.float64)
    parts = {}
    lv, off = S, a0
    for lev in range(L):
        if made[lev] is None:
            break
        if lev:
            lv, off = _down2(lv, sizes, lev - 1, off, made[lev]), made[lev][0]
        if plan.by_level.get(lev):
            n0, n1 = need[lev]
            R = plan.radius(lev)              # blur only the rows that reach the band
            b0, b1 = max(off, n0 - R), min(off + len(lv), n1 + R)
            part = _level_part(plan, lev, lv[b0 - off:b1 - off], blur)
            if part is not None:
                parts[lev] = part[n0 - b0:n1 - b0]
    acc = None
    if coarse is not None:
        n0, n1 = need[L]
        r0 = plan.rows(L)[0]
        acc = coarse[n0 - r0:n1 - r0]
    for lev in range(L - 1, -1, -1):
        if acc is not None:
            acc = _up2(acc, sizes, lev, need[lev + 1][0], need[lev])
        part = parts.pop(lev, None)
        if part is not None:
            if acc is None:
                acc = part
            else:
                acc += part
    Sy = S[y0 - a0:y1 - a0]
    out = plan.a0 * Sy
    if acc is not None:
        out += acc
    del acc
    return np.maximum(out, 0.0, out=out), Sy
