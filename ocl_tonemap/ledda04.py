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
device pass (state step + mapping), ``kernels/bilateral.cl`` the filter.
Reconstructions are argued in docs/models.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, asdict, field

import numpy as np

from .bilateral import LEDDA_RANGE, V_FLOOR, BilateralSpec, bilateral_reference
from .display import (DISPLAY_LINEAR_MAX, SHOULDER_KNEE, SIGNAL_CEILING, DisplaySpec,
                      apply_shoulder, scene_key)

NAME = "ledda04"
LOCAL = True

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
#: A pixel's adaptation restarts (new sigma_in, sigma_fin) when its goal sigma
#: moves more than this many log10 units from the goal that started the
#: current course (Sec. 5.2, last paragraph; our threshold).
CHANGE_LOG10 = 0.1
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
                  "t_course", "energy", "K")


# --- static model (Sec. 4) -------------------------------------------------------

def luminances(rgb: np.ndarray, ward: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Photopic Y and scotopic Y' of working RGB (cd/m^2), Eqs. 6-7.

    Eq. 7 has a negative red weight; Y' < 0 (every orange and red) is clamped to
    0. ``ward`` (the default mode): Y' of Ward-Larson et al. 1997
    (``photometry.scotopic_luminance``), positive like V'(lambda) (docs/models.md)."""
    rgb = np.asarray(rgb, np.float64)
    Y = rgb @ np.array(Y_COEFFS)
    if ward:
        from .photometry import scotopic_luminance
        return Y, scotopic_luminance(rgb)
    Ys = np.maximum(rgb @ np.array(YS_COEFFS), 0.0)
    return Y, Ys


def neutral_rod_ratio(ward: bool) -> float:
    """Y'/Y of a neutral grey: 0.777 for Eqs. 6-7, 2.57 for Ward's Y' over Eq. 6's Y."""
    if ward:
        from .photometry import neutral_scotopic_ratio
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


def mesopic_factor(I_A):
    """mes = 3 u^2 - 2 u^3, u = clamp((log10 I_A + 2) / 2.6, 0, 1), Eq. 11.

    0 (rods only) at I_A <= 0.01 cd/m^2, 1 (cones only) at I_A >= 10^0.6 ~ 4 cd/m^2
    ("rods are completely saturated ... above around 4 cd/m^2", Sec. 4.3)."""
    u = np.clip((np.log10(np.maximum(np.asarray(I_A, np.float64), V_FLOOR)) + 2.0) / 2.6, 0.0, 1.0)
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


# --- settings --------------------------------------------------------------------

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


# --- per-pixel state ----------------------------------------------------------------

def initial_state(I_c, I_r, E) -> dict:
    """Fully adapted to the given adaptation luminances (course finished)."""
    sc, sr = sigma_of(I_c, BETA_CONE), sigma_of(I_r, BETA_ROD)
    E = np.broadcast_to(np.asarray(E, np.float64), sc.shape)
    return {"sigma_in_cone": sc, "sigma_fin_cone": sc, "sigma_anchor_cone": sc,
            "sigma_in_rod": sr, "sigma_fin_rod": sr, "sigma_anchor_rod": sr,
            "t_course": np.full(sc.shape, T_DONE), "energy": np.array(E, np.float64),
            "K": K_of_energy(E)}


def preadapted_state(L_cd: float, seconds: float | None, shape, ward: bool = False) -> dict:
    """Uniform state after looking at a neutral field of ``L_cd`` cd/m^2 for
    ``seconds`` (None: for long, E at its ceiling). Y' of a neutral field is
    Y * :func:`neutral_rod_ratio`."""
    ratio = neutral_rod_ratio(ward)
    E = E_MAX if seconds is None else L_cd * seconds
    return initial_state(np.full(shape, float(L_cd)), np.full(shape, L_cd * ratio), E)


def step_reference(state: dict, I_c, I_r, dt: float, change_log10: float = CHANGE_LOG10) -> dict:
    """Advance every pixel by ``dt`` s and take the new frame's goals (float64).

    1. The previous frame was seen for dt: t += dt; E += I_A_prev dt (Eq. 16,
       I_A_prev recovered from sigma_fin_cone by inverting Eq. 5).
    2. New goals sigma_goal = Eq. 5 of this frame's I_A. If either receptor's
       goal left its anchor by more than ``change_log10``, the course restarts:
       sigma_in = the current sigma_t, sigma_fin = anchor = goal, t = 0,
       K = Eq. 17 of the energy just accumulated, E = 0. Otherwise sigma_fin
       follows the goal and the course goes on.
    """
    s = {k: np.array(v, np.float64) for k, v in state.items()}
    t_prev = s["t_course"]
    sig_c_now = sigma_at(s["sigma_in_cone"], s["sigma_fin_cone"], t_prev + dt, s["K"], "cone")
    sig_r_now = sigma_at(s["sigma_in_rod"], s["sigma_fin_rod"], t_prev + dt, s["K"], "rod")
    I_prev = (s["sigma_fin_cone"] / BETA_CONE) ** (1.0 / ALPHA)
    E = np.minimum(s["energy"] + I_prev * dt, 1e30)
    t = np.minimum(t_prev + dt, T_DONE)
    gc, gr = sigma_of(I_c, BETA_CONE), sigma_of(I_r, BETA_ROD)
    change = ((np.abs(np.log10(gc / s["sigma_anchor_cone"])) > change_log10)
              | (np.abs(np.log10(gr / s["sigma_anchor_rod"])) > change_log10))
    out = {
        "sigma_in_cone": np.where(change, sig_c_now, s["sigma_in_cone"]),
        "sigma_fin_cone": gc,
        "sigma_anchor_cone": np.where(change, gc, s["sigma_anchor_cone"]),
        "sigma_in_rod": np.where(change, sig_r_now, s["sigma_in_rod"]),
        "sigma_fin_rod": gr,
        "sigma_anchor_rod": np.where(change, gr, s["sigma_anchor_rod"]),
        "t_course": np.where(change, 0.0, t),
        "energy": np.where(change, 0.0, E),
        "K": np.where(change, K_of_energy(E), s["K"]),
    }
    return out


def current_sigmas(state: dict) -> tuple[np.ndarray, np.ndarray]:
    t, K = state["t_course"], state["K"]
    return (sigma_at(state["sigma_in_cone"], state["sigma_fin_cone"], t, K, "cone"),
            sigma_at(state["sigma_in_rod"], state["sigma_fin_rod"], t, K, "rod"))


def map_reference(rgb: np.ndarray, Ys: np.ndarray, I_c: np.ndarray, sigma_c, sigma_r,
                  sigma_disp: float, unit_cd: float, white_signal: float = 1.0,
                  knee: float = 0.0) -> np.ndarray:
    """Eqs. 11-13: display-linear RGB from scene rgb (cd/m^2), Y', the cone
    adaptation luminance (for mes) and the current sigmas; then the highlight
    shoulder when ``knee`` > 0.

    Y_coneO / Y = mes sigma_disp / sigma_cone because (R/(1-R))^(1/n) = Y/sigma
    exactly (Eq. 2); using the quotient form keeps R -> 1 from cancelling.
    """
    mes = mesopic_factor(I_c)
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
    mes = float(mesopic_factor(Gc))
    f = mes * Gc / float(sigma_of(Gc, BETA_CONE)) + (1.0 - mes) * Gr / float(sigma_of(Gr, BETA_ROD))
    return float(scene_key(Gc)) * display.white_cd / f


def adaptation_maps_reference(rgb: np.ndarray, sigma_s: float):
    """Y, Y' and the local adaptation luminances I_A (cones), I_A' (rods)."""
    Y, Ys = luminances(rgb)
    return Y, Ys, bilateral_reference(Y, sigma_s, LEDDA_RANGE), bilateral_reference(Ys, sigma_s, LEDDA_RANGE)


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


def logmean(x: np.ndarray) -> float:
    return float(np.exp(np.mean(np.log(np.maximum(np.asarray(x, np.float64), V_FLOOR)))))


# --- the observer: one frame on a backend ---------------------------------------------

#: Neutral Y'/Y of Eqs. 6-7 (a grey of Y cd/m^2 has Y' = 0.777 Y).
NEUTRAL_ROD_RATIO = sum(YS_COEFFS) / sum(Y_COEFFS)
#: mes = 1 from here up (Eq. 11): rods saturated, their output weight is 0.
PHOTOPIC_FLOOR = 10.0 ** 0.6


class LeddaObserver:
    """Per-pixel adaptation state of one observer and the frame procedure.

    ``rods``: ``"auto"`` skips the rod filter on frames where every pixel is
    photopic (min I_A >= 10^0.6 cd/m^2, mes = 1: the rod output weight is 0)
    and lets the rod state follow the cone adaptation luminance x the
    neutral Y'/Y; ``"always"`` filters Y' every frame. Banded (out-of-memory)
    frames always filter both.
    """

    def __init__(self, settings: LeddaSettings, display: DisplaySpec,
                 preadapt: tuple[float, float | None] | None = None, rods: str = "auto"):
        if rods not in ("auto", "always"):
            raise ValueError(f"rods must be auto or always (got {rods!r})")
        self.settings = settings
        self.display = display
        self.preadapt = preadapt
        self.rods = rods
        self.sigma_disp = display_sigma(display, settings.display_adapt_cd)
        self.ward = settings.mode != "paper"
        self.rod_ratio = neutral_rod_ratio(self.ward)
        self._host: dict | None = None      # authoritative when _dev is None
        self._dev = None                    # (cl.Buffer, (h, w)) authoritative on device
        self._bufs = {}
        self._filters = None
        self.summary: FrameSummary | None = None

    # -- state -----------------------------------------------------------------
    def pixel_state(self) -> dict | None:
        """Per-pixel state as float32 (h, w) arrays (downloads from the device)."""
        if self._dev is not None:
            import pyopencl as cl
            buf, (h, w), rt = self._dev
            a = np.empty((len(STATE_CHANNELS), h, w), np.float32)
            cl.enqueue_copy(rt.queue, a, buf)
            # the device copy stays authoritative (and resident for the next frame);
            # the host copy is a snapshot for checkpoints
            return {k: np.array(a[i]) for i, k in enumerate(STATE_CHANNELS)}
        if self._host is None:
            return None
        return {k: np.array(v, copy=True) for k, v in self._host.items()}

    def _take_host_state(self) -> dict | None:
        """Move the state to the host (it becomes authoritative there)."""
        if self._dev is not None:
            self._host = self.pixel_state()
            self._dev = None
        return self._host

    def set_pixel_state(self, pixels: dict | None) -> None:
        if pixels is not None:
            missing = [k for k in STATE_CHANNELS if k not in pixels]
            if missing:
                raise ValueError(f"per-pixel state lacks {', '.join(missing)}")
            shapes = {np.shape(pixels[k]) for k in STATE_CHANNELS}
            if len(shapes) != 1 or len(next(iter(shapes))) != 2:
                raise ValueError("per-pixel state planes must be 2-D and of one size")
            pixels = {k: np.asarray(pixels[k]) for k in STATE_CHANNELS}
        self._host, self._dev = pixels, None

    def _shape(self):
        if self._dev is not None:
            return self._dev[1]
        if self._host is not None:
            return self._host["t_course"].shape
        return None

    def _start(self, fresh: bool, shape) -> tuple[str, dict | None]:
        """How this frame begins: 'init' (fully adapted to it), or 'step' from a
        state (preadapted for a fresh observer)."""
        if fresh:
            if self.preadapt is not None:
                return "step", preadapted_state(self.preadapt[0], self.preadapt[1], shape,
                                                self.ward)
            return "init", None
        have = self._shape()
        if have is None:
            raise ValueError("this ledda04 state has no per-pixel state (was it saved with "
                             "its .pixels.exr side file?)")
        if tuple(have) != tuple(shape):
            raise ValueError(f"per-pixel adaptation state is {have[1]}x{have[0]} but the frame "
                             f"is {shape[1]}x{shape[0]}; local adaptation needs one image size")
        return "step", None

    # -- reference ---------------------------------------------------------------
    def frame_mapping(self, G_cone: float, G_rod: float) -> tuple[float, float, float]:
        """(display sigma, white signal, shoulder knee) of one frame."""
        white = self.display.white_cd / self.display.unit_cd
        if self.settings.mode == "paper":
            return self.sigma_disp, white, 0.0
        return anchored_sigma(self.display, G_cone, G_rod), white, SHOULDER_KNEE

    def process_reference(self, pixels: np.ndarray, scale: float, dt: float, fresh: bool):
        from .metering import MeteringSpec, reference_goal
        from .photometry import sanitize
        h, w = pixels.shape[:2]
        rgb, repairs = sanitize(pixels[..., :3], scale)
        Y, Ys = luminances(rgb, self.ward)
        G_rod, G_cone = reference_goal(np.maximum(Y, V_FLOOR), np.maximum(Ys, V_FLOOR),
                                       MeteringSpec.parse("logmean"))
        sig = self.settings.sigma_px(w, h)
        st_ = self.settings.strength
        I_c = blend_levels(bilateral_reference(Y, sig, LEDDA_RANGE), G_cone, st_)
        rods = self.rods == "always" or I_c.min() < PHOTOPIC_FLOOR
        I_r = blend_levels(bilateral_reference(Ys, sig, LEDDA_RANGE), G_rod, st_) if rods else \
            np.maximum(I_c * self.rod_ratio, V_FLOOR)
        mode, pre = self._start(fresh, (h, w))
        if mode == "init":
            st = initial_state(I_c, I_r, E_MAX)
            restarted = 0.0
        else:
            prev = pre if pre is not None else self._take_host_state()
            st = step_reference(prev, I_c, I_r, dt, self.settings.change_log10)
            restarted = float(np.mean(st["t_course"] == 0.0))
        self._host, self._dev = st, None
        s_c, s_r = current_sigmas(st)
        sd, white, knee = self.frame_mapping(G_cone, G_rod)
        out = map_reference(rgb, Ys, I_c, s_c, s_r, sd, self.display.unit_cd, white, knee)
        self.summary = FrameSummary(sig, "exact (float64)", sd, bool(rods),
                                    self.settings.mode, st_, G_cone, G_rod, restarted,
                                    logmean(I_c), logmean(I_r))
        return out.astype(np.float32), repairs, (logmean(I_r), logmean(I_c))

    # -- OpenCL -------------------------------------------------------------------
    def _buf(self, rt, name: str, nbytes: int):
        import pyopencl as cl
        b = self._bufs.get(name)
        if b is None or b.size < nbytes:
            b = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE, max(nbytes, 4))
            self._bufs[name] = b
        return b

    def process_opencl(self, backend, pixels: np.ndarray, scale: float, dt: float, fresh: bool):
        import pyopencl as cl
        from .bilateral import DeviceBilateral, spatial_radius
        from .metering import MeteringSpec
        from .photometry import RepairCounts
        from .runtime import round_up
        rt = backend.rt
        q = rt.queue
        h, w = pixels.shape[:2]
        sig = self.settings.sigma_px(w, h)
        if self._filters is None:
            self._filters = (DeviceBilateral(rt), DeviceBilateral(rt))
        fc, fr = self._filters
        method = fc.choose(self.settings.bilateral, sig, w, h)
        bs = self.settings.bilateral
        mode, pre = self._start(fresh, (h, w))
        if pre is not None:
            self.set_pixel_state(pre)
        halo = spatial_radius(sig) if method == "exact" else 0
        rows = max(1, min(h, backend.max_band_pixels // max(w, 1) - 2 * halo))
        banded = rows < h
        bands = [(y0, min(rows, h - y0)) for y0 in range(0, h, rows)]
        lum_k = rt.kernel("ledda04.cl", "ledda04_luminance")
        map_k = rt.kernel("ledda04.cl", "ledda04_step_map")
        counts = self._buf(rt, "counts", 4)
        cl.enqueue_fill_buffer(q, counts, np.int32(0), 0, 4)
        logmean_spec = MeteringSpec.parse("logmean")
        f32, i32 = np.float32, np.int32

        def colour_and_lum(a: int, b: int, own: tuple[int, int] | None):
            """Rows [a, b) to working space; returns (repairs, n, Yl, Ysl buffers)."""
            rc = backend._to_working(pixels[a:b], scale, count=own is not None, count_rows=own)
            n = (b - a) * w
            yl = self._buf(rt, "Yl", n * 4)
            ysl = self._buf(rt, "Ysl", n * 4)
            lum_k(q, (round_up(n, 64),), (64,), backend._bufs["rgb"], i32(n), yl, ysl,
                  i32(self.ward))
            return rc, n, yl, ysl

        # the frame's global log-averages (default mode's blend and anchor): one
        # band is coloured once and stays resident; banded frames take a pass
        resident = colour_and_lum(0, h, (0, h)) if not banded else None
        gsums = None
        for y0, nr in ([(0, h)] if not banded else bands):
            _, n, yl, ysl = resident if resident is not None else \
                colour_and_lum(y0, y0 + nr, None)
            gs = backend.meter.band_sums(yl, ysl, n, w, h, y0, logmean_spec)
            if gsums is None:
                gsums = gs
            else:
                gsums.add(gs)
        G_rod_g, G_cone_g = gsums.goal(logmean_spec)
        strength = self.settings.strength
        sd, white, knee = self.frame_mapping(G_cone_g, G_rod_g)
        geoms = None
        if method == "fast":
            zr = [[np.inf, -np.inf], [np.inf, -np.inf]]
            for y0, nr in bands:                    # pass A: z ranges of Y and Y'
                if banded:
                    _, n, yl, ysl = colour_and_lum(y0, y0 + nr, None)
                else:
                    _, n, yl, ysl = resident
                for k, (flt, buf) in enumerate(((fc, yl), (fr, ysl))):
                    lo, hi = flt.z_range(buf, n, LEDDA_RANGE)
                    zr[k] = [min(zr[k][0], lo), max(zr[k][1], hi)]
            geoms = [flt.fit_geometry(w, h, zr[k][0], zr[k][1], sig, LEDDA_RANGE, bs.q_s, bs.q_r)
                     for k, flt in enumerate((fc, fr))]
            for flt, g in zip((fc, fr), geoms):
                flt.begin_grid(g)
            for y0, nr in bands:                    # pass B: splat
                if banded:
                    _, n, yl, ysl = colour_and_lum(y0, y0 + nr, None)
                fc.splat(yl, w, nr, y0, geoms[0], LEDDA_RANGE)
                fr.splat(ysl, w, nr, y0, geoms[1], LEDDA_RANGE)
            fc.blur(geoms[0], LEDDA_RANGE)
            fr.blur(geoms[1], LEDDA_RANGE)

        repairs = RepairCounts()
        sums = None
        out = np.empty((h, w, 3), np.float32)
        rods_used = True
        if banded and self._dev is not None:
            self._take_host_state()                  # banded frames keep state on the host
        if banded and mode == "init":
            self._host = {k: np.empty((h, w), np.float32) for k in STATE_CHANNELS}
        nstate = len(STATE_CHANNELS)
        for y0, nr in bands:                        # pass C: filter/slice, step, map
            a, b = max(0, y0 - halo), min(h, y0 + nr + halo)
            if resident is not None:
                rc, _, yl, ysl = resident
                resident = (RepairCounts(), *resident[1:])     # count the repairs once
            else:
                rc, _, yl, ysl = colour_and_lum(a, b, (y0 - a, y0 - a + nr))
            repairs += rc
            n = nr * w
            ic = self._buf(rt, "Ic", n * 4)
            ir = self._buf(rt, "Ir", n * 4)
            if method == "exact":
                fc.exact(yl, ic, w, b - a, a, y0, nr, sig, LEDDA_RANGE)
            else:
                fc.slice(yl, ic, w, nr, y0, y0, nr, geoms[0], LEDDA_RANGE)
            rods_needed = banded or self.rods == "always" or \
                math.exp(fc.z_range(ic, n, LEDDA_RANGE)[0]) < PHOTOPIC_FLOOR
            if rods_needed:
                if method == "exact":
                    fr.exact(ysl, ir, w, b - a, a, y0, nr, sig, LEDDA_RANGE)
                else:
                    fr.slice(ysl, ir, w, nr, y0, y0, nr, geoms[1], LEDDA_RANGE)
            rods_used = rods_used and rods_needed
            if banded:
                st = self._buf(rt, "state_band", nstate * n * 4)
                if mode != "init":
                    planes = np.stack([self._host[k][y0:y0 + nr] for k in STATE_CHANNELS])
                    cl.enqueue_copy(q, st, np.ascontiguousarray(planes, np.float32))
            elif self._dev is not None:
                st = self._dev[0]                    # resident from the last frame
            else:
                st = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE, nstate * n * 4)
                if mode != "init":
                    planes = np.stack([self._host[k] for k in STATE_CHANNELS])
                    cl.enqueue_copy(q, st, np.ascontiguousarray(planes, np.float32))
            map_k(q, (round_up(n, 64),), (64,), backend._bufs["rgb"], i32((y0 - a) * w), ic, ir,
                  i32(0 if rods_needed else 1), f32(self.rod_ratio), st, i32(n), i32(n),
                  f32(dt), i32(1 if mode == "init" else 0), f32(E_MAX),
                  f32(self.settings.change_log10 * math.log2(10.0)), f32(sd),
                  f32(1.0 / self.display.unit_cd), backend._bufs["out"], counts,
                  f32(strength), f32(math.log(max(G_cone_g, V_FLOOR))),
                  f32(math.log(max(G_rod_g, V_FLOOR))), f32(1.0 / white), f32(knee),
                  i32(self.ward))
            cl.enqueue_copy(q, out[y0:y0 + nr], backend._bufs["out"])
            s = backend.meter.band_sums(ic, ir if rods_needed else ic, n, w, h, y0, logmean_spec)
            if sums is None:
                sums = s
            else:
                sums.add(s)
            if banded:
                planes = np.empty((nstate, nr, w), np.float32)
                cl.enqueue_copy(q, planes, st)
                for i, k in enumerate(STATE_CHANNELS):
                    self._host[k][y0:y0 + nr] = planes[i]
            else:
                self._dev, self._host = (st, (h, w), rt), None
        G_rod, G_cone = sums.goal(logmean_spec)
        if not rods_used:
            G_rod = max(G_cone * self.rod_ratio, V_FLOOR)
        nres = np.empty(1, np.int32)
        cl.enqueue_copy(q, nres, counts)
        grid = ""
        if method == "fast":
            g = geoms[0]
            grid = f" (q_s={sig / g.s_s:.3g}, q_r={LEDDA_RANGE.z_width() / g.s_r:.3g})"
        self.summary = FrameSummary(sig, method + grid, sd, bool(rods_used),
                                    self.settings.mode, strength, G_cone_g, G_rod_g,
                                    float(nres[0]) / (h * w) if mode != "init" else 0.0,
                                    G_cone, G_rod)
        return out, repairs, (G_rod, G_cone)


def make_observer(options: dict | None, display: DisplaySpec,
                  preadapt: tuple[float, float | None] | None) -> LeddaObserver:
    """Observer from operator options: sigma_spatial (px), bilateral (exact|fast|auto),
    bilateral_sampling ("Q" or "QS,QR"), display_adapt_cd, change_log10, rods, mode
    (default|paper), local_strength (0..1)."""
    o = {k: v for k, v in (options or {}).items() if v is not None}
    spec = BilateralSpec.parse(o.pop("bilateral", "auto") or "auto", o.pop("bilateral_sampling", None))
    settings = LeddaSettings(o.pop("sigma_spatial", None), spec, o.pop("display_adapt_cd", None),
                             o.pop("change_log10", CHANGE_LOG10), o.pop("mode", "default"),
                             o.pop("local_strength", None))
    rods = o.pop("rods", "auto")
    if o:
        raise ValueError(f"unknown ledda04 option(s): {', '.join(sorted(o))}")
    return LeddaObserver(settings, display, preadapt, rods)
