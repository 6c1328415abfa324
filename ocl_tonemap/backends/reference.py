"""The float64 NumPy reference backend: every stage straight from ``models/``."""

from __future__ import annotations

import numpy as np

from ..models import durand2000
from ..models import metering as met
from ..models.photometry import photopic_luminance, sanitize, scotopic_luminance
from ..operators.base import FrameStats
from .planes import band_readable, plane_shape, read_rows


def _mask(spec: met.MeteringSpec, w: int, h: int):
    if spec.mode != "mask":
        return None
    from ..imageio import read_weight_mask
    return read_weight_mask(spec.mask, w, h)


class ReferenceBackend:
    """Float64 NumPy, straight from the equations; the ground truth."""

    name = "reference"

    def describe(self) -> str:
        return "float64 NumPy reference"

    def schedule(self, op):
        spec = op.schedules.get(self.name)
        if spec:
            from . import load_schedule
            return load_schedule(spec)(self, op)
        return PointwiseSchedule(self, op)

    def working(self, pixels: np.ndarray, scale: float, spec: met.MeteringSpec,
                illuminant: bool = True):
        """Colour stage and metering only: (rgb cd/m^2, repairs, (G_rod, G_cone), estimate_fn)
        (the estimate is made when called: ``illuminant`` changes nothing here)."""
        rgb, repairs = sanitize(pixels[..., :3], scale)
        h, w = rgb.shape[:2]
        G = met.reference_goal(photopic_luminance(rgb), scotopic_luminance(rgb), spec,
                               _mask(spec, w, h))
        return rgb, repairs, G, lambda: durand2000.illuminant_estimate_reference(rgb)


class PointwiseSchedule:
    """Colour, metering, the host's state step, one per-pixel map (float64)."""

    #: chromatic adaptation's gains go on the cone signals before the map (Eq. 6).
    receptor_gains = True
    streams = False

    def __init__(self, backend, op):
        self.backend, self.op = backend, op

    def measure(self, frame, spec: met.MeteringSpec, want_illuminant: bool = False) -> FrameStats:
        rgb, repairs = sanitize(frame.pixels[..., :3], frame.scale)
        Y, Ys = photopic_luminance(rgb), scotopic_luminance(rgb)
        h, w = Y.shape
        G_rod, G_cone = met.reference_goal(Y, Ys, spec, _mask(spec, w, h))
        return FrameStats(w, h, G_rod, G_cone, repairs,
                          lambda: durand2000.illuminant_estimate_reference(rgb),
                          handle=(frame.pixels, rgb, Y, Ys))

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        self.op.integrate(state, stats, dt, fresh)

    def apply(self, frame, state, stats, params, gains=None, sink=None):
        px, rgb, Y, Ys = stats.handle if stats.handle is not None and \
            stats.handle[0] is frame.pixels else (None, *self._working(frame))
        if gains is not None:                      # Eq. 6: cone signals only
            rgb = rgb * np.asarray(gains, np.float64)
            Y = photopic_luminance(rgb)
        out = self.op.map_reference(rgb, Y, Ys, params).astype(np.float32)
        if sink is not None:
            sink(0, out)
            return None
        return out

    @staticmethod
    def _working(frame):
        rgb, _ = sanitize(frame.pixels[..., :3], frame.scale)
        return rgb, photopic_luminance(rgb), scotopic_luminance(rgb)


class PixelStateMixin:
    """Per-pixel state kept by a schedule: host planes (float64 in the reference).

    ``band_state``: the schedule reads its state by row bands, so a band-readable
    source (``backends/planes.py``) is kept as it is; else it is read whole."""

    planes: tuple = ()
    band_state = False

    def pixel_state(self) -> dict | None:
        if self._host is None:
            return None
        if band_readable(self._host):
            return self._host if getattr(self._host, "spilled", True) else self._host.as_dict()
        return {k: np.array(v, copy=True) for k, v in self._host.items()}

    def set_pixel_state(self, pixels) -> None:
        if pixels is not None:
            names = pixels.names if band_readable(pixels) else tuple(pixels)
            missing = [k for k in self.planes if k not in names]
            if missing:
                raise ValueError(f"per-pixel state lacks {', '.join(missing)}")
            if band_readable(pixels):
                if not self.band_state:
                    h = plane_shape(pixels)[0]
                    pixels = dict(zip(self.planes, read_rows(pixels, self.planes, 0, h)))
            else:
                shapes = {np.shape(pixels[k]) for k in self.planes}
                if len(shapes) != 1 or len(next(iter(shapes))) != 2:
                    raise ValueError("per-pixel state planes must be 2-D and of one size")
                pixels = {k: np.asarray(pixels[k]) for k in self.planes}
        self._host = pixels

    def state_shape(self):
        return None if self._host is None else plane_shape(self._host)

    def check_shape(self, fresh: bool, shape) -> None:
        if fresh:
            return
        have = self.state_shape()
        if have is None:
            raise ValueError(f"this {self.op.name} state has no per-pixel state (was it saved "
                             "with its .pixels.exr side file?)")
        if tuple(have) != tuple(shape):
            raise ValueError(f"per-pixel adaptation state is {have[1]}x{have[0]} but the frame "
                             f"is {shape[1]}x{shape[0]}; local adaptation needs one image size")


class LeddaSchedule(PixelStateMixin):
    """ledda04 in float64: exact bilateral filter, the state step and map of
    ``models/ledda2004.py``."""

    receptor_gains = False
    streams = False

    def __init__(self, backend, op):
        from ..models.ledda2004 import STATE_CHANNELS
        self.backend, self.op = backend, op
        self.planes = STATE_CHANNELS
        self._host = None

    def measure(self, frame, spec=None, want_illuminant: bool = False) -> FrameStats:
        from ..models import ledda2004 as L
        from ..models.bilateral import LEDDA_RANGE, V_FLOOR, bilateral_reference
        op, s = self.op, self.op.settings
        h, w = frame.pixels.shape[:2]
        rgb, repairs = sanitize(frame.pixels[..., :3], frame.scale)
        Y, Ys = L.luminances(rgb, op.ward)
        G_rod_g, G_cone_g = met.reference_goal(np.maximum(Y, V_FLOOR), np.maximum(Ys, V_FLOOR),
                                               met.MeteringSpec.parse("logmean"))
        sig = s.sigma_px(w, h)
        I_c = L.blend_levels(bilateral_reference(Y, sig, LEDDA_RANGE), G_cone_g, s.strength)
        rods = op.rods == "always" or I_c.min() < L.PHOTOPIC_FLOOR
        I_r = L.blend_levels(bilateral_reference(Ys, sig, LEDDA_RANGE), G_rod_g, s.strength) \
            if rods else np.maximum(I_c * op.rod_ratio, V_FLOOR)
        return FrameStats(w, h, L.logmean(I_r), L.logmean(I_c), repairs,
                          values={"global_cone": G_cone_g, "global_rod": G_rod_g, "sigma_px": sig,
                                  "rods": bool(rods), "bilateral": "exact (float64)"},
                          planes={"I_c": I_c, "I_r": I_r}, handle=(frame.pixels, rgb, Ys))

    def stats_planes(self, stats):
        """The per-pixel adaptation inputs ``integrate`` reads (float64)."""
        return {k: np.asarray(stats.planes[k]) for k in ("I_c", "I_r")}

    def stats_from_planes(self, stats, planes) -> FrameStats:
        stats.planes = {k: np.asarray(planes[k], np.float64) for k in ("I_c", "I_r")}
        return stats

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        from ..models import ledda2004 as L
        op = self.op
        shape = (stats.height, stats.width)
        self.check_shape(fresh, shape)
        I_c, I_r = stats.planes["I_c"], stats.planes["I_r"]
        if fresh and op.preadapt is None:
            st, restarted = L.initial_state(I_c, I_r, L.E_MAX), 0.0
        else:
            prev = L.preadapted_state(op.preadapt[0], op.preadapt[1], shape, op.ward) \
                if fresh else self._host
            st = L.step_reference(prev, I_c, I_r, dt, op.settings.change_log10)
            restarted = float(np.mean(st["t_course"] == 0.0))
        self._host = st
        stats.values["restarted_fraction"] = restarted
        state.values = {"logmean_I_A_cone": float(stats.G_cone),
                        "logmean_I_A_rod": float(stats.G_rod)}

    def apply(self, frame, state, stats, params=None, gains=None, sink=None):
        from ..models import ledda2004 as L
        op = self.op
        _, rgb, Ys = stats.handle
        s_c, s_r = L.current_sigmas(self._host)
        sd, white, knee = op.frame_mapping(stats.values["global_cone"], stats.values["global_rod"])
        stats.values["sigma_disp"] = sd
        out = L.map_reference(rgb, Ys, stats.planes["I_c"], s_c, s_r, sd, op.display.unit_cd,
                              white, knee)
        return out.astype(np.float32)

    def summary(self, stats) -> dict:
        return ledda_summary(self.op, stats)


def ledda_summary(op, stats) -> dict:
    """ledda04's per-frame record (metadata, plots), the same on every backend."""
    from ..operators.ledda04 import FrameSummary
    v = stats.values
    return FrameSummary(v["sigma_px"], v["bilateral"], v["sigma_disp"], v["rods"],
                        op.settings.mode, op.settings.strength, v["global_cone"],
                        v["global_rod"], v.get("restarted_fraction", 0.0), stats.G_cone,
                        stats.G_rod).as_dict()


class NoPixelState:
    """Schedules of operators that keep no per-pixel state."""

    def pixel_state(self):
        return None

    def set_pixel_state(self, pixels) -> None:
        if pixels:
            raise ValueError(f"{self.op.name} keeps no per-pixel state")


class KirkSchedule(NoPixelState):
    """kirk11 in float64: Eqs. 8-16, exact bilateral base, composition."""

    receptor_gains = False
    streams = False

    def __init__(self, backend, op):
        self.backend, self.op = backend, op

    def measure(self, frame, spec=None, want_illuminant: bool = False) -> FrameStats:
        from ..models import kirk2011 as K
        from ..models import lmsr
        if frame.wavelengths is not None:
            sp, repairs = sanitize(frame.pixels, frame.scale)
            src, q = None, lmsr.spectral_to_lmsr(frame.wavelengths, sp)
        else:
            src, repairs = sanitize(frame.pixels[..., :3], frame.scale)
            q = lmsr.rgb_to_lmsr(src)
        h, w = q.shape[:2]
        return FrameStats(w, h, K.logmean(q[..., 3]), K.logmean(q[..., 0] + q[..., 1]), repairs,
                          handle=(frame.pixels, src, q))

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        self.op.integrate(state, stats, dt, fresh)

    def apply(self, frame, state, stats, params=None, gains=None, sink=None):
        from ..models import kirk2011 as K
        from ..models.bilateral import RangeKernel, bilateral_reference
        op, s, v = self.op, self.op.settings, stats.values
        _, src, q = stats.handle
        D = frame.display_primaries if frame.display_primaries is not None else np.eye(3)
        area = K.model_scale()
        q_hat, w = K.purkinje_shift(q, area, v["k1"], v["k2"], s.shift_xyz, v["rod_gain"],
                                    white=not s.paper)
        p, fb = K.solve_display(op.M(D), q_hat, s.paper)
        shift_rgb = p @ np.asarray(D, np.float64).T
        # range reduction of the mesopic image's own luminance (rods add to it)
        logY = np.log10(np.maximum(shift_rgb @ durand2000.Y_WEIGHTS, K.Y_FLOOR))
        h, wd = logY.shape
        base = bilateral_reference(logY, s.sigma_px(wd, h),
                                   RangeKernel("difference", K.SIGMA_RANGE_LOG10))
        out = op.finish(K.compose_reference(src if src is not None else shift_rgb, shift_rgb,
                                            w, logY, base, s, op.display, blend=src is not None),
                        stats)
        v.update(model_scale=area, w_mean=float(w.mean()), fallback_fraction=float(fb.mean()),
                 input="spectral" if frame.wavelengths is not None else "rgb")
        return out.astype(np.float32)

    def summary(self, stats) -> dict:
        return kirk_summary(stats)


def kirk_summary(stats) -> dict:
    from ..operators.kirk11 import KirkSummary
    v = stats.values
    return KirkSummary(v["model_scale"], v["k1"], v["k2"], v["rod_gain"], v["w_mean"],
                       v["fallback_fraction"], v["input"]).as_dict()
