"""kirk11 on the device: LMSR (kernels/kirk11.cl), the shift and display solve, the
bilateral base (backends/opencl/bilateral.py) and the composition.

measure    LMSR of the frame (resident for one band) and its log-averages;
integrate  the receptor levels (host scalars, ``operators/kirk11.py``);
apply      Eqs. 10-16 per band, the base layer, the composition; frames beyond
           the backend's band size compose on the host (float64).
"""

from __future__ import annotations

import numpy as np

from ...models import lmsr
from ...models.kirk2011 import (RHO, SIGMA_RANGE_LOG10, compose_reference, display_matrix,
                                logmean, model_scale, subset_solvers, white_norm)
from ...models.bilateral import RangeKernel
from ...models.photometry import RepairCounts
from ...operators.base import FrameStats
from ..reference import NoPixelState
from .bilateral import DeviceBilateral
from .runtime import round_up

class KirkDevice:
    def __init__(self, rt):
        import pyopencl as cl
        self.rt = rt
        self.cl = cl
        self.bil = DeviceBilateral(rt)
        self._k_lmsr = rt.kernel("kirk11.cl", "to_lmsr")
        self._k_shift = rt.kernel("kirk11.cl", "kirk11_shift")
        self._k_compose = rt.kernel("kirk11.cl", "kirk11_compose")

    def _buf(self, nbytes: int, host: np.ndarray | None = None):
        cl = self.cl
        mf = cl.mem_flags
        if host is not None:
            return cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR,
                             hostbuf=np.ascontiguousarray(host, np.float32))
        return cl.Buffer(self.rt.context, mf.READ_WRITE, max(int(nbytes), 4))

    def shift(self, q, n: int, area, k1, k2, gain, xyz, M, D, paper: bool = False):
        """kirk11_shift on n LMSR pixels: (rgb, w, log10 Y, fallback count) buffers.
        ``paper``: the printed opponent space (no white normalisation) and Eq. 15's
        exact NNLS; else D_W and the gamut map."""
        dw = np.ones(3) if paper else white_norm()[:3]
        par = np.array([area, k1, k2, gain, *xyz, *RHO, *dw, 1.0 if paper else 0.0], np.float32)
        out, wbuf, logY = self._buf(n * 12), self._buf(n * 4), self._buf(n * 4)
        fb = self._buf(4, np.zeros(1, np.int32).view(np.float32))
        self._k_shift(self.rt.queue, (round_up(n, 64),), (64,), q, np.int32(n),
                      self._buf(0, par), self._buf(0, np.linalg.inv(M).reshape(-1)),
                      self._buf(0, subset_solvers(M).reshape(-1)),
                      self._buf(0, M), self._buf(0, D), out, wbuf, logY, fb)
        return out, wbuf, logY, fb

    def shift_rgb(self, rgb: np.ndarray, area: float, k1: float, k2: float, gain: float,
                  M: np.ndarray, D: np.ndarray, xyz) -> tuple[np.ndarray, float]:
        """Eqs. 10-13 and 15 on working RGB (cd/m^2, host array): the shifted RGB and
        the NNLS fallback share. Used by the Purkinje effect for other operators."""
        cl, q_ = self.cl, self.rt.queue
        h, w = rgb.shape[:2]
        n = h * w
        gsz, wg = (round_up(n, 64),), (64,)
        src = self._buf(0, rgb.reshape(n, 3))
        q = self._buf(n * 16)
        self._k_lmsr(q_, gsz, wg, src, np.int32(3), np.int32(n), self._buf(0, lmsr.fitted()["H"]), q)
        out, _, _, fb = self.shift(q, n, area, k1, k2, gain, xyz, M, D)
        res = np.empty((h, w, 3), np.float32)
        cl.enqueue_copy(q_, res, out)
        nfb = np.empty(1, np.int32)
        cl.enqueue_copy(q_, nfb, fb)
        return res, float(nfb[0]) / max(n, 1)

    def _repair(self, buf, n: int, scale: float, count: bool) -> RepairCounts:
        """photometry.sanitize on the device, in place (kernels/colour.cl repair_scale)."""
        cl, q_ = self.cl, self.rt.queue
        if getattr(self, "_k_repair", None) is None:
            self._k_repair = self.rt.kernel("colour.cl", "repair_scale")
            self._counts = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, 8 * 4)
        cl.enqueue_fill_buffer(q_, self._counts, np.int32(0), 0, 8 * 4)
        self._k_repair(q_, (round_up(max(n, 1), 64),), (64,), buf, np.int32(n),
                       np.float32(scale), self._counts)
        rc = RepairCounts()
        if count:
            c = np.empty(8, np.int32)
            cl.enqueue_copy(q_, c, self._counts)
            for k, v in zip(RepairCounts.KEYS, c):
                setattr(rc, k, int(v))
        return rc

    def lmsr_band(self, backend, band: np.ndarray, scale: float, wavelengths, count: bool):
        """One band (or a whole frame) to LMSR on the device: (q buffer, source
        buffer, repairs). RGB goes through the device colour stage; spectra are
        uploaded as they are and repaired on the device (``_repair``)."""
        nr, w = band.shape[:2]
        n = nr * w
        if wavelengths is None:
            rc = backend.to_working(band, scale, count=count)
            src, W, nc = backend.bufs["rgb"], lmsr.fitted()["H"], 3
        else:                                     # repaired and scaled on the device
            nc = band.shape[2]
            mf = self.cl.mem_flags
            src = self.cl.Buffer(self.rt.context, mf.READ_WRITE | mf.COPY_HOST_PTR,
                                 hostbuf=np.ascontiguousarray(band, np.float32).reshape(n, nc))
            W = lmsr.spectrum_weights(wavelengths)
            rc = self._repair(src, n * nc, scale, count)
        q = self._buf(n * 16)
        self._k_lmsr(self.rt.queue, (round_up(n, 64),), (64,), src, np.int32(nc), np.int32(n),
                     self._buf(0, W), q)
        return q, src, rc


class KirkSchedule(NoPixelState):
    receptor_gains = False
    streams = False

    def __init__(self, backend, op):
        self.backend, self.op = backend, op
        self.dev = KirkDevice(backend.rt)

    def measure(self, frame, spec=None, want_illuminant: bool = False) -> FrameStats:
        import pyopencl as cl
        be = self.backend
        h, w = frame.pixels.shape[:2]
        n = h * w
        bands = be.bands(h, w)
        if len(bands) == 1:
            q, src, repairs = self.dev.lmsr_band(be, frame.pixels, frame.scale, frame.wavelengths,
                                                 True)
            qh = np.empty((n, 4), np.float32)
            cl.enqueue_copy(be.rt.queue, qh, q)
            return FrameStats(w, h, logmean(qh[:, 3]), logmean(qh[:, 0] + qh[:, 1]),
                              repairs if isinstance(repairs, RepairCounts) else RepairCounts(),
                              handle=(frame.pixels, q, src))
        repairs = RepairCounts()
        sum_lm = sum_r = 0.0
        for y0, nr in bands:                               # the frame's levels, per band
            qb, _, rc = self.dev.lmsr_band(be, frame.pixels[y0:y0 + nr], frame.scale,
                                           frame.wavelengths, True)
            repairs += rc
            qh = np.empty((nr * w, 4), np.float32)
            cl.enqueue_copy(be.rt.queue, qh, qb)
            sum_lm += float(np.log(np.maximum(qh[:, 0].astype(np.float64) + qh[:, 1], 1e-6)).sum())
            sum_r += float(np.log(np.maximum(qh[:, 3].astype(np.float64), 1e-6)).sum())
        return FrameStats(w, h, float(np.exp(sum_r / n)), float(np.exp(sum_lm / n)), repairs,
                          handle=(frame.pixels, None, None))

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        self.op.integrate(state, stats, dt, fresh)

    def apply(self, frame, state, stats, params=None, gains=None, sink=None):
        import pyopencl as cl
        be, dev, op = self.backend, self.dev, self.op
        s, v = op.settings, stats.values
        q_ = be.rt.queue
        h, w = stats.height, stats.width
        n = h * w
        D = frame.display_primaries if frame.display_primaries is not None else np.eye(3)
        M = display_matrix(D)
        area = model_scale()
        _, q, src = stats.handle
        if q is None or stats.handle[0] is not frame.pixels:
            return self._apply_banded(frame, stats, D, M, area)
        gsz, wg = (round_up(n, 64),), (64,)
        shifted, wbuf, logY, fb = dev.shift(q, n, area, v["k1"], v["k2"], v["rod_gain"],
                                            s.shift_xyz, M, D, s.paper)
        base = dev._buf(n * 4)                  # Durand & Dorsey 2002 base layer
        rk = RangeKernel("difference", SIGMA_RANGE_LOG10)
        sig = s.sigma_px(w, h)
        if dev.bil.choose(op.bilateral, sig, w, h) == "exact":
            dev.bil.exact(logY, base, w, h, 0, 0, h, sig, rk)
        else:
            dev.bil.fast(logY, base, w, h, sig, rk, op.bilateral.q_s, op.bilateral.q_r)
        bh = np.empty(n, np.float32)
        cl.enqueue_copy(q_, bh, base)
        bmin, bmax = float(bh.min()), float(bh.max())
        span = bmax - bmin
        c = min(1.0, np.log10(s.target_contrast) / span) if span > 0 else 1.0
        out = dev._buf(n * 12)
        blend = frame.wavelengths is None
        dev._k_compose(q_, gsz, wg, src if blend else shifted, shifted, wbuf, logY, base,
                       np.int32(n), np.float32(c), np.float32(bmax), np.float32(s.beta),
                       np.float32(s.gamma),
                       np.float32(op.display.white_cd / op.display.unit_cd),
                       np.int32(1 if blend else 0), out, np.int32(0 if s.paper else 1))
        res = np.empty((h, w, 3), np.float32)
        cl.enqueue_copy(q_, res, out)
        res = op.finish(res, stats).astype(np.float32)
        nfb = np.empty(1, np.int32)
        cl.enqueue_copy(q_, nfb, fb)
        wh = np.empty(n, np.float32)
        cl.enqueue_copy(q_, wh, wbuf)
        v.update(model_scale=area, w_mean=float(wh.mean()), fallback_fraction=float(nfb[0]) / n,
                 input="spectral" if frame.wavelengths is not None else "rgb")
        return res

    def _apply_banded(self, frame, stats, D, M, area):
        """Frames beyond the backend's band size: the shift in row bands, the base
        through ``DeviceBilateral.filter_banded``, the composition on the host
        (float64, the reference's ``compose_reference``)."""
        import pyopencl as cl
        be, dev, op = self.backend, self.dev, self.op
        s, v = op.settings, stats.values
        q_ = be.rt.queue
        h, w = stats.height, stats.width
        blend = frame.wavelengths is None
        shifted = np.empty((h, w, 3), np.float32)
        wh = np.empty((h, w), np.float32)
        logY = np.empty((h, w), np.float32)
        src = np.empty((h, w, 3), np.float32) if blend else None
        nfb = 0
        for y0, nr in be.bands(h, w):
            qb, sb, _ = dev.lmsr_band(be, frame.pixels[y0:y0 + nr], frame.scale,
                                      frame.wavelengths, False)
            ob, wb, lb, fb = dev.shift(qb, nr * w, area, v["k1"], v["k2"], v["rod_gain"],
                                       s.shift_xyz, M, D, s.paper)
            cl.enqueue_copy(q_, shifted[y0:y0 + nr], ob)
            cl.enqueue_copy(q_, wh[y0:y0 + nr], wb)
            cl.enqueue_copy(q_, logY[y0:y0 + nr], lb)
            if blend:
                cl.enqueue_copy(q_, src[y0:y0 + nr], sb)
            c = np.empty(1, np.int32)
            cl.enqueue_copy(q_, c, fb)
            nfb += int(c[0])
        sig = s.sigma_px(w, h)
        method = dev.bil.choose(op.bilateral, sig, w, h)
        base = dev.bil.filter_banded(logY, sig, RangeKernel("difference", SIGMA_RANGE_LOG10),
                                     method, be.max_band_pixels, op.bilateral.q_s,
                                     op.bilateral.q_r)
        out = op.finish(compose_reference(src, shifted.astype(np.float64),
                                          wh.astype(np.float64), logY.astype(np.float64),
                                          base.astype(np.float64), s, op.display, blend), stats)
        v.update(model_scale=area, w_mean=float(wh.mean()), fallback_fraction=nfb / (h * w),
                 input="spectral" if frame.wavelengths is not None else "rgb")
        return out.astype(np.float32)

    def summary(self, stats) -> dict:
        from ..reference import kirk_summary
        return kirk_summary(stats)
