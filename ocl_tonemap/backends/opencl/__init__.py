"""The OpenCL backend: float32 kernels (``kernels/*.cl``) on one device.

Frames larger than ``max_band_pixels`` are processed in row bands
(``bands.row_bands``): the measure pass meters every band (sums add up exactly as
for one band), the apply pass maps each band. A frame that fits stays resident
between the passes. One pool of working buffers serves every schedule.
"""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from ...models import metering as met
from ...models.photometry import RepairCounts
from ...operators.base import FrameStats, Operator
from ..bands import row_bands
from ..base import Levels, NoPixelState, load_schedule
from .convolution import DeviceBlur
from .display import BlurredOutputEncoding
from .flare import DeviceFlare
from .image import DeviceArrayOutput, DeviceImage, device_image
from .lmsr import KirkDevice
from .metering import DeviceMeter, MeteringPasses, repair_counts
from .runtime import describe_device, frame_params, get_runtime, index_defines, round_up
from . import pinned
from .pinned import HostArrays
from .pointwise import PointwiseStages
from .stats import TAIL, statistics
from .transfers import ConstantBuffers, Transfers, counted, transfer
from .visibility import VisibilityStage


class OpenCLBackend(MeteringPasses, VisibilityStage, PointwiseStages):
    """Float32 OpenCL kernels (kernels/*.cl)."""

    name = "opencl"
    #: Frames of half floats go up as they are (half the bytes) and become float32 there.
    half_input = True

    def __init__(self, device: str | None = None, max_band_pixels: int | None = None):
        self.rt = get_runtime(device)
        self.meter = DeviceMeter(self.rt)
        self._colour = self.rt.kernel("colour.cl", "scene_to_working4")
        self._gains = self.rt.kernel("colour.cl", "apply_gains")
        self._half = None              # colour.cl:half_to_float
        self._arrays = None            # the memory pool of device-array outputs
        self._consts = ConstantBuffers(self.rt.context)
        self._illum = self.rt.kernel("metering.cl", "illuminant_partial")
        self._blocks = self.rt.kernel("metering.cl", "block_sums")
        self._blocks16 = self.rt.kernel("metering.cl", "block_means_log16",
                                        (("LOG16_STEPS", met.LOG16_STEPS),
                                         ("LOG16_OFFSET", met.LOG16_OFFSET)))
        self._resident = None          # (h, w) of the working frame whole in bufs["rgb"]
        self._visibility = None        # the visibility planes' kernels, made on first use
        self._keep = self._kept = None  # keep_scene_luminance: the array, what was kept
        self._ahead = None             # source_proxy_ahead's: (its arguments, sums, collect)
        if max_band_pixels is None:
            # Per pixel: src (<=4 floats), rgb 3, Y, Y', out 3 = 48 B; keep to 1/4
            # of global memory and under the largest single allocation.
            max_band_pixels = min(self.rt.max_alloc_bytes() // 16,
                                  self.rt.global_mem_bytes() // (48 * 4))
        self.max_band_pixels = int(max(1, max_band_pixels))
        #: Folder for per-pixel planes of banded frames (``backends/planes.py``);
        #: None keeps them in memory. Set for a stretch of work by :meth:`banded`.
        self.spill_dir = None
        self.bufs = None
        self._cap = 0
        self._pool: dict = {}

    def describe(self) -> str:
        return describe_device(self.rt.device)

    def schedule(self, op):
        spec = op.schedules.get(self.name)
        if spec:
            return load_schedule(spec)(self, op)
        if type(op).kernel_call is Operator.kernel_call:
            # no kernel: the float64 map on the host (the one place a backend lends
            # another's schedule)
            return load_schedule(".reference:PointwiseSchedule")(self, op)
        return PointwiseSchedule(self, op)

    @contextmanager
    def banded(self, rows_pixels: int | None, spill_dir: str | None):
        """Frames in bands of ``rows_pixels`` pixels, per-pixel planes of banded frames
        spilled to ``spill_dir``, for the ``with`` block (the streaming path)."""
        was = self.max_band_pixels, self.spill_dir
        self.max_band_pixels = int(rows_pixels) if rows_pixels else was[0]
        self.spill_dir = spill_dir
        try:
            yield self
        finally:
            self.max_band_pixels, self.spill_dir = was

    def device_runtime(self):
        return self.rt

    def device_blur(self, max_pixels: int | None = None):
        """The separable blur on the device (effects: flare, acuity): ``.blur(img, taps,
        edge)`` and ``.blur_axis``, in bands of at most ``max_pixels`` (default: the
        backend's band size now)."""
        return DeviceBlur(self.rt, max_pixels or self.max_band_pixels)

    def acuity_encoding(self, encoding, h: int, w: int, taps, t: float, blur):
        """``encoding`` with the loss-of-acuity blur (``taps``, blend ``t``) before it,
        on the device where the operator leaves the frame (``blur``: a :meth:`device_blur`),
        or None where the frame is mapped in more than one band (then the host blurs the
        display-linear frame). Its scratch is a spent frame of the colour stage, or the
        pool's until the end of the frame."""
        if encoding is None or blur is None or len(self.bands(h, w)) != 1:
            return None

        def run(src):
            # the operator has run: the colour stage's frames are spent (not a frame more)
            b, nb = self.bufs, 12 * h * w
            tmp = next((b[k] for k in ("rgb", "src") if b is not None and b[k] != src
                        and b[k].size >= nb), None)
            blur.acuity_in_place(src, h, w, taps, t,
                                 tmp if tmp is not None else self.buffer("acuity:tmp", nb))
            self.release("acuity:")
        return BlurredOutputEncoding(encoding, run, h * w)

    def flare_device(self):
        """The fast flare on the device (``effects/flare.py``)."""
        return DeviceFlare(self.rt, self.buffer, self.release, self._spare_frame)

    def _spare_frame(self, nbytes: int):
        """The colour stage's upload buffer where the working frame it made is resident
        and whole (``working(on_device=True)``): its content is spent until the next
        colour stage, so a scene effect on the device may leave its frame there (the
        flare: no frame of its own, and the colour stage's copy is none); else None."""
        b = self.bufs
        if self._resident is None or b is None or b["src"].size < nbytes:
            return None
        return b["src"]

    def purkinje_device(self):
        """kirk11's shift kernels for the Purkinje effect on other operators."""
        return KirkDevice(self.rt)

    def device_image(self, arr):
        """A ``pyopencl.array.Array`` frame as a device image (``image.device_image``),
        None for anything else."""
        return device_image(self.rt, arr)

    def device_output(self):
        """The output left on the device, as a ``pyopencl.array.Array`` (from a memory
        pool: a frame's array the caller has let go of serves a later frame)."""
        if self._arrays is None:
            import pyopencl.tools as clt
            self._arrays = clt.MemoryPool(clt.ImmediateAllocator(self.rt.queue))
        return DeviceArrayOutput(self.rt, self._arrays)

    def device_array(self, pixels: np.ndarray):
        """Host pixels as a ``pyopencl.array.Array`` (one upload; the outputs' pool)."""
        import pyopencl.array as cla
        out = cla.empty(self.rt.queue, pixels.shape, np.float32,
                        allocator=self.device_output().allocator)
        transfer(self.rt.queue, out.base_data, np.ascontiguousarray(pixels, np.float32))
        return out

    def transfers(self) -> Transfers:
        """Host <-> device transfers so far in this thread (``transfers.py``)."""
        return counted()

    # -- buffers -----------------------------------------------------------------------
    def buffer(self, name: str, nbytes: int):
        """A named device buffer of at least ``nbytes`` from the pool (grown as needed)."""
        import pyopencl as cl
        b = self._pool.get(name)
        if b is None or b.size < nbytes:
            b = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, max(int(nbytes), 4))
            self._pool[name] = b
        return b

    def release(self, *prefixes: str) -> None:
        """Drop the pool's buffers whose names start with one of ``prefixes`` (scratch
        a stage no longer needs: on a CPU device they are the host's memory)."""
        for name in [n for n in self._pool if n.startswith(prefixes)]:
            del self._pool[name]

    def constant(self, arr: np.ndarray):
        """A read-only device copy of a small array (a kernel's parameters), uploaded only
        where the device does not hold the same values already."""
        return self._consts.get(np.asarray(arr, np.float32))

    def _buffers(self, npix: int, channels: int):
        need = npix * max(channels, 3)
        if self.bufs is None or self._cap < need:
            cap = max(need, 1)
            # (src and out: room after the frame for the statistics that come down with it)
            self.bufs = {k: self.buffer(k, cap * 4 + (TAIL if k != "rgb" else 0))
                         for k in ("src", "rgb", "out")}
            # one channel each: a third of the others (cap >= 3 x pixels)
            self.bufs.update({k: self.buffer(k, -(-cap // 3) * 4) for k in ("Y", "Ys")})
            self.bufs["counts"] = self.buffer("counts", 8 * 4)
            self._cap = cap
        return self.bufs

    def output_buffer(self, n: int, one_band: bool):
        """Where a per-pixel kernel writes the display-linear output of ``n`` pixels: for
        a frame in one band the colour stage's upload buffer, spent once its colour
        stage has made rgb, Y and Ys (the output frame's memory is then never touched:
        a frame less at the peak, 95 MiB at 4K); else ``out``."""
        b = self.bufs
        return b["src"] if one_band and b["src"].size >= 12 * n else b["out"]

    # -- the output -------------------------------------------------------------------------
    def output_array(self, h: int, w: int, encoding=None):
        """The array a frame's output comes back into: display-linear float32 on the
        host, or ``encoding``'s (a ``display.DeviceOutputEncoding``: code values on the
        host; an ``image.DeviceArrayOutput``: display-linear on the device)."""
        return pinned.outputs(self.rt).empty((h, w, 3), np.float32, TAIL) \
            if encoding is None else encoding.array(h, w)

    def host_arrays(self, keep: int) -> HostArrays:
        """Arrays for frames read to come here (``imageio.FramePool``'s allocator):
        page-locked where the device is not a CPU (``pinned.py``)."""
        return HostArrays(self.rt, keep)

    def fetch_output(self, dst: np.ndarray, buf, n: int, encoding=None) -> None:
        """Bring ``n`` pixels of a per-pixel kernel's RGB output (``buf``) back into
        ``dst`` (C-contiguous rows of :meth:`output_array`), through the device display
        encoding when one is given (then only code values cross to the host)."""
        if encoding is None:             # (with the frame's last statistics: stats.py)
            statistics(self.rt).download(dst, buf)
        else:
            encoding.fetch(self.rt.queue, buf, n, dst)

    # -- the colour stage ------------------------------------------------------------------
    def to_working(self, band: np.ndarray, scale: float, count: bool,
                   count_rows: tuple[int, int] | None = None) -> RepairCounts:
        """Upload one band and run the colour stage into ``bufs`` rgb, Y, Ys; returns
        its repair counts (of rows ``count_rows`` of the band only, when given)."""
        import pyopencl as cl
        q = self.rt.queue
        rows, width, channels = band.shape
        n = rows * width
        b = self._buffers(n, channels)
        lo, hi = count_rows if count_rows is not None else (0, rows)
        if isinstance(band, DeviceImage):          # a frame made on the device this frame
            if band.buffer != b["src"]:            # (already there: _spare_frame)
                band.copy_to(q, b["src"])
        elif band.dtype == np.float16:             # up as stored, made float32 there
            m = band.size
            half = self.buffer("src16", 2 * m)
            transfer(q, half, np.ascontiguousarray(band))
            if self._half is None:
                self._half = self.rt.kernel("colour.cl", "half_to_float")
            self._half(q, (round_up(m, 64),), (64,), half, b["src"], np.int32(m))
        else:
            transfer(q, b["src"], np.ascontiguousarray(band, np.float32))
        cl.enqueue_fill_buffer(q, b["counts"], np.int32(0), 0, 8 * 4)
        self._colour(q, (round_up(self.rt.pixel_items(n, 4), 64),), (64,), b["src"],
                     np.int32(channels), np.int32(n), np.float32(scale), b["rgb"], b["Y"],
                     b["Ys"], b["counts"], np.int32(lo * width), np.int32(hi * width))
        self.keep_luminance_of(band, scale, n)
        return self.read_repairs(b["counts"]) if count else RepairCounts()

    def read_repairs(self, counts) -> RepairCounts:
        """The repair counts a colour kernel left in ``counts`` (8 int32, RepairCounts.KEYS
        first)."""
        c = np.empty(8, np.int32)
        transfer(self.rt.queue, c, counts)
        return repair_counts(c)

    def bands(self, h: int, w: int, halo: int = 0):
        return row_bands(h, w, self.max_band_pixels, halo)

    def working_rows(self, pixels: np.ndarray, scale: float) -> np.ndarray:
        """The colour stage of some rows, brought back: working RGB in cd/m^2."""
        self.to_working(pixels, scale, count=False)
        out = np.empty(pixels.shape[:2] + (3,), np.float32)
        transfer(self.rt.queue, out, self.bufs["rgb"])
        return out

    def working(self, pixels: np.ndarray, scale: float, spec: met.MeteringSpec,
                illuminant: bool = True, on_device: bool = False,
                proxy_stride: int = 0, metered: Levels | None = None) -> Levels:
        """Colour stage and metering only: rgb cd/m^2, repairs, (G_rod, G_cone), the
        illuminant estimate (``illuminant`` False: no illuminant sums, None). ``on_device``: rgb is a
        :class:`~.image.DeviceImage` (for scene effects that run on the device) where the
        frame is one band, else a host array; it is the colour stage's buffer, valid until
        the backend's next colour stage (:meth:`to_working`). ``metered`` known: the
        colour stage alone (no sums read down), and those Levels with its rgb."""
        h, w, _ = pixels.shape
        statistics(self.rt).drop()         # a frame's first colour stage
        bands = self.bands(h, w)
        rgb = None if (on_device and len(bands) == 1) else np.empty((h, w, 3), np.float32)
        if metered is None:
            bands, repairs, G, illum, max_Y, proxy, max_Ys = self.meter_pass(
                pixels, scale, spec, illuminant, rgb, proxy_stride)
        else:
            self._ahead = None
            for y0, nr in bands:
                self.to_working(pixels[y0:y0 + nr], scale, count=False)
                if rgb is not None:
                    transfer(self.rt.queue, rgb[y0:y0 + nr], self.bufs["rgb"])
        self._resident = (h, w) if len(bands) == 1 else None
        if rgb is None:           # the colour stage's own buffer, until its next frame
            rgb = DeviceImage(self.rt, self.bufs["rgb"], (h, w, 3))
        if metered is not None:
            return metered._replace(rgb=rgb, proxy=None)
        return Levels(rgb, repairs, G, (lambda: illum[:3]) if illuminant else None, max_Y,
                      proxy, max_Ys)

    # -- per-pixel kernels ---------------------------------------------------------------------
    def run_pointwise(self, call, rgb, Y, Ys, out, n: int) -> None:
        """Enqueue a per-pixel kernel (operators.base.KernelCall) over ``n`` pixels."""
        names = tuple(k for k, _ in call.params)
        knl = self.rt.kernel(call.file, call.kernel, index_defines(names) + tuple(call.defines))
        values = [v for _, v in call.params]
        p = frame_params(values) if call.frame_params else \
            self.constant(np.array(values or [0.0], np.float32))
        extra = tuple(self.constant(b) for b in call.buffers)
        items = self.rt.pixel_items(max(n, 1), call.pixels_per_item)
        knl(self.rt.queue, (round_up(items, 64),), (64,), rgb, Y, Ys, out, np.int32(n), p,
            *extra)


class PointwiseSchedule(NoPixelState):
    """Colour, metering, the host's state step, one per-pixel kernel, over bands."""

    receptor_gains = True
    streams = True
    encodes_output = True
    applies_stored = True

    def __init__(self, backend: OpenCLBackend, op):
        self.backend, self.op = backend, op

    def measure(self, frame, spec: met.MeteringSpec, want_illuminant: bool = False) -> FrameStats:
        be = self.backend
        h, w, _ = frame.pixels.shape
        bands, repairs, (G_rod, G_cone), illum, *_ = be.meter_pass(frame.pixels, frame.scale,
                                                                  spec, want_illuminant, None)
        # one band stays resident in the backend's buffers until the next frame
        return FrameStats(w, h, G_rod, G_cone, repairs, lambda: illum[:3],
                          handle=(frame.pixels, bands))

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        self.op.integrate(state, stats, dt, fresh)

    def apply(self, frame, state, stats, params, gains=None, sink=None, encoding=None):
        """Map every band (re-reading it unless the frame is the resident one); with
        ``sink(y0, band)`` bands go there and None is returned."""
        be = self.backend
        h, w, _ = frame.pixels.shape
        resident = stats.handle is not None and stats.handle[0] is frame.pixels
        bands = stats.handle[1] if resident else be.bands(h, w)
        call = self.op.kernel_call(params)
        out = be.output_array(h, w, encoding) if sink is None else None
        for y0, nr in bands:
            if len(bands) > 1 or not resident:
                be.to_working(frame.pixels if len(bands) == 1 else frame.pixels[y0:y0 + nr],
                              frame.scale, count=False)
            b = be.bufs
            n = nr * w
            if gains is not None:                          # Eq. 6: cone signals only
                g = np.asarray(gains, np.float32)
                be._gains(be.rt.queue, (round_up(n, 64),), (64,), b["rgb"], b["Y"],
                          np.int32(n), g[0], g[1], g[2])
            dst = be.output_buffer(n, len(bands) == 1)
            be.run_pointwise(call, b["rgb"], b["Y"], b["Ys"], dst, n)
            if sink is None:
                be.fetch_output(out[y0:y0 + nr], dst, n, encoding)
            else:
                band = np.empty((nr, w, 3), np.float32)
                transfer(be.rt.queue, band, dst)
                sink(y0, band)
        return out
