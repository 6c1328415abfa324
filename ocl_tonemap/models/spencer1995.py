"""Flares around light sources: Spencer, Shirley, Zimmerman & Greenberg 1995,
as used by Durand & Dorsey 2000, Sec. 6 (Eqs. 7-8).

The eye's point-spread function is a weighted sum of four radial bases
(theta: angle from the source in *degrees*, see docs/models.md; lambda: nm)::

    f0 = 2.61e6 exp(-(theta/0.02)^2)            (Eq. 7)
    f1 = 20.91 / (theta + 0.02)^3
    f2 = 72.37 / (theta + 0.02)^2
    f3 = 436.9 (568/lambda) exp(-(theta - 3 lambda/568)^2)   (lenticular halo)

Each basis is normalised to unit energy over 0 <= theta <= THETA_MAX, so the
weights of Eq. 8 are energy fractions and the PSF conserves light; the
weights follow the pupil diameter D(L_wa). f3 is evaluated per R, G, B at the
dominant wavelengths of the working space's primaries.

Only light sources scatter (Sec. 6.2): the part of each pixel above
``threshold`` x L_wa, ``S = rgb max(0, 1 - threshold L_wa / Y)``, is replaced by
PSF * S; a frame with no pixel above the threshold is unchanged.

Two methods, one interface:

``exact``  float64 FFT convolution with the PSF sampled (and supersampled near
           the centre) at every pixel offset of the frame; the reference.
``fast``   the PSF fitted (non-negative least squares) by a delta plus Gaussians
           spaced ``per_octave`` per octave; each Gaussian is applied on the
           level of a 2x pyramid where it is 1-2 pixels wide (box down,
           bilinear up, the pyramid's own blur subtracted from its variance),
           with the blurs on the device.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from .convolution import EDGE_ZERO, blur_reference, gaussian_taps
from .numerics import nnls
from .photometry import Y_WEIGHTS

#: Normalisation support of each basis, degrees from the source.
THETA_MAX = 90.0
#: Dominant wavelengths (nm) of the BT.709 primaries (R, G, B), for f3.
WAVELENGTHS_RGB = (611.3, 549.1, 464.3)
#: Radiance's findglare: a glare source is brighter than 7x the adaptation luminance.
DEFAULT_THRESHOLD = 7.0
#: Luminance floor for the pupil formula, cd/m^2 (absolute threshold of vision).
PUPIL_L_FLOOR = 1.0e-6


def f0(theta):
    return 2.61e6 * np.exp(-(np.asarray(theta, np.float64) / 0.02) ** 2)


def f1(theta):
    return 20.91 / (np.asarray(theta, np.float64) + 0.02) ** 3


def f2(theta):
    return 72.37 / (np.asarray(theta, np.float64) + 0.02) ** 2


def f3(theta, lam):
    return 436.9 * (568.0 / lam) * np.exp(-(np.asarray(theta, np.float64) - 3.0 * lam / 568.0) ** 2)


def _basis(name: str):
    if name.startswith("f3:"):
        lam = float(name[3:])
        return lambda t: f3(t, lam)
    return {"f0": f0, "f1": f1, "f2": f2}[name]


def pupil_diameter(L_wa) -> np.ndarray:
    """Pupil diameter D, mm, Moon & Spencer 1944 in cd/m^2:
    4.9 - 3 tanh(0.4 log10 L) (1.9 mm in daylight, 7.9 mm in the dark).
    Eq. 8's printed "log(0.5 (L_waR + L_waC) + 1)" is read as this with L the
    mean of the two levels (docs/models.md)."""
    L = np.maximum(np.asarray(L_wa, np.float64), PUPIL_L_FLOOR)
    return 4.9 - 3.0 * np.tanh(0.4 * np.log10(L))


def flare_weights(D: float) -> tuple[float, float, float, float]:
    """(w0, w1, w2, w3), Eq. 8: Spencer et al.'s photopic (D = 2 mm) to scotopic
    (D = 7 mm) sets, linear in the pupil diameter (held at the ends: the pupil
    ranges over 1.9-7.9 mm, and w3 < 0 below 2 mm)."""
    D = min(max(float(D), 2.0), 7.0)      # interpolate between the sets, never beyond
    w1 = 0.478
    w2 = 0.138 + 0.08 * (D - 2.0) / 5.0
    w3 = 0.033 * (D - 2.0) / 5.0
    return 1.0 - w1 - w2 - w3, w1, w2, w3


@functools.lru_cache(maxsize=16)
def basis_norm(name: str) -> float:
    """Energy of one basis over 0..THETA_MAX degrees: int 2 pi theta f dtheta (deg^2)."""
    t = np.concatenate([np.linspace(0.0, 0.5, 50001), np.geomspace(0.5, THETA_MAX, 50001)[1:]])
    y = 2.0 * np.pi * t * _basis(name)(t)
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)))


def _pixel_average(fn, ox: np.ndarray, oy: np.ndarray, deg_per_px: float, sub: int) -> np.ndarray:
    """Mean of fn(theta) over the pixel at offset (ox, oy) px, sub x sub samples."""
    o = (np.arange(sub) + 0.5) / sub - 0.5
    sx, sy = np.meshgrid(o, o)
    th = np.hypot(ox[..., None] + sx.ravel(), oy[..., None] + sy.ravel()) * deg_per_px
    return fn(th).mean(axis=-1)


def basis_kernel(name: str, shape: tuple[int, int], deg_per_px: float) -> np.ndarray:
    """Normalised basis sampled at every offset of a frame ``shape`` = (H, W): an
    (2H-1, 2W-1) array of energy fractions per pixel (centre at [H-1, W-1]).
    Pixels near the centre are supersampled (16x16 within 3 px, 4x4 within 12)."""
    h, w = shape
    fn = _basis(name)
    dy = np.arange(-(h - 1), h)[:, None]
    dx = np.arange(-(w - 1), w)[None, :]
    r = np.hypot(dx, dy)
    k = fn(r * deg_per_px)
    for lim, sub in ((12, 4), (3, 16)):
        m = (np.abs(dx) <= lim) & (np.abs(dy) <= lim)
        if m.any():
            yy, xx = np.nonzero(m)
            o = (np.arange(sub) + 0.5) / sub - 0.5
            ox, oy = np.meshgrid(o, o)
            th = np.hypot(dx[0, xx][:, None] + ox.ravel(), dy[yy, 0][:, None] + oy.ravel())
            k[yy, xx] = fn(th * deg_per_px).mean(axis=1)
    k[r * deg_per_px > THETA_MAX] = 0.0
    k = k * (deg_per_px ** 2 / basis_norm(name))
    k[h - 1, w - 1] = centre_energy(name, deg_per_px)
    return k


def centre_energy(name: str, deg_per_px: float) -> float:
    """Energy share of the source's own pixel: the basis's energy within the disc of
    equal area (f0 is 0.02 deg wide, below any supersampling of a large pixel)."""
    return basis_energy_within(name, deg_per_px / math.sqrt(math.pi))


def channel_bases(ch: int) -> tuple[str, str, str, str]:
    return ("f0", "f1", "f2", f"f3:{WAVELENGTHS_RGB[ch]:g}")


def psf_kernel(shape: tuple[int, int], deg_per_px: float, D: float) -> np.ndarray:
    """The exact discrete PSF per channel, (3, 2H-1, 2W-1)."""
    w = flare_weights(D)
    shared = sum(wi * basis_kernel(b, shape, deg_per_px) for wi, b in zip(w[:3], channel_bases(0)))
    return np.stack([shared + w[3] * basis_kernel(channel_bases(c)[3], shape, deg_per_px)
                     for c in range(3)])


def source_part(rgb: np.ndarray, L_wa: float, threshold: float = DEFAULT_THRESHOLD) -> np.ndarray:
    """The part of each pixel that is a light source: rgb max(0, 1 - threshold L_wa / Y)."""
    rgb = np.asarray(rgb, np.float64)
    Y = rgb @ Y_WEIGHTS
    lim = threshold * max(L_wa, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(Y > lim, 1.0 - lim / np.where(Y > 0, Y, 1.0), 0.0)
    return rgb * f[..., None]


def fft_size(n: int) -> int:
    """The smallest 2^a 3^b 5^c >= n (a length pocketfft transforms fast)."""
    best = 1 << max(0, (n - 1).bit_length())
    f5 = 1
    while f5 < best:
        f35 = f5
        while f35 < best:
            f = f35
            while f < n:
                f *= 2
            best = min(best, f)
            f35 *= 3
        f5 *= 5
    return best


def _fft_shape(h: int, w: int) -> tuple[int, int]:
    """Circular size for a linear 'same' convolution of an (h, w) image with a
    (2h-1, 2w-1) kernel: 2h-1 is enough (the wrapped part of the full result
    never reaches the rows kept), rounded up to a fast length."""
    return fft_size(2 * h - 1), fft_size(2 * w - 1)


def _fftconvolve_same(img: np.ndarray, kern: np.ndarray, kern_fft=None) -> np.ndarray:
    """Linear convolution of (H, W) with a (2H-1, 2W-1) centred kernel, cropped to (H, W)."""
    h, w = img.shape
    H, W = _fft_shape(h, w)
    KF = kern_fft if kern_fft is not None else np.fft.rfft2(kern, (H, W))
    full = np.fft.irfft2(np.fft.rfft2(img, (H, W)) * KF, (H, W))
    return full[h - 1:2 * h - 1, w - 1:2 * w - 1]


@functools.lru_cache(maxsize=8)
def _ring_kernel_fft(shape: tuple[int, int], deg_per_px: float, ch: int) -> np.ndarray:
    """FFT of the normalised f3 kernel of channel ``ch`` for the fast method's ring level."""
    h, w = shape
    return np.fft.rfft2(basis_kernel(channel_bases(ch)[3], shape, deg_per_px), _fft_shape(h, w))


def convolve_exact(src: np.ndarray, deg_per_px: float, D: float) -> np.ndarray:
    """PSF * src, float64, exact (FFT of the full-support kernel)."""
    h, w, _ = src.shape
    K = psf_kernel((h, w), deg_per_px, D)
    return np.stack([np.maximum(_fftconvolve_same(src[..., c], K[c]), 0.0) for c in range(3)],
                    axis=-1)


# --- fast method: delta + Gaussians on a pyramid --------------------------------------

@dataclass(frozen=True)
class GaussianFit:
    """PSF bases fitted by a delta plus Gaussians: weights[basis] = (delta, a_1..a_n)."""

    sigmas: tuple           # px
    weights: dict           # basis name -> np.ndarray (1 + len(sigmas))
    l2_error: dict          # basis name -> ||fit - profile|| / ||profile||, ring-area weighted


def basis_energy_within(name: str, theta: float) -> float:
    """Share of a basis's energy within ``theta`` degrees of the source."""
    theta = min(theta, THETA_MAX)
    t = np.linspace(0.0, min(0.5, theta), 20001)
    if theta > 0.5:
        t = np.concatenate([t, np.geomspace(0.5, theta, 20001)[1:]])
    y = 2.0 * np.pi * t * _basis(name)(t)
    return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(t)) / basis_norm(name))


#: Smallest Gaussian of the fit, px (with the delta it covers f0/f1's sub-pixel core).
FIT_SIGMA_MIN = 0.5
#: Weight of the energy-conservation row in the fit.
FIT_ENERGY_WEIGHT = 1.0e3
#: Weight of the rows for the energy beyond radii 2 px .. R/2 (relative to the basis's
#: own energy there, floored at FIT_TAIL_FLOOR of its energy).
FIT_TAIL_WEIGHT = 1.0
FIT_TAIL_FLOOR = 1.0e-3


@functools.lru_cache(maxsize=8)
def fit_gaussians(shape: tuple[int, int], deg_per_px: float, per_octave: int = 1) -> GaussianFit:
    """Fit each basis's radial profile (pixel-averaged) out to the frame's
    diagonal with non-negative weights: relative residuals on log-spaced radii
    (each octave counts the same) plus one heavily weighted row that keeps
    the fitted energy equal to the basis's energy inside the diagonal."""
    h, w = shape
    R = math.hypot(h, w)
    sig = []
    s = FIT_SIGMA_MIN
    while s <= R:
        sig.append(s)
        s *= 2.0 ** (1.0 / per_octave)
    # sample offsets: every (i, j), 0 <= j <= i <= 12, then log-spaced radii on the axis
    ii, jj = np.nonzero(np.tril(np.ones((13, 13), bool)))
    far = np.geomspace(13.0, max(R, 13.0), 24 * max(1, int(math.log2(R) + 1)))
    ox = np.concatenate([ii.astype(float), far])
    oy = np.concatenate([jj.astype(float), np.zeros_like(far)])
    r = np.hypot(ox, oy)
    sub = np.where(r <= 3, 16, np.where(r <= 12, 4, 1))
    cols = [np.where(r == 0, 1.0, 0.0)]
    for sg in sig:
        t = gaussian_taps(sg)
        at = np.arange(len(t))
        cols.append(np.interp(ox, at, t, right=0.0) * np.interp(oy, at, t, right=0.0))
    A = np.stack(cols, axis=1)
    # each column's energy within the diagonal (a wide Gaussian leaves the frame:
    # counting all of it starved the core of f2, 27% short on the source's pixel)
    inside = np.array([1.0] + [-math.expm1(-R * R / (2.0 * sg * sg)) for sg in sig])
    # each column's energy between rho and the diagonal, at radii rho: the per-pixel
    # rows cannot see energy spread thin over the frame (a wide Gaussian's pixels sit
    # below the residuals' floor), so without these a core the Gaussians cannot
    # shape (f0 at 0.04 deg/px) put 2% of its energy into a 1000 px veil
    rho = np.geomspace(2.0, max(R / 2.0, 4.0), 10)
    beyond = np.array([[0.0] + [math.exp(-p * p / (2.0 * sg * sg)) - (1.0 - inside[k + 1])
                                for k, sg in enumerate(sig)] for p in rho])
    weights, errs = {}, {}
    for name in channel_bases(0)[:3]:
            fn = _basis(name)
            prof = np.empty_like(r)
            for sv in np.unique(sub):
                m = sub == sv
                prof[m] = _pixel_average(fn, ox[m], oy[m], deg_per_px, int(sv))
            prof = prof * (deg_per_px ** 2 / basis_norm(name))
            prof[r * deg_per_px > THETA_MAX] = 0.0
            prof[r == 0] = centre_energy(name, deg_per_px)
            if not prof.max() > 0:              # nothing of this basis reaches a pixel
                weights[name], errs[name] = np.zeros(A.shape[1]), 0.0
                continue
            scale = 1.0 / np.maximum(prof, prof.max() * 1e-6)
            E = basis_energy_within(name, R * deg_per_px)
            E_beyond = np.array([E - basis_energy_within(name, p * deg_per_px) for p in rho])
            wb = FIT_TAIL_WEIGHT / np.maximum(E_beyond, FIT_TAIL_FLOOR * E)
            M = np.vstack([A * scale[:, None], FIT_ENERGY_WEIGHT * inside[None, :],
                           beyond * wb[:, None]])
            b = np.concatenate([prof * scale, [FIT_ENERGY_WEIGHT * E], E_beyond * wb])
            a, _ = nnls(M, b)
            fit = A @ a
            area = r + 0.5
            weights[name] = a
            errs[name] = float(np.sqrt(np.sum(area * (fit - prof) ** 2) / np.sum(area * prof ** 2)))
    return GaussianFit(tuple(sig), weights, errs)


#: A Gaussian goes to the coarsest level where it is still this wide (coarse px).
#: With the [1 3 3 1] pyramid 1.5 px is as accurate as 2 (a point source anywhere:
#: 0.93-1.02 of exact at every pixel either way) and keeps one full-resolution
#: Gaussian fewer; 0.7 px doubles the error (0.86-1.10).
PYRAMID_MIN_SIGMA = 1.5
#: Variance (px^2 of the finer level) one level's round trip adds: the
#: [1 3 3 1]/8 decimation (0.75) and the bilinear 2x upsampling (0.75).
PYRAMID_STEP_VARIANCE = 1.5
#: Coarse levels hold this many samples beyond the frame on every side: the
#: decimation reaches one sample past the frame (light at its edge keeps its
#: place), the upsampling one more.
PYRAMID_MARGIN = 2


def pyramid_level(sigma: float, max_level: int,
                  min_coarse: float | None = None) -> tuple[int, float]:
    """(level, coarse sigma) for a Gaussian of ``sigma`` full-resolution px: the
    coarsest level where it is still >= ``min_coarse`` px wide after removing
    the pyramid's own variance (PYRAMID_STEP_VARIANCE (4^l - 1)/3 px^2)."""
    min_coarse = PYRAMID_MIN_SIGMA if min_coarse is None else min_coarse
    best = (0, sigma)
    for lev in range(1, max_level + 1):
        v = sigma * sigma - PYRAMID_STEP_VARIANCE * (4.0 ** lev - 1.0) / 3.0
        if v <= 0:
            break
        sc = math.sqrt(v) / 2.0 ** lev
        if sc < min_coarse:
            break
        best = (lev, sc)
    return best


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


#: The coarsest pyramid level keeps at least this many pixels across.
PYRAMID_MIN_SIZE = 16
#: The halo ring (f3) is convolved directly on the coarsest level where its
#: width (0.71 deg) is still this many pixels.
RING_MIN_PX = 1.5


def ring_level(deg_per_px: float, max_level: int) -> int:
    lev = 0
    while lev < max_level and (1.0 / math.sqrt(2.0)) / (deg_per_px * 2.0 ** (lev + 1)) >= RING_MIN_PX:
        lev += 1
    return lev


@dataclass(frozen=True)
class FastPlan:
    """What :func:`convolve_fast` does for a frame: the delta's weight, each
    level's Gaussians, the ring, and the level the work is cut at for frames in
    row bands (``split``: the levels from it up are computed whole)."""

    shape: tuple            # (H, W) of the frame
    deg_per_px: float
    a0: float               # weight of the delta
    by_level: dict          # level -> [(coarse sigma, weight), ...]
    lring: int              # level of the f3 ring (-1: no ring)
    w3: float
    top: int                # coarsest level used
    split: int = 0          # levels >= split are computed whole

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


def fast_plan(shape: tuple[int, int], deg_per_px: float, D: float,
                  per_octave: int, fit: GaussianFit | None = None) -> FastPlan:
    """The fast method's plan for a frame of ``shape`` (``fit``: the frame's
    :func:`fit_gaussians`, when the caller has it)."""
    h, w = shape
    if fit is None:
        fit = fit_gaussians((h, w), float(deg_per_px), int(per_octave))
    wts = flare_weights(D)
    a = sum(wi * fit.weights[b] for wi, b in zip(wts[:3], channel_bases(0)))
    max_level = max(0, int(math.log2(max(1, min(h, w)) / PYRAMID_MIN_SIZE)))
    by_level: dict[int, list] = {}
    for k, sg in enumerate(fit.sigmas):
        if a[k + 1] > 0:
            lev, sc = pyramid_level(sg, max_level)
            by_level.setdefault(lev, []).append((sc, a[k + 1]))
    lring = ring_level(deg_per_px, max_level) if wts[3] > 0 else -1
    top = max(max(by_level, default=0), lring)
    return FastPlan((h, w), float(deg_per_px), float(a[0]), by_level, lring, float(wts[3]), top)


def _level_part(plan: FastPlan, lev: int, img: np.ndarray, blur) -> np.ndarray | None:
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
        ring = np.stack([plan.w3 * _fftconvolve_same(img[..., c], None, _ring_kernel_fft(
            img.shape[:2], dl, c)) for c in range(3)], axis=-1)
        part = ring if part is None else part + ring
    return part


def _wide_part(plan: FastPlan, lev0: int, level: np.ndarray, blur) -> np.ndarray | None:
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
                  blur=None) -> np.ndarray:
    """PSF * src approximated on a pyramid.

    f0, f1, f2 (monotone): the fitted delta + Gaussians, each Gaussian on the
    coarsest level where it is >= PYRAMID_MIN_SIGMA px wide; ``blur(img, taps)``
    does the zero-edged separable blur: the device's (``DeviceBlur.blur``) or,
    by default, the float64 reference. f3 (a ring, which centred Gaussians
    cannot make): a direct FFT convolution on the coarsest level where the ring
    is still RING_MIN_PX wide (a few thousand pixels at video sizes). Levels
    above 0 hold PYRAMID_MARGIN samples beyond the frame, so light at the
    frame's edge stays where it is.
    """
    blur = blur or (lambda img, taps: blur_reference(img, taps, EDGE_ZERO))
    h, w, _ = src.shape
    plan = fast_plan((h, w), deg_per_px, D, per_octave)
    src = np.asarray(src, np.float64)
    out = plan.a0 * src
    acc = _wide_part(plan, 0, src, blur)
    if acc is not None:
        out = out + acc
    return np.maximum(out, 0.0)


def apply_flare(rgb: np.ndarray, L_wa: float, L_waR: float, fov_deg: float,
                method: str = "fast", threshold: float = DEFAULT_THRESHOLD, per_octave: int = 1,
                blur=None) -> tuple[np.ndarray, dict]:
    """Add the flares of the frame's light sources (cd/m^2 in, cd/m^2 out).

    Returns the new frame and what was done: sources (pixels), pupil diameter,
    weights, the share of source energy that stayed inside the frame.
    """
    rgb = np.asarray(rgb, np.float64)
    h, w, _ = rgb.shape
    D = float(pupil_diameter(0.5 * (L_wa + L_waR)))
    S = source_part(rgb, L_wa, threshold)
    n_src = int(np.count_nonzero(S.any(axis=-1)))
    info = {"sources": n_src, "pupil_mm": D, "weights": list(flare_weights(D)),
            "method": method, "threshold": threshold}
    if n_src == 0:
        return rgb, info
    deg_per_px = fov_deg / w
    if method == "exact":
        F = convolve_exact(S, deg_per_px, D)
    elif method == "fast":
        F = convolve_fast(S, deg_per_px, D, per_octave, blur)
    else:
        raise ValueError(f"unknown flare method {method!r} (fast | exact)")
    info["energy_in_frame"] = float(F.sum() / max(S.sum(), 1e-300))
    return rgb - S + F, info


# --- the fast method in row bands (frames streamed with bounded memory) ------------------

def banded_fast(shape: tuple[int, int], deg_per_px: float, D: float, per_octave: int = 1,
                max_pixels: int | None = None) -> FastPlan:
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
    plan = fast_plan(tuple(shape), deg_per_px, D, per_octave)
    split = 0
    cap = max(1, int(max_pixels)) if max_pixels else 1
    hh, ww = shape
    while split < plan.top and hh * ww > cap and (plan.lring < 0 or split < plan.lring):
        split += 1
        hh, ww = (hh + 1) // 2, (ww + 1) // 2
    return replace(plan, split=split)


def down_rows(plan: FastPlan, S: np.ndarray, a0: int, c0: int, c1: int) -> np.ndarray:
    """Rows [c0, c1) of level ``plan.split`` (every column, margins too) from the
    source rows [a0, a0 + len(S)), which must hold ``plan.source_rows(split, c0,
    c1)[0]``: the whole frame's values of those rows."""
    need = plan.source_rows(plan.split, c0, c1)
    sizes = plan.sizes
    lv, off = np.asarray(S, np.float64), a0
    for lev in range(1, plan.split + 1):
        lv, off = _down2(lv, sizes, lev - 1, off, need[lev]), need[lev][0]
    return lv


def banded_coarse(plan: FastPlan, level_split: np.ndarray, blur=None) -> np.ndarray | None:
    """The wide part at level ``split``: :func:`convolve_fast`'s accumulator there
    (rows ``plan.rows(split)``), from the source part on that level (the same
    rows, built band by band with :func:`down_rows`). None when no level >= split
    has anything."""
    blur = blur or (lambda img, taps: blur_reference(img, taps, EDGE_ZERO))
    return _wide_part(plan, plan.split, level_split, blur)


def banded_rows(plan: FastPlan, y0: int, y1: int, source_rows, coarse, blur=None):
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
