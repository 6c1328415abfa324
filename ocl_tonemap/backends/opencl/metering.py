"""Metering reductions on an OpenCL runtime (kernels/metering.cl): two-stage
sums per band, which add up over bands to the whole frame's reading; the
reference is ``models/metering.py``."""

from __future__ import annotations

import numpy as np

from ...models.metering import (HIST_BINS, HIST_HI, HIST_LO, LOG_FLOOR,
                                MeteringSpec, MeterSums, log16_decode, log16_encode)
from ...models.photometry import RepairCounts
from ..base import Levels
from ..weights import read_weight_mask
from .runtime import round_up
from .stats import statistics
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
        self.result = cl.Buffer(rt.context, mf.READ_WRITE, 8 * 4)      # the sums
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
        return self.band_sums_later(y_buf, ys_buf, n, width, height, y0, spec, counts)()

    def band_sums_later(self, y_buf, ys_buf, n: int, width: int, height: int, y0: int,
                        spec: MeteringSpec, counts=None):
        """:meth:`band_sums` enqueued: its sums are put in the frame's statistics
        (``stats.py``) and the function returned gives them, reading them with whatever
        else was put there by then."""
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
        st = statistics(self.rt)
        sums = st.put(self.result, 32, np.float32)
        got = st.put(counts, 32, np.int32) if counts is not None else None
        hists = [self._histogram(b, n, st) for b in (y_buf, ys_buf)] \
            if spec.mode == "percentile" else None

        def done() -> MeterSums:
            ms = MeterSums(sums.get()[:7].astype(np.float64))
            self.counts = got.get() if got is not None else None
            if hists is not None:
                ms.hist_Y, ms.hist_Ys = (h.get().astype(np.int64) for h in hists)
            return ms
        return done

    def _histogram(self, buf, n: int, st):
        import pyopencl as cl
        q = self.rt.queue
        cl.enqueue_fill_buffer(q, self.hist, np.int32(0), 0, HIST_BINS * 4)
        groups = max(1, min(self.GROUPS, -(-n // 256)))
        self._k_hist(q, (groups * 256,), (256,), buf, np.int32(n), np.float32(HIST_LO),
                     np.float32(HIST_HI), np.int32(HIST_BINS), np.float32(LOG_FLOOR), self.hist,
                     cl.LocalMemory(HIST_BINS * 4))
        return st.put(self.hist, HIST_BINS * 4, np.int32)


class MeteringPasses:
    """The metering passes of :class:`~.OpenCLBackend` (a mixin): the colour stage and
    the metering over a frame's bands, the illuminant's sums and the block means the
    flare's source proxy reads. It uses the backend's ``rt``, ``meter``, ``bufs``,
    ``buffer``, ``bands``, ``to_working`` and the ``_resident`` / ``_ahead`` marks."""

    ILLUM_GROUPS = 64

    def _illuminant_sums(self, n: int):
        """Device sums (Y r, Y g, Y b, Y Y) over the resident band, put in the frame's
        statistics: a function that gives them (float64)."""
        import pyopencl as cl
        out = self.buffer("illum", self.ILLUM_GROUPS * 4 * 4)
        wg = 64
        groups = max(1, min(self.ILLUM_GROUPS, -(-n // wg)))
        self._illum(self.rt.queue, (groups * wg,), (wg,), self.bufs["rgb"], self.bufs["Y"],
                    np.int32(n), out, cl.LocalMemory(wg * 4 * 4))
        part = statistics(self.rt).put(out, groups * 16, np.float32, (groups, 4))
        return lambda: part.get().astype(np.float64).sum(axis=0)

    def _block_sums(self, w: int, nr: int, y0: int, s: int, into: np.ndarray) -> None:
        """Add the band's block sums (``metering.cl:block_sums``) into ``into`` (block
        rows x block columns x 4, float64): frames in bands."""
        bw = into.shape[1]
        by0, by1 = y0 // s, (y0 + nr - 1) // s + 1
        n = (by1 - by0) * bw
        out = self.buffer("blocks", n * 16)
        self._blocks(self.rt.queue, (round_up(n, 64),), None, self.bufs["rgb"], np.int32(w),
                     np.int32(nr), np.int32(y0), np.int32(s), np.int32(bw), np.int32(by0),
                     np.int32(by1 - by0), np.float32(0.0), out)
        part = np.empty((by1 - by0, bw, 4), np.float32)
        transfer(self.rt.queue, part, out)
        into[by0:by1] += part

    def _block_means_later(self, h: int, w: int, s: int, lim: float = 0.0):
        """The block means of the resident frame (``lim`` > 0: of its flare source part,
        ``metering.cl:block_means_log16``) put in the frame's statistics: a function
        that gives them (block rows x block columns x 3, float64)."""
        bh, bw = -(-h // s), -(-w // s)
        n = bh * bw
        out = self.buffer("blocks16" if lim <= 0 else "sblocks16", n * 6 + 16)
        self._blocks16(self.rt.queue, (round_up(n, 64),), None, self.bufs["rgb"], np.int32(w),
                       np.int32(h), np.int32(s), np.int32(bw), np.int32(bh), np.float32(lim),
                       out)
        codes = statistics(self.rt).put(out, n * 6, np.uint16, (bh, bw, 3))
        return lambda: log16_decode(codes.get())

    def meter_pass(self, pixels, scale, spec, illuminant: bool, keep_rgb: np.ndarray | None,
                   proxy_stride: int = 0):
        """Colour stage + metering over the bands (+ illuminant sums, + the working
        rgb copied to ``keep_rgb``, + block means of ``proxy_stride``): (bands, repairs,
        (G_rod, G_cone), illuminant sums, the largest working luminance, the proxy).
        A whole frame's sums, illuminant sums and block means come down in one read."""
        h, w, _ = pixels.shape
        bands = self.bands(h, w)
        repairs = RepairCounts()
        sums = None
        illum = np.zeros(4)
        self._resident = None
        self._ahead = None
        stride = int(proxy_stride)
        whole = len(bands) == 1
        blocks = np.zeros((-(-h // stride), -(-w // stride), 4)) if stride and not whole \
            else None
        proxy = None
        for y0, nr in bands:
            self.to_working(pixels[y0:y0 + nr], scale, count=False)
            b = self.bufs
            later = [self.meter.band_sums_later(b["Y"], b["Ys"], nr * w, w, h, y0, spec,
                                                b["counts"])]
            if illuminant:
                later.append(self._illuminant_sums(nr * w))
            if stride and whole:
                proxy = self._block_means_later(h, w, stride)
            s = later[0]()
            repairs += repair_counts(self.meter.counts)
            if illuminant:
                illum += later[1]()
            if sums is None:
                sums = s
            else:
                sums.add(s)
            if blocks is not None:
                self._block_sums(w, nr, y0, stride, blocks)
            if keep_rgb is not None:
                transfer(self.rt.queue, keep_rgb[y0:y0 + nr], b["rgb"])
        if blocks is not None:
            proxy = log16_decode(log16_encode(blocks[..., :3] / np.maximum(blocks[..., 3:], 1.0)))
        elif proxy is not None:
            proxy = proxy()
        return (bands, repairs, sums.goal(spec), illum, float(sums.sums[5]), proxy,
                float(sums.sums[6]))

    def source_proxy(self, shape, stride: int, lim: float) -> np.ndarray | None:
        """Block means of the flare's source part of the frame the last :meth:`working`
        made, where it is still whole on the device (one band); else None."""
        h, w = int(shape[0]), int(shape[1])
        if self._resident != (h, w):
            return None
        ahead, self._ahead = self._ahead, None
        if ahead is None or ahead[0] != (h, w, int(stride), float(lim)):
            ahead = (None, self._block_means_later(h, w, int(stride), float(lim)))
        return ahead[1]()

    def source_proxy_ahead(self, shape, stride: int, lim: float) -> None:
        h, w = int(shape[0]), int(shape[1])
        self._ahead = None
        if self._resident == (h, w):
            self._ahead = ((h, w, int(stride), float(lim)),
                           self._block_means_later(h, w, int(stride), float(lim)))

    def scene_levels(self, source, scale: float, spec: MeteringSpec,
                     illuminant: bool, proxy_stride: int = 0) -> Levels:
        """:meth:`meter_pass` over a band source (nothing kept)."""
        _, repairs, G, illum, max_Y, proxy, max_Ys = self.meter_pass(
            source, scale, spec, illuminant, None, proxy_stride)
        return Levels(None, repairs, G, (lambda: illum[:3]) if illuminant else None, max_Y,
                      proxy, max_Ys)
