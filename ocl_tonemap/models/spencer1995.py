"""Flares around light sources: Spencer, Shirley, Zimmerman & Greenberg 1995,
as used by Durand & Dorsey 2000, Sec. 6 (Eqs. 7-8).

The eye's point-spread function is a weighted sum of four radial bases
(theta: angle from the source in *degrees*, see docs/models.md; lambda: nm),
Eq. 7::

    f0 = 2.61e6 exp(-(theta/0.02)^2)
    f1 = 20.91 / (theta + 0.02)^3
    f2 = 72.37 / (theta + 0.02)^2
    f3 = 436.9 (568/lambda) exp(-(theta - 3 lambda/568)^2)   (lenticular halo)

Each basis is normalised to unit energy over 0 <= theta <= THETA_MAX, so the
weights of Eq. 8 (:func:`flare_weights`) are energy fractions and the PSF
conserves light; the weights follow the pupil diameter D(L_wa) (Moon & Spencer
1944, :func:`pupil_diameter`). f3 is evaluated per R, G, B at the dominant
wavelengths of the working space's primaries.

Only light sources scatter (Sec. 6.2): the part of each pixel above
``threshold`` x L_wa, ``S = rgb max(0, 1 - threshold L_wa / Y)``
(:func:`source_part`), is replaced by PSF * S; a frame with no pixel above the
threshold is unchanged.

Two methods, one interface (executed in ``backends/flare_exec.py``):

``exact``  PSF * S with the PSF sampled (and supersampled near the centre) at
           every pixel offset of the frame (:func:`psf_kernel`); the reference.
``fast``   the PSF fitted (non-negative least squares, :func:`fit_gaussians`)
           by a delta plus Gaussians spaced ``per_octave`` per octave; each
           Gaussian applied on the level of a 2x pyramid where it is 1-2 pixels
           wide ([1 3 3 1]/8 down, bilinear up, the pyramid's own blur
           subtracted from its variance): Eq. F, :class:`FastPlan`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from . import cie146, watson2012
from .convolution import gaussian_taps
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
    mean of the two levels (docs/models.md).

    >>> round(float(pupil_diameter(1.0)), 2), round(float(pupil_diameter(1e6)), 2)
    (4.9, 1.95)
    """
    L = np.maximum(np.asarray(L_wa, np.float64), PUPIL_L_FLOOR)
    return 4.9 - 3.0 * np.tanh(0.4 * np.log10(L))


#: The observer's age where none is given, years: Adrian's threshold's (the flare
#: without an age keeps Eq. 8 as printed: docs/models.md, "Observer age").
DEFAULT_AGE = 25.0
#: ``--age spencer``: no observer's age, Eq. 8 as Spencer et al. print it (the same as
#: None in this module's functions; a value of its own so that the option's default,
#: DEFAULT_AGE, does not take its place).
LITERAL_AGE = "spencer"


def is_literal(age) -> bool:
    """True for no age (None or :data:`LITERAL_AGE`): Eq. 8 and its pupil as printed."""
    return age is None or age == LITERAL_AGE


#: The visual field's largest angular area, deg^2 (a fisheye frame counts as this).
FIELD_AREA_MAX = 180.0 * 130.0


def observer_pupil(G_cone: float, G_rod: float, fov_deg: float, shape,
                   age: float | None = None) -> float:
    """The flare's pupil, mm: Watson & Yellott 2012 (``models/watson2012.py``) for an
    observer of ``age`` seeing the frame (photopic G_cone over the frame's angular
    area, both eyes); with ``age`` None, Eq. 8's Moon & Spencer pupil of the mean
    level, as Durand & Dorsey print it (:func:`pupil_diameter`)."""
    if is_literal(age):
        return float(pupil_diameter(0.5 * (G_cone + G_rod)))
    h, w = (int(v) for v in shape[:2])
    area = min(float(fov_deg) ** 2 * h / max(w, 1), FIELD_AREA_MAX)
    return float(watson2012.pupil_diameter(max(float(G_cone), 0.0), area, age))


def spencer_weights(D: float) -> tuple[float, float, float, float]:
    """(w0, w1, w2, w3), Eq. 8 as printed: Spencer et al.'s photopic (D = 2 mm) to
    scotopic (D = 7 mm) sets, linear in the pupil diameter (held at the ends: the
    pupil ranges over 1.9-7.9 mm, and w3 < 0 below 2 mm).

    >>> [round(w, 3) for w in spencer_weights(2.0)]
    [0.384, 0.478, 0.138, 0.0]
    """
    D = min(max(float(D), 2.0), 7.0)      # interpolate between the sets, never beyond
    w1 = 0.478
    w2 = 0.138 + 0.08 * (D - 2.0) / 5.0
    w3 = 0.033 * (D - 2.0) / 5.0
    return 1.0 - w1 - w2 - w3, w1, w2, w3


#: Angles (degrees) over which the smooth scatter is held to CIE 146's glare equation.
GLARE_FIT_DEG = (2.0, 20.0)
_SR_PER_DEG2 = (180.0 / math.pi) ** 2


@functools.lru_cache(maxsize=512)
def _glare_gains(D: float, age: float) -> tuple[float, float]:
    th = np.geomspace(*GLARE_FIT_DEG, 33)
    _, w1, w2, _ = spencer_weights(D)
    A = np.stack([w1 * f1(th) / basis_norm("f1"), w2 * f2(th) / basis_norm("f2")], 1)
    b = cie146.veil_per_lux(th, age)
    g, _ = nnls(A * _SR_PER_DEG2 / b[:, None], np.ones_like(th))
    return float(g[0]), float(g[1])


def glare_gains(D: float, age: float) -> tuple[float, float]:
    """(g1, g2): the factors on Spencer's f1 and f2 weights that hold the smooth
    scatter, per steradian, to CIE 146's general disability-glare equation (brown
    eyes) of an observer of ``age`` at 2-20 degrees (relative least squares, >= 0).
    The lenticular halo (f3) keeps Spencer's weight: CIE 146 has no ring."""
    return _glare_gains(round(float(D), 3), round(float(age), 1))


def flare_weights(D: float, age: float | None = None) -> tuple[float, float, float, float]:
    """(w0, w1, w2, w3) of the PSF: Eq. 8 with the smooth scatter (w1, w2) scaled by
    :func:`glare_gains` for an observer of ``age`` (None: Eq. 8 as printed), the
    rest of the light in the core w0 (never below 0: the scatter then scaled down).

    >>> round(sum(flare_weights(pupil_diameter(1e-3), 25.0)), 12)
    1.0
    >>> flare_weights(2.0) == spencer_weights(2.0)
    True
    """
    w0, w1, w2, w3 = spencer_weights(D)
    if is_literal(age):
        return w0, w1, w2, w3
    g1, g2 = glare_gains(D, age)
    w1, w2 = g1 * w1, g2 * w2
    if w1 + w2 + w3 > 1.0:                  # more scatter than light: all of it scattered
        k = (1.0 - w3) / (w1 + w2)
        w1, w2 = k * w1, k * w2
    return max(0.0, 1.0 - w1 - w2 - w3), w1, w2, w3


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


def psf_kernel(shape: tuple[int, int], deg_per_px: float, D: float,
               age: float | None = None) -> np.ndarray:
    """The exact discrete PSF per channel, (3, 2H-1, 2W-1)."""
    w = flare_weights(D, age)
    shared = sum(wi * basis_kernel(b, shape, deg_per_px) for wi, b in zip(w[:3], channel_bases(0)))
    return np.stack([shared + w[3] * basis_kernel(channel_bases(c)[3], shape, deg_per_px)
                     for c in range(3)])


def source_limit(L_wa: float, threshold: float = DEFAULT_THRESHOLD,
                 shown: float | None = None) -> float:
    """The luminance (cd/m^2) above which a pixel is a light source: the paper's test,
    ``threshold`` x the adaptation level (7, Radiance's findglare), and beyond what
    the display can show the observer (``shown``: the scene luminance its state
    maps to display white, where known; inf: nothing is). Durand & Dorsey restrict
    flares to light sources (Sec. 6.2); a field the display shows within its range
    is not one: the viewer's own eye makes its glare from the screen, and adding
    it again would count it twice (docs/models.md, "Flare")."""
    lim = threshold * max(float(L_wa), 0.0)
    return lim if shown is None else max(lim, float(shown))


def source_part(rgb: np.ndarray, L_wa: float, threshold: float = DEFAULT_THRESHOLD) -> np.ndarray:
    """The part of each pixel that is a light source: rgb max(0, 1 - threshold L_wa / Y)."""
    rgb = np.asarray(rgb, np.float64)
    Y = rgb @ Y_WEIGHTS
    lim = threshold * max(L_wa, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(Y > lim, 1.0 - lim / np.where(Y > 0, Y, 1.0), 0.0)
    return rgb * f[..., None]


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


#: The coarsest pyramid level keeps at least this many pixels across.
PYRAMID_MIN_SIZE = 16
#: The halo ring (f3) is convolved directly on the coarsest level where its
#: width (0.71 deg) is still this many pixels.
RING_MIN_PX = 1.5


def ring_level(deg_per_px: float, max_level: int) -> int:
    """The coarsest level (<= ``max_level``) where f3's ring, 1/sqrt(2) deg wide,
    is still RING_MIN_PX pixels wide."""
    lev = 0
    while lev < max_level and (1.0 / math.sqrt(2.0)) / (deg_per_px * 2.0 ** (lev + 1)) >= RING_MIN_PX:
        lev += 1
    return lev


@dataclass(frozen=True)
class FastPlan:
    """The fast method for a frame, Eq. F (the fit's weights combined by Eq. 8):

        PSF * S ~ a0 S + sum_l U^l( sum_(sigma, a) in by_level[l] a G_sigma * D^l S )
                       + w3 U^lring( f3_lring * D^lring S )                     (Eq. F)

    D: the pyramid's [1 3 3 1]/8 decimation, U: its bilinear 2x upsampling, G_sigma:
    a Gaussian of sigma coarse px (:func:`pyramid_level`), f3_l: the normalised f3
    kernel sampled at level l's pixel size. How it is executed (the pyramid's
    storage, FFT sizes, row bands): ``backends/flare_exec.py``."""

    shape: tuple            # (H, W) of the frame
    deg_per_px: float
    a0: float               # weight of the delta
    by_level: dict          # level -> [(coarse sigma, weight), ...]
    lring: int              # level of the f3 ring (-1: no ring)
    w3: float
    top: int                # coarsest level used


def fast_plan(shape: tuple[int, int], deg_per_px: float, D: float,
              per_octave: int, fit: GaussianFit | None = None,
              age: float | None = None) -> FastPlan:
    """Eq. F's terms for a frame of ``shape`` at pupil diameter ``D`` (``fit``:
    the frame's :func:`fit_gaussians`, when the caller has it): the fit's
    weights combined by Eq. 8, each Gaussian on its :func:`pyramid_level`, the
    ring on :func:`ring_level`."""
    h, w = shape
    if fit is None:
        fit = fit_gaussians((h, w), float(deg_per_px), int(per_octave))
    wts = flare_weights(D, age)
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
