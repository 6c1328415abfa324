"""kirk11 on the device: LMSR (kernels/kirk11.cl), the shift and display solve, the
bilateral base (backends/opencl/bilateral.py) and the composition.

measure    LMSR of the frame (resident for one band) and its log-averages;
integrate  the receptor levels (host scalars, ``operators/kirk11.py``);
apply      Eqs. 10-16, the base layer, the composition, ``finish``; frames beyond
           the backend's band size (and streamed ones, read from their file by
           bands) in passes over row bands on the device, in memory bounded by
           the band (``KirkSchedule._apply_banded``).
"""

from __future__ import annotations

import math

import numpy as np

from ...models import kirk2011 as K
from ...models import lmsr
from ...models.bilateral import RangeKernel, spatial_radius
from ...models.durand2002 import (BASE_HIST_BINS, BASE_HIST_HI, BASE_HIST_LO, BaseRange,
                                   base_hist_edges, compression)
from ...models.display import SHOULDER_KNEE
from ...models.kirk2011 import (RHO, SIGMA_RANGE_LOG10, anchor_gain, display_matrix,
                                model_scale, subset_solvers, white_norm)
from ...models.photometry import RepairCounts
from ...operators.base import FrameStats
from ..reference import NoPixelState
from .bilateral import DeviceBilateral
from .image import DeviceImage
from .runtime import round_up

#: Model constants of kernels/kirk11.cl, given as build options (never retyped);
#: DISPLAY_LINEAR_MAX and the other shared ones come with every program (constants.py).
#: Eq. 11's A^-1 as the kernel's closed form takes it: the four entries of its first two
#: rows that are not 0 (the last row, (0, 1, 1), is written out there).
KERNEL_CONSTANTS = (
    ("L_MAX_F", lmsr.L_MAX), ("M_MAX_F", lmsr.M_MAX), ("S_MAX_F", lmsr.S_MAX),
    ("ALPHA_F", K.ALPHA), ("REGULATION_C", K.REGULATION_C),
    *((f"A_INV_{i}{j}", float(K.A_INV[i, j])) for i in (0, 1) for j in (0, 2)),
    ("N_SUPPORTS", len(K.SUBSETS)), ("Y_FLOOR", K.Y_FLOOR), ("LOG_FLOOR", K.LOG_FLOOR),
)


class KirkDevice:
    def __init__(self, rt):
        import pyopencl as cl
        self.rt = rt
        self.cl = cl
        self.bil = DeviceBilateral(rt)
        c = KERNEL_CONSTANTS
        self._k_lmsr = rt.kernel("kirk11.cl", "to_lmsr", c)
        self._k_shift = rt.kernel("kirk11.cl", "kirk11_shift", c)
        self._k_compose = rt.kernel("kirk11.cl", "kirk11_compose", c)
        self._k_sums = rt.kernel("kirk11.cl", "kirk11_sums", c)
        self._k_finish = rt.kernel("kirk11.cl", "kirk11_finish", c)
        self._k_spectrum = rt.kernel("colour.cl", "spectrum_to_lmsr")
        self._k_hist = rt.kernel("kirk11.cl", "base_histogram", c)
        self._partial = self._buf(self.SUM_GROUPS * 16)       # kirk11_sums, per group
        self._hist = self._buf(BASE_HIST_BINS * 4)             # base_histogram's counts

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

    SUM_GROUPS, SUM_WG = 128, 64
    #: kirk11_sums modes
    LOG_LEVELS, PLANE, LOG_OUTPUT = 0, 1, 2

    def sums(self, x, n: int, mode: int, inv_u: float = 1.0) -> tuple[float, float]:
        """kirk11_sums over ``n`` pixels of ``x``, added in float64: LOG_LEVELS (LMSR):
        (sum ln max(R, f), sum ln max(L+M, f)), as ``kirk2011.logmean``; PLANE:
        (sum x, 0); LOG_OUTPUT (display-linear RGB): (sum ln max(Y inv_u, f), 0), as
        ``anchor_gain`` (f: ``kirk2011.LOG_FLOOR``). Only the groups' records come back."""
        cl = self.cl
        if n <= 0:
            return 0.0, 0.0
        wg = self.SUM_WG
        groups = max(1, min(self.SUM_GROUPS, -(-n // (4 * wg))))
        self._k_sums(self.rt.queue, (groups * wg,), (wg,), x, np.int32(n), np.int32(mode),
                     np.float32(inv_u), self._partial, cl.LocalMemory(wg * 16))
        host = np.empty((groups, 4), np.float32)
        cl.enqueue_copy(self.rt.queue, host, self._partial)
        t = host.astype(np.float64).sum(axis=0)
        return float(t[0]), float(t[1])

    #: base_histogram: at most this many work-items, each a stretch of >= HIST_MIN_RUN
    HIST_ITEMS, HIST_MIN_RUN = 16384, 64

    def base_range(self, percentiles) -> "DeviceBaseRange":
        """A :class:`~ocl_tonemap.models.durand2002.BaseRange` fed with device buffers."""
        return DeviceBaseRange(self, percentiles)

    def finish(self, rgb, n: int, gain: float, inv_white: float, knee: float) -> None:
        """``Kirk11.finish`` in place on ``n`` display-linear pixels (kernels/kirk11.cl
        kirk11_finish): the gain under the signal ceiling, the shoulder (knee 0: none),
        the clamp."""
        if n > 0:
            self._k_finish(self.rt.queue, (round_up(self.rt.pixel_items(n, 4), 64),), (64,),
                           rgb, np.int32(n), np.float32(gain), np.float32(inv_white),
                           np.float32(knee))

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

    def lmsr_band(self, backend, band: np.ndarray, scale: float, wavelengths, count: bool):
        """One band (or a whole frame) to LMSR on the device: (q buffer, source
        buffer, repairs). RGB goes through the device colour stage; a spectral cube is
        copied into a pooled buffer and repaired, scaled and weighted in one pass
        (kernels/colour.cl spectrum_to_lmsr); its source buffer holds the raw values."""
        cl = self.cl
        q_ = self.rt.queue
        nr, w = band.shape[:2]
        n = nr * w
        q = self._buf(n * 16)
        if wavelengths is None:
            rc = backend.to_working(band, scale, count=count)
            src = backend.bufs["rgb"]
            self._k_lmsr(q_, (round_up(n, 64),), (64,), src, np.int32(3), np.int32(n),
                         self._buf(0, lmsr.fitted()["H"]), q)
            return q, src, rc
        nc = band.shape[2]
        cube = np.ascontiguousarray(band, np.float32)
        src = backend.buffer("kirk:cube", cube.nbytes)
        cl.enqueue_copy(q_, src, cube)
        counts = backend.buffer("counts", 8 * 4)
        cl.enqueue_fill_buffer(q_, counts, np.int32(0), 0, 8 * 4)
        Wt = np.ascontiguousarray(lmsr.spectrum_weights(wavelengths).T, np.float32)
        self._k_spectrum(q_, (round_up(n, 64),), (64,), src, np.int32(nc), np.int32(n),
                         np.float32(scale), self._buf(0, Wt), q, counts)
        return q, src, (backend.read_repairs(counts) if count else RepairCounts())


class DeviceBaseRange:
    """Durand & Dorsey 2002's base range over base layers on the device, band by band:
    the exact extremes (``DeviceBilateral.z_range``) and, for percentiles, the counts
    in BaseRange's bins (kirk11.cl ``base_histogram``, the host's bins exactly), so the
    base layer no longer comes to the host (it did, for ``BaseRange.add``)."""

    def __init__(self, dev: KirkDevice, percentiles):
        self.dev, self.acc = dev, BaseRange(percentiles)
        self.lo, self.hi, self.n = math.inf, -math.inf, 0
        if not self.acc.exact:
            dev.cl.enqueue_fill_buffer(dev.rt.queue, dev._hist, np.int32(0), 0,
                                       BASE_HIST_BINS * 4)

    def add(self, base, n: int) -> "DeviceBaseRange":
        """Adds the n base values (log10, float32) of the device buffer ``base``."""
        if n <= 0:
            return self
        dev = self.dev
        lo, hi = dev.bil.z_range(base, n, RangeKernel("difference", SIGMA_RANGE_LOG10))
        self.lo, self.hi, self.n = min(self.lo, lo), max(self.hi, hi), self.n + n
        if not self.acc.exact:
            num, off, den = base_hist_edges()
            items = max(1, min(dev.HIST_ITEMS, n // dev.HIST_MIN_RUN))
            dev._k_hist(dev.rt.queue, (round_up(items, 64),), (64,), base, np.int32(n),
                        np.int32(BASE_HIST_BINS), np.float32(BASE_HIST_LO),
                        np.float32(BASE_HIST_BINS / (BASE_HIST_HI - BASE_HIST_LO)),
                        np.int32(num), np.int32(off), np.float32(1.0 / den), dev._hist)
        return self

    def result(self) -> tuple[float, float]:
        hist = None
        if not self.acc.exact and self.n:
            hist = np.empty(BASE_HIST_BINS, np.int32)
            self.dev.cl.enqueue_copy(self.dev.rt.queue, hist, self.dev._hist)
        return self.acc.add_counts(hist, self.lo, self.hi, self.n).result()


class _Banded:
    """The handle of a frame beyond one device band (or a band source reading its
    file): the frame, and the shift pass's findings once made."""

    def __init__(self, frame):
        self.frame = frame
        self.found = None            # ((k1, k2, rod gain), (z_min, z_max))


class KirkSchedule(NoPixelState):
    receptor_gains = False
    streams = True

    def __init__(self, backend, op):
        self.backend, self.op = backend, op
        self.dev = KirkDevice(backend.rt)

    def measure(self, frame, spec=None, want_illuminant: bool = False) -> FrameStats:
        be = self.backend
        h, w = frame.pixels.shape[:2]
        n = h * w
        bands = be.bands(h, w)
        be.last_max_Y = 0.0                 # for flare on auto (Tonemapper.process_stream)
        if len(bands) == 1 and isinstance(frame.pixels, (np.ndarray, DeviceImage)):
            q, src, repairs = self.dev.lmsr_band(be, frame.pixels, frame.scale, frame.wavelengths,
                                                 True)
            self._note_max_Y(frame, n)
            sum_r, sum_lm = self.dev.sums(q, n, self.dev.LOG_LEVELS)     # kirk2011.logmean
            return FrameStats(w, h, math.exp(sum_r / n), math.exp(sum_lm / n),
                              repairs if isinstance(repairs, RepairCounts) else RepairCounts(),
                              handle=(frame.pixels, q, src))
        repairs = RepairCounts()
        sum_lm = sum_r = 0.0
        for y0, nr in bands:                               # the frame's levels, per band
            qb, _, rc = self.dev.lmsr_band(be, frame.pixels[y0:y0 + nr], frame.scale,
                                           frame.wavelengths, True)
            repairs += rc
            self._note_max_Y(frame, nr * w)
            r, lm = self.dev.sums(qb, nr * w, self.dev.LOG_LEVELS)
            sum_r, sum_lm = sum_r + r, sum_lm + lm
        return FrameStats(w, h, float(np.exp(sum_r / n)), float(np.exp(sum_lm / n)), repairs,
                          handle=_Banded(frame))

    def _note_max_Y(self, frame, n: int) -> None:
        """The largest working luminance so far (RGB: the colour stage's Y of the band
        just read), as ``meter_pass`` leaves it in ``backend.last_max_Y``."""
        if frame.wavelengths is None:
            be = self.backend
            top = self.dev.bil.z_range(be.bufs["Y"], n, RangeKernel("difference", 1.0))[1]
            be.last_max_Y = max(be.last_max_Y, top)

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        self.op.integrate(state, stats, dt, fresh)

    def apply(self, frame, state, stats, params=None, gains=None, sink=None):
        """Eqs. 10-16, the base layer and the composition; with ``sink(y0, band)`` the
        display-linear bands go there and None is returned."""
        import pyopencl as cl
        be, dev, op = self.backend, self.dev, self.op
        s, v = op.settings, stats.values
        q_ = be.rt.queue
        h, w = stats.height, stats.width
        n = h * w
        resident = isinstance(stats.handle, tuple) and stats.handle[0] is frame.pixels
        if not resident:
            return self._apply_banded(frame, stats, sink)
        D = frame.display_primaries if frame.display_primaries is not None else np.eye(3)
        M = display_matrix(D)
        area = model_scale()
        _, q, src = stats.handle
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
        _, bmax = brange = dev.base_range(s.base_percentiles).add(base, n).result()
        c = compression(brange, s.target_contrast)
        out = dev._buf(n * 12)
        blend = frame.wavelengths is None
        dev._k_compose(q_, gsz, wg, src if blend else shifted, shifted, wbuf, logY, base,
                       np.int32(n), np.float32(c), np.float32(bmax), np.float32(s.beta),
                       np.float32(s.gamma),
                       np.float32(op.display.white_cd / op.display.unit_cd),
                       np.int32(1 if blend else 0), out, np.int32(0 if s.paper else 1))
        self._finish(out, n, self._gain(out, n, stats))
        nfb = np.empty(1, np.int32)
        cl.enqueue_copy(q_, nfb, fb)
        v.update(model_scale=area, w_mean=dev.sums(wbuf, n, dev.PLANE)[0] / n,
                 fallback_fraction=float(nfb[0]) / n,
                 input="spectral" if frame.wavelengths is not None else "rgb")
        if sink is not None:
            res = np.empty((h, w, 3), np.float32)
            cl.enqueue_copy(q_, res, out)
            sink(0, res)
            return None
        res = be.output_array(h, w)
        be.fetch_output(res, out, n)
        return res

    # -- Kirk11.finish on the device ---------------------------------------------------------
    def _gain(self, out, n: int, stats, log_sum: float | None = None) -> float:
        """``anchor_gain`` of the composed frame (``out``, n pixels; or the whole frame's
        ``log_sum`` of a banded one); 1 in the paper mode."""
        op = self.op
        if op.s.paper:
            return 1.0
        if log_sum is None:
            u = op.display.white_cd / op.display.unit_cd
            log_sum = self.dev.sums(out, n, self.dev.LOG_OUTPUT, 1.0 / u)[0]
        return anchor_gain(np.array([math.exp(log_sum / n)]), stats.G_cone,
                           stats.values["levels"]["A_cone"])

    def _finish(self, out, n: int, gain: float) -> None:
        """``Kirk11.finish`` in place on the device (the shoulder and clamp per pixel;
        the gain is the whole frame's)."""
        op = self.op
        u = op.display.white_cd / op.display.unit_cd
        self.dev.finish(out, n, gain, 1.0 / u, 0.0 if op.s.paper else SHOULDER_KNEE)

    # -- frames beyond one band: passes over row bands, each re-reading its rows --------
    def _shift_rows(self, frame, v, a: int, b: int):
        """Rows [a, b) of the frame read, to LMSR and through Eqs. 10-16 on the device:
        (the composition's source buffer, shifted RGB, w, log10 Y, fallback count)."""
        s = self.op.settings
        D = frame.display_primaries if frame.display_primaries is not None else np.eye(3)
        q, src, _ = self.dev.lmsr_band(self.backend, frame.pixels[a:b], frame.scale,
                                       frame.wavelengths, False)
        out, wb, lb, fb = self.dev.shift(q, (b - a) * frame.pixels.shape[1], model_scale(),
                                         v["k1"], v["k2"], v["rod_gain"], s.shift_xyz,
                                         display_matrix(D), D, s.paper)
        return (src if frame.wavelengths is None else out), out, wb, lb, fb

    def _shift_pass(self, frame, stats) -> tuple[float, float]:
        """Pass 1 of a banded frame: the shift per band, reduced to the summary (w_mean of
        Eq. 16, the share of Eq. 15's fallback) and the range of log10 Y (the grid's z
        axis). Made once per frame and levels (the summary may ask first)."""
        import pyopencl as cl
        v, q_ = stats.values, self.backend.rt.queue
        key = (v["k1"], v["k2"], v["rod_gain"])
        memo = stats.handle if isinstance(stats.handle, _Banded) and \
            stats.handle.frame.pixels is frame.pixels else None
        if memo is not None and memo.found is not None and memo.found[0] == key:
            return memo.found[1]
        h, w = frame.pixels.shape[:2]
        rk = RangeKernel("difference", SIGMA_RANGE_LOG10)
        w_sum, nfb, lo, hi = 0.0, 0, np.inf, -np.inf
        for y0, nr in self.backend.bands(h, w):
            _, _, wb, lb, fb = self._shift_rows(frame, v, y0, y0 + nr)
            c = np.empty(1, np.int32)
            cl.enqueue_copy(q_, c, fb)
            w_sum += self.dev.sums(wb, nr * w, self.dev.PLANE)[0]
            nfb += int(c[0])
            zl, zh = self.dev.bil.z_range(lb, nr * w, rk)
            lo, hi = min(lo, zl), max(hi, zh)
        v.update(model_scale=model_scale(), w_mean=w_sum / (h * w),
                 fallback_fraction=nfb / (h * w),
                 input="spectral" if frame.wavelengths is not None else "rgb")
        if memo is not None:
            memo.found = (key, (lo, hi))
        return lo, hi

    def _apply_banded(self, frame, stats, sink=None):
        """Frames beyond the backend's band size, in passes over row bands that re-read
        their rows (a band source re-decodes them) and keep no whole-frame plane:
        (1) the shift -> summary, z range; (2, grid) the shift, splatted; (3) the base
        layer (grid slice, or the exact filter on rows read with a ceil(3 sigma) halo)
        -> its min and max (Durand & Dorsey 2002's compression); (4, default mode) the
        composition -> the log-average for ``anchor_gain``; (5) the composition and
        ``Kirk11.finish`` on the device (:meth:`_finish`) -> ``sink`` or the output."""
        import pyopencl as cl
        be, dev, op = self.backend, self.dev, self.op
        s, v = op.settings, stats.values
        q_ = be.rt.queue
        h, w = frame.pixels.shape[:2]
        n = h * w
        z_lo, z_hi = self._shift_pass(frame, stats)
        rk = RangeKernel("difference", SIGMA_RANGE_LOG10)
        sig = s.sigma_px(w, h)
        method = dev.bil.choose(op.bilateral, sig, w, h)
        halo = spatial_radius(sig) if method == "exact" else 0
        bands = be.bands(h, w, halo)
        if method != "exact":
            geom = dev.bil.fit_geometry(w, h, z_lo, z_hi, sig, rk, op.bilateral.q_s,
                                        op.bilateral.q_r)
            dev.bil.begin_grid(geom)
            for y0, nr in bands:
                dev.bil.splat(self._shift_rows(frame, v, y0, y0 + nr)[3], w, nr, y0, geom, rk)
            dev.bil.blur(geom, rk)

        def base(y0, nr, rows_too=True):
            """The base layer of rows [y0, y0+nr) and (``rows_too``) those rows shifted,
            read last (a band source keeps the alpha of the rows it read last)."""
            out = dev._buf(nr * w * 4)
            if method == "exact":
                a, b = max(0, y0 - halo), min(h, y0 + nr + halo)
                rows = self._shift_rows(frame, v, a, b)
                dev.bil.exact(rows[3], out, w, b - a, a, y0, nr, sig, rk)
                if rows_too and (a, b) != (y0, y0 + nr):
                    rows = self._shift_rows(frame, v, y0, y0 + nr)
            else:
                rows = self._shift_rows(frame, v, y0, y0 + nr)
                dev.bil.slice(rows[3], out, w, nr, y0, y0, nr, geom, rk)
            return out, rows

        acc = dev.base_range(s.base_percentiles)
        for y0, nr in bands:
            acc.add(base(y0, nr, False)[0], nr * w)
        _, bmax = brange = acc.result()
        c = compression(brange, s.target_contrast)
        u = op.display.white_cd / op.display.unit_cd
        blend = frame.wavelengths is None

        def compose(y0, nr):
            bb, (src, shifted, wb, lb, _) = base(y0, nr)
            m = nr * w
            out = dev._buf(m * 12)
            dev._k_compose(q_, (round_up(m, 64),), (64,), src, shifted, wb, lb, bb,
                           np.int32(m), np.float32(c), np.float32(bmax), np.float32(s.beta),
                           np.float32(s.gamma), np.float32(u), np.int32(1 if blend else 0),
                           out, np.int32(0 if s.paper else 1))
            return out

        gain = 1.0
        if not s.paper:                         # the frame's log-average for the anchor
            log_sum = sum(dev.sums(compose(y0, nr), nr * w, dev.LOG_OUTPUT, 1.0 / u)[0]
                          for y0, nr in bands)
            gain = self._gain(None, n, stats, log_sum)
        res = be.output_array(h, w) if sink is None else None
        for y0, nr in bands:
            out = compose(y0, nr)
            self._finish(out, nr * w, gain)
            if sink is None:
                be.fetch_output(res[y0:y0 + nr], out, nr * w)
            else:
                band = np.empty((nr, w, 3), np.float32)
                cl.enqueue_copy(q_, band, out)
                sink(y0, band)
        return res

    def summary(self, stats) -> dict:
        """The frame's record; a banded frame streamed to a sink is summarised before
        its apply, so the shift pass runs here then."""
        from ..reference import kirk_summary
        if "w_mean" not in stats.values and isinstance(stats.handle, _Banded):
            self._shift_pass(stats.handle.frame, stats)
        return kirk_summary(stats)
