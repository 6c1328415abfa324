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
from dataclasses import dataclass

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


def _fftconvolve_same(img: np.ndarray, kern: np.ndarray, kern_fft=None) -> np.ndarray:
    """Linear convolution of (H, W) with a (2H-1, 2W-1) centred kernel, cropped to (H, W)."""
    h, w = img.shape
    H, W = 3 * h - 2, 3 * w - 2
    KF = kern_fft if kern_fft is not None else np.fft.rfft2(kern, (H, W))
    full = np.fft.irfft2(np.fft.rfft2(img, (H, W)) * KF, (H, W))
    return full[h - 1:2 * h - 1, w - 1:2 * w - 1]


@functools.lru_cache(maxsize=8)
def _ring_kernel_fft(shape: tuple[int, int], deg_per_px: float, ch: int) -> np.ndarray:
    """FFT of the normalised f3 kernel of channel ``ch`` for the fast method's ring level."""
    h, w = shape
    return np.fft.rfft2(basis_kernel(channel_bases(ch)[3], shape, deg_per_px), (3 * h - 2, 3 * w - 2))


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
            M = np.vstack([A * scale[:, None], FIT_ENERGY_WEIGHT * np.ones((1, A.shape[1]))])
            b = np.concatenate([prof * scale, [FIT_ENERGY_WEIGHT * E]])
            a, _ = nnls(M, b)
            fit = A @ a
            area = r + 0.5
            weights[name] = a
            errs[name] = float(np.sqrt(np.sum(area * (fit - prof) ** 2) / np.sum(area * prof ** 2)))
    return GaussianFit(tuple(sig), weights, errs)


#: A Gaussian goes to the coarsest level where it is still this wide (coarse px):
#: 1 px is 1.4x faster, 2 px cuts the largest error next to a source from 28% to 10%
#: (benchmarks/results/flare.md).
PYRAMID_MIN_SIGMA = 2.0


def pyramid_level(sigma: float, max_level: int,
                  min_coarse: float | None = None) -> tuple[int, float]:
    """(level, coarse sigma) for a Gaussian of ``sigma`` full-resolution px: the
    coarsest level where it is still >= ``min_coarse`` px wide after removing
    the pyramid's own variance ((4^l - 1)/3 px^2: box down + bilinear up)."""
    min_coarse = PYRAMID_MIN_SIGMA if min_coarse is None else min_coarse
    best = (0, sigma)
    for lev in range(1, max_level + 1):
        v = sigma * sigma - (4.0 ** lev - 1.0) / 3.0
        if v <= 0:
            break
        sc = math.sqrt(v) / 2.0 ** lev
        if sc < min_coarse:
            break
        best = (lev, sc)
    return best


def _down2(a: np.ndarray) -> np.ndarray:
    """2x2 box average; an odd last row/column is repeated (edge padding)."""
    h, w = a.shape[:2]
    pad = [(0, h % 2), (0, w % 2)] + [(0, 0)] * (a.ndim - 2)
    p = np.pad(a, pad, mode="edge") if (h % 2 or w % 2) else a
    return 0.25 * (p[0::2, 0::2] + p[1::2, 0::2] + p[0::2, 1::2] + p[1::2, 1::2])


def _up2(a: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear 2x upsampling to ``shape``: fine[2j] = .75 c[j] + .25 c[j-1], the
    coarse field held at its edges (it is smooth there: blurred light)."""
    def axis_up(x, n, ax):
        first = np.take(x, [0], axis=ax)
        last = np.take(x, [x.shape[ax] - 1], axis=ax)
        prev = np.concatenate([first, x], axis=ax)[(slice(None),) * ax + (slice(0, -1),)]
        nxt = np.concatenate([x, last], axis=ax)[(slice(None),) * ax + (slice(1, None),)]
        even, odd = 0.75 * x + 0.25 * prev, 0.75 * x + 0.25 * nxt
        out = np.stack([even, odd], axis=ax + 1)
        out = out.reshape(x.shape[:ax] + (2 * x.shape[ax],) + x.shape[ax + 1:])
        return np.take(out, np.arange(n), axis=ax)
    return axis_up(axis_up(a, shape[0], 0), shape[1], 1)


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


def _pyramid_plan(shape: tuple[int, int], deg_per_px: float, D: float, per_octave: int):
    """The fast method's plan for a frame of ``shape``: (fit, the four basis weights,
    the shared Gaussian weights, level -> [(sigma on the level, weight)], the ring's
    level or -1, the coarsest level used)."""
    h, w = shape
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
    return fit, wts, a, by_level, lring, top


def convolve_fast(src: np.ndarray, deg_per_px: float, D: float, per_octave: int = 1,
                  blur=None) -> np.ndarray:
    """PSF * src approximated on a pyramid.

    f0, f1, f2 (monotone): the fitted delta + Gaussians, each Gaussian on the
    coarsest level where it is >= 1 px wide; ``blur(img, taps)`` does the
    zero-edged separable blur: the device's (``DeviceBlur.blur``) or, by
    default, the float64 reference. f3 (a ring, which centred Gaussians cannot
    make): a direct FFT convolution on the coarsest level where the ring is
    still RING_MIN_PX wide (a few thousand pixels at video sizes).
    """
    blur = blur or (lambda img, taps: blur_reference(img, taps, EDGE_ZERO))
    h, w, _ = src.shape
    fit, (w0, w1, w2, w3), a, by_level, lring, top = _pyramid_plan((h, w), deg_per_px, D,
                                                                  per_octave)
    levels = [np.asarray(src, np.float64)]
    for _ in range(top):
        levels.append(_down2(levels[-1]))
    acc = None
    for lev in range(len(levels) - 1, -1, -1):
        if acc is not None:
            acc = _up2(acc, levels[lev].shape[:2])
        part = None
        for sc, wk in by_level.get(lev, []):
            b = wk * np.asarray(blur(levels[lev], gaussian_taps(sc)), np.float64)
            part = b if part is None else part + b
        if lev == lring:
            lv = levels[lev]
            dl = deg_per_px * 2.0 ** lev
            ring = np.stack([w3 * _fftconvolve_same(lv[..., c], None, _ring_kernel_fft(
                lv.shape[:2], dl, c)) for c in range(3)], axis=-1)
            part = ring if part is None else part + ring
        if part is not None:
            acc = part if acc is None else acc + part
    out = a[0] * np.asarray(src, np.float64)
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

@dataclass(frozen=True)
class BandedFast:
    """:func:`convolve_fast` split for frames that are never whole in memory.

    The pyramid is cut at level ``split``: the levels from ``split`` up (the
    wide Gaussians and the halo ring, whose supports reach across the frame)
    are computed whole from level ``split`` alone, a ``2^split``-times smaller
    image built band by band (:meth:`coarse`); the delta and the Gaussians of
    the finer levels (each <= ~4 px wide on its level, so a few dozen rows
    reach) are computed per output band from the source rows around it
    (:meth:`rows`), and the wide part is brought up through the same bilinear
    steps. Box averages over rows aligned to ``2^split``, the zero-edged blurs
    with halo rows and the clamped upsampling steps are the whole-frame ones,
    so the result is :func:`convolve_fast`'s to rounding (float32 blurs on the
    device: ~1e-6 relative; the float64 reference blur: ~1e-12), not a further
    approximation. ``split`` <= the ring's level (the ring stays whole);
    memory: a few float64 copies of level ``split`` plus the band and its halo.
    """

    shape: tuple            # (H, W) of the frame
    deg_per_px: float
    a0: float               # weight of the delta
    by_level: dict          # level -> [(coarse sigma, weight), ...]
    lring: int              # level of the f3 ring (-1: no ring)
    w3: float
    top: int                # coarsest level used
    split: int              # levels >= split are computed whole

    @property
    def sizes(self) -> list:
        """(H_l, W_l) of every level 0..top (``_down2`` pads odd sizes)."""
        s = [tuple(self.shape)]
        for _ in range(self.top):
            h, w = s[-1]
            s.append(((h + 1) // 2, (w + 1) // 2))
        return s

    def radius(self, lev: int) -> int:
        """Rows the Gaussians of level ``lev`` reach (their taps' radius)."""
        return max((len(gaussian_taps(sc)) - 1 for sc, _ in self.by_level.get(lev, [])),
                   default=0)

    def span(self, y0: int, y1: int):
        """(rows needed on each level 0..split to make rows [y0, y1), source rows
        [a0, a1) they come from): the band, the taps' halo, the upsampling's
        neighbours, aligned to the boxes of level ``split - 1``."""
        L, sizes = self.split, self.sizes
        need = [(y0, y1)]
        for lev in range(1, L + 1):
            p0, p1 = need[-1]
            need.append((max(0, p0 // 2 - 1), min(sizes[lev][0], (p1 - 1) // 2 + 2)))
        a0, a1 = y0, y1
        for lev in range(1, L):
            R = self.radius(lev)
            if R:
                a0 = min(a0, max(0, need[lev][0] - R) * 2 ** lev)
                a1 = max(a1, min(sizes[lev][0], need[lev][1] + R) * 2 ** lev)
        R = self.radius(0)
        a0, a1 = min(a0, max(0, y0 - R)), max(a1, y1 + R)
        step = 2 ** max(L - 1, 0)
        return need, (a0 // step) * step, min(self.shape[0], -(-a1 // step) * step)


def banded_fast(shape: tuple[int, int], deg_per_px: float, D: float, per_octave: int = 1,
                max_pixels: int | None = None) -> BandedFast:
    """The plan of :func:`convolve_fast` for a frame of ``shape`` = (H, W), split at
    the finest level whose image holds at most ``max_pixels`` pixels (not above
    the ring's level nor the coarsest level used)."""
    h, w = shape
    fit, (w0, w1, w2, w3), a, by_level, lring, top = _pyramid_plan((h, w), deg_per_px, D,
                                                                  per_octave)
    split = 0
    cap = max(1, int(max_pixels)) if max_pixels else 1
    hh, ww = h, w
    while split < top and hh * ww > cap and (lring < 0 or split < lring):
        split += 1
        hh, ww = (hh + 1) // 2, (ww + 1) // 2
    return BandedFast((h, w), float(deg_per_px), float(a[0]), by_level, lring, float(w3),
                      top, split)


def _level_part(plan: BandedFast, lev: int, img: np.ndarray, blur) -> np.ndarray | None:
    """The Gaussians (and the ring) of pyramid level ``lev`` on ``img``, summed in
    :func:`convolve_fast`'s order."""
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


def banded_coarse(plan: BandedFast, level_split: np.ndarray, blur=None) -> np.ndarray | None:
    """The wide part at level ``split``: :func:`convolve_fast`'s accumulator there,
    from the source part box-averaged to that level (``level_split``, built band
    by band with :func:`down_rows`). None when no level >= split has anything."""
    blur = blur or (lambda img, taps: blur_reference(img, taps, EDGE_ZERO))
    levels = {plan.split: np.asarray(level_split, np.float64)}
    for lev in range(plan.split + 1, plan.top + 1):
        levels[lev] = _down2(levels[lev - 1])
    acc = None
    for lev in range(plan.top, plan.split - 1, -1):
        if acc is not None:
            acc = _up2(acc, levels[lev].shape[:2])
        part = _level_part(plan, lev, levels[lev], blur)
        if part is not None:
            acc = part if acc is None else acc + part
        del levels[lev]
    return acc


def down_rows(S: np.ndarray, levels: int) -> np.ndarray:
    """``levels`` 2x box steps of rows that start on a multiple of ``2^levels`` and
    end on one or at the frame's last row: the same rows as the whole frame's."""
    for _ in range(levels):
        S = _down2(S)
    return S


def _up2_rows(c: np.ndarray, c0: int, hc: int, f0: int, f1: int, wf: int) -> np.ndarray:
    """Rows [f0, f1) of ``_up2`` of a level whose rows [c0, c0 + len(c)) are ``c``
    (of ``hc`` rows in all; the fine level is ``wf`` wide): the same values, with
    fewer temporaries."""
    i = np.arange(f0, f1)
    j = i // 2
    nb = np.where(i % 2 == 0, np.maximum(j - 1, 0), np.minimum(j + 1, hc - 1))
    x = 0.75 * c[j - c0]
    x += 0.25 * c[nb - c0]
    out = np.empty((x.shape[0], 2 * x.shape[1]) + x.shape[2:], np.float64)
    ev, od = out[:, 0::2], out[:, 1::2]
    np.multiply(x, 0.75, out=ev)                 # .75 x + .25 x[k - 1], held at the edge
    ev[:, 1:] += 0.25 * x[:, :-1]
    ev[:, :1] += 0.25 * x[:, :1]
    np.multiply(x, 0.75, out=od)                 # .75 x + .25 x[k + 1]
    od[:, :-1] += 0.25 * x[:, 1:]
    od[:, -1:] += 0.25 * x[:, -1:]
    return out[:, :wf]


def banded_rows(plan: BandedFast, y0: int, y1: int, source_rows, coarse, blur=None):
    """Rows [y0, y1) of PSF * S (:func:`convolve_fast`'s values): ``source_rows(a,
    b)`` gives rows [a, b) of the source part S (float64, H x W x 3 sliced);
    ``coarse`` is :func:`banded_coarse`'s result. Returns (F rows, S rows)."""
    blur = blur or (lambda img, taps: blur_reference(img, taps, EDGE_ZERO))
    L, sizes = plan.split, plan.sizes
    need, a0, a1 = plan.span(y0, y1)
    S = np.asarray(source_rows(a0, a1), np.float64)
    parts = {}
    lv, off = S, a0
    for lev in range(L):
        if lev:
            lv, off = _down2(lv), off // 2
        if plan.by_level.get(lev):
            n0, n1 = need[lev]
            R = plan.radius(lev)              # blur only the rows that reach the band
            b0, b1 = max(off, n0 - R), min(off + len(lv), n1 + R)
            parts[lev] = _level_part(plan, lev, lv[b0 - off:b1 - off], blur)[n0 - b0:n1 - b0]
    acc = None
    if coarse is not None:
        n0, n1 = need[L]
        acc = coarse[n0:n1]
    for lev in range(L - 1, -1, -1):
        if acc is not None:
            acc = _up2_rows(acc, need[lev + 1][0], sizes[lev + 1][0], need[lev][0],
                            need[lev][1], sizes[lev][1])
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
