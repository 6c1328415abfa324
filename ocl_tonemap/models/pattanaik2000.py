"""Pattanaik, Tumblin, Yee & Greenberg 2000: time-dependent global adaptation.

>>> round(float(sigma_cone(25.0)), 1)      # Eq. 5 at the CRT's A = 25 (Sec. 4.3: 646)
646.1
>>> s = receptor_levels_steady(1.0, 1.0)   # Eq. 6 at 1 cd/m^2
>>> round(s["B_rod"], 4), round(s["B_cone"], 6)
(0.0385, 1.0)

"Time-Dependent Visual Adaptation for Fast Realistic Image Display",
SIGGRAPH 2000. Equation numbers below are the paper's. Units: cd/m^2 for
luminances (photopic for cones, scotopic for rods), seconds for time.

The float64 functions here are the reference; ``kernels/pattanaik00.cl`` is
the fused per-pixel device pass (Eqs. 2, 3, 8 and the inverse of Sec. 4.3), run
by ``operators/pattanaik00.py``. The receptor time course (Sec. 4.1.2) is shared:
kirk11 and the Purkinje effect take their adaptation from it.
Reconstructions of the garbled text are in docs/models.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, asdict

import numpy as np

from .display import (DISPLAY_LINEAR_MAX, SHOULDER_KNEE, SIGNAL_CEILING, DisplaySpec,
                      apply_shoulder)
from .integrators import bleaching_step, exponential_step
from .photometry import neutral_scotopic_ratio

#: Eq. 2 exponent (Hunt's n, Sec. 4.1.1).
N = 0.73
#: Floor on luminance inside the response (cd/m^2): far below the absolute
#: threshold of vision (~1e-6) and far above float32 denormals.
L_FLOOR = 1.0e-10
#: Floor on adaptation luminance where Eqs. 4-5 are 0/0 at A = 0.
A_FLOOR = 1.0e-10
#: Floor on colour ratios before the Eq. 3 power (log of 0 is -inf).
RATIO_FLOOR = 1.0e-12
LN10 = math.log(10.0)
#: The display's response is kept below B_rod + B_cone by this fraction before its
#: inverse (DisplayObserver.luminance), which diverges there.
RESPONSE_MARGIN = 1.0e-6


# --- The receptor time course, Sec. 4.1.2 (shared by kirk11 and the Purkinje effect) ---
#
# Four signals per observer: neural adaptation levels A (cd/m^2, fast, symmetric)
# and pigment bleaching B (0..1, slow, asymmetric: bleaching in light, regeneration
# over minutes in the dark) for rods and cones. pattanaik00 uses them directly;
# kirk11 and the Purkinje effect take their adaptation level from A and the rods'
# dark adaptation from B (:func:`rod_sensitivity`).

#: Neural time constants t0, s.
T0_ROD, T0_CONE = 0.150, 0.080
#: Pigment regeneration time constants tau, s.
TAU_ROD, TAU_CONE = 400.0, 110.0
#: Bleaching half-rate constants of Eq. 7 (J = T*B*G/k), cd/m^2.
K_ROD, K_CONE = 16.0, 2.2e8


def bleach_static(G, k_half: float, tau: float):
    """Hunt's static bleaching factor (Pattanaik Eq. 6), k/(k + tau G): 0.04/(0.04 + A)
    for rods, 2e6/(2e6 + A) for cones; the steady state of Eq. 7."""
    G = np.maximum(np.asarray(G, np.float64), 0.0)
    return (k_half / tau) / (k_half / tau + G)


def receptor_levels_steady(G_rod: float, G_cone: float) -> dict:
    """Fully adapted to the goals: A = G, B = Eq. 6."""
    return {"A_rod": float(G_rod), "A_cone": float(G_cone),
            "B_rod": float(bleach_static(G_rod, K_ROD, TAU_ROD)),
            "B_cone": float(bleach_static(G_cone, K_CONE, TAU_CONE))}


def receptor_levels_advance(values: dict, G_rod: float, G_cone: float, dt: float) -> dict:
    """Advance A (exact exponential filters, t0 150/80 ms) and B (Eq. 7's kinetics,
    solved exactly) by ``dt`` seconds toward the goals."""
    return {
        "A_rod": exponential_step(values["A_rod"], G_rod, dt, T0_ROD),
        "A_cone": exponential_step(values["A_cone"], G_cone, dt, T0_CONE),
        "B_rod": bleaching_step(values["B_rod"], G_rod, dt, K_ROD, TAU_ROD),
        "B_cone": bleaching_step(values["B_cone"], G_cone, dt, K_CONE, TAU_CONE),
    }


def receptor_levels_neural(values: dict, G_rod: float, G_cone: float, dt: float) -> dict:
    """The default mode's step: A as :func:`receptor_levels_advance`, B Hunt's static
    factor (Eq. 6) at the new A. The slow course is the shared pigment model's
    (``models/bleaching.py``), which reaches A through the goals as an equivalent
    background: Eq. 7's own kinetics would count the pigment twice."""
    A_rod = exponential_step(values["A_rod"], G_rod, dt, T0_ROD)
    A_cone = exponential_step(values["A_cone"], G_cone, dt, T0_CONE)
    return {"A_rod": A_rod, "A_cone": A_cone,
            "B_rod": float(bleach_static(A_rod, K_ROD, TAU_ROD)),
            "B_cone": float(bleach_static(A_cone, K_CONE, TAU_CONE))}


def receptor_levels_preadapted(L_rod: float, L_cone: float, seconds: float | None) -> dict:
    """After a neutral field (rods see ``L_rod``, cones ``L_cone``): fully adapted
    to it, or from full dark adaptation exposed to it for ``seconds``."""
    if seconds is None:
        return receptor_levels_steady(L_rod, L_cone)
    dark = {"A_rod": A_FLOOR, "A_cone": A_FLOOR, "B_rod": 1.0, "B_cone": 1.0}
    return receptor_levels_advance(dark, L_rod, L_cone, seconds)


#: The response increment of a flash at threshold on a black field (Eq. 2's R): where
#: the dark-adapted observer's threshold is Hecht et al. 1937's absolute threshold
#: (``benchmarks/lib/human/dark.criterion``); the shape of the threshold curve that the
#: pigment course's equivalent background is read on (``Operator.equivalent_goal``).
DETECT_CRITERION = 0.103


def flash_threshold(A: float, receptor: str, c: float = DETECT_CRITERION) -> float:
    """The flash (cd/m^2; scotopic for rods) whose response B sat(x, sigma(A)) reaches
    ``c`` on a black field, for a receptor adapted to ``A`` (B static, Eq. 6); inf
    where B < c (too bleached to see it)."""
    if receptor == "rod":
        sigma, B = float(sigma_rod(A)), float(bleach_static(A, K_ROD, TAU_ROD))
    else:
        sigma, B = float(sigma_cone(A)), float(bleach_static(A, K_CONE, TAU_CONE))
    q = c / B if B > 0.0 else math.inf
    if q >= 1.0:
        return math.inf
    return sigma * (q / (1.0 - q)) ** (1.0 / N)


def rod_sensitivity(values: dict) -> float:
    """How far the rods' dark adaptation has come: B_rod over its steady value at the
    current level A_rod, in [0, 1]. 1 when adapted; right after a bright field
    (rhodopsin bleached) near 0, recovering over minutes (tau 400 s)."""
    b_inf = float(bleach_static(values["A_rod"], K_ROD, TAU_ROD))
    return float(min(1.0, max(0.0, values["B_rod"] / b_inf))) if b_inf > 0 else 0.0



# --- Static response model (Sec. 4.1.1) ---------------------------------------

#: Eq. 4's numerator: Hunt's 2^(1/n) x (reference white = 5 A) = 12.9223, as in
#: Eq. 5; the printed 2.5874 drops the 5 (docs/models.md, reconstruction 6).
SIGMA_ROD_HUNT, SIGMA_ROD_PRINTED = 12.9223, 2.5874
#: Amplitude of the rod response in the default mode: Hunt's rod bleaching factor
#: B_S = 0.5/(1 + 0.3 (5 L_AS/2.26 S/S_W)^0.3) + 0.5/(1 + 5 (5 L_AS/2.26)); Eq. 6
#: keeps only the adaptation term, 0.04/(0.04 + A), at amplitude 1 where Hunt's is
#: 0.5 (docs/models.md, reconstruction 7). The paper mode uses 1.
ROD_AMPLITUDE = 0.5
#: ``mode``: "default" (Hunt's rod sigma and amplitude, highlight shoulder) or
#: "paper" (Eqs. 4 and 6 as printed, hard clip at display white).
MODES = ("default", "paper")


def sigma_rod(A_rod, printed: bool = False):
    """Half-saturation of rods, Eq. 4 (cd/m^2 scotopic). j = 1/(5e5*A + 1).

    Default: Hunt's rod sigma, 12.9223 A / (...), which gives the paper's own
    display value sigma_rod(25) = 722 (Sec. 4.3); ``printed``: Eq. 4's
    numerator as printed, 2.5874 A (144.7 at 25)."""
    A = np.maximum(np.asarray(A_rod, np.float64), A_FLOOR)
    j2 = (1.0 / (5.0e5 * A + 1.0)) ** 2
    c = SIGMA_ROD_PRINTED if printed else SIGMA_ROD_HUNT
    return c * A / (19000.0 * j2 * A + 0.2615 * (1.0 - j2) ** 4 * A ** (1.0 / 6.0))


def sigma_cone(A_cone):
    """Half-saturation of cones, Eq. 5 (cd/m^2). k = 1/(5*A + 1)."""
    A = np.maximum(np.asarray(A_cone, np.float64), A_FLOOR)
    k4 = (1.0 / (5.0 * A + 1.0)) ** 4
    return 12.9223 * A / (k4 * A + 0.171 * (1.0 - k4) ** 2 * A ** (1.0 / 3.0))


def bleach_rod_static(G_rod):
    """Hunt's static rod bleaching factor, Eq. 6: 0.04/(0.04 + A)."""
    return 0.04 / (0.04 + np.maximum(np.asarray(G_rod, np.float64), 0.0))


def bleach_cone_static(G_cone):
    """Hunt's static cone bleaching factor, Eq. 6: 2e6/(2e6 + A)."""
    return 2.0e6 / (2.0e6 + np.maximum(np.asarray(G_cone, np.float64), 0.0))


def saturation(L, sigma):
    """L^n / (L^n + sigma^n) of Eq. 2, written as 1/(1 + (sigma/L)^n) (no overflow)."""
    L = np.maximum(np.asarray(L, np.float64), L_FLOOR)
    return 1.0 / (1.0 + (np.asarray(sigma, np.float64) / L) ** N)


def response(L, sigma, bleach):
    """Receptor response R = B * L^n/(L^n + sigma^n), Eq. 2."""
    return bleach * saturation(L, sigma)


def colour_slope(L_cone, sigma_c, bleach_c):
    """S_color = dR_cone / dlog10(L_cone), Eq. 3 (log10 reconstruction, see docs/models.md).

    d/dln L of Eq. 2 is n*B*x*(1 - x) with x = L^n/(L^n + sigma^n) (the printed
    right-hand side); per log10 unit it is ln(10) times that. Base 10 is the
    one that reproduces the paper's display S_d = 0.1383.
    """
    x = saturation(L_cone, sigma_c)
    return LN10 * N * bleach_c * x * (1.0 - x)



def response_slope(L_b, values: dict, rod_amplitude: float = ROD_AMPLITUDE):
    """dR/dln L of Eq. 2, cones and rods together, for a small neutral increment on a
    background of L_b cd/m^2 seen under the receptor levels ``values`` (A, B): the
    observer's own gain for a visibility threshold (``adrian1989.transient_factor``):
    n (B_cone x_c (1 - x_c) + B_rod x_r (1 - x_r)), x = L^n/(L^n + sigma^n)."""
    L = np.asarray(L_b, np.float64)
    xc = saturation(L, sigma_cone(values["A_cone"]))
    xr = saturation(L * neutral_scotopic_ratio(), sigma_rod(values["A_rod"]))
    return N * (values["B_cone"] * xc * (1.0 - xc)
                + rod_amplitude * values["B_rod"] * xr * (1.0 - xr))


def steady_slope(L_b):
    """:func:`response_slope` of observers fully adapted to each neutral L_b (any shape)."""
    L = np.maximum(np.asarray(L_b, np.float64), 0.0)
    Lr = L * neutral_scotopic_ratio()
    return response_slope(L, {"A_rod": Lr, "A_cone": L,
                              "B_rod": bleach_static(Lr, K_ROD, TAU_ROD),
                              "B_cone": bleach_static(L, K_CONE, TAU_CONE)})


def adaptation_luminance(values: dict) -> float:
    """The cone adaptation level A_cone of the receptor levels, cd/m^2."""
    return float(values["A_cone"])

# --- Display observer (Sec. 4.3) ------------------------------------------------

@dataclass(frozen=True)
class DisplayObserver:
    """Steady-state constants of the display observer (Sec. 4.3)."""

    sigma_rod: float
    sigma_cone: float
    B_rod: float
    B_cone: float
    ref_white: float   # response, Eq. 8 form at display white
    ref_black: float   # response at display black
    S_d: float         # response slope per log10 between black and white
    unit_cd: float
    signal_offset: float = 0.0   # cd/m^2 of display black taken out (DisplaySpec.to_signal)
    signal_gain: float = 0.0     # display-linear per cd/m^2 after that (0: 1/unit_cd)

    @classmethod
    def from_spec(cls, d: DisplaySpec, rod_amplitude: float = 1.0) -> "DisplayObserver":
        if d.paper_crt:
            # Printed constants, verbatim (sigma_rod = 722 is Hunt's form of
            # Eq. 4 at A = 25; the printed Eq. 4 gives 144.7; docs/models.md).
            sr, sc, br, bc = 722.0, 646.0, 0.0016, 1.0
        else:
            A = d.adapt_cd
            sr, sc = float(sigma_rod(A)), float(sigma_cone(A))
            br, bc = float(bleach_rod_static(A)) * rod_amplitude, float(bleach_cone_static(A))
        w = float(response(d.white_cd, sr, br) + response(d.white_cd, sc, bc))
        k = float(response(d.black_cd, sr, br) + response(d.black_cd, sc, bc))
        # Forward difference of Eq. 2 between display REF_blk and REF_whit.
        s_d = (w - k) / math.log10(d.white_cd / d.black_cd)
        return cls(sr, sc, br, bc, w, k, s_d, d.unit_cd, d.signal_offset, d.signal_gain)

    @property
    def gain(self) -> float:
        return self.signal_gain or 1.0 / self.unit_cd

    def luminance(self, R):
        """Inverse of R = B_r x/(x + s_r) + B_c x/(x + s_c), x = L^n (display sees L
        with both receptors): the quadratic
            (B_r + B_c - R) x^2 + (B_r s_c + B_c s_r - R (s_r + s_c)) x - R s_r s_c = 0
        has one non-negative root; solved in the cancellation-free form."""
        sr, sc = self.sigma_rod ** N, self.sigma_cone ** N
        rmax = self.B_rod + self.B_cone
        R = np.clip(np.asarray(R, np.float64), 0.0, rmax * (1.0 - RESPONSE_MARGIN))
        a = rmax - R
        b = self.B_rod * sc + self.B_cone * sr - R * (sr + sc)
        c = R * sr * sc
        disc = np.sqrt(b * b + 4.0 * a * c)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(b > 0, 2.0 * c / (b + disc), (disc - b) / (2.0 * a))
        return np.maximum(x, 0.0) ** (1.0 / N)


# --- Appearance model and its inverse (Secs. 4.2, 4.3) -----------------------

def reference_responses(v: dict, printed: bool = False, rod_amplitude: float = 1.0):
    """Scene REF_whit and REF_blk, Eq. 8: responses at 5*A and 5/32*A."""
    sr, sc = sigma_rod(v["A_rod"], printed), sigma_cone(v["A_cone"])
    br = v["B_rod"] * rod_amplitude
    white = (response(5.0 * v["A_rod"], sr, br)
             + response(5.0 * v["A_cone"], sc, v["B_cone"]))
    black = (response(5.0 / 32.0 * v["A_rod"], sr, br)
             + response(5.0 / 32.0 * v["A_cone"], sc, v["B_cone"]))
    return float(white), float(black)


#: Default mode: a scene white response above the display's maps to the display
#: white response times (scene white / display white)^STEVENS (docs/models.md).
STEVENS = 0.25


def appearance_map(scene_white, scene_black, disp: DisplayObserver, stevens: float = 0.0):
    """Inverse appearance model, Sec. 4.3 rules 1-4, as R_display = gain*R_lum + offset.

    Q_lum = R_lum - REF_blk (Sec. 4.2); Q_span = white - black, Q_mid = mean.
    ``stevens`` > 0 (the default mode): a scene whose white response exceeds the
    display's keeps part of the excess, its white mapped to the display white
    response times (scene white / display white)^stevens (below the display's
    saturation), so brighter scenes stay brighter (the Stevens effect the
    response model carries); the highlight shoulder then rolls it off.
    Returns (gain, offset, rule).
    """
    dw, dk = disp.ref_white, disp.ref_black
    if stevens > 0.0 and scene_white > dw:
        rmax = disp.B_rod + disp.B_cone
        dw = min(dw * (scene_white / dw) ** stevens, dw + 0.5 * (rmax - dw))
    span_s, span_d = scene_white - scene_black, dw - dk
    if scene_black >= dk and scene_white <= dw:          # rule 1: reproduce directly
        return 1.0, 0.0, 1
    if span_s > span_d:                                   # rule 2: compress and offset
        g = span_d / span_s
        return g, dk - g * scene_black, 2
    if 0.5 * (scene_white + scene_black) > 0.5 * (dw + dk):  # rule 3: offset down
        return 1.0, dw - scene_white, 3
    return 1.0, dk - scene_black, 4                        # rule 4: offset up


def display_response(R_lum, gain: float, offset: float, toe: float = 0.0):
    """R_display of scene responses ``R_lum``: Sec. 4.3's gain R_lum + offset, and in
    the default mode (``toe`` R_0 > 0: the scene response that line puts at the
    display's black) a toe below 2 R_0, display black + gain R_lum^2 / (4 R_0): C1 at
    2 R_0, R_lum = 0 at the display's black, above the line everywhere below it. The
    paper clips what the line puts below the display's black: an observer adapted to
    the scene sees detail there (docs/models.md, "Shadows").

    >>> display_response(np.array([0.0, 0.02, 0.04, 0.1]), 1.0, -0.02, 0.02).round(4).tolist()
    [0.0, 0.005, 0.02, 0.08]
    """
    R = np.asarray(R_lum, np.float64)
    line = gain * R + offset
    if not toe > 0.0:
        return line
    return np.where(R < 2.0 * toe, (gain * toe + offset) + gain * R * R / (4.0 * toe), line)


def toe_response(gain: float, offset: float, display_black: float) -> float:
    """R_0 of :func:`display_response`: the scene response ``gain R + offset`` puts at
    the display's black response (0: the line never goes below it)."""
    return max((display_black - offset) / gain, 0.0) if gain > 0.0 else 0.0


# --- Colour in the default mode -----------------------------------------------------



def luminance_level_adaptation_factor(L_A):
    """F_L of CIECAM02 / Hunt (CIE 159:2004): 0.2 k^4 (5 L_A) + 0.1 (1 - k^4)^2
    (5 L_A)^(1/3), k = 1/(5 L_A + 1); L_A in cd/m^2. (Eq. 5 is 12.9223 A / F_L.)"""
    L = np.maximum(np.asarray(L_A, np.float64), A_FLOOR)
    k4 = (1.0 / (5.0 * L + 1.0)) ** 4
    return 0.2 * k4 * 5.0 * L + 0.1 * (1.0 - k4) ** 2 * np.cbrt(5.0 * L)


#: The adaptation level above which the default colour's Hunt effect no longer grows,
#: cd/m^2 (issue 67): 1.4x the chroma of a 20 cd/m^2 display observer, the effect's
#: size between interior and bright daylight. Past it the factor kept growing (1.6x at
#: 5000 cd/m^2) and daylight photographs' coloured mid-tones came out at up to 1.7x
#: the scene's saturation: a display cannot show that colourfulness without driving
#: foliage and sky to its gamut's edge (docs/models.md).
HUNT_CAP_CD = 1000.0


def chroma_scale(A_cone, A_display):
    """Default mode's colour: chroma of the scene relative to the display observer's,
    (F_L(A_cone) / F_L(A_display))^(1/4), CIECAM02's colourfulness M = C F_L^(1/4)
    (the Hunt effect: colours look more colourful in brighter light, and fade as
    cones lose their response at night), applied as a hue-preserving scale of
    the colour ratios about neutral; A_cone taken at most :data:`HUNT_CAP_CD`. 1 when
    scene and display adaptation match."""
    A = np.minimum(np.asarray(A_cone, np.float64), HUNT_CAP_CD)
    return (luminance_level_adaptation_factor(A)
            / luminance_level_adaptation_factor(A_display)) ** 0.25


# --- Per-frame scalars for the per-pixel pass ---------------------------------------

@dataclass(frozen=True)
class FrameParams:
    """Everything the per-pixel pass needs for one frame (all scalars)."""

    sigma_rod: float
    sigma_cone: float
    B_rod: float
    B_cone: float
    gain: float
    offset: float
    rule: int
    display: DisplayObserver
    mode: str = "default"
    shoulder_knee: float = SHOULDER_KNEE   # 0: hard clip at display white (paper)
    white_signal: float = 1.0              # display-linear value of display white
    chroma: float | None = None            # default mode's chroma scale; None: Eq. 3
    raw: bool = False                      # the smooth part alone (see map_reference)
    toe: float = 0.0                       # default mode's shadow toe R_0; 0: the paper's clip

    def as_dict(self) -> dict:
        d = asdict(self)
        d["display"] = asdict(self.display)
        return d


def frame_params(state, display: DisplaySpec,
                 mode: str = "default") -> FrameParams:
    """Per-frame scalars. ``mode="paper"``: Eq. 4 as printed and a hard clip at
    display white; default: Hunt's rod sigma and the highlight shoulder."""
    if mode not in MODES:
        raise ValueError(f"pattanaik00 mode must be one of {', '.join(MODES)} (got {mode!r})")
    printed = mode == "paper"
    amp = 1.0 if printed else ROD_AMPLITUDE
    v = state.values
    disp = DisplayObserver.from_spec(display, amp)
    w, k = reference_responses(v, printed, amp)
    gain, offset, rule = appearance_map(w, k, disp, 0.0 if printed else STEVENS)
    return FrameParams(float(sigma_rod(v["A_rod"], printed)), float(sigma_cone(v["A_cone"])),
                       v["B_rod"] * amp, v["B_cone"], gain, offset, rule, disp, mode,
                       0.0 if printed else SHOULDER_KNEE,
                       float(display.to_signal(display.white_cd)),
                       None if printed else float(chroma_scale(v["A_cone"], display.adapt_cd)),
                       toe=0.0 if printed else toe_response(gain, offset, disp.ref_black))


def map_reference(rgb: np.ndarray, Y: np.ndarray, Ys: np.ndarray, p: FrameParams) -> np.ndarray:
    """Float64 reference of the per-pixel pass: scene cd/m^2 -> display-linear.

    rgb: (..., 3) working-space cd/m^2 (already sanitised); Y, Ys: photopic and
    scotopic luminance. Returns (..., 3) display-linear (1.0 = display unit).
    ``p.raw``: the smooth function whose positive part this is, before the
    highlight shoulder and the clip (what an OCIO export samples on a lattice, then
    clamps at 0: ``colour/export.py``): no floor on the display signal or the
    colour ratios, and where the signal is below display black the product is kept
    negative, so that max(raw, 0) is exactly the clamped output.
    """
    xc = saturation(Y, p.sigma_cone)
    R_lum = p.B_rod * saturation(Ys, p.sigma_rod) + p.B_cone * xc      # Eq. 2, R_rod + R_cone
    s_color = LN10 * N * p.B_cone * xc * (1.0 - xc)                   # Eq. 3
    R_disp = display_response(R_lum, p.gain, p.offset, p.toe)           # Sec. 4.3 rules
    L_disp = p.display.luminance(R_disp)                                # inverse Eq. 2
    if p.toe > 0.0 and p.display.signal_offset > 0.0:
        # the toe's floor is the display's black: no light (both luminances at the floor,
        # R = the floor's 1e-8-ish response) and what rounds to it show there exactly, not
        # at the inverse's rounding about it (black stays black)
        black = (R_disp <= p.gain * p.toe + p.offset) | (
            (np.asarray(Y) <= L_FLOOR) & (np.asarray(Ys) <= L_FLOOR))
        L_disp = np.where(black, p.display.signal_offset, L_disp)
    Yc = np.asarray(Y, np.float64)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(Yc > L_FLOOR, rgb / np.where(Yc > L_FLOOR, Yc, 1.0), 1.0)
    # Q_color = ratio^S_color (Eq. 3); display colour ratio C_d = Q_color^(1/S_d).
    if p.chroma is None:       # paper: Q_color^(1/S_d) = ratio^(S_color/S_d)
        c_disp = np.maximum(ratio, RATIO_FLOOR) ** (s_color / p.display.S_d)[..., None]
    else:                      # default: CIECAM02 colourfulness, hue kept (docs/models.md)
        c_disp = np.maximum(1.0 + p.chroma * (ratio - 1.0), 0.0)
    if p.raw and p.chroma is not None:
        c_raw = 1.0 + p.chroma * (ratio - 1.0)
        L_raw = (L_disp - p.display.signal_offset) * p.display.gain
        return L_raw[..., None] * np.where(L_raw[..., None] < 0.0, np.abs(c_raw), c_raw)
    L_sig = np.minimum(np.maximum(L_disp - p.display.signal_offset, 0.0) * p.display.gain,
                       SIGNAL_CEILING)
    if p.raw:                  # the paper's colour: no shoulder (its knee is 0 there)
        return L_sig[..., None] * c_disp
    out = apply_shoulder(L_sig[..., None] * c_disp, p.white_signal, p.shoulder_knee)
    return np.clip(out, 0.0, DISPLAY_LINEAR_MAX)


# --- Scheduler hooks --------------------------------------------------------

def steady_state(G_rod: float, G_cone: float) -> dict:
    """Fully adapted state: A = G, B = Hunt's static B (Eq. 6)."""
    return receptor_levels_steady(G_rod, G_cone)


def advance(values: dict, G_rod: float, G_cone: float, dt: float) -> dict:
    """Advance the four adaptation signals by ``dt`` seconds toward the goals (Sec. 4.1.2).

    A: exact exponential filters (t0 = 150 ms rods, 80 ms cones).
    B: exact solution of Eq. 7's kinetics (see adaptation.bleaching_step).
    """
    return receptor_levels_advance(values, G_rod, G_cone, dt)


def preadapted(L_cd: float, seconds: float | None) -> dict:
    """State of an observer who looked at a neutral field of ``L_cd`` cd/m^2.

    Without ``seconds``: fully adapted to it. With ``seconds``: starting
    dark-adapted (A at the floor, B = 1, full pigment) and exposed for that
    long, so longer exposure leaves more pigment bleached.
    """
    return receptor_levels_preadapted(L_cd * neutral_scotopic_ratio(), L_cd, seconds)
