"""kirk11: Kirk & O'Brien 2011, the Purkinje colour shift (rods in the cone pathways),
bilateral range reduction (Durand & Dorsey 2002) and mesopic dimming.

The model is ``models/kirk2011.py``; this module declares the operator and its
time course (the shared receptor levels of ``models/pattanaik2000.py``: the rods'
mixing follows the adapted scotopic level and the rods' dark adaptation, the
display anchor the adapted cone level). Its phases run on
``backends/reference/kirk11.py:KirkSchedule`` and ``backends/opencl/kirk11.py:KirkSchedule``.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..models import lmsr
from ..models.bilateral import BilateralSpec
from ..models.display import DISPLAY_LINEAR_MAX, SHOULDER_KNEE, SIGNAL_CEILING, apply_shoulder
from ..models.kirk2011 import (KAPPA1, KAPPA2, KirkSettings, anchor_gain, display_matrix,
                               kappas)
from ..models.pattanaik2000 import (A_FLOOR, K_CONE, K_ROD, TAU_CONE, TAU_ROD, bleach_static,
                                    flash_threshold, receptor_levels_neural,
                                    receptor_levels_advance, receptor_levels_preadapted,
                                    receptor_levels_steady, response_slope, rod_sensitivity)
from ..models.photometry import Y_WEIGHTS
from ..base.quantities import Numbers, Quantity
from .base import Operator, Option, Stage, StateSpec
from .ledda04 import BILATERAL_OPTIONS
from .pattanaik00 import MODE_OPTION

LEVEL_KEYS = ("A_rod", "A_cone", "B_rod", "B_cone")


def _ordered(lo_hi) -> str:
    return "" if lo_hi[0] < lo_hi[1] else "LO below HI"


@dataclass
class KirkSummary:
    model_scale: float = 0.0
    k1: float = KAPPA1
    k2: float = KAPPA2
    rod_gain: float = 1.0
    w_mean: float = 0.0
    fallback_fraction: float = 0.0
    input: str = "rgb"

    def as_dict(self) -> dict:
        return asdict(self)


class Kirk11(Operator):
    name = "kirk11"
    description = ("Kirk & O'Brien 2011: Purkinje colour shift (rods in the cone pathways), "
                   "bilateral range reduction, mesopic dimming")
    citation = ("Kirk & O'Brien, Perceptually Based Tone Mapping for Low-Light Conditions, "
                "ACM TOG 30(4), SIGGRAPH 2011")
    own_effects = ("purkinje",)
    export_blocker = ("its bilateral base layer (range reduction by each pixel's "
                      "neighbourhood)")
    options = (
        MODE_OPTION, *BILATERAL_OPTIONS,
        Option("kappa", "--kappa", "rod mixing: following the frame's mesopic level (default; "
               "photopic scenes unshifted) or fixed at full scotopic values (the paper's choice)",
               choices=("full", "adaptive")),
        Option("shift_xyz", "--shift-scale", "Purkinje shift scales of Eq. 12 (default 15,15,5)",
               metavar="X,Y,Z",
               decl=Numbers("Purkinje shift scales", "X,Y,Z", parts=tuple(
                   Quantity(f"{c} scale", "", 0.0, 1000.0) for c in "XYZ"))),
        Option("gamma", "--night-dim", "range kept by fully scotopic pixels (default 0.25; 1 = "
               "no dimming)", metavar="GAMMA",
               decl=Quantity("range kept by scotopic pixels", "", 0.0, 1.0)),
        Option("target_contrast", "--target-contrast", "base-layer contrast after Durand & "
               "Dorsey 2002 compression (default 300; the paper's 5 with --mode paper)",
               metavar="C", decl=Quantity("base-layer contrast", "", 1.0, 1e8, above=True)),
        Option("base_percentiles", "--base-percentiles", "percentiles of the base layer "
               "taken as its range and white (default 1,99 as pfstmo_durand02; 0,100 = its "
               "minimum and maximum, the paper's and --mode paper's)", metavar="LO,HI",
               decl=Numbers("base-layer percentiles", "LO,HI", rule=_ordered, parts=(
                   Quantity("low percentile", "%", 0.0, 100.0),
                   Quantity("high percentile", "%", 0.0, 100.0)))),
    )
    state = StateSpec(scalars=("logmean_I_A_cone", "logmean_I_A_rod", *LEVEL_KEYS))
    inputs = ("rgb", "spectral")
    metering = "local"
    schedules = {"reference": ".reference.kirk11:KirkSchedule", "opencl": ".opencl.kirk11:KirkSchedule"}
    stages = (
        Stage("lmsr", "colour", "working RGB (via H) or spectra (Eq. 8) -> LMSR, repaired",
              "models.lmsr.rgb_to_lmsr", "kirk11.cl:to_lmsr"),
        Stage("levels", "reduction", "log-averages of L+M and R", "models.kirk2011.logmean"),
        Stage("adapt", "state", "receptor levels (Pattanaik 2000 Sec. 4.1.2) -> kappa, rod gain",
              "models.pattanaik2000.receptor_levels_advance"),
        Stage("shift", "pointwise", "Eqs. 10-15: opponent shift, display solve, w (Eq. 16)",
              "models.kirk2011.purkinje_shift", "kirk11.cl:kirk11_shift"),
        Stage("base", "neighbourhood", "Durand & Dorsey 2002 base layer of log10 Y",
              "models.bilateral.bilateral_reference", "bilateral.cl:bilateral_exact|grid_*",
              halo="ceil(3 sigma_spatial) rows (exact); none (grid)"),
        Stage("compose", "pointwise", "range reduction, blend, mesopic dimming, anchor",
              "models.kirk2011.compose_reference", "kirk11.cl:kirk11_compose"),
    )

    def __init__(self, options=None, display=None, preadapt=None):
        super().__init__(options, display, preadapt)
        o = dict(self.options)
        self.bilateral = BilateralSpec.parse(o.pop("bilateral", "auto"),
                                             o.pop("bilateral_sampling", None))
        self.settings = KirkSettings(**o)

    @property
    def s(self) -> KirkSettings:
        return self.settings

    @staticmethod
    def M(D) -> np.ndarray:
        """Eq. 14: display RGB -> LMS for display primaries D."""
        return display_matrix(D)

    # -- time course -----------------------------------------------------------------------
    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        """The receptor levels advanced to this frame's goals (default mode), and the
        frame's (k1, k2, rod gain) in ``stats.values``."""
        goals = self.pigment_goals(state, stats, dt, fresh) if self.uses_pigment() else stats
        L_waR, L_wa = goals.G_rod, goals.G_cone
        v = state.values
        levels = {k: float(v[k]) for k in LEVEL_KEYS} \
            if not fresh and all(k in v for k in LEVEL_KEYS) else None
        if self.s.paper:
            levels = None
            k1, k2, gain = kappas(self.s, L_waR)
        else:
            if fresh or levels is None:
                if fresh and self.preadapt is not None:
                    levels = {k: v for k, v in self.observer_preadapted(*self.preadapt).items()
                              if k in LEVEL_KEYS}
                else:
                    levels = receptor_levels_steady(L_waR, L_wa)
            else:                   # the slow course is the shared pigment's: A's goals
                levels = receptor_levels_neural(levels, L_waR, L_wa, dt)
            k1, k2, gain = kappas(self.s, levels["A_rod"])
            sens = rod_sensitivity(levels)
            k1, k2, gain = k1 * sens, k2 * sens, gain * sens
        stats.values.update(k1=k1, k2=k2, rod_gain=gain, levels=levels)
        state.values = {"logmean_I_A_cone": float(L_wa), "logmean_I_A_rod": float(L_waR)}
        if levels is not None:
            state.values.update({k: float(x) for k, x in levels.items()})

    def summary(self, params, stats=None) -> dict:
        """The frame's record (metadata, plots), the same from every schedule."""
        v = stats.values
        return KirkSummary(v["model_scale"], v["k1"], v["k2"], v["rod_gain"], v["w_mean"],
                           v["fallback_fraction"], v["input"]).as_dict()

    def finish(self, out: np.ndarray, stats) -> np.ndarray:
        """The absolute level (``anchor_gain``) and, in the default mode, the highlight
        shoulder; display-linear in, display-linear out."""
        u = self.display.white_cd / self.display.unit_cd
        out = np.asarray(out, np.float64)
        if self.s.paper:
            return np.clip(out, 0.0, DISPLAY_LINEAR_MAX)
        g = anchor_gain(out @ Y_WEIGHTS / u, *self.anchor_levels(stats))
        out = apply_shoulder(np.minimum(out * g, SIGNAL_CEILING), u, SHOULDER_KNEE)
        return np.clip(out, 0.0, DISPLAY_LINEAR_MAX)

    @staticmethod
    def anchor_levels(stats) -> tuple[float, float, float]:
        """(frame level, adapted cone level, share of the peak seen) of ``anchor_gain``."""
        v = stats.values
        return stats.G_cone, v["levels"]["A_cone"], float(v.get("peak_seen", 1.0))

    # -- the observer: the receptor levels of its time course ----------------------------
    @staticmethod
    def _rod_per_cone() -> float:
        w = lmsr.rgb_to_lmsr(np.ones(3))         # a neutral: rod goal per cone goal
        return float(w[3] / (w[0] + w[1]))

    pigment_course = True

    def receptor_threshold(self, receptor, L):
        """Its levels are pattanaik00's receptor signals: their threshold curve."""
        return math.log10(flash_threshold(max(L, A_FLOOR), receptor))

    def rod_per_cone(self) -> float:
        return self._rod_per_cone()

    def observer_preadapted(self, L_cd, seconds):
        if self.uses_pigment():              # (the pigment's own course: ``pigment_goals``)
            return self.pigment_observer(receptor_levels_steady(L_cd * self._rod_per_cone(),
                                                                L_cd), L_cd, seconds)
        return receptor_levels_preadapted(L_cd * self._rod_per_cone(), L_cd, seconds)

    def observer_advance(self, obs, L_cd, dt):
        if self.uses_pigment():
            return self.pigment_observer_advance(obs, L_cd, dt)
        return receptor_levels_advance(obs, L_cd * self._rod_per_cone(), L_cd, dt)

    def advance(self, values, stats, dt):
        """The receptor levels' step of the default mode (:meth:`pigment_observer_advance`)."""
        return receptor_levels_neural(values, stats.G_rod, stats.G_cone, dt)

    def observer_slope(self, obs, L_b):
        return response_slope(L_b, obs)

    def observer_level(self, obs):
        return float(obs["A_cone"])

    def observer_steady_slope(self, L_b):
        L = np.maximum(np.asarray(L_b, np.float64), 0.0)
        Lr = L * self._rod_per_cone()
        return response_slope(L, {"A_rod": Lr, "A_cone": L,
                                  "B_rod": bleach_static(Lr, K_ROD, TAU_ROD),
                                  "B_cone": bleach_static(L, K_CONE, TAU_CONE)})

    def observer_of(self, state, stats=None):
        v = state.values
        if all(k in v for k in LEVEL_KEYS):
            return {k: float(v[k]) for k in LEVEL_KEYS}
        return receptor_levels_steady(v["logmean_I_A_rod"], v["logmean_I_A_cone"])  # paper

    def plot_curves(self, state, Ls):
        return None
