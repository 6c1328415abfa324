"""Separable convolution: Gaussian taps, a float64 reference and the device pass.

Shared by the loss-of-acuity blur (Durand & Dorsey 2000, Sec. 7; clamped
edges) and the fast flare (sums of Gaussians on a pyramid; zero outside the
image, as the exact linear convolution it approximates).
"""

from __future__ import annotations

import math

import numpy as np

EDGE_ZERO, EDGE_CLAMP = 0, 1
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


def _shift(a: np.ndarray, d: int, axis: int, edge: int) -> np.ndarray:
    """a shifted so that out[i] = a[i + d] along ``axis`` (zero or clamped outside)."""
    n = a.shape[axis]
    idx = np.arange(n) + d
    if edge == EDGE_CLAMP:
        return np.take(a, np.clip(idx, 0, n - 1), axis=axis)
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


class DeviceBlur:
    """``kernels/convolution.cl`` on one runtime, in row bands with halo rows
    when a frame does not fit in ``max_pixels``."""

    def __init__(self, rt, max_pixels: int | None = None):
        self.rt = rt
        self.max_pixels = int(max_pixels or max(1, rt.max_alloc_bytes() // 16))
        self._k = rt.kernel("convolution.cl", "blur_axis")
        self._bufs = None
        self._cap = 0

    def _buffers(self, n: int):
        import pyopencl as cl
        if self._bufs is None or self._cap < n:
            mf = cl.mem_flags
            self._bufs = [cl.Buffer(self.rt.context, mf.READ_WRITE, max(n, 1) * 4) for _ in range(2)]
            self._cap = n
        return self._bufs

    def blur(self, img: np.ndarray, taps: np.ndarray, edge: int = EDGE_ZERO) -> np.ndarray:
        """Blur each plane of an (H, W[, C]) float array; returns float32 of the same shape."""
        import pyopencl as cl
        from .runtime import round_up
        a = np.asarray(img, np.float32)
        planes = a[..., None] if a.ndim == 2 else a
        h, w, nc = planes.shape
        R = len(taps) - 1
        if R == 0:
            return np.array(a, np.float32) * np.float32(taps[0])
        q = self.rt.queue
        tap_buf = cl.Buffer(self.rt.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                            hostbuf=np.asarray(taps, np.float32))
        rows = max(1, min(h, self.max_pixels // max(w, 1) - 2 * R))
        out = np.empty((h, w, nc), np.float32)
        for c in range(nc):
            plane = np.ascontiguousarray(planes[..., c])
            for y0 in range(0, h, rows):
                y1 = min(h, y0 + rows)
                a0, a1 = max(0, y0 - R), min(h, y1 + R)       # band plus halo rows
                bh = a1 - a0
                src, tmp = self._buffers(bh * w)
                cl.enqueue_copy(q, src, plane[a0:a1])
                gs = (round_up(w, 16), round_up(bh, 4))
                self._k(q, gs, (16, 4), src, tmp, np.int32(w), np.int32(bh), tap_buf,
                        np.int32(R), np.int32(0), np.int32(edge))
                # Along y the band's own edge is the image's only where a0 = 0 / a1 = h:
                # halo rows make interior band edges exact for the rows we keep.
                self._k(q, gs, (16, 4), tmp, src, np.int32(w), np.int32(bh), tap_buf,
                        np.int32(R), np.int32(1), np.int32(edge))
                band = np.empty((bh, w), np.float32)
                cl.enqueue_copy(q, band, src)
                out[y0:y1, :, c] = band[y0 - a0:y1 - a0]
        return out[..., 0] if a.ndim == 2 else out
