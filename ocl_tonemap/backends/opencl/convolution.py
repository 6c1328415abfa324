"""Separable Gaussian blur on an OpenCL runtime (kernels/convolution.cl), in row
bands with halo rows when a frame does not fit; the reference is
``models/convolution.py``."""

from __future__ import annotations

import numpy as np

from ...models.convolution import EDGE_ZERO
from ..bands import row_bands
from .runtime import round_up
from .transfers import host_buffer, transfer


class DeviceBlur:
    """``kernels/convolution.cl`` on one runtime, in row bands with halo rows
    when a frame does not fit in ``max_pixels``."""

    def __init__(self, rt, max_pixels: int | None = None):
        self.rt = rt
        self.max_pixels = int(max_pixels or max(1, rt.max_alloc_bytes() // 16))
        self._k = rt.kernel("convolution.cl", "blur_axis")
        self._bufs = None
        self._cap = 0
        self._k_rgb = None                     # acuity_rgb_x, acuity_rgb_y_blend

    def _buffers(self, n: int):
        import pyopencl as cl
        if self._bufs is None or self._cap < n:
            mf = cl.mem_flags
            self._bufs = [cl.Buffer(self.rt.context, mf.READ_WRITE, max(n, 1) * 4) for _ in range(2)]
            self._cap = n
        return self._bufs

    def _prepare(self, img, taps):
        """(float32 image, its (H, W, C) planes view, tap radius, tap buffer or None
        when the taps are one weight)."""
        a = np.asarray(img, np.float32)
        planes = a[..., None] if a.ndim == 2 else a
        R = len(taps) - 1
        if R == 0:
            return a, planes, R, None
        tap_buf = host_buffer(self.rt.context, np.asarray(taps, np.float32))
        return a, planes, R, tap_buf

    def blur(self, img: np.ndarray, taps: np.ndarray, edge: int = EDGE_ZERO) -> np.ndarray:
        """Blur each plane of an (H, W[, C]) float array; returns float32 of the same shape."""
        a, planes, R, tap_buf = self._prepare(img, taps)
        if tap_buf is None:
            return np.array(a, np.float32) * np.float32(taps[0])
        h, w, nc = planes.shape
        q = self.rt.queue
        out = np.empty((h, w, nc), np.float32)
        for c in range(nc):
            plane = np.ascontiguousarray(planes[..., c])
            for y0, nr in row_bands(h, w, self.max_pixels, R):
                y1 = y0 + nr
                a0, a1 = max(0, y0 - R), min(h, y1 + R)       # band plus halo rows
                bh = a1 - a0
                src, tmp = self._buffers(bh * w)
                transfer(q, src, plane[a0:a1])
                gs = (round_up(w, 16), round_up(bh, 4))
                self._k(q, gs, (16, 4), src, tmp, np.int32(w), np.int32(bh), tap_buf,
                        np.int32(R), np.int32(0), np.int32(edge))
                # Along y the band's own edge is the image's only where a0 = 0 / a1 = h:
                # halo rows make interior band edges exact for the rows we keep.
                self._k(q, gs, (16, 4), tmp, src, np.int32(w), np.int32(bh), tap_buf,
                        np.int32(R), np.int32(1), np.int32(edge))
                band = np.empty((bh, w), np.float32)
                transfer(q, band, src)
                out[y0:y1, :, c] = band[y0 - a0:y1 - a0]
        return out[..., 0] if a.ndim == 2 else out

    def blur_axis(self, img: np.ndarray, taps: np.ndarray, edge: int = EDGE_ZERO,
                  axis: int = 0) -> np.ndarray:
        """One of :meth:`blur`'s two passes (``axis`` 0: along x, its first; 1: along
        y) on each plane of an (H, W[, C]) array, float32 out: x then y gives
        :meth:`blur`'s values, so a frame's rows can be blurred along x as they
        come and along y once the rows below them have come (streamed acuity)."""
        a, planes, R, tap_buf = self._prepare(img, taps)
        if tap_buf is None:
            return np.array(a, np.float32) * np.float32(taps[0])
        h, w, nc = planes.shape
        q = self.rt.queue
        halo = R if axis == 1 else 0
        out = np.empty((h, w, nc), np.float32)
        for c in range(nc):
            plane = np.ascontiguousarray(planes[..., c])
            for y0, nr in row_bands(h, w, self.max_pixels, halo):
                y1 = y0 + nr
                a0, a1 = max(0, y0 - halo), min(h, y1 + halo)
                bh = a1 - a0
                src, tmp = self._buffers(bh * w)
                transfer(q, src, plane[a0:a1])
                gs = (round_up(w, 16), round_up(bh, 4))
                self._k(q, gs, (16, 4), src, tmp, np.int32(w), np.int32(bh), tap_buf,
                        np.int32(R), np.int32(axis), np.int32(edge))
                band = np.empty((bh, w), np.float32)
                transfer(q, band, tmp)
                out[y0:y1, :, c] = band[y0 - a0:y1 - a0]
        return out[..., 0] if a.ndim == 2 else out

    def acuity_in_place(self, buf, h: int, w: int, taps: np.ndarray, t: float, tmp) -> None:
        """The loss-of-acuity blur of a display-linear RGB frame where it is (``buf``:
        h x w interleaved float RGB on the device), clamped edges, blended in place:
        buf + t (blur - buf) (``kernels/convolution.cl`` acuity_rgb_x, _y_blend; the
        reference: ``models/shaler1937.apply_acuity``). ``tmp``: 12 h w bytes."""
        if self._k_rgb is None:
            self._k_rgb = (self.rt.kernel("convolution.cl", "acuity_rgb_x"),
                           self.rt.kernel("convolution.cl", "acuity_rgb_y_blend"))
        R = len(taps) - 1
        tap_buf = host_buffer(self.rt.context, np.asarray(taps, np.float32))
        q, (kx, ky) = self.rt.queue, self._k_rgb
        gs = (round_up(self.rt.pixel_items(h * w, 4), 64),)      # four pixels an item on CPUs
        kx(q, gs, (64,), buf, tmp, np.int32(w), np.int32(h), tap_buf, np.int32(R))
        ky(q, gs, (64,), tmp, buf, np.int32(w), np.int32(h), tap_buf, np.int32(R),
           np.float32(t))
