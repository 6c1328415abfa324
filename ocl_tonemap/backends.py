"""Compute backends: the float64 NumPy reference and OpenCL.

Both run the same stages on one frame: bad-value policy and luminances
(colour stage), metering, then -- after the host scheduler has advanced the
adaptation state through ``step`` -- the operator's per-pixel pass.

The OpenCL backend processes images larger than ``max_band_pixels`` in row
bands: pass 1 meters every band (sums add up exactly as for one band), pass 2
maps each band. A frame that fits stays resident between the passes.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from . import metering as met
from .photometry import RepairCounts, photopic_luminance, sanitize, scotopic_luminance

#: (G_rod, G_cone, illuminant_fn) -> (operator frame params, von Kries gains or None);
#: illuminant_fn() returns the frame's illuminant estimate (computed on demand).
StepFn = Callable[[float, float, Callable], tuple]


class ReferenceBackend:
    """Float64 NumPy, straight from the equations; the ground truth."""

    name = "reference"

    def describe(self) -> str:
        return "float64 NumPy reference"

    def working(self, pixels: np.ndarray, scale: float, spec: met.MeteringSpec):
        """Colour stage and metering only: (rgb cd/m^2, repairs, (G_rod, G_cone), estimate_fn)."""
        rgb, repairs = sanitize(pixels[..., :3], scale)
        G = met.reference_goal(photopic_luminance(rgb), scotopic_luminance(rgb), spec)
        from .effects import illuminant_estimate_reference
        return rgb, repairs, G, lambda: illuminant_estimate_reference(rgb)

    def process(self, pixels: np.ndarray, scale: float, spec: met.MeteringSpec, op,
                step: StepFn):
        from .effects import illuminant_estimate_reference
        rgb, repairs = sanitize(pixels[..., :3], scale)
        Y = photopic_luminance(rgb)
        Ys = scotopic_luminance(rgb)
        G_rod, G_cone = met.reference_goal(Y, Ys, spec)
        params, gains = step(G_rod, G_cone, lambda: illuminant_estimate_reference(rgb))
        if gains is not None:                      # Eq. 6: cone signals only
            rgb = rgb * np.asarray(gains, np.float64)
            Y = photopic_luminance(rgb)
        out = op.map_reference(rgb, Y, Ys, params)
        return out.astype(np.float32), repairs, (G_rod, G_cone)


class OpenCLBackend:
    """Float32 OpenCL kernels (kernels/*.cl)."""

    name = "opencl"

    def __init__(self, device: str | None = None, max_band_pixels: int | None = None):
        from .runtime import get_runtime
        self.rt = get_runtime(device)
        self.meter = met.DeviceMeter(self.rt)
        self._colour = self.rt.kernel("colour.cl", "scene_to_working")
        self._gains = self.rt.kernel("colour.cl", "apply_gains")
        self._illum = self.rt.kernel("metering.cl", "illuminant_partial")
        if max_band_pixels is None:
            # Per pixel: src (<=4 floats), rgb 3, Y, Y', out 3 = 48 B; keep to 1/4
            # of global memory and under the largest single allocation.
            max_band_pixels = min(self.rt.max_alloc_bytes() // 16,
                                  self.rt.global_mem_bytes() // (48 * 4))
        self.max_band_pixels = int(max(1, max_band_pixels))
        self._bufs = None
        self._cap = 0

    def describe(self) -> str:
        from .runtime import describe_device
        return describe_device(self.rt.device)

    def _buffers(self, npix: int, channels: int):
        import pyopencl as cl
        need = npix * max(channels, 3)
        if self._bufs is None or self._cap < need:
            ctx, mf = self.rt.context, cl.mem_flags
            cap = max(need, 1)
            self._bufs = {
                "src": cl.Buffer(ctx, mf.READ_ONLY, cap * 4),
                "rgb": cl.Buffer(ctx, mf.READ_WRITE, cap * 4),
                "Y": cl.Buffer(ctx, mf.READ_WRITE, cap * 4),
                "Ys": cl.Buffer(ctx, mf.READ_WRITE, cap * 4),
                "out": cl.Buffer(ctx, mf.READ_WRITE, cap * 4),
                "counts": cl.Buffer(ctx, mf.READ_WRITE, 8 * 4),
            }
            self._cap = cap
        return self._bufs

    def _to_working(self, band: np.ndarray, scale: float, count: bool,
                    count_rows: tuple[int, int] | None = None):
        """Upload one band and run the colour stage; returns its repair counts
        (of rows ``count_rows`` of the band only, when given)."""
        import pyopencl as cl
        from .runtime import round_up
        q = self.rt.queue
        rows, width, channels = band.shape
        n = rows * width
        b = self._buffers(n, channels)
        lo, hi = count_rows if count_rows is not None else (0, rows)
        cl.enqueue_copy(q, b["src"], np.ascontiguousarray(band, np.float32))
        cl.enqueue_fill_buffer(q, b["counts"], np.int32(0), 0, 8 * 4)
        self._colour(q, (round_up(n, 64),), (64,), b["src"], np.int32(channels), np.int32(n),
                     np.float32(scale), b["rgb"], b["Y"], b["Ys"], b["counts"],
                     np.int32(lo * width), np.int32(hi * width))
        rc = RepairCounts()
        if count:
            c = np.empty(8, np.int32)
            cl.enqueue_copy(q, c, b["counts"])
            for k, v in zip(RepairCounts.KEYS, c):
                setattr(rc, k, int(v))
        return rc

    ILLUM_GROUPS = 64

    def _illuminant_sums(self, n: int) -> np.ndarray:
        """Device sums (Y r, Y g, Y b, Y Y) over the resident band (float64 on the host)."""
        import pyopencl as cl
        b = self._bufs
        if "illum" not in b:
            b["illum"] = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE,
                                   self.ILLUM_GROUPS * 4 * 4)
        wg = 64
        groups = max(1, min(self.ILLUM_GROUPS, -(-n // wg)))
        self._illum(self.rt.queue, (groups * wg,), (wg,), b["rgb"], b["Y"], np.int32(n),
                    b["illum"], cl.LocalMemory(wg * 4 * 4))
        part = np.empty((groups, 4), np.float32)
        cl.enqueue_copy(self.rt.queue, part, b["illum"])
        return part.astype(np.float64).sum(axis=0)

    def _bands(self, h: int, w: int):
        rows = max(1, min(h, self.max_band_pixels // max(w, 1)))
        return [(y0, min(rows, h - y0)) for y0 in range(0, h, rows)]

    def _meter_pass(self, pixels, scale, spec, illuminant: bool, keep_rgb: np.ndarray | None):
        """Pass 1 over the bands: colour stage + metering (+ illuminant sums,
        + the working rgb copied to ``keep_rgb``)."""
        import pyopencl as cl
        h, w, _ = pixels.shape
        bands = self._bands(h, w)
        repairs = RepairCounts()
        sums = None
        illum = np.zeros(4)
        for y0, nr in bands:
            repairs += self._to_working(pixels[y0:y0 + nr], scale, count=True)
            b = self._bufs
            s = self.meter.band_sums(b["Y"], b["Ys"], nr * w, w, h, y0, spec)
            if sums is None:
                sums = s
            else:
                sums.add(s)
            if illuminant:
                illum += self._illuminant_sums(nr * w)
            if keep_rgb is not None:
                cl.enqueue_copy(self.rt.queue, keep_rgb[y0:y0 + nr], b["rgb"])
        self.last_max_Y = float(sums.sums[5])
        return bands, repairs, sums.goal(spec), illum

    def working(self, pixels: np.ndarray, scale: float, spec: met.MeteringSpec):
        """Colour stage and metering only: (rgb cd/m^2, repairs, (G_rod, G_cone), estimate_fn)."""
        h, w, _ = pixels.shape
        rgb = np.empty((h, w, 3), np.float32)
        _, repairs, G, illum = self._meter_pass(pixels, scale, spec, True, rgb)
        return rgb, repairs, G, lambda: illum[:3]

    def process(self, pixels, scale: float, spec: met.MeteringSpec, op, step: StepFn,
                sink=None):
        """Meter, step, map. ``pixels`` may be any object with ``shape`` whose row
        slices give bands (a band source reading a file); with ``sink(y0, band)``
        each mapped band goes there instead of into a whole output frame (None is
        returned for it): host memory then stays at a few bands."""
        import pyopencl as cl
        from .runtime import round_up
        h, w, c = pixels.shape
        bands, repairs, (G_rod, G_cone), illum = self._meter_pass(
            pixels, scale, spec, getattr(step, "wants_illuminant", False), None)
        self.last_repairs = repairs
        params, gains = step(G_rod, G_cone, lambda: illum[:3])
        out = np.empty((h, w, 3), np.float32) if sink is None else None
        for i, (y0, nr) in enumerate(bands):              # pass 2: per-pixel operator
            if len(bands) > 1:
                self._to_working(pixels[y0:y0 + nr], scale, count=False)
            b = self._bufs
            n = nr * w
            if gains is not None:                          # Eq. 6: cone signals only
                g = np.asarray(gains, np.float32)
                self._gains(self.rt.queue, (round_up(n, 64),), (64,), b["rgb"], b["Y"],
                            np.int32(n), g[0], g[1], g[2])
            op.map_opencl(self.rt, b["rgb"], b["Y"], b["Ys"], b["out"], n, params)
            if sink is None:
                cl.enqueue_copy(self.rt.queue, out[y0:y0 + nr], b["out"])
            else:
                band = np.empty((nr, w, 3), np.float32)
                cl.enqueue_copy(self.rt.queue, band, b["out"])
                sink(y0, band)
        return out, repairs, (G_rod, G_cone)


def make_backend(name: str = "opencl", device: str | None = None,
                 max_band_pixels: int | None = None):
    if name == "reference":
        return ReferenceBackend()
    if name == "opencl":
        return OpenCLBackend(device, max_band_pixels)
    raise ValueError(f"unknown backend {name!r} (opencl | reference)")
