"""ledda04: Ledda, Santos & Chalmers 2004, local adaptation with a dark/light time course.

The model is ``models/ledda2004.py``; this module declares the operator: options,
per-pixel state, stages, and the per-frame mapping scalars. Its phases run on the
schedules ``backends/reference/ledda04.py:LeddaSchedule`` (float64) and
``backends/opencl/ledda04.py:LeddaSchedule`` (bilateral filter, state step and
mapping on the device, in row bands with halos when a frame does not fit).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from ..models import bleaching
from ..models import ledda2004 as L
from ..models.bilateral import V_FLOOR, BilateralSpec
from ..models.display import SHOULDER_KNEE
from ..models.metering import LOG_FLOOR
from ..models.ledda2004 import (CHANGE_LOG10, LOCAL_STRENGTH, MODES, STATE_CHANNELS,
                                anchored_sigma, display_sigma, neutral_rod_ratio)
from ..base.quantities import Numbers, Quantity
from .base import Operator, Option, Stage, StateSpec, white_luminance
from .pigment import PIGMENT_KEY
from .pattanaik00 import MODE_OPTION


#: Options of the bilateral filter, shared with kirk11.
BILATERAL_OPTIONS = (
    Option("sigma_spatial", "--sigma-spatial", "bilateral spatial sigma (default: 2%% of the "
           "larger side)", metavar="PX",
           decl=Quantity("bilateral spatial sigma", "px", 0.0, 1e5, above=True)),
    Option("bilateral", "--bilateral", "exact brute force, fast bilateral grid, or auto (exact "
           "when cheap)", choices=("auto", "exact", "fast"), default="auto"),
    Option("bilateral_sampling", "--bilateral-sampling", "grid sampling rate per sigma in "
           "space[,range] (default 2,2; higher is slower and closer to exact)", metavar="Q[,QR]",
           decl=Numbers("bilateral grid sampling", "Q[,QR]", count=(1, 2),
                        each=Quantity("samples per sigma", "", 0.5, 16.0))),
)


@dataclass(frozen=True)
class LeddaSettings:
    """User-facing settings of the local operator.

    sigma_spatial : bilateral spatial sigma, pixels; None = 2% of the larger image
        side (Durand & Dorsey 2002's choice, the filter Ledda cites as [9]).
    bilateral : exact | fast | auto, and the grid sampling (see bilateral.py).
    display_adapt_cd : display adaptation level for sigma_disp (default 0.4 x white).
    change_log10 : restart threshold of the time course (log10 of sigma).
    mode : "default" or "paper" (:data:`MODES`).
    local_strength : share of the local level in each pixel's adaptation level,
        0 (global) .. 1 (the paper's fully local); None: 0.5, or 1 in paper mode.
    """

    sigma_spatial: float | None = None
    bilateral: BilateralSpec = field(default_factory=BilateralSpec)
    display_adapt_cd: float | None = None
    change_log10: float = CHANGE_LOG10
    mode: str = "default"
    local_strength: float | None = None

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"ledda04 mode must be one of {', '.join(MODES)} (got {self.mode!r})")
        ls = self.local_strength
        if ls is not None and not (0.0 <= ls <= 1.0):
            raise ValueError(f"--local-strength must be between 0 and 1 (got {ls})")

    @property
    def strength(self) -> float:
        if self.local_strength is not None:
            return float(self.local_strength)
        return 1.0 if self.mode == "paper" else LOCAL_STRENGTH

    def sigma_px(self, width: int, height: int) -> float:
        if self.sigma_spatial is not None:
            if not (self.sigma_spatial > 0 and math.isfinite(self.sigma_spatial)):
                raise ValueError(f"sigma_spatial must be > 0 px (got {self.sigma_spatial})")
            return float(self.sigma_spatial)
        return max(0.02 * max(width, height), 0.5)




@dataclass(frozen=True)
class FrameSummary:
    """Scalars recorded per frame (metadata, plots)."""

    sigma_spatial_px: float
    bilateral: str
    sigma_disp: float
    rods_modelled: bool
    mode: str
    local_strength: float
    global_cone: float          # the frame's log-average (Eq. 6 Y), cd/m^2
    global_rod: float
    restarted_fraction: float
    logmean_I_A_cone: float
    logmean_I_A_rod: float

    def as_dict(self) -> dict:
        return asdict(self)


class Ledda04(Operator):
    name = "ledda04"
    description = "Ledda, Santos & Chalmers 2004: local (bilateral) adaptation, dark/light time course"
    citation = ("Ledda, Santos & Chalmers, A Local Model of Eye Adaptation for High Dynamic "
                "Range Images, Afrigraph 2004")
    export_blocker = "local adaptation (each pixel adapts to its bilateral neighbourhood)"
    options = (
        MODE_OPTION, *BILATERAL_OPTIONS,
        Option("rods", "--rods", "auto: skip the rod filter on all-photopic frames",
               choices=("auto", "always"), default="auto"),
        Option("local_strength", "--local-strength", "ledda04: share of the local (bilateral) "
               "level in each pixel's adaptation, 0 (global) .. 1 (the paper's fully local); "
               "default 0.5", metavar="S",
               decl=Quantity("share of the local level", "", 0.0, 1.0)),
        Option("mode", "--ledda-mode", "ledda04: the same as --mode", choices=MODES),
        Option("display_adapt_cd", None, "display adaptation level for sigma_disp, cd/m^2 "
               "(default 0.4 x white)",
               decl=Quantity("display adaptation level", "cd/m^2", 0.0, 1e4, above=True)),
        Option("change_log10", None, "restart threshold of the time course, log10 of sigma",
               decl=Quantity("restart threshold", "log10", 0.0, 10.0, above=True)),
    )
    state = StateSpec(scalars=("logmean_I_A_cone", "logmean_I_A_rod"), planes=STATE_CHANNELS)
    metering = "local"
    schedules = {"reference": ".reference.ledda04:LeddaSchedule",
                 "opencl": ".opencl.ledda04:LeddaSchedule"}
    stages = (
        Stage("colour", "colour", "working RGB x scale -> cd/m^2; Y, Y' (Eqs. 6-7)",
              "models.ledda2004.luminances", "ledda04.cl:ledda04_luminance"),
        Stage("global", "reduction", "the frame's log-average levels (default mode's blend)",
              "models.metering.reference_goal", "metering.cl:meter_partial"),
        Stage("local_levels", "neighbourhood", "I_A, I_A': bilateral filter of Y, Y' (Eqs. 8-10)",
              "models.bilateral.bilateral_reference", "bilateral.cl:bilateral_exact|grid_*",
              halo="ceil(3 sigma_spatial) rows (exact); none (grid)"),
        Stage("adapt", "state", "per-pixel time course, Eqs. 14-17 (dark/light, restarts)",
              "models.ledda2004.step_reference", "ledda04.cl:ledda04_step"),
        Stage("map", "pointwise", "Eqs. 11-13 with the current sigmas, shoulder",
              "models.ledda2004.map_reference", "ledda04.cl:ledda04_map4"),
    )

    def __init__(self, options=None, display=None, preadapt=None):
        super().__init__(options, display, preadapt)
        o = dict(self.options)
        spec = BilateralSpec.parse(o.pop("bilateral", "auto") or "auto",
                                   o.pop("bilateral_sampling", None))
        self.settings = LeddaSettings(o.pop("sigma_spatial", None), spec,
                                      o.pop("display_adapt_cd", None),
                                      o.pop("change_log10", CHANGE_LOG10),
                                      o.pop("mode", "default"), o.pop("local_strength", None))
        self.rods = o.pop("rods", "auto")
        if self.rods not in ("auto", "always"):
            raise ValueError(f"rods must be auto or always (got {self.rods!r})")
        self.sigma_disp = display_sigma(display, self.settings.display_adapt_cd) \
            if display is not None else None
        self.ward = self.settings.mode != "paper"
        self.rod_ratio = neutral_rod_ratio(self.ward)

    #: The default mode's slow course is the shared pigment model's (issue 66): each
    #: pixel adapts at once to its level times the frame's factor (goal + equivalent
    #: background) / goal; ``--mode paper`` keeps Eqs. 14-17's per-pixel courses.
    pigment_course = True
    pigment_matching = "local"

    def uses_pigment(self) -> bool:
        return self.settings.mode != "paper"

    def rod_per_cone(self) -> float:
        return self.rod_ratio

    def receptor_threshold(self, receptor: str, L_cd: float) -> float:
        """The threshold curve the frame factor moves every pixel along: a flash on a
        dark field is seen at sigma times a constant (Eqs. 2-3), sigma = beta I^alpha
        (Eq. 5) of the frame's log-average, which a black frame meters at LOG_FLOOR
        (the dark-adapted observer's own level: no dark light below it)."""
        beta = L.BETA_ROD if receptor == "rod" else L.BETA_CONE
        return math.log10(float(L.sigma_of(max(L_cd, LOG_FLOOR), beta)))

    def pigment_gains(self, state, stats, dt: float, fresh: bool) -> tuple[float, float]:
        """The frame's factors on every pixel's cone and rod level (1, 1 in paper mode):
        the shared pigment course's raised goals over the frame's own."""
        if not self.uses_pigment():
            return 1.0, 1.0
        g = self._global_goals(stats)
        return _factors(self.pigment_goals(state, g, dt, fresh), g)

    def mesopic_gain(self, state, stats) -> float:
        """The factor on every pixel's cone level where Eq. 11's mes is read: the
        larger of the frame's two pigment factors (1 in paper mode, and near 1 on a
        steady field). The eye's state is as light adapted as its most bleached
        receptor says: with the rods bleached, the cones carry what is seen (read at
        the pixel's own level alone, a dark frame after daylight weighted the blinded
        rods, and even a 1 cd/m^2 target showed only after 5 minutes)."""
        pig = state.extra.get(PIGMENT_KEY)
        if not self.uses_pigment() or not bleaching.check(pig):
            return 1.0
        g = self._global_goals(stats)
        return max(*_factors(self.raised_goals(pig, g), g), 1.0)

    @staticmethod
    def _global_goals(stats):
        """The frame's statistics with the scene's own log-averages as its goals (the
        same on every backend: the local levels' log-averages differ by where each
        blends them with the global one)."""
        return replace(stats, G_cone=float(stats.values["global_cone"]),
                       G_rod=float(stats.values["global_rod"]))

    def summary(self, params, stats=None) -> dict:
        """The frame's record (metadata, plots), the same from every schedule."""
        v = stats.values
        return FrameSummary(v["sigma_px"], v["bilateral"], v["sigma_disp"], v["rods"],
                            self.settings.mode, self.settings.strength, v["global_cone"],
                            v["global_rod"], v.get("restarted_fraction", 0.0), stats.G_cone,
                            stats.G_rod).as_dict()

    def frame_mapping(self, G_cone: float, G_rod: float) -> tuple[float, float, float]:
        """(display sigma, white signal, shoulder knee) of one frame."""
        white = self.display.white_cd / self.display.unit_cd
        if self.settings.mode == "paper":
            return self.sigma_disp, white, 0.0
        return anchored_sigma(self.display, G_cone, G_rod), white, SHOULDER_KNEE

    # -- the observer (a uniform field: every pixel's course alike) ------------------------
    def observer_preadapted(self, L_cd, seconds):
        if self.uses_pigment():              # the run's own: adapted at once, the pigment
            return self.pigment_observer(L.initial_state(L_cd, L_cd * self.rod_ratio, L.E_MAX),
                                         L_cd, seconds)
        return L.preadapted_state(L_cd, seconds, (), self.ward)

    def advance(self, values, stats, dt):
        """The default mode's step of one observer (``pigment_observer_advance``): each
        pixel at once at its raised level, as the schedules do."""
        return L.initial_state(stats.G_cone, stats.G_rod, L.E_MAX)

    def observer_advance(self, obs, L_cd, dt):
        if self.uses_pigment():
            return self.pigment_observer_advance(obs, L_cd, dt)
        Lr = L_cd * self.rod_ratio
        now = L.step_reference(obs, L_cd, Lr, 0.0)      # the field changes now ...
        return L.step_reference(now, L_cd, Lr, dt)      # ... and is seen for dt

    def observer_slope(self, obs, L_b):
        sc, sr = _sigmas_now(obs)
        return L.response_slope(L_b, sc, sr, self.ward)

    def observer_level(self, obs):
        return L.adaptation_luminance(_sigmas_now(obs)[0])

    def observer_steady_slope(self, L_b):
        Lb = np.asarray(L_b, np.float64)
        return L.response_slope(Lb, L.sigma_of(Lb, L.BETA_CONE),
                                L.sigma_of(Lb * self.rod_ratio, L.BETA_ROD), self.ward)

    #: Each pixel has its own course: the run's observer is its per-pixel state.
    observer_per_pixel = True

    def observer_of(self, state, stats=None):
        """The per-pixel state (float64), with its current sigmas (Eqs. 14-15) made
        once: the planes and the target read them more than once a frame."""
        obs = {k: np.asarray(v, np.float64) for k, v in (state.pixels or {}).items()}
        if obs:
            obs[SIGMAS_NOW[0]], obs[SIGMAS_NOW[1]] = L.current_sigmas(obs)
        return obs

    def plot_curves(self, state, Ls):
        return None                       # no single curve: each pixel has its own

    def white_luminance_at(self, G_rod: float, G_cone: float, lo: float = 0.0) -> float:
        """A uniform region of L cd/m^2 in a frame of log-averages (G_cone, G_rod),
        steady: each of its pixels adapted to its blended level (``blend_levels``:
        the bilateral level of a uniform region is L), Eqs. 11-13 before the
        shoulder. Local adaptation shows far more than a global map: with the
        default strength 0.5, a region needs about the square of the global ratio."""
        import numpy as np
        s = self.settings.strength
        sd, white, _ = self.frame_mapping(G_cone, G_rod)

        def shown(Lc):
            Ic = L.blend_levels(Lc, G_cone, s)
            Ir = L.blend_levels(Lc * self.rod_ratio, G_rod, s)
            rgb = np.repeat(Lc[:, None], 3, axis=1)
            return L.map_reference(rgb, Lc * self.rod_ratio, Ic, L.sigma_of(Ic, L.BETA_CONE),
                                   L.sigma_of(Ir, L.BETA_ROD), sd, self.display.unit_cd,
                                   white, 0.0)
        return white_luminance(shown, white, lo)


def _factors(raised, frame) -> tuple[float, float]:
    """(cone, rod) factors of the raised goals over the frame's own."""
    return (float(raised.G_cone) / max(frame.G_cone, V_FLOOR),
            float(raised.G_rod) / max(frame.G_rod, V_FLOOR))


#: Keys of an observer (:meth:`Ledda04.observer_of`) holding its current sigmas.
SIGMAS_NOW = ("sigma_cone_now", "sigma_rod_now")


def _sigmas_now(obs):
    """The current (cone, rod) sigmas of an observer state: made by observer_of where
    it made them, else from the state (Eqs. 14-15)."""
    if SIGMAS_NOW[0] in obs:
        return obs[SIGMAS_NOW[0]], obs[SIGMAS_NOW[1]]
    return L.current_sigmas(obs)
