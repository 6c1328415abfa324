"""Issue 66 item 4, "seconds as well as minutes": the tunnel entrance (CIE 88:2004) and
light adaptation on a dark-adapted eye (Baker 1949), by each operator's own observer.

A. The tunnel entrance. A driver adapted for good to the access zone's L20 enters a
tunnel lit as CIE 88:2004 asks (our reading of the standard; its text was not at
hand, the numbers are the usual ones): the threshold zone, one stopping distance
long, at L_th = k L20 for its first half, falling linearly to 0.4 L_th over its
second; then the transition zone, L_tr(t) = L_th (1.9 + t)^-1.4 with t in seconds
from the transition zone's start (1.9^-1.4 = 0.407: the curve starts where the
threshold zone ends), down to the interior level. A second driver meets the interior
level at once (a step from L20 at the entrance). A fixed target (CIE 88's small
target: 20 cm at the stopping distance; contrast :data:`CONTRAST` below the road, a
negative contrast) lies on the road luminance of each moment; its visibility level
VL = |L_t - L_road| / dL_th, dL_th Adrian 1989's threshold times the transient factor
of the operator's state (``ocl_tonemap/effects/visibility.py``: :func:`seen` for the drive,
:func:`trace` for the step; no veil). Expected: along the curve VL stays near its
threshold-zone value (CIE 88's k makes the target visible to an eye still adapted to
L20 on entering; the curve is its assumption of how fast adaptation follows); after
the step VL falls below 1 for some seconds.

B. Light adaptation (Baker 1949). An observer dark-adapted for good (the darkest
field the tool takes, :data:`ocl_tonemap.base.quantities.LUMINANCE_RANGE`'s lowest), a
uniform field switched on at t = 0: the increment threshold of the visibility
calculator's target on it over the first minute (dL_th = Adrian's steady threshold x
TAF, TAF clipped to >= 1 as the model has it), and the unclipped gain ratio
s_steady / s_now (below 1: the observer is more sensitive than when adapted). Baker's
data: at the onset the threshold jumps well above its steady value and falls to it
within seconds to tens of seconds. The model has no onset transient (the pigment's
neural phase follows a brighter field at once; the operators' gains are highest when
dark adapted): the expected result is a threshold at or below its steady value from
the start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

OPERATORS = ("pattanaik00", "durand00", "kirk11", "ledda04")
#: The access zone's luminance L20, cd/m^2 (a sunlit approach).
L20 = 5000.0
#: Design speed and its stopping distance (CIE 88:2004, 80 km/h: 100 m), and the k
#: of the L20 method for symmetrical lighting at that stopping distance (our reading:
#: 0.05 at 60 m, 0.06 at 100 m, 0.10 at 160 m).
SPEED_KMH = 80.0
STOPPING_M = 100.0
K_TH = 0.06
L_TH = K_TH * L20
#: The interior zone's level, cd/m^2.
L_INTERIOR = 5.0
#: The threshold zone's end value over L_th (CIE 88: linear to 0.4 L_th over its
#: second half).
THRESHOLD_END = 0.4
#: CIE 88's small target: 20 cm seen at the stopping distance; its contrast below the
#: road (L_t = (1 - CONTRAST) L_road).
TARGET_M = 0.2
CONTRAST = 0.2
#: The drive's step, s, and its length after the entrance.
DT_S = 0.02
DRIVE_S = 40.0
#: The sudden step's sampling: every 0.01 s for 5 s, then every 0.1 s to 60 s.
STEP_TIMES = np.unique(np.r_[np.arange(0.0, 5.0, 0.01), np.arange(5.0, 60.0001, 0.1)])
#: Baker: the fields switched on (cd/m^2) and the seconds after the onset.
BAKER_FIELDS = (10.0, 100.0, 1000.0)
BAKER_TIMES = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0)


def target_arcmin(size_m: float = TARGET_M, distance_m: float = STOPPING_M) -> float:
    """The angle (arcmin) of ``size_m`` at ``distance_m``."""
    return math.degrees(2.0 * math.atan(0.5 * size_m / distance_m)) * 60.0


def threshold_zone_s() -> float:
    """Seconds the threshold zone (one stopping distance) takes at the design speed."""
    return STOPPING_M / (SPEED_KMH / 3.6)


def transition(L_th: float, t) -> np.ndarray:
    """CIE 88:2004's transition curve L_th (1.9 + t)^-1.4, t (s) from its start."""
    return L_th * (1.9 + np.asarray(t, np.float64)) ** -1.4


def transition_end_s(L_th: float = L_TH, L_in: float = L_INTERIOR) -> float:
    """Seconds into the transition zone where its curve reaches the interior level."""
    return (L_th / L_in) ** (1.0 / 1.4) - 1.9


def road(t, L_th: float = L_TH, L_in: float = L_INTERIOR, L_access: float = L20,
         tz_s: float | None = None) -> np.ndarray:
    """The road luminance (cd/m^2) ``t`` s after the entrance (t < 0: the access zone):
    the threshold zone (L_th, then linear to 0.4 L_th), the transition curve, the
    interior level."""
    D = threshold_zone_s() if tz_s is None else tz_s
    t = np.asarray(t, np.float64)
    thz = np.where(t < 0.5 * D, L_th,
                   L_th * (1.0 - (1.0 - THRESHOLD_END) * (t - 0.5 * D) / (0.5 * D)))
    tr = np.maximum(transition(L_th, np.maximum(t - D, 0.0)), L_in)
    return np.where(t < 0.0, L_access, np.where(t < D, thz, tr))


def viewing():
    """The observer (``visibility.Viewing``): the small target, 25 years, the
    project's 0.2 s look, Adrian 1989."""
    from ocl_tonemap.effects.visibility import Viewing
    return Viewing(size_arcmin=target_arcmin())


@dataclass
class Drive:
    """One operator's drive along the curve and its sudden step."""

    op: str
    t: np.ndarray            # s after the entrance
    L_road: np.ndarray
    L_a: np.ndarray          # the eye's level, cd/m^2
    VL: np.ndarray
    VL_threshold_zone: float  # at the entrance: L_th, the eye still adapted to L20
    VL_adapted_th: float      # an eye adapted to L_th
    step_t: np.ndarray
    step_VL: np.ndarray
    step_VL_adapted: float    # an eye adapted to the interior level

    def _after_tz(self):
        return self.t >= threshold_zone_s()

    @property
    def vl_min(self) -> float:
        """VL's least over the drive (t >= 0)."""
        return float(self.VL.min())

    @property
    def vl_min_t(self) -> float:
        return float(self.t[int(self.VL.argmin())])

    @property
    def vl_min_curve(self) -> float:
        """VL's least along the transition curve and the interior."""
        return float(self.VL[self._after_tz()].min())

    @property
    def below1_drive_s(self) -> float:
        """Seconds of the drive with VL < 1."""
        return float(np.sum(self.VL < 1.0) * DT_S)

    @property
    def step_below1_s(self) -> float:
        """Seconds after the sudden step with VL < 1 (each sample counted for the gap
        to the next)."""
        gaps = np.diff(np.r_[self.step_t, self.step_t[-1]])
        return float(np.sum(gaps[self.step_VL < 1.0]))

    @property
    def step_last_below1_s(self) -> float | None:
        """The last sample after the step with VL < 1 (None: never below)."""
        b = self.step_t[self.step_VL < 1.0]
        return float(b[-1]) if b.size else None


def drive(name: str, view=None, dt: float = DT_S, seconds: float = DRIVE_S) -> Drive:
    """``name``'s observer adapted to L20, driven along :func:`road` (the field held at
    each step's midpoint luminance over ``dt``), and stepped to the interior level."""
    from ocl_tonemap.operators import get_operator
    from ocl_tonemap.effects.visibility import seen, trace
    view = view or viewing()
    op = get_operator(name)({})
    g = view.media_gain
    obs = op.observer_preadapted(L20 * g, None)
    n = int(round(seconds / dt))
    ts = np.arange(n + 1) * dt
    Ls = road(ts)
    first = seen(op, obs, view, float(Ls[0]), 0.0, (1.0 - CONTRAST) * float(Ls[0]))
    La, VL = [first.L_a], [first.VL]
    for i in range(1, n + 1):
        obs = op.observer_advance(obs, float(road(0.5 * (ts[i - 1] + ts[i]))) * g, dt)
        s = seen(op, obs, view, float(Ls[i]), 0.0, (1.0 - CONTRAST) * float(Ls[i]))
        La.append(s.L_a)
        VL.append(s.VL)
    adapted_th = seen(op, op.observer_preadapted(L_TH * g, None), view, L_TH, 0.0,
                      (1.0 - CONTRAST) * L_TH).VL
    pts = trace(op, L20, None, L_INTERIOR, STEP_TIMES, view, "negative",
                (1.0 - CONTRAST) * L_INTERIOR)
    adapted_in = seen(op, op.observer_preadapted(L_INTERIOR * g, None), view, L_INTERIOR,
                      0.0, (1.0 - CONTRAST) * L_INTERIOR).VL
    return Drive(name, ts, Ls, np.array(La), np.array(VL), float(first.VL), float(adapted_th),
                 np.array([p.t for p in pts]), np.array([p.VL for p in pts]),
                 float(adapted_in))


@dataclass
class Onset:
    """One operator's threshold after a field goes on before a dark-adapted eye."""

    op: str
    L: float
    t: tuple
    steady: float            # Adrian's dL_th adapted to L, cd/m^2
    dL_th: np.ndarray        # steady x TAF (TAF >= 1)
    ratio: np.ndarray        # unclipped s_steady / s_now
    L_a: np.ndarray

    @property
    def onset_over_steady(self) -> float:
        """dL_th at t = 0 (the dark-adapted state, the field just on) over steady."""
        return float(self.dL_th[0] / self.steady)

    def over_steady_at(self, t: float) -> float:
        return float(self.dL_th[self.t.index(t)] / self.steady)

    @property
    def above_steady_until(self) -> float | None:
        """The last sampled time with dL_th above 1.01 x steady (None: never)."""
        b = [t for t, d in zip(self.t, self.dL_th) if d > 1.01 * self.steady]
        return b[-1] if b else None


def onset(name: str, L: float, view=None, times=BAKER_TIMES) -> Onset:
    """``name``'s observer dark-adapted for good, a field of ``L`` from t = 0."""
    from ocl_tonemap.operators import get_operator
    from ocl_tonemap.base.quantities import LUMINANCE_RANGE
    from ocl_tonemap.effects.visibility import trace
    view = view or viewing()
    op = get_operator(name)({})
    g = view.media_gain
    pts = trace(op, LUMINANCE_RANGE[0], None, L, times, view)
    s_ss = float(op.observer_steady_slope(L * g))
    obs = op.observer_preadapted(LUMINANCE_RANGE[0] * g, None)
    ratio, now = [], 0.0
    for t in times:
        obs = op.observer_advance(obs, L * g, t - now)
        now = t
        ratio.append(s_ss / max(float(op.observer_slope(obs, L * g)), 1e-300))
    return Onset(name, float(L), tuple(times), float(view.steady(L)),
                 np.array([p.dL_th for p in pts]), np.array(ratio),
                 np.array([p.L_a for p in pts]))


def run_all(operators=OPERATORS, fields=BAKER_FIELDS):
    """({op: Drive}, {op: {L: Onset}}); an operator whose observer fails is left out
    with its error ({op: message} third)."""
    drives, onsets, failed = {}, {}, {}
    view = viewing()
    for name in operators:
        try:
            drives[name] = drive(name, view)
            onsets[name] = {L: onset(name, L, view) for L in fields}
        except Exception as e:            # an operator without a working observer
            failed[name] = f"{type(e).__name__}: {e}"
    return drives, onsets, failed
