"""Separable convolution: Gaussian taps, a float64 reference and the device pass.

Shared by the loss-of-acuity blur (Durand & Dorsey 2000, Sec. 7; clamped
edges), the fast flare (sums of Gaussians on a pyramid; zero outside the
image, as the exact linear convolution it approximates) and the visibility
planes' target and surround (reflected edges: a surround at the frame's edge is
the picture mirrored, not darkness).
"""

from __future__ import annotations

import math

import numpy as np

EDGE_ZERO, EDGE_CLAMP, EDGE_REFLECT = 0, 1, 2
#: Gaussian taps are kept out to this many sigma (weight beyond: < 1.2e-4 of the total).
TRUNCATE_SIGMA = 4.0


def gaussian_taps(sigma: float) -> np.ndarray:
    """Half-kernel [w0, w1, ..., wR] of a sampled Gaussian, normalised so that
    w0 + 2 sum(w1..wR) = 1. ``sigma`` in pixels; sigma <= 0 gives the identity."""
    if not sigma > 0:
        return np.ones(1)
    R = max(1, int(math.ceil(TRUNCATE_SIGMA * sigma)))
    r = np.arange(R + 1, dtype=np.float64)
    t = np.exp(-0.5 * (r / sigma) ** 2)
    return t / (t[0] + 2.0 * t[1:].sum())


def reflect_index(idx, n: int):
    """Indices mirrored into 0..n-1 without repeating the edge (-1 -> 1, n -> n - 2),
    folded as often as they need (period 2 (n - 1)); a single sample: 0."""
    if n == 1:
        return np.zeros_like(idx)
    m = np.mod(idx, 2 * (n - 1))
    return np.where(m >= n, 2 * (n - 1) - m, m)


def _shift(a: np.ndarray, d: int, axis: int, edge: int) -> np.ndarray:
    """a shifted so that out[i] = a[i + d] along ``axis`` (zero, clamped or
    reflected outside)."""
    n = a.shape[axis]
    idx = np.arange(n) + d
    if edge == EDGE_CLAMP:
        return np.take(a, np.clip(idx, 0, n - 1), axis=axis)
    if edge == EDGE_REFLECT:
        return np.take(a, reflect_index(idx, n), axis=axis)
    ok = (idx >= 0) & (idx < n)
    out = np.take(a, np.clip(idx, 0, n - 1), axis=axis)
    shape = [1] * a.ndim
    shape[axis] = n
    return out * ok.reshape(shape)


def blur_reference(img: np.ndarray, taps: np.ndarray, edge: int = EDGE_ZERO) -> np.ndarray:
    """Float64 separable convolution of an (H, W[, C]) array with the same taps along y and x."""
    a = np.asarray(img, np.float64)
    for axis in (1, 0):
        out = taps[0] * a
        for r in range(1, len(taps)):
            out = out + taps[r] * (_shift(a, -r, axis, edge) + _shift(a, r, axis, edge))
        a = out
    return a


def blur_axis_reference(img: np.ndarray, taps: np.ndarray, edge: int = EDGE_ZERO,
                        axis: int = 0) -> np.ndarray:
    """One of :func:`blur_reference`'s passes (``axis`` 0: along x, its first; 1:
    along y), float64: x then y gives its values."""
    a = np.asarray(img, np.float64)
    ax = 1 if axis == 0 else 0
    out = taps[0] * a
    for r in range(1, len(taps)):
        out = out + taps[r] * (_shift(a, -r, ax, edge) + _shift(a, r, ax, edge))
    return out


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
