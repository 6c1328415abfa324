"""The visibility planes of a frame (``run --visibility``), float64: the algorithm
both backends run (the reference here, ``backends/opencl/visibility.py`` in float32
kernels), apart from where and how.

- the scene's photopic luminance Y (the pipeline's bad-value policy);
- a target's luminance and its surround's: Y's block means on a grid as coarse as the
  Gaussian allows (a sigma of the target's size / 2.355, and of :data:`SURROUND` times
  it), blurred with reflected edges, brought back bilinearly;
- the veil of the whole field (``cie146.field_weights`` over :data:`VEIL_CELL_DEG`
  cells, brought back bilinearly);
- L_b = surround + veil, the polarity of target - surround, Adrian's threshold at L_b
  (``view.steady``: ``visibility.Viewing``) times the observer's TAF at L_b;
- VL = |target - surround| / dL_th.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from . import adrian1989 as ad
from . import cie146
from .convolution import EDGE_REFLECT, blur_reference, gaussian_taps
from .photometry import Y_WEIGHTS, sanitize

#: The floor of a background, cd/m^2 (the least luminance a user gives).
LB_FLOOR = 1e-6


def transient(op, obs: dict, L_b, gain: float = 1.0) -> np.ndarray:
    """TAF of backgrounds ``L_b`` (scene cd/m^2) for an observer in state ``obs`` of
    operator ``op`` whose media pass ``gain`` of the light (``Viewing.media_gain``)."""
    L = np.asarray(L_b, np.float64) * gain
    return ad.transient_factor(op.observer_steady_slope(L), op.observer_slope(obs, L))



#: The planes of a visibility EXR, in order, with their units (the header says them).
PLANES = (("La", "cd/m^2", "the eye's (cone) adaptation luminance, from the operator's state "
          "(scene luminance: the light behind the media over their gain)"),
          ("Lveil", "cd/m^2", "the disability veil of the whole field (CIE 146 at the "
           "observer's age, the field within 1 degree left out)"),
          ("Lb", "cd/m^2", "the background: the surround's luminance plus the veil"),
          ("dLth", "cd/m^2", "Adrian 1989's threshold x the transient factor"),
          ("VL", "1", "|target - surround| / dLth (CIE 140 visibility level)"))
PLANE_NAMES = tuple(n for n, _, _ in PLANES)
#: The background is the surround of a target: a Gaussian of this many target sizes.
SURROUND = 3.0
#: The veil is made on cells at least this wide, degrees (a power of two of pixels:
#: 16 at 1080p and 50 degrees, 120 x 68 cells), then brought back bilinearly; within
#: 2-20 degrees of a lamp the cells keep CIE 146's veil within 10 % (tests).
VEIL_CELL_DEG = 0.4


@dataclass(frozen=True)
class Geometry:
    """A frame as the planes see it: h x w pixels, an angular grid ``fov_deg`` wide
    (as the flare and acuity take it)."""

    height: int
    width: int
    fov_deg: float

    @property
    def deg_per_px(self) -> float:
        return self.fov_deg / self.width

    @property
    def px_per_arcmin(self) -> float:
        return self.width / (self.fov_deg * 60.0)


def blur_step(sigma_px: float, h: int, w: int) -> int:
    """The coarsest grid (1, 2, 4 or 8 times) on which a Gaussian of ``sigma_px`` is
    still >= 1 cell wide (the block mean's own blur, s^2/12 of variance, then adds
    at most 1/12 of sigma^2 ... s = 8: 8 %) and the frame >= 16 cells."""
    s = 1
    while s < 8 and sigma_px / (2 * s) >= 1.0 and min(h, w) // (2 * s) >= 16:
        s *= 2
    return s


def veil_step(g: Geometry) -> int:
    """Pixels a side of the veil's cells: the least power of two at least
    :data:`VEIL_CELL_DEG` wide, with 8 cells or more across the frame's short side."""
    s = 1
    while s * g.deg_per_px < VEIL_CELL_DEG and min(g.height, g.width) // (2 * s) >= 8:
        s *= 2
    return s


@dataclass(frozen=True)
class Recipe:
    """What a run's planes are made with, the same every frame of a size: the
    target's and the surround's grid steps and Gaussian taps (on the coarse grid), the
    veil's step and its weights (``cie146.field_weights`` on its cells)."""

    geometry: Geometry
    size_arcmin: float
    target_step: int
    target_taps: np.ndarray
    surround_step: int
    surround_taps: np.ndarray
    veil_step: int
    veil_weights: np.ndarray

    @property
    def veil_shape(self) -> tuple[int, int]:
        s = self.veil_step
        return -(-self.geometry.height // s), -(-self.geometry.width // s)


@functools.lru_cache(maxsize=8)
def recipe(g: Geometry, size_arcmin: float, age: float) -> Recipe:
    """The planes' :class:`Recipe` of frames of ``g`` for a target of ``size_arcmin``
    and an observer of ``age`` (the veil's CIE 146 age term; pigmentation 0.5)."""
    size_px = size_arcmin * g.px_per_arcmin
    steps = []
    for sigma in (size_px / 2.355, SURROUND * size_px / 2.355):   # FWHM = the size
        s = blur_step(sigma, g.height, g.width)
        # (a Gaussian 4 times wider than the grid, its edges reflected, is the grid's
        # mean to float precision: held there, its taps stay within a kernel's
        # constant memory at any size and field)
        sc = min(sigma / s, 4.0 * max(-(-g.height // s), -(-g.width // s)))
        steps += [s, gaussian_taps(sc) if sc > 0.3 else np.ones(1)]
    sv = veil_step(g)
    shape = (-(-g.height // sv), -(-g.width // sv))
    K = cie146.field_weights(shape, g.deg_per_px * sv, age)
    return Recipe(g, float(size_arcmin), *steps, sv, K)


def below_a_pixel(g: Geometry, size_arcmin: float) -> bool:
    """Whether a target of ``size_arcmin`` is too small for the frame's pixels: its
    surround's Gaussian (:data:`SURROUND` sizes) then blurs nothing, target and surround
    are the same, and VL is 0 everywhere."""
    return SURROUND * size_arcmin * g.px_per_arcmin / 2.355 <= 0.3


def block_mean(a: np.ndarray, s: int) -> np.ndarray:
    """Means of s x s blocks (the blocks at the bottom and right edges of what pixels
    they have), in ``a``'s float type: the whole blocks as a sum of s^2 strided
    slices (no reshaped reductions over short axes, which NumPy runs slowly).

    >>> block_mean(np.arange(15.0).reshape(3, 5), 2).tolist()
    [[3.0, 5.0, 6.5], [10.5, 12.5, 14.0]]
    """
    a = np.asarray(a)
    dt = a.dtype if a.dtype in (np.float32, np.float64) else np.float32
    if s <= 1:
        return a.astype(dt, copy=False)
    h, w = a.shape[:2]
    hf, wf = h // s * s, w // s * s
    out = np.empty((-(-h // s), -(-w // s)) + a.shape[2:], dt)

    def means(part, ny, nx):
        b = part.reshape(part.shape[0] // ny, ny, part.shape[1] // nx, nx, *a.shape[2:])
        return b.sum(axis=3, dtype=dt).sum(axis=1) * dt.type(1.0 / (ny * nx))
    if hf and wf:
        acc = np.zeros((hf // s, wf // s) + a.shape[2:], dt)
        for dy in range(s):
            for dx in range(s):
                acc += a[dy:hf:s, dx:wf:s]
        acc *= dt.type(1.0 / (s * s))
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
    a = np.moveaxis(np.asarray(a), axis, 0)
    dt = a.dtype
    ap = np.concatenate([a[:1], a, a[-1:]])
    out = np.empty((n,) + a.shape[1:], dt)
    for p in range(min(s, n)):
        off = (p + 0.5) / s - 0.5
        d = -1 if off < 0 else 0
        f = dt.type(off - d)
        c = len(range(p, n, s))
        out[p::s] = ap[d + 1:d + 1 + c] * (dt.type(1.0) - f) + ap[d + 2:d + 2 + c] * f
    return np.moveaxis(out, 0, axis)


def upsample(a: np.ndarray, shape, s: int) -> np.ndarray:
    """Bilinear from a grid s times coarser (block centres) to ``shape``, in ``a``'s
    float type (the device's kernels take the same weights)."""
    a = np.asarray(a)
    if s <= 1:
        return a
    return _upsample_axis(_upsample_axis(a, shape[0], s, 0), shape[1], s, 1)


def value_at(grid: np.ndarray, s: int, x: int, y: int) -> float:
    """Pixel (x, y) of :func:`upsample` of ``grid`` (s times coarser), without the rest."""
    if s <= 1:
        return float(grid[y, x])
    gh, gw = grid.shape
    u, v = (x + 0.5) / s - 0.5, (y + 0.5) / s - 0.5
    fu, fv = math.floor(u), math.floor(v)
    ax, ay = u - fu, v - fv
    x0, x1 = min(max(fu, 0), gw - 1), min(max(fu + 1, 0), gw - 1)
    y0, y1 = min(max(fv, 0), gh - 1), min(max(fv + 1, 0), gh - 1)
    c0 = grid[y0, x0] * (1.0 - ay) + grid[y1, x0] * ay
    c1 = grid[y0, x1] * (1.0 - ay) + grid[y1, x1] * ay
    return float(c0 * (1.0 - ax) + c1 * ax)


def scene_luminance(pixels: np.ndarray, scale: float) -> np.ndarray:
    """Photopic luminance, cd/m^2, float64, of working-space ``pixels`` x ``scale``,
    bad values repaired by the pipeline's policy (``photometry.sanitize``: NaN,
    -Inf, negatives, denormals 0; +Inf and beyond the ceiling L_MAX)."""
    clean, _ = sanitize(np.asarray(pixels)[..., :3], scale)
    return clean @ Y_WEIGHTS


def smoothed(Y: np.ndarray, s: int, taps: np.ndarray) -> np.ndarray:
    """``Y``'s s x s block means blurred by ``taps`` (reflected edges) and brought
    back bilinearly, >= 0, float64: a target's or a surround's luminance."""
    c = blur_reference(block_mean(np.asarray(Y, np.float64), s), taps, EDGE_REFLECT)
    return np.maximum(upsample(c, Y.shape, s), 0.0)


def veil_cells(Y: np.ndarray, r: Recipe) -> np.ndarray:
    """The veil (cd/m^2) at the centres of the recipe's cells, float64."""
    return cie146.field_veil(block_mean(np.asarray(Y, np.float64), r.veil_step),
                             r.veil_weights)


def reference_planes(op, obs: dict, Y: np.ndarray, r: Recipe, view,
                     veil: np.ndarray | None = None) -> dict:
    """The visibility planes of one frame, float64 (H x W), from ``Y`` the scene's
    photopic luminance (cd/m^2, :func:`scene_luminance`) and ``obs`` the operator's
    observer after the frame (:meth:`Operator.observer_of`); ``veil`` the veil's cells
    (:func:`veil_cells` by default; the halo added where asked). Also "veil_cells"."""
    Y = np.asarray(Y, np.float64)
    tgt = smoothed(Y, r.target_step, r.target_taps)
    sur = smoothed(Y, r.surround_step, r.surround_taps)
    cells = veil_cells(Y, r) if veil is None else np.asarray(veil, np.float64)
    V = np.maximum(upsample(cells, Y.shape, r.veil_step), 0.0)
    Lb = np.maximum(sur + V, LB_FLOOR)
    dL = tgt - sur
    th = view.steady(Lb, dL < 0) * transient(op, obs, Lb, view.media_gain)
    La = np.broadcast_to(np.asarray(op.observer_level(obs), np.float64) / view.media_gain,
                         Y.shape)
    return {"La": La, "Lveil": V, "Lb": Lb, "dLth": th, "VL": np.abs(dL) / th,
            "veil_cells": cells}


#: The largest value a half-float plane holds (larger ones are held there, counted).
HALF_MAX = float(np.finfo(np.float16).max)


def as_samples(planes: dict, dtype) -> tuple[np.ndarray, int]:
    """The planes as one H x W x 5 array of ``dtype`` (half: values beyond its range
    held at :data:`HALF_MAX`, counted), with that count."""
    stack = np.stack([np.asarray(planes[n], np.float64) for n in PLANE_NAMES], axis=-1)
    clamped = 0
    if np.dtype(dtype) == np.float16:
        over = stack > HALF_MAX
        clamped = int(over.sum())
        if clamped:
            stack = np.minimum(stack, HALF_MAX)
    return stack.astype(dtype), clamped
