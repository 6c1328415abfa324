"""ledda04 on the device: luminances, the bilateral filter (exact or grid), the
per-pixel state step and the mapping (kernels/ledda04.cl, kernels/bilateral.cl).

measure    colour stage and Y, Y' per band; the frame's log-average levels; the
           bilateral filter of Y and Y' (exact: bands with halo rows; grid: the
           frame's z range, splat band by band, blur, slice band by band) into the
           adaptation levels I_A, I_A' (resident for one band, host planes for more);
integrate  ``ledda04_step4`` on the per-pixel state (resident on the device between
           frames when the frame is one band, on the host otherwise);
apply      ``ledda04_map4`` per band (four pixels per work-item).
"""

from __future__ import annotations

import math

import numpy as np

from ...models import ledda2004 as L
from ...models.bilateral import LEDDA_RANGE, V_FLOOR, spatial_radius
from ...models.metering import MeteringSpec
from ...models.photometry import RepairCounts
from ...operators.base import FrameStats
from ..base import Later
from ..planes import PlaneStore, UniformPlanes, read_rows
from .bilateral import Z_IDENTITY, DeviceBilateral
from .ledda04_state import LeddaPixelState
from .metering import repair_counts
from .stats import statistics
from .runtime import round_up
from .transfers import transfer

#: Model constants of kernels/ledda04.cl, given as build options (never retyped);
#: DISPLAY_LINEAR_MAX and the other shared ones come with every program (constants.py).
KERNEL_CONSTANTS = (
    ("V_FLOOR", V_FLOOR), ("ALPHA", L.ALPHA), ("BETA_CONE", L.BETA_CONE),
    ("BETA_ROD", L.BETA_ROD), ("TAU_CONE", L.TAU_CONE), ("TAU_ROD", L.TAU_ROD),
    ("LN_RHO_CONE", math.log(L.RHO_CONE)), ("LN_RHO_ROD", math.log(L.RHO_ROD)),
    ("K_MAX", L.K_MAX), ("K_SLOPE", L.K_SLOPE), ("E_MAX", L.E_MAX),
    ("E_CEILING", L.E_CEILING), ("T_DONE", L.T_DONE), ("T_HOLD", L.T_HOLD),
    ("COURSE_DONE", L.COURSE_DONE), ("COURSE_RUNNING", L.COURSE_RUNNING),
    ("AHEAD_TOL", L.AHEAD_TOL), ("JUMP_LOG2", L.JUMP_LOG10 * math.log2(10.0)),
    ("MES_LOG_OFFSET", L.MES_LOG_OFFSET), ("MES_LOG_SPAN", L.MES_LOG_SPAN), ("N_EXP", L.N),
    *((f"Y_COEFF_{c}", v) for c, v in zip("RGB", L.Y_COEFFS)),
    *((f"YS_COEFF_{c}", v) for c, v in zip("RGB", L.YS_COEFFS)),
)
LOGMEAN = MeteringSpec.parse("logmean")


class LeddaSchedule(LeddaPixelState):
    receptor_gains = False
    streams = True
    encodes_output = True
    band_state = True
    applies_stored = True

    def __init__(self, backend, op):
        self.backend, self.op = backend, op
        self.planes = L.STATE_CHANNELS
        self._host = None        # authoritative when _dev is None: dict or PlaneStore
        self._dev = None         # (cl.Buffer, (h, w)) authoritative on the device
        self._filters = None
        rt = backend.rt
        self._k_lum = rt.kernel("ledda04.cl", "ledda04_luminance", KERNEL_CONSTANTS)
        self.set_map_kernel(vector=True)
        self.set_step_kernel(vector=True)

    def set_map_kernel(self, vector: bool = True) -> None:
        """``ledda04_map4`` (four pixels per work-item, the default) or the scalar
        ``ledda04_map`` (kept to test the one against the other)."""
        self._map_vector = vector
        self._k_map = self.backend.rt.kernel("ledda04.cl", "ledda04_map4" if vector
                                             else "ledda04_map", KERNEL_CONSTANTS)

    def set_step_kernel(self, vector: bool = True) -> None:
        """``ledda04_step4`` (four pixels per work-item, the default) or the scalar
        ``ledda04_step`` (kept to test the one against the other)."""
        self._step_vector = vector
        self._k_step = self.backend.rt.kernel("ledda04.cl", "ledda04_step4" if vector
                                              else "ledda04_step", KERNEL_CONSTANTS)

    def visibility_observer(self):
        """(kernel file, its constants, state buffer, plane stride, rod ratio) of the
        per-pixel observer where the state is resident on the device
        (``backends/opencl/visibility.py``: ledda04.cl's ``ledda04_observer``), else None."""
        if self._dev is None:
            return None
        buf, (h, w) = self._dev
        return "ledda04.cl", KERNEL_CONSTANTS, buf, h * w, float(self.op.rod_ratio)

    # -- measure -----------------------------------------------------------------------
    def _colour_and_lum(self, frame, a: int, b: int, own):
        """Rows [a, b) to working space and Y, Y'; returns (repairs, n, Yl, Ysl)."""
        be = self.backend
        w = frame.pixels.shape[1]
        rc = be.to_working(frame.pixels[a:b], frame.scale, count=own is not None, count_rows=own)
        n = (b - a) * w
        yl, ysl = be.buffer("ledda_Y", n * 4), be.buffer("ledda_Ys", n * 4)
        self._k_lum(be.rt.queue, (round_up(n, 64),), (64,), be.bufs["rgb"], np.int32(n), yl, ysl,
                    np.int32(self.op.ward))
        return rc, n, yl, ysl

    def measure(self, frame, spec=None, want_illuminant: bool = False) -> FrameStats:
        """Banded frames (and streamed ones, whose rows are read again for each pass)
        take three passes before the state step: the global log-averages with the
        z ranges, the grid splat (grid filter only), the local levels."""
        be, op, s = self.backend, self.op, self.op.settings
        q = be.rt.queue
        h, w = frame.pixels.shape[:2]
        sig = s.sigma_px(w, h)
        if self._filters is None:
            self._filters = (DeviceBilateral(be.rt), DeviceBilateral(be.rt))
        fc, fr = self._filters
        method = fc.choose(s.bilateral, sig, w, h)
        halo = spatial_radius(sig) if method == "exact" else 0
        bands = be.bands(h, w, halo)
        banded = len(bands) > 1
        # the frame's global log-averages (and the z ranges of Y and Y' for the
        # grid): one band is coloured once and stays resident
        # (a resident frame's repair counts, sums and z ranges come down in one read)
        resident = self._colour_and_lum(frame, 0, h, None) if not banded else None
        gsums = None
        zr = [[np.inf, -np.inf], [np.inf, -np.inf]]
        for y0, nr in ([(0, h)] if not banded else bands):
            _, n, yl, ysl = resident if resident is not None else \
                self._colour_and_lum(frame, y0, y0 + nr, None)
            gs = be.meter.band_sums_later(yl, ysl, n, w, h, y0, LOGMEAN,
                                          be.bufs["counts"] if resident is not None else None)
            ranges = []
            if method == "fast":
                for flt, buf in ((fc, yl), (fr, ysl)):
                    # z once per pixel: the resident band's stays in the filter's z
                    # buffer for its splat and slice
                    ranges.append(flt.z_range_later(flt.z_map(buf, n, LEDDA_RANGE), n,
                                                    Z_IDENTITY)[0])
            gs = gs()
            if resident is not None:
                resident = (repair_counts(be.meter.counts), *resident[1:])
            if gsums is None:
                gsums = gs
            else:
                gsums.add(gs)
            for k, got in enumerate(ranges):
                lo, hi = got()
                zr[k] = [min(zr[k][0], lo), max(zr[k][1], hi)]
        G_rod_g, G_cone_g = gsums.goal(LOGMEAN)
        geoms = None
        if method == "fast":
            geoms = [flt.fit_geometry(w, h, zr[k][0], zr[k][1], sig, LEDDA_RANGE, s.bilateral.q_s,
                                      s.bilateral.q_r) for k, flt in enumerate((fc, fr))]
            for flt, g in zip((fc, fr), geoms):
                flt.begin_grid(g)
            for y0, nr in bands:                    # splat
                if banded:
                    _, n, yl, ysl = self._colour_and_lum(frame, y0, y0 + nr, None)
                else:
                    _, n, yl, ysl = resident
                fc.splat(yl, w, nr, y0, geoms[0], LEDDA_RANGE, z_ready=not banded)
                fr.splat(ysl, w, nr, y0, geoms[1], LEDDA_RANGE, z_ready=not banded)
            fc.blur(geoms[0], LEDDA_RANGE)
            fr.blur(geoms[1], LEDDA_RANGE)
        repairs = RepairCounts()
        sums = None
        rods_used = True
        planes = self._store(("I_c", "I_r"), (h, w)) if banded else {}
        for y0, nr in bands:                        # filter / slice: the adaptation levels
            a, b = max(0, y0 - halo), min(h, y0 + nr + halo)
            if resident is not None:
                rc, _, yl, ysl = resident
                resident = (RepairCounts(), *resident[1:])     # count the repairs once
            else:
                rc, _, yl, ysl = self._colour_and_lum(frame, a, b, (y0 - a, y0 - a + nr))
            repairs += rc
            n = nr * w
            ic, ir = be.buffer("ledda_Ic", n * 4), be.buffer("ledda_Ir", n * 4)
            if method == "exact":
                fc.exact(yl, ic, w, b - a, a, y0, nr, sig, LEDDA_RANGE)
            else:
                fc.slice(yl, ic, w, nr, y0, y0, nr, geoms[0], LEDDA_RANGE, z_ready=not banded)
            # the rods where the darkest cone level is below photopic: on a resident
            # frame decided on the device (the rod filter gated, else I_r = I_c) and
            # read with the sums, no read between the two filters
            darkest, gate = None, None
            if not (banded or op.rods == "always"):
                darkest, zbuf = fc.z_range_later(ic, n, Z_IDENTITY)
                gate = (zbuf, L.PHOTOPIC_FLOOR, ic)
            if method == "exact":
                fr.exact(ysl, ir, w, b - a, a, y0, nr, sig, LEDDA_RANGE, gate=gate)
            else:
                fr.slice(ysl, ir, w, nr, y0, y0, nr, geoms[1], LEDDA_RANGE,
                         z_ready=not banded, gate=gate)
            sb = be.meter.band_sums(ic, ir, n, w, h, y0, LOGMEAN)
            rods_needed = darkest is None or darkest()[0] < L.PHOTOPIC_FLOOR
            rods_used = rods_used and rods_needed
            if sums is None:
                sums = sb
            else:
                sums.add(sb)
            if banded:
                lv = np.empty((2, nr, w), np.float32)
                transfer(q, lv[0], ic)
                transfer(q, lv[1], ir)
                planes.write(y0, lv)
            else:
                planes = {"I_c": ic, "I_r": ir}
        G_rod, G_cone = sums.goal(LOGMEAN)
        if not rods_used:
            G_rod = max(G_cone * op.rod_ratio, V_FLOOR)
        grid = ""
        if method == "fast":
            g = geoms[0]
            grid = f" (q_s={sig / g.s_s:.3g}, q_r={LEDDA_RANGE.z_width() / g.s_r:.3g})"
        return FrameStats(w, h, G_rod, G_cone, repairs,
                          values={"global_cone": G_cone_g, "global_rod": G_rod_g,
                                  "sigma_px": sig, "rods": bool(rods_used),
                                  "bilateral": method + grid},
                          planes=planes, handle=(frame.pixels, bands, banded, halo))

    # -- integrate ---------------------------------------------------------------------
    def _frame_scalars(self, stats):
        s = self.op.settings
        return (np.float32(s.strength),
                np.float32(math.log(max(stats.values["global_cone"], V_FLOOR))),
                np.float32(math.log(max(stats.values["global_rod"], V_FLOOR))))

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        """``ledda04_step`` per band. One-band frames keep the state resident on the
        device; banded ones read and write it by bands in a :class:`PlaneStore`."""
        import pyopencl as cl
        be, op = self.backend, self.op
        q = be.rt.queue
        h, w = stats.height, stats.width
        self.check_shape(fresh, (h, w))
        _, bands, banded, _ = stats.handle
        gain_c, gain_r = op.pigment_gains(state, stats, dt, fresh)
        # default mode: each pixel adapts at once to its level raised by the pigment's
        # equivalent background (the slow course is the shared pigment's)
        init = (fresh and op.preadapt is None) or op.uses_pigment()
        if fresh and op.preadapt is not None and not init:
            one = L.preadapted_state(op.preadapt[0], op.preadapt[1], (1, 1), op.ward)
            self.set_pixel_state(UniformPlanes(one, (h, w)) if banded else
                                 {k: np.broadcast_to(v, (h, w)) for k, v in one.items()})
        counts = be.buffer("ledda_counts", 4)
        cl.enqueue_fill_buffer(q, counts, np.int32(0), 0, 4)
        nstate = len(self.planes)
        src = None
        if banded:
            if self._dev is not None:
                self._host = self.pixel_state()     # banded frames keep state on the host
                self._dev = None
            src = None if init else self._host
            own = isinstance(src, PlaneStore) and src.shape == (h, w) and \
                src.spilled == (be.spill_dir is not None)
            dst = src if own else self._store(self.planes, (h, w))
        strength, lgc, lgr = self._frame_scalars(stats)
        f32, i32 = np.float32, np.int32
        for y0, nr in bands:
            n = nr * w
            ic, ir = self._band_levels(stats, y0, nr)
            if banded:
                st = be.buffer("ledda_state_band", nstate * n * 4)
                if not init:
                    transfer(q, st, read_rows(src, self.planes, y0, y0 + nr))
            elif self._dev is not None:
                st = self._dev[0]                   # resident from the last frame
            else:
                st = cl.Buffer(be.rt.context, cl.mem_flags.READ_WRITE, nstate * n * 4)
                if not init:
                    transfer(q, st, read_rows(self._host, self.planes, 0, h))
            rods = stats.values["rods"]
            items = be.rt.pixel_items(n, 4) if self._step_vector else n
            self._k_step(q, (round_up(items, 64),), (64,), ic, ir, i32(0 if rods else 1),
                         f32(op.rod_ratio), st, i32(n), i32(n), f32(dt), i32(1 if init else 0),
                         f32(L.E_MAX), f32(op.settings.change_log10 * math.log2(10.0)), counts,
                         strength, lgc, lgr, f32(gain_c), f32(gain_r))
            if banded:
                planes = np.empty((nstate, nr, w), np.float32)
                transfer(q, planes, st)
                dst.write(y0, planes)
            else:
                self._dev, self._host = (st, (h, w)), None
        if banded:
            if src is not dst and isinstance(src, PlaneStore):
                src.close()
            self._host = dst
        # the restarts' count comes down with the frame's output (stats.py)
        got = statistics(be.rt).put(counts, 4, np.int32)
        stats.values["restarted_fraction"] = \
            Later(lambda: float(got.get()[0]) / (h * w)) if not init else 0.0
        stats.values["sigma_disp"] = op.frame_mapping(stats.values["global_cone"],
                                                      stats.values["global_rod"])[0]
        state.values = {"logmean_I_A_cone": float(stats.G_cone),
                        "logmean_I_A_rod": float(stats.G_rod)}

    # -- apply -------------------------------------------------------------------------
    def apply(self, frame, state, stats, params=None, gains=None, sink=None, encoding=None):
        """``ledda04_map4`` per band (rows re-read for banded frames); with
        ``sink(y0, band)`` the bands go there and None is returned."""
        be, op = self.backend, self.op
        q = be.rt.queue
        h, w = stats.height, stats.width
        px, bands, banded, halo = stats.handle
        if not banded and px is not frame.pixels:   # changed by scene effects after metering
            be.to_working(frame.pixels, frame.scale, count=False)
        sd, white, knee = op.frame_mapping(stats.values["global_cone"], stats.values["global_rod"])
        stats.values["sigma_disp"] = sd
        strength, lgc, _ = self._frame_scalars(stats)
        f32, i32 = np.float32, np.int32
        mes_gain = f32(op.mesopic_gain(state, stats))
        out = be.output_array(h, w, encoding) if sink is None else None
        nstate = len(self.planes)
        for y0, nr in bands:
            n = nr * w
            if banded:
                be.to_working(frame.pixels[y0:y0 + nr], frame.scale, count=False)
                ic, _ = self._band_levels(stats, y0, nr, rods=False)
                st = be.buffer("ledda_state_band", nstate * n * 4)
                transfer(q, st, read_rows(self._host, self.planes, y0, y0 + nr))
            else:                                   # (stored levels: uploaded)
                ic, st = self._band_levels(stats, y0, nr, rods=False)[0], self._dev[0]
            items = be.rt.pixel_items(n, 4) if self._map_vector else n
            dst = be.output_buffer(n, len(bands) == 1)
            self._k_map(q, (round_up(items, 64),), (64,), be.bufs["rgb"], i32(0), ic, st, i32(n),
                        i32(n), f32(sd), f32(1.0 / op.display.unit_cd), dst, strength,
                        lgc, f32(1.0 / white), f32(knee), i32(op.ward), mes_gain)
            if sink is None:
                be.fetch_output(out[y0:y0 + nr], dst, n, encoding)
            else:
                band = np.empty((nr, w, 3), np.float32)
                transfer(q, band, dst)
                sink(y0, band)
        return out

