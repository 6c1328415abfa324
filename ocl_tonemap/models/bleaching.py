"""Photopigment bleaching and regeneration, shared by every operator's default time
course (issue 66): how long a person takes to see again after a bright field.

>>> s = preadapted(1.3e5, 120.0)              # Hecht's 400 000 td for two minutes
>>> round(s["Bb_rod"], 3), round(s["Bb_cone"], 3)
(0.989, 0.953)
>>> round(regeneration_minutes(1.0, 0.2), 1)   # rods, a full bleach down to 20 %: Eq. 4
13.2

The state is five numbers per observer (``AdaptationState.extra["pigment"]``):
the bleached fractions ``Bb_rod`` and ``Bb_cone`` (0: all pigment there), the
neural levels ``N_rod``, ``N_cone`` (cd/m^2: the field's memory over the first
seconds after it goes, the early neural phase) and the cones' lagging level
``M_cone`` (cd/m^2: where the cones' adaptation still is below a field that has just
come on, Eq. 7). A state of the first four alone (written before Eq. 7)
is read as one with no lag.

The equations (units: trolands td = cd/m^2 x pupil area in mm^2, scotopic for
rods; time in seconds; Bb bleached fraction):

1. Retinal illuminance through the natural pupil (Moon & Spencer 1944, the tool's
   own ``spencer1995.pupil_diameter``): I = L pi d(L_cone)^2 / 4.
2. Cones, first-order kinetics (Rushton & Henry 1968; Alpern & Pugh 1974):
   dBb/dt = I (1 - Bb) / (tau_c I0_c) - Bb / tau_c, solved exactly for I held
   over the step; steady state Bb = I / (I + I0_c).
3. Rods, bleaching at the photosensitivity Q_r (Rushton; Thomas & Lamb 1999):
   dBb/dt|bleach = I' (1 - Bb) / Q_r.
4. Rods, rate-limited regeneration (Lamb & Pugh 2004; Mahroo & Lamb 2004; Cameron,
   Mahroo & Lamb 2006): dBb/dt|regen = -v Bb / (K_m + Bb). Steps 3 and 4 together
   are integrated by an exponential integrator (the regeneration rate frozen at each
   sub-step's midpoint, of at most SUBSTEP_S, found by three fixed-point passes):
   stable for any step, from 1 ms to hours; one step or its halves agree to ~2e-9.
5. The early neural phase (Hecht's first minute: 2 log units gone in ~20 s after
   263 td, before pigment rules; Baker 1949's fast phase). The cones' N follows a
   brighter field at once (the operator's own neural filter is the fast part) and
   decays to a dimmer one with tau_N: dN/dt = (L - N) / tau_N. The rods' N rises to
   a brighter field with tau_N (a flash of milliseconds leaves next to nothing) and
   falls to a dimmer one at second order with a slow first-order end,
   dD/dt = -w_N,r D^2 / C_N - D / tau_S for D = N - L > 0 (exact over a step:
   D e / (1 + w_N,r D tau_S (1 - e) / C_N), e = exp(-dt / tau_S)): its equivalent
   background w_N,r D then falls as C_N / t once t exceeds its first few seconds,
   whatever the field, until tau_S ends it (Rushton & Powell 1972: after bleaches
   under 10 % the threshold lies well above the pigment's course for minutes;
   Hecht's 263 td: L_eq t about constant from 15 s to 10 min, falling after).
6. The threshold elevation reaches the operator as an equivalent background
   (Crawford 1947; Lamb & Pugh 2004: the equivalent background is proportional to
   what is bleached and not yet regenerated), added to the adaptation level it uses:
   cones L_eq = I_D kappa Bb + w_N (N - L), rods
   L_eq = I_D ((1 + kappa Bb) 10^(a Bb) - 1) + w_N (N - L), I_D the receptor's dark
   light (its threshold doubles on a background of I_D). On a Weber observer the log
   threshold elevation is log10(1 + L_eq / I_D): for the rods
   log10(1 + kappa Bb) + a Bb, Crawford's linear term for small bleaches and the
   Dowling-Rushton relation's (log elevation proportional to the bleach; Alpern,
   Rushton & Torii 1970) for large; with the regeneration's rate near v / K_m per
   minute once Bb is small, the rods' S2 slope near the end is about 0.23 log
   units a minute (Lamb 1981: ~0.24).
7. Light adaptation's onset (Baker 1949, as Pattanaik et al. 2000 Sec. 3.1 and Ledda
   et al. 2004 Sec. 5 read his Fig.: at the onset of a bright field on a dark-adapted
   eye the threshold jumps, falls fast over the first seconds, then slowly to its
   steady value by about 3 min, ~0.5 log in all, much alike for two fields). The
   cones' adapting level M lags a brighter field: at most psi_f log units below it (a
   step from the dark starts there, so the course does not depend on how dark it
   was), it relaxes to it in log10, d log M / dt = (log L - log M) / tau_f. A dimmer
   field is followed at once (Eqs. 2-6 carry dark adaptation). The fast phase only:
   the slow one to 3 min, on a cone response, would leave the display visibly too
   bright for a minute (docs/models.md). The operator's cone goal is taken down by
   the lag psi = log10(L / M) (``onset_lag``): its response is compressed
   (Pattanaik Sec. 3.1: "only when adaptation brings sigma nearer to the new,
   much brighter I values will the response and threshold fall to their static
   values"), so the field is white at first and its threshold raised.

Constants: published values (each with its source); the equivalent-background
gains kappa_r, kappa_c and the neural phase's w_N (rods, cones), tau_N, C_N and
tau_S are fitted, on Hecht, Haig & Chase 1937's 263, 19 500 and 400 000 td (the
other two held out,
``benchmarks/psychophysics.py``); Eq. 7's psi_f and tau_f are set on Baker's
course as the papers describe it (no numbers of his are at hand:
``benchmarks/tunnel_entrance.py``, docs/models.md).
"""

from __future__ import annotations

import math

from .photometry import neutral_scotopic_ratio
from .spencer1995 import pupil_diameter

# -- constants (each from its source) ------------------------------------------------
#: Cone pigment: regeneration time constant, s (Rushton & Henry 1968: 110-120 s;
#: Alpern & Pugh 1974).
TAU_CONE = 120.0
#: Cone pigment: half-bleaching retinal illuminance, photopic td (Rushton & Henry
#: 1968, Fig. 2: 10^4.3 td).
I0_CONE = 10.0 ** 4.3
#: Rod pigment: photosensitivity, scotopic td s (the e-fold bleaching energy, 10^7.0:
#: Pugh's exposures of 4.7-7.6 log scotopic td s bleached up to 98 %, as Lamb & Pugh
#: 2004 report them, 1 - exp(-10^7.6 / 10^7.0) = 0.98; Rushton 1972, Thomas & Lamb
#: 1999: half-bleach near 10^7 td s).
Q_ROD = 1.0e7
#: Rod regeneration, rate-limited: the largest rate (fraction a minute) and the
#: half-rate bleached fraction (Lamb & Pugh 2004; Cameron, Mahroo & Lamb 2006's
#: "standard parameters" v = 0.085 min^-1, K_m = 0.2).
V_ROD_PER_MIN = 0.085
KM_ROD = 0.2
#: The cones' early neural phase's time constant, s (fitted: the first 20 s after 263 td).
TAU_N = 8.0
#: The rods' early neural phase, second order: the product L_eq t its equivalent
#: background tends to, scotopic cd/m^2 s (fitted on Hecht's 263 td: 1000 dark
#: lights I_D_ROD x 1 s, ~17 I_D for a minute; with W_N_ROD the first seconds' decay
#: time is C_N / L_eq(0), 4 s after 263 td), and the time constant, s, that ends it
#: (fitted: Hecht's 263 td falls faster than 1 / t after ~10 min).
C_N_ROD = 0.1
TAU_S_ROD = 1200.0
#: Dark lights (Weber knees) I_D: rods 10^-4 scotopic cd/m^2 (Aguilar & Stiles 1954:
#: the rod threshold doubles near 10^-3 scotopic td through a dark pupil of ~50 mm^2,
#: ~2e-5 cd/m^2; Hecht's 3-degree field's absolute threshold near 1e-4), cones
#: 10^-2 cd/m^2 (Stiles' pi_4-pi_5 knees near 1 td through a 5 mm pupil).
I_D_ROD = 1.0e-4
I_D_CONE = 1.0e-2
#: Equivalent-background gains (dark lights per unit fraction bleached), fitted: the
#: rods' (with A_ROD) make the rod-cone breaks after 400 000 and 19 500 td come where
#: Hecht's do (12-14 and 5-7 min); the cones' the fall of the cone branch (2.3 min:
#: 0.5 log).
KAPPA_ROD = 800.0
KAPPA_CONE = 8.0
#: The rods' Dowling-Rushton slope, log units of threshold per unit fraction bleached
#: (fitted with KAPPA_ROD; the local slope of the whole elevation near Bb = 0.2 is
#: 7 log units per unit, below the 12-20 that reviews give for large bleaches: a
#: steeper one makes the rods' S2 fall faster than Hecht's 0.24 log units a minute).
A_ROD = 5.0
#: The early neural phase's weights (fitted): the share of a field left as an
#: equivalent background as it goes (rods after 263 td, cones after 400 000 td).
W_N_ROD = 3.3e-4
W_N_CONE = 6.0e-5
#: Eq. 7, the cones' onset lag (set on Baker 1949's course as Pattanaik et al. and
#: Ledda et al. describe it): the largest lag, log10 units, and its time constant, s
#: ("falls very rapidly within the first few seconds").
PSI_FAST = 1.0
TAU_FAST = 1.5
#: The largest sub-step of the rods' integrator, s (the regeneration's own time scale
#: K_m / v is 141 s): an hour is 360 sub-steps.
SUBSTEP_S = 10.0
#: The most sub-steps of one step (a step longer than this many SUBSTEP_S takes
#: longer sub-steps: the regeneration has long settled by then).
MAX_SUBSTEPS = 4096

#: The largest field taken, cd/m^2 (the sun's disk is ~1.6e9: every pigment is bleached
#: long before) and the longest step, s (a day: the state is steady by then).
L_MAX = 1.0e10
DT_MAX = 86400.0

KEYS = ("Bb_rod", "Bb_cone", "N_rod", "N_cone", "M_cone")
#: A state written before Eq. 7 (read as one with no lag).
KEYS_V1 = KEYS[:4]


def _field(L) -> float:
    """A goal as the model takes it: NaN and negatives are no light, +inf L_MAX."""
    L = float(L)
    return min(L, L_MAX) if L > 0.0 else 0.0


def dark() -> dict:
    """A fully dark-adapted observer: every pigment there, no field remembered."""
    return {k: 0.0 for k in KEYS}


def trolands(L_rod: float, L_cone: float) -> tuple[float, float]:
    """Eq. 1: (scotopic, photopic) retinal illuminance, td, through the natural pupil
    at the cones' level."""
    d = float(pupil_diameter(max(float(L_cone), 0.0)))
    area = math.pi * d * d / 4.0
    return max(float(L_rod), 0.0) * area, max(float(L_cone), 0.0) * area


def _cone_step(bb: float, I: float, dt: float) -> float:
    """Eq. 2 exactly."""
    r = (1.0 + I / I0_CONE) / TAU_CONE
    b_inf = (I / I0_CONE) / (1.0 + I / I0_CONE)
    return min(max(b_inf + (bb - b_inf) * math.exp(-r * dt), 0.0), 1.0)


def _rod_step(bb: float, I: float, dt: float) -> float:
    """Eqs. 3-4: an exponential integrator over sub-steps."""
    n = min(MAX_SUBSTEPS, max(1, math.ceil(dt / SUBSTEP_S)))
    h = dt / n
    a = I / Q_ROD
    v = V_ROD_PER_MIN / 60.0
    for _ in range(n):
        bb0 = bb
        for _ in range(3):    # Eq. 4's rate frozen at the sub-step's midpoint, iterated
            r = v / (KM_ROD + 0.5 * (bb0 + bb))
            b_inf = a / (a + r)
            bb = b_inf + (bb0 - b_inf) * math.exp(-(a + r) * h)
    return min(max(bb, 0.0), 1.0)


def _neural_step(N: float, L: float, dt: float) -> float:
    """Eq. 5 exactly (the cones: first order)."""
    return L if L >= N else L + (N - L) * math.exp(-dt / TAU_N)


def _rod_neural_step(N: float, L: float, dt: float) -> float:
    """Eq. 5 exactly (the rods: up with tau_N, down at second order)."""
    if L >= N:
        return L + (N - L) * math.exp(-dt / TAU_N)
    d, e = N - L, math.exp(-dt / TAU_S_ROD)
    return L + d * e / (1.0 + W_N_ROD * d * TAU_S_ROD * (1.0 - e) / C_N_ROD)


def _onset_step(M: float, L: float, dt: float, psi: float, tau: float) -> float:
    """Eq. 7 exactly (the lagging level: at most ``psi`` below the field, then toward
    it in log10 with ``tau``; a dimmer field at once)."""
    if not L > 0.0 or M >= L:
        return L
    lag = min(math.log10(L / M), psi) if M > 0.0 else psi
    return L * 10.0 ** (-lag * math.exp(-dt / tau))


def advance(s: dict, L_rod: float, L_cone: float, dt: float) -> dict:
    """The pigment state ``s`` after ``dt`` seconds of a field of ``L_rod`` scotopic and
    ``L_cone`` photopic cd/m^2 (held over the step)."""
    if not dt > 0.0:
        return dict(s)
    dt = min(float(dt), DT_MAX)
    L_rod, L_cone = _field(L_rod), _field(L_cone)
    I_r, I_c = trolands(L_rod, L_cone)
    return {"Bb_rod": _rod_step(s["Bb_rod"], I_r, dt),
            "Bb_cone": _cone_step(s["Bb_cone"], I_c, dt),
            "N_rod": _rod_neural_step(s["N_rod"], L_rod, dt),
            "N_cone": _neural_step(s["N_cone"], L_cone, dt),
            "M_cone": _onset_step(s.get("M_cone", L_cone), L_cone, dt, PSI_FAST, TAU_FAST)}


def steady(L_rod: float, L_cone: float) -> dict:
    """Adapted for good to a field (the state's fixed point, reached by a day of it)."""
    return advance(dark(), L_rod, L_cone, 86400.0)


def preadapted(L_cd: float, seconds: float | None, scotopic_ratio: float | None = None
               ) -> dict:
    """After a neutral field of ``L_cd`` cd/m^2 (scotopic: x ``scotopic_ratio``, the
    neutral's by default) for ``seconds`` from the dark (None: adapted for good)."""
    if scotopic_ratio is None:
        scotopic_ratio = neutral_scotopic_ratio()
    L_rod = L_cd * scotopic_ratio
    if seconds is None:
        return steady(L_rod, L_cd)
    return advance(dark(), L_rod, L_cd, float(seconds))


def equivalent_background(s: dict, L_rod: float = 0.0, L_cone: float = 0.0
                          ) -> tuple[float, float]:
    """Eq. 6: (rods' scotopic, cones' photopic) equivalent background, cd/m^2, on a
    field of ``L_rod``, ``L_cone``."""
    b = s["Bb_rod"]
    return (I_D_ROD * ((1.0 + KAPPA_ROD * b) * 10.0 ** (A_ROD * b) - 1.0)
            + W_N_ROD * max(s["N_rod"] - L_rod, 0.0),
            I_D_CONE * KAPPA_CONE * s["Bb_cone"] + W_N_CONE * max(s["N_cone"] - L_cone, 0.0))


def onset_lag(s: dict, L_cone: float) -> float:
    """Eq. 7: log10 units the cones' adapting level is still below a field of
    ``L_cone`` cd/m^2 that came on lately (0 on a steady or dimming field; a state
    without Eq. 7's level has none)."""
    L, M = _field(L_cone), s.get("M_cone", 0.0)
    return math.log10(L / M) if 0.0 < M < L else 0.0


def rod_sensitivity(s: dict, L_rod: float, L_cone: float) -> float:
    """How far the rods have come back on a field (L_rod scotopic, L_cone photopic
    cd/m^2): a Weber observer's rod threshold on that field held for good over its
    threshold with the pigment state ``s`` (Eq. 6), in (0, 1]. 1 on a steady field;
    near 0 right after a bright one (the rods' equivalent background), rising as the
    rhodopsin regenerates, never falling while the field stays."""
    def threshold(st):
        return I_D_ROD + L_rod + equivalent_background(st, L_rod, L_cone)[0]
    return float(min(1.0, threshold(steady(L_rod, L_cone)) / threshold(s)))


def dark_light(receptor: str) -> float:
    """I_D of ``"rod"`` (scotopic cd/m^2) or ``"cone"`` (cd/m^2)."""
    return I_D_ROD if receptor == "rod" else I_D_CONE


def elevation(s: dict) -> tuple[float, float]:
    """Log10 threshold elevation of a Weber observer (rods, cones) over its dark one."""
    Lr, Lc = equivalent_background(s)
    return math.log10(1.0 + Lr / I_D_ROD), math.log10(1.0 + Lc / I_D_CONE)


def regeneration_minutes(b_from: float, b_to: float) -> float:
    """Minutes the rods take in the dark from ``b_from`` to ``b_to`` bleached (Eq. 4
    integrated: ((b0 - b1) + K_m ln(b0 / b1)) / v)."""
    return ((b_from - b_to) + KM_ROD * math.log(b_from / b_to)) / V_ROD_PER_MIN


def check(s) -> bool:
    """Whether ``s`` is a pigment state (the state file's check)."""
    return (isinstance(s, dict) and set(s) in (set(KEYS), set(KEYS_V1))
            and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                    and math.isfinite(v) and v >= 0.0 for v in s.values())
            and s["Bb_rod"] <= 1.0 and s["Bb_cone"] <= 1.0)
