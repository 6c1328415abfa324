"""kirk11 on the device (kernels/kirk11.cl + the bilateral kernels); whole frames."""

from __future__ import annotations

import numpy as np

from . import lmsr
from .bilateral import DeviceBilateral, RangeKernel
from .kirk11 import (RHO, SIGMA_RANGE_LOG10, KirkSummary, logmean, subset_solvers,
                     model_scale, white_norm)
from .photometry import RepairCounts


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

    def _shift(self, q, n: int, area, k1, k2, gain, xyz, M, D, paper: bool = False):
        """kirk11_shift on n LMSR pixels: (rgb, w, log10 Y, fallback count) buffers.
        ``paper``: the printed opponent space (no white normalisation) and Eq. 15's
        exact NNLS; else D_W and the gamut map."""
        from .runtime import round_up
        dw = np.ones(3) if paper else white_norm()[:3]
        par = np.array([area, k1, k2, gain, *xyz, *RHO, *dw, 1.0 if paper else 0.0], np.float32)
        out, wbuf, logY = self._buf(n * 12), self._buf(n * 4), self._buf(n * 4)
        fb = self._buf(4, np.zeros(1, np.int32).view(np.float32))
        self._k_shift(self.rt.queue, (round_up(n, 64),), (64,), q, np.int32(n),
                      self._buf(0, par), self._buf(0, np.linalg.inv(M).reshape(-1)),
                      self._buf(0, subset_solvers(M).reshape(-1)),
                      self._buf(0, M), self._buf(0, D), out, wbuf, logY, fb)
        return out, wbuf, logY, fb

    def process(self, obs, backend, pixels, scale, wavelengths, dt: float = 0.0,
                fresh: bool = True):
        from .runtime import round_up
        cl, q_ = self.cl, self.rt.queue
        h, w = pixels.shape[:2]
        n = h * w
        if n > backend.max_band_pixels:
            return self._process_banded(obs, backend, pixels, scale, wavelengths, dt, fresh)
        gsz, wg = (round_up(n, 64),), (64,)
        s = obs.s
        q, src, repairs = self._lmsr_band(backend, pixels, scale, wavelengths, True)
        qh = np.empty((n, 4), np.float32)
        cl.enqueue_copy(q_, qh, q)
        L_wa, L_waR = logmean(qh[:, 0] + qh[:, 1]), logmean(qh[:, 3])
        area = model_scale()
        k1, k2, gain = obs.begin_frame(L_waR, L_wa, dt, fresh)
        shifted, wbuf, logY, fb = self._shift(q, n, area, k1, k2, gain, s.shift_xyz, obs.M,
                                              obs.D, s.paper)
        # Durand & Dorsey 2002 base layer
        base = self._buf(n * 4)
        rk = RangeKernel("difference", SIGMA_RANGE_LOG10)
        sig = s.sigma_px(w, h)
        if self.bil.choose(s.bilateral, sig, w, h) == "exact":
            self.bil.exact(logY, base, w, h, 0, 0, h, sig, rk)
        else:
            self.bil.fast(logY, base, w, h, sig, rk, s.bilateral.q_s, s.bilateral.q_r)
        bh = np.empty(n, np.float32)
        cl.enqueue_copy(q_, bh, base)
        bmin, bmax = float(bh.min()), float(bh.max())
        span = bmax - bmin
        c = min(1.0, np.log10(s.target_contrast) / span) if span > 0 else 1.0
        out = self._buf(n * 12)
        blend = wavelengths is None
        self._k_compose(q_, gsz, wg, src if blend else shifted, shifted, wbuf, logY, base,
                        np.int32(n), np.float32(c), np.float32(bmax), np.float32(s.beta),
                        np.float32(s.gamma),
                        np.float32(obs.display.white_cd / obs.display.unit_cd),
                        np.int32(1 if blend else 0), out, np.int32(0 if s.paper else 1))
        res = np.empty((h, w, 3), np.float32)
        cl.enqueue_copy(q_, res, out)
        res = obs.finish(res).astype(np.float32)
        nfb = np.empty(1, np.int32)
        cl.enqueue_copy(q_, nfb, fb)
        wh = np.empty(n, np.float32)
        cl.enqueue_copy(q_, wh, wbuf)
        obs.summary = KirkSummary(area, k1, k2, gain, float(wh.mean()), float(nfb[0]) / n,
                                  "spectral" if wavelengths is not None else "rgb")
        if not isinstance(repairs, RepairCounts):
            repairs = RepairCounts()
        return res, repairs, (L_waR, L_wa)

    def shift_rgb(self, rgb: np.ndarray, area: float, k1: float, k2: float, gain: float,
                  M: np.ndarray, D: np.ndarray, xyz) -> tuple[np.ndarray, float]:
        """Eqs. 10-13 and 15 on working RGB (cd/m^2, host array): the shifted RGB and
        the NNLS fallback share. Used by the Purkinje effect for other operators."""
        from .runtime import round_up
        cl, q_ = self.cl, self.rt.queue
        h, w = rgb.shape[:2]
        n = h * w
        gsz, wg = (round_up(n, 64),), (64,)
        src = self._buf(0, rgb.reshape(n, 3))
        q = self._buf(n * 16)
        self._k_lmsr(q_, gsz, wg, src, np.int32(3), np.int32(n), self._buf(0, lmsr.fitted()["H"]), q)
        out, _, _, fb = self._shift(q, n, area, k1, k2, gain, xyz, M, D)
        res = np.empty((h, w, 3), np.float32)
        cl.enqueue_copy(q_, res, out)
        nfb = np.empty(1, np.int32)
        cl.enqueue_copy(q_, nfb, fb)
        return res, float(nfb[0]) / max(n, 1)

    def _repair(self, buf, n: int, scale: float, count: bool) -> RepairCounts:
        """photometry.sanitize on the device, in place (kernels/colour.cl repair_scale)."""
        from .runtime import round_up
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

    def _lmsr_band(self, backend, band: np.ndarray, scale: float, wavelengths, count: bool):
        """One band (or a whole frame) to LMSR on the device: (q buffer, source
        buffer, repairs). RGB goes through the device colour stage; spectra are
        uploaded as they are and repaired on the device (``_repair``)."""
        from .runtime import round_up
        nr, w = band.shape[:2]
        n = nr * w
        if wavelengths is None:
            rc = backend._to_working(band, scale, count=count)
            src, W, nc = backend._bufs["rgb"], lmsr.fitted()["H"], 3
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

    def _process_banded(self, obs, backend, pixels, scale, wavelengths, dt, fresh):
        """Frames beyond ``backend.max_band_pixels``: per-pixel passes in row bands,
        the bilateral base through ``DeviceBilateral.filter_banded``, the final
        composition on the host (float64, the reference's ``compose_reference``)."""
        from .kirk11 import compose_reference
        cl, q_ = self.cl, self.rt.queue
        h, w = pixels.shape[:2]
        rows = max(1, backend.max_band_pixels // max(w, 1))
        bands = [(y0, min(rows, h - y0)) for y0 in range(0, h, rows)]
        s = obs.s
        repairs = RepairCounts()
        sum_lm = sum_r = 0.0
        for y0, nr in bands:                               # pass 1: the frame's levels
            qb, _, rc = self._lmsr_band(backend, pixels[y0:y0 + nr], scale, wavelengths, True)
            repairs += rc
            qh = np.empty((nr * w, 4), np.float32)
            cl.enqueue_copy(q_, qh, qb)
            sum_lm += float(np.log(np.maximum(qh[:, 0].astype(np.float64) + qh[:, 1], 1e-6)).sum())
            sum_r += float(np.log(np.maximum(qh[:, 3].astype(np.float64), 1e-6)).sum())
        L_wa, L_waR = float(np.exp(sum_lm / (h * w))), float(np.exp(sum_r / (h * w)))
        area = model_scale()
        k1, k2, gain = obs.begin_frame(L_waR, L_wa, dt, fresh)
        blend = wavelengths is None
        shifted = np.empty((h, w, 3), np.float32)
        wh = np.empty((h, w), np.float32)
        logY = np.empty((h, w), np.float32)
        src = np.empty((h, w, 3), np.float32) if blend else None
        nfb = 0
        for y0, nr in bands:                               # pass 2: shift, per band
            qb, sb, _ = self._lmsr_band(backend, pixels[y0:y0 + nr], scale, wavelengths, False)
            ob, wb, lb, fb = self._shift(qb, nr * w, area, k1, k2, gain, s.shift_xyz, obs.M,
                                         obs.D, s.paper)
            cl.enqueue_copy(q_, shifted[y0:y0 + nr], ob)
            cl.enqueue_copy(q_, wh[y0:y0 + nr], wb)
            cl.enqueue_copy(q_, logY[y0:y0 + nr], lb)
            if blend:
                cl.enqueue_copy(q_, src[y0:y0 + nr], sb)
            c = np.empty(1, np.int32)
            cl.enqueue_copy(q_, c, fb)
            nfb += int(c[0])
        sig = s.sigma_px(w, h)
        method = self.bil.choose(s.bilateral, sig, w, h)
        base = self.bil.filter_banded(logY, sig, RangeKernel("difference", SIGMA_RANGE_LOG10),
                                      method, backend.max_band_pixels, s.bilateral.q_s,
                                      s.bilateral.q_r)
        out = obs.finish(compose_reference(src, shifted.astype(np.float64),
                                           wh.astype(np.float64), logY.astype(np.float64),
                                           base.astype(np.float64), s, obs.display, blend))
        obs.summary = KirkSummary(area, k1, k2, gain, float(wh.mean()), nfb / (h * w),
                                  "spectral" if wavelengths is not None else "rgb")
        return out.astype(np.float32), repairs, (L_waR, L_wa)
