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

import numpy as np

from ...models.bilateral import RangeKernel, spatial_radius
from ...models.durand2002 import compression
from ...models.display import SHOULDER_KNEE
from ...models.kirk2011 import (SIGMA_RANGE_LOG10, anchor_gain, anchor_key, display_matrix,
                                mean_exp, model_scale)
from ...models.photometry import RepairCounts
from ...operators.base import FrameStats
from ..base import Later, NoPixelState
from .image import DeviceImage
from .lmsr import KirkDevice
from .metering import repair_counts
from .runtime import round_up
from .stats import TAIL, statistics
from .transfers import transfer

class _Banded:
    """The handle of a frame beyond one device band (or a band source reading its
    file): the frame, and the shift pass's findings once made."""

    def __init__(self, frame):
        self.frame = frame
        self.found = None            # ((k1, k2, rod gain), (z_min, z_max))


class KirkSchedule(NoPixelState):
    receptor_gains = False
    streams = True
    encodes_output = True

    def __init__(self, backend, op):
        self.backend, self.op = backend, op
        self.dev = KirkDevice(backend.rt)

    def measure(self, frame, spec=None, want_illuminant: bool = False) -> FrameStats:
        be = self.backend
        h, w = frame.pixels.shape[:2]
        n = h * w
        bands = be.bands(h, w)
        if len(bands) == 1 and isinstance(frame.pixels, (np.ndarray, DeviceImage)):
            q, src, _ = self.dev.lmsr_band(be, frame.pixels, frame.scale, frame.wavelengths,
                                           False)
            # the colour stage's repair counts come down with the level sums, in one read
            counts = statistics(be.rt).put(be.buffer("counts", 8 * 4), 32, np.int32)
            sum_r, sum_lm, lit = self.dev.sums_later(q, n, self.dev.LOG_LEVELS)()
            return FrameStats(w, h, mean_exp(sum_r, lit), mean_exp(sum_lm, lit),
                              repair_counts(counts.get()), handle=(frame.pixels, q, src))
        repairs = RepairCounts()
        sum_lm = sum_r = lit = 0.0
        for y0, nr in bands:                               # the frame's levels, per band
            qb, _, rc = self.dev.lmsr_band(be, frame.pixels[y0:y0 + nr], frame.scale,
                                           frame.wavelengths, True)
            repairs += rc
            r, lm, k = self.dev.sums(qb, nr * w, self.dev.LOG_LEVELS)
            sum_r, sum_lm, lit = sum_r + r, sum_lm + lm, lit + k
        return FrameStats(w, h, mean_exp(sum_r, lit), mean_exp(sum_lm, lit), repairs,
                          handle=_Banded(frame))

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        self.op.integrate(state, stats, dt, fresh)

    def apply(self, frame, state, stats, params=None, gains=None, sink=None, encoding=None):
        """Eqs. 10-16, the base layer and the composition; with ``sink(y0, band)`` the
        display-linear bands go there and None is returned."""
        be, dev, op = self.backend, self.dev, self.op
        s, v = op.settings, stats.values
        q_ = be.rt.queue
        h, w = stats.height, stats.width
        n = h * w
        if not isinstance(stats.handle, tuple):
            return self._apply_banded(frame, stats, sink, encoding)
        D = frame.display_primaries if frame.display_primaries is not None else np.eye(3)
        M = display_matrix(D)
        area = model_scale()
        px, q, src = stats.handle
        if px is not frame.pixels:      # a frame the scene effects changed after metering
            q, src, _ = dev.lmsr_band(be, frame.pixels, frame.scale, frame.wavelengths, False)
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
        # the compression, the anchor gain: made and used on the device, nothing read
        rp = dev.base_range(s.base_percentiles).add(base, n, True).compression(s.target_contrast)
        out = dev._buf(n * 12 + TAIL)           # (room for the statistics: stats.py)
        u = op.display.white_cd / op.display.unit_cd
        blend = frame.wavelengths is None
        dev._k_compose(q_, gsz, wg, src if blend else shifted, shifted, wbuf, logY, base,
                       np.int32(n), rp, np.float32(s.beta), np.float32(s.gamma),
                       np.float32(u), np.int32(1 if blend else 0), out,
                       np.int32(0 if s.paper else 1))
        self._finish(out, n, 1.0 if op.s.paper else dev.gain(
            out, n, 1.0 / u, anchor_key(*op.anchor_levels(stats))))
        # the record's fallbacks and w mean come down with the output (stats.py)
        nfb = statistics(be.rt).put(fb, 4, np.int32)
        w_sum = dev.sums_later(wbuf, n, dev.PLANE)
        v.update(model_scale=area, w_mean=Later(lambda: w_sum()[0] / n),
                 fallback_fraction=Later(lambda: float(nfb.get()[0]) / n),
                 input="spectral" if frame.wavelengths is not None else "rgb")
        if sink is not None:
            res = np.empty((h, w, 3), np.float32)
            transfer(q_, res, out)
            sink(0, res)
            return None
        res = be.output_array(h, w, encoding)
        be.fetch_output(res, out, n, encoding)
        return res

    # -- Kirk11.finish on the device ---------------------------------------------------------
    def _gain(self, out, n: int, stats, log_sum: tuple | None = None) -> float:
        """``anchor_gain`` of the composed frame (``out``, n pixels; or the whole frame's
        (log sum, lit pixels) of a banded one); 1 in the paper mode."""
        op = self.op
        if op.s.paper:
            return 1.0
        if log_sum is None:
            u = op.display.white_cd / op.display.unit_cd
            log_sum = self.dev.sums(out, n, self.dev.LOG_OUTPUT, 1.0 / u)[::2]
        return anchor_gain(np.array([mean_exp(*log_sum)]), *op.anchor_levels(stats))

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
            transfer(q_, c, fb)
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

    def _apply_banded(self, frame, stats, sink=None, encoding=None):
        """Frames beyond the backend's band size, in passes over row bands that re-read
        their rows (a band source re-decodes them) and keep no whole-frame plane:
        (1) the shift -> summary, z range; (2, grid) the shift, splatted; (3) the base
        layer (grid slice, or the exact filter on rows read with a ceil(3 sigma) halo)
        -> its min and max (Durand & Dorsey 2002's compression); (4, default mode) the
        composition -> the log-average for ``anchor_gain``; (5) the composition and
        ``Kirk11.finish`` on the device (:meth:`_finish`) -> ``sink`` or the output."""
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
        rp = dev._buf(0, np.array([compression(brange, s.target_contrast), bmax], np.float32))
        u = op.display.white_cd / op.display.unit_cd
        blend = frame.wavelengths is None

        def compose(y0, nr):
            bb, (src, shifted, wb, lb, _) = base(y0, nr)
            m = nr * w
            out = dev._buf(m * 12)
            dev._k_compose(q_, (round_up(m, 64),), (64,), src, shifted, wb, lb, bb,
                           np.int32(m), rp, np.float32(s.beta),
                           np.float32(s.gamma), np.float32(u), np.int32(1 if blend else 0),
                           out, np.int32(0 if s.paper else 1))
            return out

        gain = 1.0
        if not s.paper:                         # the frame's log-average for the anchor
            log_sum = np.sum([dev.sums(compose(y0, nr), nr * w, dev.LOG_OUTPUT, 1.0 / u)[::2]
                              for y0, nr in bands], axis=0)
            gain = self._gain(None, n, stats, log_sum)
        res = be.output_array(h, w, encoding) if sink is None else None
        for y0, nr in bands:
            out = compose(y0, nr)
            self._finish(out, nr * w, gain)
            if sink is None:
                be.fetch_output(res[y0:y0 + nr], out, nr * w, encoding)
            else:
                band = np.empty((nr, w, 3), np.float32)
                transfer(q_, band, out)
                sink(y0, band)
        return res

    def summary(self, stats, params, frame=None) -> dict:
        """The frame's record; a banded frame streamed to a sink is summarised before
        its apply, so the shift pass runs here then, on the frame to be mapped
        (``frame``: where scene effects changed it after its metering)."""
        if isinstance(stats.handle, _Banded):
            if frame is not None and frame.pixels is not stats.handle.frame.pixels:
                stats.handle.frame, stats.handle.found = frame, None
            if "w_mean" not in stats.values:
                self._shift_pass(stats.handle.frame, stats)
        return self.op.summary(params, stats)
