"""Metering reductions on an OpenCL runtime (kernels/metering.cl): two-stage
sums per band, which add up over bands to the whole frame's reading; the
reference is ``models/metering.py``."""

from __future__ import annotations

import numpy as np

from ...imageio import read_weight_mask
from ...models.metering import HIST_BINS, HIST_HI, HIST_LO, LOG_FLOOR, MeteringSpec, MeterSums


class DeviceMeter:
    """Two-stage device reductions over one band at a time."""

    GROUPS = 128
    WG = 64

    def __init__(self, rt):
        import pyopencl as cl
        self.rt = rt
        mf = cl.mem_flags
        self.partial = cl.Buffer(rt.context, mf.READ_WRITE, self.GROUPS * 8 * 4)
        self.result = cl.Buffer(rt.context, mf.READ_WRITE, 8 * 4)
        self.hist = cl.Buffer(rt.context, mf.READ_WRITE, HIST_BINS * 4)
        self._k_partial = rt.kernel("metering.cl", "meter_partial")
        self._k_final = rt.kernel("metering.cl", "meter_final")
        self._k_hist = rt.kernel("metering.cl", "log_histogram")
        self._no_mask = cl.Buffer(rt.context, mf.READ_ONLY, 4)
        self._mask_key = None
        self._mask_buf = None

    def _mask(self, spec: MeteringSpec, width: int, height: int):
        import pyopencl as cl
        if spec.mode != "mask":
            return self._no_mask
        key = (spec.mask, width, height)
        if key != self._mask_key:
            self._mask_buf = cl.Buffer(self.rt.context,
                                       cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                                       hostbuf=read_weight_mask(spec.mask, width, height))
            self._mask_key = key
        return self._mask_buf

    def band_sums(self, y_buf, ys_buf, n: int, width: int, height: int, y0: int,
                  spec: MeteringSpec) -> MeterSums:
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
        out = np.empty(8, np.float32)
        cl.enqueue_copy(q, out, self.result)
        ms = MeterSums(out[:7].astype(np.float64))
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
        cl.enqueue_copy(q, h, self.hist)
        return h.astype(np.int64)
