"""Ledda, Santos & Chalmers 2004: local adaptation with a dark/light time course.

"A Local Model of Eye Adaptation for High Dynamic Range Images", Afrigraph
2004. Equation numbers are the paper's. Units: cd/m^2 (photopic Y for
cones, scotopic Y' for rods), seconds.

Per pixel:
  Y, Y'          Eqs. 6-7 (the paper's coefficients, applied to working RGB)
  I_A, I_A'      bilateral filter of Y and Y' (Eqs. 8-10, ``bilateral.py``)
  sigma          beta * I_A^alpha, Eq. 5 (alpha = 0.69; beta_cone 5.83, beta_rod 2.0)
  R_cone, R_rod  Y^n / (Y^n + sigma^n), Eqs. 2-3
  mes            smoothstep of (log10 I_A + 2)/2.6, Eq. 11 (reconstructed)
  output         Y_coneO = mes sigma_disp (R/(1-R))^(1/n) (Eq. 12), Y_rodO likewise
                 with 1 - mes (Eq. 13); RGB = rgb * Y_coneO/Y + Y_rodO.
Time course (Sec. 5.2, Eqs. 14-17, Table 1, reconstructed): each pixel's
sigma moves from sigma_in to sigma_fin along a dark or light curve; a change
of illumination restarts it from the current sigma. The per-pixel state is
small and serialisable (see :data:`STATE_CHANNELS`).

The float64 functions below are the reference; ``kernels/ledda04.cl`` is the
device pass (state step, mapping), ``kernels/bilateral.cl`` the filter, run by
``operators/ledda04.py`` and ``backends/opencl/ledda04.py``.

>>> float(mesopic_factor_ledda2004(0.01)), float(mesopic_factor_ledda2004(10.0))
(0.0, 1.0)
>>> round(float(K_of_energy(0.0)), 1), round(float(K_of_energy(1e9)), 4)
(12.0, 5.6598)

Reconstructions are argued in docs/models.md.
"""

from __future__ import annotations

import math

import numpy as np

from .bilateral import LEDDA_RANGE, V_FLOOR, bilateral_reference
from .photometry import neutral_scotopic_ratio, scotopic_luminance
from .display import DISPLAY_LINEAR_MAX, SIGNAL_CEILING, DisplaySpec, apply_shoulder, scene_key

#: Eq. 5 exponent and the per-receptor betas, cd/m^2 ("between 5.83 and 2.0
#: depending on the receptor": cones are the less sensitive system).
ALPHA = 0.69
BETA_CONE, BETA_ROD = 5.83, 2.0
#: Naka-Rushton exponent of Eqs. 1-3 (0.7 < n < 2; Hunt's 0.73 as in
#: Pattanaik 2000). It cancels between Eq. 2 and its inverse Eq. 12.
N = 0.73
#: Eqs. 6-7 (Pattanaik et al. 1998's RGB -> Y, Y').
Y_COEFFS = (0.256, 0.67, 0.065)
YS_COEFFS = (-0.702, 1.039, 0.433)
#: Table 1 time constants, s.
TAU_CONE, TAU_ROD = 600.0, 2400.0
RHO_CONE, RHO_ROD = 20.0, 20.0
#: Eq. 17: K = -0.0006 E + 12, valid for E up to 10567 cd/m^2 s (Mote & Riopelle).
K_SLOPE, K_MAX, E_MAX = -0.0006, 12.0, 10567.0
K_MIN = K_MAX + K_SLOPE * E_MAX
#: Display adaptation level as a fraction of display white (Sec. 4.4: 30-50
#: cd/m^2 on the paper's display; 40 for a 100 cd/m^2 white).
DISPLAY_ADAPT_FRACTION = 0.4
#: A pixel's goal sigma that turns back by more than this many log10 units from
#: its anchor (the goal at its last such move) begins a new course (Sec. 5.2, last
#: paragraph; our threshold, a hysteresis against noise): :func:`step_reference`.
CHANGE_LOG10 = 0.03
#: A goal that moves more than this (log10 of sigma) in one frame is a "new change
#: in illumination" (Sec. 5.2): its new course holds sigma_in for the curves' first
#: second (Figure 9's temporary blindness); smaller turns start past the hold.
JUMP_LOG10 = 0.3
#: Where the curves of Eqs. 14-15 begin (s): they hold sigma_in before.
T_HOLD = 1.0
#: A re-aimed course is finished when sigma is within this fraction of its goal
#: (:func:`course_clock`).
COURSE_DONE = 1.0e-5
#: A jump ahead (JUMP_LOG10) re-aims a course while more than this fraction of it
#: is left, and begins a new one with its hold after (:func:`course_done`).
COURSE_RUNNING = 0.02
#: A goal within this fraction of the current sigma counts as ahead of it
#: (:func:`goal_ahead`).
AHEAD_TOL = 1.0e-4
#: Eq. 11: u = (log10 I_A + MES_LOG_OFFSET) / MES_LOG_SPAN, i.e. mes from 0 at
#: 10^-2 cd/m^2 to 1 at 10^0.6 ~ 4 cd/m^2 (mesopic_factor_ledda2004).
MES_LOG_OFFSET, MES_LOG_SPAN = 2.0, 2.6
#: Ceiling of the accumulated energy E, cd/m^2 s (stays finite in float32).
E_CEILING = 1.0e30
#: "Long ago": t of a pixel whose course has finished, s.
T_DONE = 1.0e9

#: ``mode``: "default" (adaptation to a blend of the local and the frame's global
#: level, display anchored to the scene's key, highlight shoulder) or "paper"
#: (fully local, the fixed display sigma, hard clip): docs/models.md.
MODES = ("default", "paper")
#: Default share of the local (bilateral) level in the adaptation level
#: (Reinhard & Devlin 2005's light-adaptation mix; 1 = the paper's fully local).
LOCAL_STRENGTH = 0.5

#: Per-pixel state planes, in this order (float32 on the device).
STATE_CHANNELS = ("sigma_in_cone", "sigma_fin_cone", "sigma_anchor_cone",
                  "sigma_in_rod", "sigma_fin_rod", "sigma_anchor_rod",
                  "t_cone", "t_rod", "energy", "K")


# --- static model (Sec. 4) -------------------------------------------------------

def luminances(rgb: np.ndarray, ward: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Photopic Y and scotopic Y' of working RGB (cd/m^2), Eqs. 6-7.

    Eq. 7 has a negative red weight; Y' < 0 (every orange and red) is clamped to
    0. ``ward`` (the default mode): Y' of Ward-Larson et al. 1997
    (``photometry.scotopic_luminance``), positive like V'(lambda) (docs/models.md)."""
    rgb = np.asarray(rgb, np.float64)
    Y = rgb @ np.array(Y_COEFFS)
    if ward:
        return Y, scotopic_luminance(rgb)
    Ys = np.maximum(rgb @ np.array(YS_COEFFS), 0.0)
    return Y, Ys


def neutral_rod_ratio(ward: bool) -> float:
    """Y'/Y of a neutral grey: 0.777 for Eqs. 6-7, 2.57 for Ward's Y' over Eq. 6's Y."""
    if ward:
        return neutral_scotopic_ratio() / sum(Y_COEFFS)
    return sum(YS_COEFFS) / sum(Y_COEFFS)


def sigma_of(I_A, beta: float):
    """Half-saturation sigma = beta * I_A^alpha, Eq. 5 (cd/m^2); I_A floored at V_FLOOR."""
    return beta * np.maximum(np.asarray(I_A, np.float64), V_FLOOR) ** ALPHA


def response(Y, sigma):
    """R = Y^n / (Y^n + sigma^n), Eqs. 2-3, as 1/(1 + (sigma/Y)^n) (no overflow)."""
    Y = np.maximum(np.asarray(Y, np.float64), 1e-300)
    return 1.0 / (1.0 + (np.asarray(sigma, np.float64) / Y) ** N)


def inverse_response(R, sigma_disp):
    """Eqs. 12-13 without mes: sigma_disp * (R / (1 - R))^(1/n)."""
    R = np.asarray(R, np.float64)
    return sigma_disp * (R / (1.0 - R)) ** (1.0 / N)


def mesopic_factor_ledda2004(I_A):
    """mes = 3 u^2 - 2 u^3, u = clamp((log10 I_A + 2) / 2.6, 0, 1), Eq. 11.

    0 (rods only) at I_A <= 0.01 cd/m^2, 1 (cones only) at I_A >= 10^0.6 ~ 4 cd/m^2
    ("rods are completely saturated ... above around 4 cd/m^2", Sec. 4.3)."""
    u = np.clip((np.log10(np.maximum(np.asarray(I_A, np.float64), V_FLOOR)) + MES_LOG_OFFSET)
                / MES_LOG_SPAN, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def display_sigma(display: DisplaySpec, adapt_cd: float | None = None) -> float:
    """The single display sigma (Sec. 4.4): Eq. 4 with the cone beta at the display
    adaptation level (``adapt_cd``, default 0.4 x display white = 40 cd/m^2)."""
    L = adapt_cd if adapt_cd else DISPLAY_ADAPT_FRACTION * display.white_cd
    return BETA_CONE * L ** ALPHA


# --- time course (Sec. 5.2) ------------------------------------------------------

def K_of_energy(E):
    """K = -0.0006 E + 12 (Eq. 17), E = intensity x pre-adaptation time (Eq. 16),
    cd/m^2 s; E clamped to [0, 10567] (the range of Mote & Riopelle's data)."""
    return K_MAX + K_SLOPE * np.clip(np.asarray(E, np.float64), 0.0, E_MAX)


def dark_fraction(t, K, tau):
    """Where sigma_t stands between sigma_fin (0) and sigma_in (1) in the dark, Eq. 14:

        (e^{K/t} - e^{K/tau}) / (e^K - e^{K/tau}),  1 s <= t <= tau,

    i.e. (CONE_dark - pos_fin) / (pos_in - pos_fin) with CONE_dark = sigma_in e^{K/t},
    pos_in = sigma_in e^K, pos_fin = sigma_in e^{K/tau} (Table 1); 1 before t = 1 s,
    0 from t = tau."""
    t = np.asarray(t, np.float64)
    K = np.asarray(K, np.float64)
    tt = np.maximum(t, 1.0)
    with np.errstate(over="ignore"):
        f = (np.exp(K / tt) - np.exp(K / tau)) / (np.exp(K) - np.exp(K / tau))
    return np.where(t >= tau, 0.0, np.clip(f, 0.0, 1.0))


def light_fraction(t, rho):
    """The light curve, Eq. 15: (CONE_light - pos_fin)/(pos_in - pos_fin) with
    CONE_light = sigma_in K log t, pos_in = 0, pos_fin = sigma_in K log rho (Table 1)
    = 1 - log t / log rho; 1 before t = 1 s, 0 from t = rho."""
    t = np.maximum(np.asarray(t, np.float64), 1.0)
    return np.clip(1.0 - np.log(t) / math.log(rho), 0.0, 1.0)


def sigma_at(sigma_in, sigma_fin, t, K, receptor: str):
    """sigma_t of Eqs. 14-15 for one receptor: dark when sigma_fin < sigma_in.
    Rods lag the cones by tau_cone in the dark (ROD_dark uses t - tau_cone)."""
    sigma_in = np.asarray(sigma_in, np.float64)
    sigma_fin = np.asarray(sigma_fin, np.float64)
    if receptor == "cone":
        fd = dark_fraction(t, K, TAU_CONE)
        fl = light_fraction(t, RHO_CONE)
    else:
        fd = dark_fraction(np.asarray(t, np.float64) - TAU_CONE, K, TAU_ROD)
        fl = light_fraction(t, RHO_ROD)
    f = np.where(sigma_fin < sigma_in, fd, fl)
    return sigma_fin + f * (sigma_in - sigma_fin)



def adaptation_luminance(sigma_cone):
    """I_A of a cone sigma, Eq. 5 inverted: (sigma / beta)^(1/alpha), cd/m^2."""
    return (np.asarray(sigma_cone, np.float64) / BETA_CONE) ** (1.0 / ALPHA)


def response_slope(L_b, sigma_cone, sigma_rod, ward: bool = True):
    """dR/dln Y of Eqs. 2-3, cones and rods mixed by Eq. 11's mes at the current cone
    level, for a small neutral increment on a background of L_b cd/m^2 seen with
    the current sigmas: the observer's own gain for a visibility threshold
    (``adrian1989.transient_factor``): n (mes x_c (1 - x_c) + (1 - mes) x_r (1 - x_r))."""
    L = np.asarray(L_b, np.float64)
    mes = mesopic_factor_ledda2004(adaptation_luminance(sigma_cone))
    xc = response(L, sigma_cone)
    xr = response(L * neutral_rod_ratio(ward), sigma_rod)
    return N * (mes * xc * (1.0 - xc) + (1.0 - mes) * xr * (1.0 - xr))

# --- per-pixel state ----------------------------------------------------------------

def initial_state(I_c, I_r, E) -> dict:
    """Fully adapted to the given adaptation luminances (course finished)."""
    sc, sr = sigma_of(I_c, BETA_CONE), sigma_of(I_r, BETA_ROD)
    E = np.broadcast_to(np.asarray(E, np.float64), sc.shape)
    return {"sigma_in_cone": sc, "sigma_fin_cone": sc, "sigma_anchor_cone": sc,
            "sigma_in_rod": sr, "sigma_fin_rod": sr, "sigma_anchor_rod": sr,
            "t_cone": np.full(sc.shape, T_DONE), "t_rod": np.full(sc.shape, T_DONE),
            "energy": np.array(E, np.float64),
            "K": K_of_energy(E)}


def preadapted_state(L_cd: float, seconds: float | None, shape, ward: bool = False) -> dict:
    """Uniform state after looking at a neutral field of ``L_cd`` cd/m^2 for
    ``seconds`` (None: for long, E at its ceiling). Y' of a neutral field is
    Y * :func:`neutral_rod_ratio`."""
    ratio = neutral_rod_ratio(ward)
    E = E_MAX if seconds is None else L_cd * seconds
    return initial_state(np.full(shape, float(L_cd)), np.full(shape, L_cd * ratio), E)


def course_clock(sigma_in, sigma_goal, sigma_now, K, t_now, receptor: str):
    """The time on the curve sigma_in -> sigma_goal (Eqs. 14-15 inverted) at which
    sigma stands at ``sigma_now`` (between the two): the clock of a course re-aimed
    at a new goal ahead, so that sigma stays continuous and goes on at the curve's
    pace. f = (goal - now) / (goal - sigma_in) left of the course:
    - dark, cones: t = K / ln(e^{K/tau} + f (e^K - e^{K/tau})) (Eq. 14 inverted);
      rods: tau_cone later;
    - light: t = rho^(1 - f) (Eq. 15 inverted);
    - f = 1 (sigma still at sigma_in, the course in its hold): the clock runs on
      (``t_now``, at most the hold's end); sigma within COURSE_DONE of the goal:
      finished (T_DONE)."""
    sin, goal = np.asarray(sigma_in, np.float64), np.asarray(sigma_goal, np.float64)
    K = np.asarray(K, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.clip((goal - np.asarray(sigma_now, np.float64)) / (goal - sin), 0.0, 1.0)
    dark = goal < sin
    tau = TAU_CONE if receptor == "cone" else TAU_ROD
    lag = 0.0 if receptor == "cone" else TAU_CONE
    a = np.exp(K / tau)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t_dark = lag + K / np.log(a + f * (np.exp(K) - a))
    rho = RHO_CONE if receptor == "cone" else RHO_ROD
    t = np.where(dark, t_dark, rho ** (1.0 - f))
    hold_end = np.where(dark, lag + T_HOLD, T_HOLD)
    held = f >= 1.0 - 1e-5
    t = np.where(held, np.minimum(np.asarray(t_now, np.float64), hold_end), t)
    near = np.abs(goal - np.asarray(sigma_now, np.float64)) <= COURSE_DONE * goal
    return np.where(near, T_DONE, t)


def step_reference(state: dict, I_c, I_r, dt: float, change_log10: float = CHANGE_LOG10,
                   jump_log10: float = JUMP_LOG10, report: dict | None = None) -> dict:
    """Advance every pixel by ``dt`` s and take the new frame's goals (float64).

    1. The previous frame was seen for dt: each receptor's clock t += dt, its
       sigma now = Eqs. 14-15 at that clock; E += I_A_prev dt (Eq. 16, I_A_prev
       recovered from sigma_fin_cone by inverting Eq. 5).
    2. New goals sigma_goal = Eq. 5 of this frame's I_A; sigma_fin follows them.
    3. Sec. 5.2's "new change in illumination", per pixel, both receptors together:
       - a goal ahead of sigma on its course (farther or nearer, on the side it
         is heading to) re-aims it: sigma_in kept, the clock set where the curve to the new goal
         passes the current sigma (:func:`course_clock`), so a drifting goal is
         followed at the curve's pace, never frozen;
       - a goal that turned back, or left a course without direction (adapted),
         by more than ``change_log10`` from its anchor begins a new course:
         sigma_in = sigma now, K = Eq. 17 of the energy since the last one, E = 0,
         clock 0 (the hold of Figure 9) when the goal moved more than
         ``jump_log10`` in this frame, else T_HOLD (past the hold);
       - a goal that turned back less than that is followed on the running course.
    A jump ahead begins a new course (with the hold) only where the cones' course
    is done (:func:`course_done`): a new change after the eye had settled.
    ``report``, when given, gets "new_courses": the share of pixels that began one.
    docs/models.md, ledda04, "Changes", says why (issue 45's rings, frozen pixels).
    """
    s = {k: np.array(v, np.float64) for k, v in state.items()}
    K = s["K"]
    t_c = np.minimum(s["t_cone"] + dt, T_DONE)
    t_r = np.minimum(s["t_rod"] + dt, T_DONE)
    now_c = sigma_at(s["sigma_in_cone"], s["sigma_fin_cone"], t_c, K, "cone")
    now_r = sigma_at(s["sigma_in_rod"], s["sigma_fin_rod"], t_r, K, "rod")
    I_prev = (s["sigma_fin_cone"] / BETA_CONE) ** (1.0 / ALPHA)
    E = np.minimum(s["energy"] + I_prev * dt, E_CEILING)
    gc, gr = sigma_of(I_c, BETA_CONE), sigma_of(I_r, BETA_ROD)
    moved = ((np.abs(np.log10(gc / s["sigma_anchor_cone"])) > change_log10)
             | (np.abs(np.log10(gr / s["sigma_anchor_rod"])) > change_log10))
    jumped = ((np.abs(np.log10(gc / s["sigma_fin_cone"])) > jump_log10)
              | (np.abs(np.log10(gr / s["sigma_fin_rod"])) > jump_log10))
    ahead_c = goal_ahead(s["sigma_in_cone"], s["sigma_fin_cone"], now_c, gc)
    ahead_r = goal_ahead(s["sigma_in_rod"], s["sigma_fin_rod"], now_r, gr)
    new = moved & (~(ahead_c & ahead_r)
                   | (jumped & course_done(s["sigma_in_cone"], s["sigma_fin_cone"], now_c)))
    t0 = np.where(jumped, 0.0, T_HOLD)
    if report is not None:
        report["new_courses"] = float(np.mean(new))
    # a goal that did not move keeps its clock (exactly: the same course)
    t_c = np.where(ahead_c & (gc != s["sigma_fin_cone"]),
                   course_clock(s["sigma_in_cone"], gc, now_c, K, t_c, "cone"), t_c)
    t_r = np.where(ahead_r & (gr != s["sigma_fin_rod"]),
                   course_clock(s["sigma_in_rod"], gr, now_r, K, t_r, "rod"), t_r)
    return {
        "sigma_in_cone": np.where(new, now_c, s["sigma_in_cone"]),
        "sigma_fin_cone": gc,
        "sigma_anchor_cone": np.where(moved, gc, s["sigma_anchor_cone"]),
        "sigma_in_rod": np.where(new, now_r, s["sigma_in_rod"]),
        "sigma_fin_rod": gr,
        "sigma_anchor_rod": np.where(moved, gr, s["sigma_anchor_rod"]),
        "t_cone": np.where(new, t0, t_c),
        "t_rod": np.where(new, t0, t_r),
        "energy": np.where(new, 0.0, E),
        "K": np.where(new, K_of_energy(E), K),
    }


def has_direction(sin: np.ndarray, sfin: np.ndarray) -> np.ndarray:
    """True where the course sin -> sfin moves (dark or light) by more than 1e-5."""
    return np.abs(sfin - sin) > 1e-5 * sin


def goal_ahead(sigma_in, sigma_fin, sigma_now, sigma_goal):
    """True where the course sigma_in -> sigma_fin has a direction (dark or light)
    and the new goal lies beyond the current sigma in it, or within AHEAD_TOL of it
    (where either answer gives the same sigma, the float32 device and this reference
    must not take different branches)."""
    sin, sfin = np.asarray(sigma_in, np.float64), np.asarray(sigma_fin, np.float64)
    now = np.asarray(sigma_now, np.float64)
    d = np.where(has_direction(sin, sfin), np.sign(sfin - sin), 0.0)
    return (d != 0.0) & ((np.asarray(sigma_goal, np.float64) - now) * d > -AHEAD_TOL * now)


def course_done(sigma_in, sigma_fin, sigma_now):
    """True where less than COURSE_RUNNING of the course sigma_in -> sigma_fin is left
    (or it has no direction): a jump then is a new change, with its hold."""
    sin, sfin = np.asarray(sigma_in, np.float64), np.asarray(sigma_fin, np.float64)
    span = sfin - sin
    with np.errstate(divide="ignore", invalid="ignore"):
        left = np.where(has_direction(sin, sfin), (sfin - np.asarray(sigma_now)) / span, 0.0)
    return left <= COURSE_RUNNING


def current_sigmas(state: dict) -> tuple[np.ndarray, np.ndarray]:
    K = state["K"]
    return (sigma_at(state["sigma_in_cone"], state["sigma_fin_cone"], state["t_cone"], K, "cone"),
            sigma_at(state["sigma_in_rod"], state["sigma_fin_rod"], state["t_rod"], K, "rod"))


def map_reference(rgb: np.ndarray, Ys: np.ndarray, I_c: np.ndarray, sigma_c, sigma_r,
                  sigma_disp: float, unit_cd: float, white_signal: float = 1.0,
                  knee: float = 0.0) -> np.ndarray:
    """Eqs. 11-13: display-linear RGB from scene rgb (cd/m^2), Y', the cone
    adaptation luminance (for mes) and the current sigmas; then the highlight
    shoulder when ``knee`` > 0.

    Y_coneO / Y = mes sigma_disp / sigma_cone because (R/(1-R))^(1/n) = Y/sigma
    exactly (Eq. 2); using the quotient form keeps R -> 1 from cancelling.
    """
    mes = mesopic_factor_ledda2004(I_c)
    cone_gain = mes * sigma_disp / np.asarray(sigma_c, np.float64)
    rod_out = (1.0 - mes) * sigma_disp * np.asarray(Ys, np.float64) / np.asarray(sigma_r, np.float64)
    out = (np.asarray(rgb, np.float64) * cone_gain[..., None] + rod_out[..., None]) / unit_cd
    out = apply_shoulder(np.minimum(out, SIGNAL_CEILING), white_signal, knee)
    return np.clip(out, 0.0, DISPLAY_LINEAR_MAX)


def blend_levels(I_local, G: float, strength: float):
    """Each pixel's adaptation level in the default mode: the geometric blend
    I_local^s G^(1-s) of its local (bilateral) level and the frame's global
    log-average G (Reinhard & Devlin 2005's local/global light-adaptation mix, in
    log luminance as the bilateral filter works)."""
    if strength >= 1.0:
        return np.asarray(I_local, np.float64)
    lI = np.log(np.maximum(np.asarray(I_local, np.float64), V_FLOOR))
    return np.exp(strength * lI + (1.0 - strength) * math.log(max(G, V_FLOOR)))


def anchored_sigma(display: DisplaySpec, G_cone: float, G_rod: float) -> float:
    """The default mode's display sigma: the one that shows a uniform field at the
    frame's global levels (G_cone, G_rod) at the scene's key on the display,
    ``display.scene_key(G_cone)`` x white (Eqs. 11-13 solved for sigma_disp), so a
    brighter scene is brighter and a uniform adapted field never exceeds white."""
    Gc, Gr = max(G_cone, V_FLOOR), max(G_rod, V_FLOOR)
    mes = float(mesopic_factor_ledda2004(Gc))
    f = mes * Gc / float(sigma_of(Gc, BETA_CONE)) + (1.0 - mes) * Gr / float(sigma_of(Gr, BETA_ROD))
    return float(scene_key(Gc)) * display.white_cd / f


def adaptation_maps_reference(rgb: np.ndarray, sigma_s: float):
    """Y, Y' and the local adaptation luminances I_A (cones), I_A' (rods)."""
    Y, Ys = luminances(rgb)
    return Y, Ys, bilateral_reference(Y, sigma_s, LEDDA_RANGE), bilateral_reference(Ys, sigma_s, LEDDA_RANGE)


def logmean(x: np.ndarray) -> float:
    return float(np.exp(np.mean(np.log(np.maximum(np.asarray(x, np.float64), V_FLOOR)))))


# --- the observer: one frame on a backend ---------------------------------------------

#: Neutral Y'/Y of Eqs. 6-7 (a grey of Y cd/m^2 has Y' = 0.777 Y).
NEUTRAL_ROD_RATIO = sum(YS_COEFFS) / sum(Y_COEFFS)
#: mes = 1 from here up (Eq. 11): rods saturated, their output weight is 0.
PHOTOPIC_FLOOR = 10.0 ** 0.6
