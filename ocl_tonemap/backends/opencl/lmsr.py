"""The LMSR machinery on the device (Kirk & O'Brien 2011), shared by kirk11's
schedule and the Purkinje effect on other operators: RGB or spectra -> LMSR, the
rod shift and the display solve (Eqs. 8-15), the log sums, the base layer's range
from its histogram (Durand & Dorsey 2002), and the last scale-and-shoulder."""

from __future__ import annotations

import math

import numpy as np

from ...models import kirk2011 as K, lmsr
from ...models.bilateral import RangeKernel
from ...models.durand2002 import BASE_HIST_BINS, BASE_HIST_HI, BASE_HIST_LO, BaseRange, base_hist_edges
from ...models.kirk2011 import RHO, SIGMA_RANGE_LOG10, subset_solvers, white_norm
from ...models.photometry import RepairCounts
from .bilateral import DeviceBilateral
from .image import DeviceImage
from .runtime import frame_params, round_up
from .stats import statistics
from .transfers import ConstantBuffers, transfer


#: purkinje_rgb's work-group size.
PURKINJE_WG = 64
#: kirk11_range's work-group (kernels/kirk11.cl: its chunks of the base histogram).
KIRK_RANGE_WG = 256

#: Model constants of kernels/kirk11.cl, given as build options (never retyped);
#: DISPLAY_LINEAR_MAX and the other shared ones come with every program (constants.py).
#: Eq. 11's A^-1 as the kernel's closed form takes it: the four entries of its first two
#: rows that are not 0 (the last row, (0, 1, 1), is written out there); purkinje_rgb's
#: work-group size (:data:`PURKINJE_WG`: its fallbacks are counted per group) and
#: kirk11_range's (:data:`KIRK_RANGE_WG`).
KERNEL_CONSTANTS = (
    ("L_MAX_F", lmsr.L_MAX), ("M_MAX_F", lmsr.M_MAX), ("S_MAX_F", lmsr.S_MAX),
    ("ALPHA_F", K.ALPHA), ("REGULATION_C", K.REGULATION_C),
    *((f"A_INV_{i}{j}", float(K.A_INV[i, j])) for i in (0, 1) for j in (0, 2)),
    ("N_SUPPORTS", len(K.SUBSETS)), ("Y_FLOOR", K.Y_FLOOR), ("LOG_FLOOR", K.LOG_FLOOR),
    ("PURKINJE_WG", PURKINJE_WG), ("KIRK_RANGE_WG", KIRK_RANGE_WG),
)


class KirkDevice:
    def __init__(self, rt):
        import pyopencl as cl
        self.rt = rt
        self.cl = cl
        self._consts = ConstantBuffers(rt.context)
        self.bil = DeviceBilateral(rt)
        c = KERNEL_CONSTANTS
        self._k_lmsr = rt.kernel("kirk11.cl", "to_lmsr", c)
        self._k_shift = rt.kernel("kirk11.cl", "kirk11_shift", c)
        self._k_compose = rt.kernel("kirk11.cl", "kirk11_compose", c)
        self._k_sums = rt.kernel("kirk11.cl", "kirk11_sums", c)
        self._k_finish = rt.kernel("kirk11.cl", "kirk11_finish", c)
        self._k_purkinje = rt.kernel("kirk11.cl", "purkinje_rgb", c)
        self._k_spectrum = rt.kernel("colour.cl", "spectrum_to_lmsr")
        self._k_hist = rt.kernel("kirk11.cl", "base_histogram", c)
        self._k_range = rt.kernel("kirk11.cl", "kirk11_range", c)
        self._k_gain = rt.kernel("kirk11.cl", "kirk11_gain", c)
        self._partial = self._buf(self.SUM_GROUPS * 16)       # kirk11_sums, per group
        self._params_key, self._params = None, ()              # purkinje's constants
        self._fallbacks = None                                 # purkinje's fallback count
        self._band = None                                      # purkinje's host band
        self._hist = self._buf(BASE_HIST_BINS * 4)             # base_histogram's counts

    def _buf(self, nbytes: int, host: np.ndarray | None = None):
        cl = self.cl
        mf = cl.mem_flags
        if host is not None:                   # (a table the device holds: not again)
            return self._consts.get(np.asarray(host, np.float32))
        return cl.Buffer(self.rt.context, mf.READ_WRITE, max(int(nbytes), 4))

    def shift(self, q, n: int, area, k1, k2, gain, xyz, M, D, paper: bool = False):
        """kirk11_shift on n LMSR pixels: (rgb, w, log10 Y, fallback count) buffers.
        ``paper``: the printed opponent space (no white normalisation) and Eq. 15's
        exact NNLS; else D_W and the gamut map."""
        dw = np.ones(3) if paper else white_norm()[:3]
        par = np.array([area, k1, k2, gain, *xyz, *RHO, *dw, 1.0 if paper else 0.0], np.float32)
        out, wbuf, logY = self._buf(n * 12), self._buf(n * 4), self._buf(n * 4)
        fb = self._buf(4)
        self.cl.enqueue_fill_buffer(self.rt.queue, fb, np.int32(0), 0, 4)
        self._k_shift(self.rt.queue, (round_up(n, 64),), (64,), q, np.int32(n),
                      frame_params(par), self._buf(0, np.linalg.inv(M).reshape(-1)),
                      self._buf(0, subset_solvers(M).reshape(-1)),
                      self._buf(0, M), self._buf(0, D), out, wbuf, logY, fb)
        return out, wbuf, logY, fb

    SUM_GROUPS, SUM_WG = 128, 64
    #: kirk11_sums modes
    LOG_LEVELS, PLANE, LOG_OUTPUT = 0, 1, 2

    def sums(self, x, n: int, mode: int, inv_u: float = 1.0) -> tuple[float, float, float]:
        """kirk11_sums over ``n`` pixels of ``x``, added in float64: LOG_LEVELS (LMSR):
        (sum ln R, sum ln (L+M), pixels lit), as ``kirk2011.logmean``; PLANE: (sum x, 0,
        n); LOG_OUTPUT (display-linear RGB): (sum ln (Y inv_u), 0, pixels lit), as
        ``anchor_gain``. Lit: above ``kirk2011.LOG_FLOOR`` (R or L+M; Y inv_u), the
        only pixels summed (the metering rule of ``models/metering.py``). Only the
        groups' records come back."""
        return self.sums_later(x, n, mode, inv_u)()

    def _sums_groups(self, x, n: int, mode: int, inv_u: float) -> int:
        """kirk11_sums into ``self._partial``: the number of groups."""
        cl = self.cl
        wg = self.SUM_WG
        groups = max(1, min(self.SUM_GROUPS, -(-n // (4 * wg))))
        self._k_sums(self.rt.queue, (groups * wg,), (wg,), x, np.int32(n), np.int32(mode),
                     np.float32(inv_u), self._partial, cl.LocalMemory(wg * 16))
        return groups

    def sums_later(self, x, n: int, mode: int, inv_u: float = 1.0):
        """:meth:`sums` enqueued, its groups put in the frame's statistics: a function
        that gives them."""
        if n <= 0:
            return lambda: (0.0, 0.0, 0.0)
        groups = self._sums_groups(x, n, mode, inv_u)
        got = statistics(self.rt).put(self._partial, groups * 16, np.float32, (groups, 4))

        def done():
            t = got.get().astype(np.float64).sum(axis=0)
            return float(t[0]), float(t[1]), float(t[2])
        return done

    def gain(self, out, n: int, inv_u: float, key: float):
        """``anchor_gain`` of ``n`` composed pixels (``out``) on the device
        (kirk11_gain): a one-float buffer, read by :meth:`finish`; nothing comes back."""
        buf = self._buf(4)
        if n <= 0:
            self.cl.enqueue_fill_buffer(self.rt.queue, buf, np.float32(1.0), 0, 4)
            return buf
        groups = self._sums_groups(out, n, self.LOG_OUTPUT, inv_u)
        self._k_gain(self.rt.queue, (1,), None, self._partial, np.int32(groups),
                     np.float32(key), buf)
        return buf

    #: base_histogram: at most this many work-items, each a stretch of >= HIST_MIN_RUN
    HIST_ITEMS, HIST_MIN_RUN = 16384, 64

    def base_range(self, percentiles) -> "DeviceBaseRange":
        """A :class:`~ocl_tonemap.models.durand2002.BaseRange` fed with device buffers."""
        return DeviceBaseRange(self, percentiles)

    def finish(self, rgb, n: int, gain, inv_white: float, knee: float) -> None:
        """``Kirk11.finish`` in place on ``n`` display-linear pixels (kernels/kirk11.cl
        kirk11_finish): the gain (a float, or the device buffer :meth:`gain` made) under
        the signal ceiling, the shoulder (knee 0: none), the clamp."""
        if not isinstance(gain, self.cl.Buffer):
            gain = self._buf(0, np.array([gain], np.float32))
        if n > 0:
            self._k_finish(self.rt.queue, (round_up(self.rt.pixel_items(n, 4), 64),), (64,),
                           rgb, np.int32(n), gain, np.float32(inv_white), np.float32(knee))

    #: purkinje works on host frames in bands of this many pixels (one kept buffer of
    #: 12 bytes a pixel; on a CPU device it is the host's memory).
    SHIFT_BAND = 1 << 18

    def _shift_params(self, area, k1, k2, gain, M, xyz):
        """The shift's arguments: the matrices' constant buffers made again only when ``M``
        changes; the frame's scalars a float16 argument (no upload)."""
        par = np.array([area, k1, k2, gain, *xyz, *RHO, *white_norm()[:3], 0.0], np.float32)
        key = np.asarray(M, np.float64).tobytes()
        if self._params_key != key:
            self._params_key = key
            self._params = (self._buf(0, lmsr.fitted()["H"]),
                            self._buf(0, np.linalg.inv(M).reshape(-1)),
                            self._buf(0, subset_solvers(M).reshape(-1)), self._buf(0, M))
        return (self._params[0], frame_params(par), *self._params[1:])

    def purkinje(self, rgb, area: float, k1: float, k2: float, gain: float, M: np.ndarray,
                 xyz):
        """Eqs. 10-13 and 15 (the gamut map, D = I) on working RGB (cd/m^2), each pixel
        scaled back to its source's photopic Y (kernels/kirk11.cl purkinje_rgb):
        ``(shifted, fallback share)``. ``rgb`` a :class:`~.image.DeviceImage`: shifted in
        place on the device (a new image of the same buffer comes back: another frame
        to the stages' residency checks); a host array: through one
        buffer of :data:`SHIFT_BAND` pixels, kept for the next frame. The fallback share
        is a function: its count comes down with the frame's next statistics (stats.py),
        on a whole frame with its output."""
        q_ = self.rt.queue
        params = self._shift_params(area, k1, k2, gain, M, xyz)
        if self._fallbacks is None:
            self._fallbacks = self._buf(4)
        fb = self._fallbacks                  # the fallback count, zeroed on the device
        self.cl.enqueue_fill_buffer(q_, fb, np.int32(0), 0, 4)

        def run(buf, n):
            items = round_up(self.rt.pixel_items(n, 4), PURKINJE_WG)
            self._k_purkinje(q_, (items,), (PURKINJE_WG,), buf, np.int32(n), *params, fb)

        h, w = rgb.shape[:2]
        n = h * w
        if isinstance(rgb, DeviceImage):
            run(rgb.buffer, n)
            res = DeviceImage(rgb.rt, rgb.buffer, rgb.shape)    # another frame, same buffer
        else:
            res = np.ascontiguousarray(rgb, np.float32).reshape(n, 3).copy()
            nb = 12 * min(self.SHIFT_BAND, max(n, 1))
            band = self._band
            if band is None or band.size < nb:
                band = self._band = self._buf(nb)
            for a in range(0, n, self.SHIFT_BAND):
                m = min(self.SHIFT_BAND, n - a)
                transfer(q_, band, res[a:a + m])
                run(band, m)
                transfer(q_, res[a:a + m], band)
            res = res.reshape(h, w, 3)
        got = statistics(self.rt).put(fb, 4, np.int32)   # comes down with the output
        return res, lambda: float(got.get()[0]) / max(n, 1)

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
        transfer(q_, src, cube)
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
        self._mm = None                        # the last add's (min, max) on the device
        if not self.acc.exact:
            dev.cl.enqueue_fill_buffer(dev.rt.queue, dev._hist, np.int32(0), 0,
                                       BASE_HIST_BINS * 4)

    def add(self, base, n: int, on_device: bool = False) -> "DeviceBaseRange":
        """Adds the n base values (log10, float32) of the device buffer ``base``
        (``on_device``: the one base of a whole frame, for :meth:`compression`: its
        extremes stay on the device)."""
        if n <= 0:
            return self
        dev = self.dev
        got, self._mm = dev.bil.z_range_later(base, n,
                                              RangeKernel("difference", SIGMA_RANGE_LOG10))
        if not on_device:
            lo, hi = got()
            self.lo, self.hi = min(self.lo, lo), max(self.hi, hi)
        self.n += n
        if not self.acc.exact:
            num, off, den = base_hist_edges()
            items = max(1, min(dev.HIST_ITEMS, n // dev.HIST_MIN_RUN))
            dev._k_hist(dev.rt.queue, (round_up(items, 64),), (64,), base, np.int32(n),
                        np.int32(BASE_HIST_BINS), np.float32(BASE_HIST_LO),
                        np.float32(BASE_HIST_BINS / (BASE_HIST_HI - BASE_HIST_LO)),
                        np.int32(num), np.int32(off), np.float32(1.0 / den), dev._hist)
        return self

    def compression(self, target_contrast: float):
        """``compression`` of the range and its top on the device (kirk11_range), for
        a range of one :meth:`add` made with ``on_device``: a buffer (c, base_max) the
        composition reads; nothing comes back."""
        dev, acc = self.dev, self.acc
        ranks = []
        for p in (acc.p_lo, acc.p_hi):
            r = p / 100.0 * (self.n - 1)            # BaseRange._percentile's rank
            ranks += [np.int32(math.floor(r)), np.float32(r - math.floor(r))]
        rp = dev._buf(8)
        dev._k_range(dev.rt.queue, (KIRK_RANGE_WG,), (KIRK_RANGE_WG,), self._mm, dev._hist,
                     np.int32(BASE_HIST_BINS), np.int32(1 if acc.exact else 0),
                     np.int32(self.n), *ranks, np.float32(BASE_HIST_LO),
                     np.float32((BASE_HIST_HI - BASE_HIST_LO) / BASE_HIST_BINS),
                     np.float32(math.log10(target_contrast)), rp)
        return rp

    def result(self) -> tuple[float, float]:
        hist = None
        if not self.acc.exact and self.n:
            hist = np.empty(BASE_HIST_BINS, np.int32)
            transfer(self.dev.rt.queue, hist, self.dev._hist)
        return self.acc.add_counts(hist, self.lo, self.hi, self.n).result()
