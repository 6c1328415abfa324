"""ledda04 in float64: the exact bilateral filter, the state step and the map of
``models/ledda2004.py``."""

from __future__ import annotations

import numpy as np

from ...models import ledda2004 as L, metering as met
from ...models.bilateral import LEDDA_RANGE, V_FLOOR, bilateral_reference
from ...models.ledda2004 import STATE_CHANNELS
from ...models.photometry import sanitize
from ...operators.base import FrameStats
from ..base import PixelStateMixin


class LeddaSchedule(PixelStateMixin):
    """ledda04 in float64: exact bilateral filter, the state step and map of
    ``models/ledda2004.py``."""

    receptor_gains = False
    streams = False
    encodes_output = False

    def __init__(self, backend, op):
        self.backend, self.op = backend, op
        self.planes = STATE_CHANNELS
        self._host = None

    def measure(self, frame, spec=None, want_illuminant: bool = False) -> FrameStats:
        op, s = self.op, self.op.settings
        h, w = frame.pixels.shape[:2]
        rgb, repairs = sanitize(frame.pixels[..., :3], frame.scale)
        Y, Ys = L.luminances(rgb, op.ward)
        G_rod_g, G_cone_g = met.reference_goal(np.maximum(Y, V_FLOOR), np.maximum(Ys, V_FLOOR),
                                               met.MeteringSpec.parse("logmean"))
        sig = s.sigma_px(w, h)
        local_c = bilateral_reference(Y, sig, LEDDA_RANGE)
        I_c = L.blend_levels(local_c, G_cone_g, s.strength)
        # rods where any pixel's local level is below photopic (before the blend with
        # the global level, as the device decides it; docs/models.md "rods: auto")
        rods = op.rods == "always" or local_c.min() < L.PHOTOPIC_FLOOR
        I_r = L.blend_levels(bilateral_reference(Ys, sig, LEDDA_RANGE), G_rod_g, s.strength) \
            if rods else np.maximum(I_c * op.rod_ratio, V_FLOOR)
        # the log-averages of the levels as the device meters them (the lit rule of
        # models/metering.py; no rods: I_A' from I_A)
        G_rod, G_cone = met.reference_goal(I_c, I_r if rods else I_c,
                                           met.MeteringSpec.parse("logmean"))
        if not rods:
            G_rod = max(G_cone * op.rod_ratio, V_FLOOR)
        return FrameStats(w, h, G_rod, G_cone, repairs,
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
        op = self.op
        shape = (stats.height, stats.width)
        self.check_shape(fresh, shape)
        I_c, I_r = stats.planes["I_c"], stats.planes["I_r"]
        if op.uses_pigment():          # (opencl/ledda04.py: the same)
            gain_c, gain_r = op.pigment_gains(state, stats, dt, fresh)
            st, restarted = L.initial_state(I_c * gain_c, I_r * gain_r, L.E_MAX), 0.0
        elif fresh and op.preadapt is None:
            st, restarted = L.initial_state(I_c, I_r, L.E_MAX), 0.0
        else:
            prev = L.preadapted_state(op.preadapt[0], op.preadapt[1], shape, op.ward) \
                if fresh else self._host
            report = {}
            st = L.step_reference(prev, I_c, I_r, dt, op.settings.change_log10, report=report)
            restarted = report["new_courses"]
        self._host = st
        stats.values["restarted_fraction"] = restarted
        state.values = {"logmean_I_A_cone": float(stats.G_cone),
                        "logmean_I_A_rod": float(stats.G_rod)}

    def apply(self, frame, state, stats, params=None, gains=None, sink=None, encoding=None):
        op = self.op
        px, rgb, Ys = stats.handle
        if px is not frame.pixels:      # a frame the scene effects changed after metering
            rgb, _ = sanitize(frame.pixels[..., :3], frame.scale)
            Ys = L.luminances(rgb, op.ward)[1]
        s_c, s_r = L.current_sigmas(self._host)
        sd, white, knee = op.frame_mapping(stats.values["global_cone"], stats.values["global_rod"])
        stats.values["sigma_disp"] = sd
        mes_level = stats.planes["I_c"] * op.mesopic_gain(state, stats)   # (Eq. 11's level)
        out = L.map_reference(rgb, Ys, mes_level, s_c, s_r, sd, op.display.unit_cd, white, knee)
        return out.astype(np.float32)
