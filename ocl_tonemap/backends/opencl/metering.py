"""Metering reductions on an OpenCL runtime (kernels/metering.cl): two-stage
sums per band, which add up over bands to the whole frame's reading; the
reference is ``models/metering.py``."""

from __future__ import annotations

import numpy as np

from ...models.metering import HIST_BINS, HIST_HI, HIST_LO, LOG_FLOOR, MeteringSpec, MeterSums
from ...models.photometry import RepairCounts
from ..base import Levels
from ..weights import read_weight_mask
from .runtime import round_up
from .transfers import host_buffer, transfer


def repair_counts(c) -> RepairCounts:
    """The repair counts a colour kernel left (8 int32, ``RepairCounts.KEYS`` first)."""
    rc = RepairCounts()
    for k, v in zip(RepairCounts.KEYS, c):
        setattr(rc, k, int(v))
    return rc


class DeviceMeter:
    """Two-stage device reductions over one band at a time."""

    GROUPS = 128
    WG = 64

    def __init__(self, rt):
        import pyopencl as cl
        self.rt = rt
        mf = cl.mem_flags
        self.partial = cl.Buffer(rt.context, mf.READ_WRITE, self.GROUPS * 8 * 4)
        # the sums (8 floats), then a colour stage's repair counts (8 int32): one read
        self.result = cl.Buffer(rt.context, mf.READ_WRITE, 16 * 4)
        self.hist = cl.Buffer(rt.context, mf.READ_WRITE, HIST_BINS * 4)
        self._k_partial = rt.kernel("metering.cl", "meter_partial")
        self._k_final = rt.kernel("metering.cl", "meter_final")
        self._k_hist = rt.kernel("metering.cl", "log_histogram")
        self._no_mask = cl.Buffer(rt.context, mf.READ_ONLY, 4)
        self._mask_key = None
        self._mask_buf = None
        self.counts = None                     # the last band_sums' repair counts

    def _mask(self, spec: MeteringSpec, width: int, height: int):
        if spec.mode != "mask":
            return self._no_mask
        key = (spec.mask, width, height)
        if key != self._mask_key:
            self._mask_buf = host_buffer(self.rt.context, read_weight_mask(spec.mask, width, height))
            self._mask_key = key
        return self._mask_buf

    def band_sums(self, y_buf, ys_buf, n: int, width: int, height: int, y0: int,
                  spec: MeteringSpec, counts=None) -> MeterSums:
        """The band's sums; with ``counts`` (a colour stage's repair counts, 8 int32 on
        the device) read in the same transfer, into ``self.counts``."""
        import pyopencl as cl
        q = self.rt.queue
        mode, p0, p1, p2, w_in, w_out = spec.weight_params(width, height)
        f = np.float32
        groups = max(1, min(self.GROUPS, -(-n // self.WG)))
        scratch = cl.LocalMemory(self.WG * 8 * 4)
        self._k_partial(q, (groups * self.WG,), (self.WG,), y_buf, ys_buf, np.int32(n),
                        np.int32(width), np.int32(y0), np.int32(mode), f(p0), f(p1), f(p2),
                        f(w_in), f(w_out), f(LOG_FLOOR), self._mask(spec, width, height),
                        self.partial, scratch)
        self._k_final(q, (self.WG,), (self.WG,), self.partial, np.int32(groups), self.result,
                      scratch)
        out = np.empty(16 if counts is not None else 8, np.float32)
        if counts is not None:                 # device to device: not a transfer
            cl.enqueue_copy(q, self.result, counts, byte_count=32, dst_offset=32)
        transfer(q, out, self.result)
        ms = MeterSums(out[:7].astype(np.float64))
        self.counts = out[8:].view(np.int32) if counts is not None else None
        if spec.mode == "percentile":
            ms.hist_Y = self._histogram(y_buf, n)
            ms.hist_Ys = self._histogram(ys_buf, n)
        return ms

    def _histogram(self, buf, n: int) -> np.ndarray:
        import pyopencl as cl
        q = self.rt.queue
        cl.enqueue_fill_buffer(q, self.hist, np.int32(0), 0, HIST_BINS * 4)
        groups = max(1, min(self.GROUPS, -(-n // 256)))
        self._k_hist(q, (groups * 256,), (256,), buf, np.int32(n), np.float32(HIST_LO),
                     np.float32(HIST_HI), np.int32(HIST_BINS), np.float32(LOG_FLOOR), self.hist,
                     cl.LocalMemory(HIST_BINS * 4))
        h = np.empty(HIST_BINS, np.int32)
        transfer(q, h, self.hist)
        return h.astype(np.int64)


class MeteringPasses:
    """The metering passes of :class:`~.OpenCLBackend` (a mixin): the colour stage and
    the metering over a frame's bands, the illuminant's sums and the block means the
    flare's source proxy reads. It uses the backend's ``rt``, ``meter``, ``bufs``,
    ``buffer``, ``bands``, ``to_working`` and the ``_resident`` / ``_ahead`` marks."""

    ILLUM_GROUPS = 64

    def _illuminant_sums(self, n: int) -> np.ndarray:
        """Device sums (Y r, Y g, Y b, Y Y) over the resident band (float64 on the host)."""
        import pyopencl as cl
        out = self.buffer("illum", self.ILLUM_GROUPS * 4 * 4)
        wg = 64
        groups = max(1, min(self.ILLUM_GROUPS, -(-n // wg)))
        self._illum(self.rt.queue, (groups * wg,), (wg,), self.bufs["rgb"], self.bufs["Y"],
                    np.int32(n), out, cl.LocalMemory(wg * 4 * 4))
        part = np.empty((groups, 4), np.float32)
        transfer(self.rt.queue, part, out)
        return part.astype(np.float64).sum(axis=0)

    def _block_sums(self, w: int, nr: int, y0: int, s: int, into: np.ndarray,
                    lim: float = 0.0, wait: bool = True):
        """Add the band's block sums (``metering.cl:block_sums``; ``lim`` > 0: of the
        source part) into ``into`` (block rows x block columns x 4, float64); ``wait``
        False: their read is only enqueued, and the function returned adds them once
        it has come."""
        bw = into.shape[1]
        by0, by1 = y0 // s, (y0 + nr - 1) // s + 1
        n = (by1 - by0) * bw
        out = self.buffer("blocks", n * 16)
        self._blocks(self.rt.queue, (round_up(n, 64),), None, self.bufs["rgb"], np.int32(w),
                     np.int32(nr), np.int32(y0), np.int32(s), np.int32(bw), np.int32(by0),
                     np.int32(by1 - by0), np.float32(lim), out)
        part = np.empty((by1 - by0, bw, 4), np.float32)
        ev = transfer(self.rt.queue, part, out, is_blocking=wait)

        def add():
            ev.wait()
            into[by0:by1] += part
        if not wait:
            return add
        add()
        return None

    def meter_pass(self, pixels, scale, spec, illuminant: bool, keep_rgb: np.ndarray | None,
                   proxy_stride: int = 0):
        """Colour stage + metering over the bands (+ illuminant sums, + the working
        rgb copied to ``keep_rgb``, + block sums of ``proxy_stride``): (bands, repairs,
        (G_rod, G_cone), illuminant sums, the largest working luminance, the proxy)."""
        h, w, _ = pixels.shape
        bands = self.bands(h, w)
        repairs = RepairCounts()
        sums = None
        illum = np.zeros(4)
        self._resident = None
        self._ahead = None
        stride = int(proxy_stride)
        blocks = np.zeros((-(-h // stride), -(-w // stride), 4)) if stride else None
        for y0, nr in bands:
            self.to_working(pixels[y0:y0 + nr], scale, count=False)
            b = self.bufs
            s = self.meter.band_sums(b["Y"], b["Ys"], nr * w, w, h, y0, spec, b["counts"])
            repairs += repair_counts(self.meter.counts)
            if sums is None:
                sums = s
            else:
                sums.add(s)
            if illuminant:
                illum += self._illuminant_sums(nr * w)
            if stride:
                self._block_sums(w, nr, y0, stride, blocks)
            if keep_rgb is not None:
                transfer(self.rt.queue, keep_rgb[y0:y0 + nr], b["rgb"])
        proxy = None if blocks is None else blocks[..., :3] / np.maximum(blocks[..., 3:], 1.0)
        return bands, repairs, sums.goal(spec), illum, float(sums.sums[5]), proxy

    def source_proxy(self, shape, stride: int, lim: float) -> np.ndarray | None:
        """Block means of the flare's source part of the frame the last :meth:`working`
        made, where it is still whole on the device (one band); else None."""
        h, w = int(shape[0]), int(shape[1])
        if self._resident != (h, w):
            return None
        ahead, self._ahead = self._ahead, None
        if ahead is not None and ahead[0] == (h, w, int(stride), float(lim)):
            blocks = ahead[1]
            ahead[2]()
        else:
            blocks = np.zeros((-(-h // stride), -(-w // stride), 4))
            self._block_sums(w, h, 0, int(stride), blocks, float(lim))
        return blocks[..., :3] / np.maximum(blocks[..., 3:], 1.0)

    def source_proxy_ahead(self, shape, stride: int, lim: float) -> None:
        h, w = int(shape[0]), int(shape[1])
        self._ahead = None
        if self._resident == (h, w):
            blocks = np.zeros((-(-h // stride), -(-w // stride), 4))
            self._ahead = ((h, w, int(stride), float(lim)), blocks,
                           self._block_sums(w, h, 0, int(stride), blocks, float(lim), False))

    def scene_levels(self, source, scale: float, spec: MeteringSpec,
                     illuminant: bool, proxy_stride: int = 0) -> Levels:
        """:meth:`meter_pass` over a band source (nothing kept)."""
        _, repairs, G, illum, max_Y, proxy = self.meter_pass(source, scale, spec, illuminant,
                                                             None, proxy_stride)
        return Levels(None, repairs, G, (lambda: illum[:3]) if illuminant else None, max_Y,
                      proxy)
