"""Durand & Dorsey 2000: Ferwerda's threshold operator, extended and made time-dependent.

>>> float(mesopic_factor_walraven_valeton(0.0)), float(mesopic_factor_walraven_valeton(400.0))
(1.0, 0.0)
>>> [round(v, 2) for v in BLUE_SHIFT]
[1.05, 0.97, 1.27]

"Interactive Tone Mapping", Eurographics Workshop on Rendering 2000. Equation
numbers below are the paper's. Units: cd/m^2 (photopic for cones, scotopic
for rods), seconds.

The operator is a global scale per receptor system (Sec. 3.1)::

    r_d = m_C r_w + 1.05 k m_R s_w        (Eq. 5; Eq. 6 adds von Kries gains)
    g_d = m_C g_w + 0.97 k m_R s_w
    b_d = m_C b_w + 1.27 k m_R s_w

with threshold-mapping factors m_C = eps_C(L_da)/eps_C(L_wa) and
m_R = eps_C(L_da)/eps_R(L_waR) (Ferwerda et al. 1996's TVI curves, Eqs. 1-2),
the Walraven & Valeton mesopic factor k (Eq. 4) and exponential light
adaptation of m_R, m_C with tau_R = 0.4 s, tau_C = 0.1 s (Sec. 3.3).

Chromatic adaptation (Eq. 6, below; the effect in ``effects/chromatic.py``)
scales the cone signals r_w, g_w, b_w by 1/(r_wa, g_wa, b_wa) before this
pass, leaving the rod signal s_w alone, exactly as Eq. 6 does.

State (serialisable): the *inverse thresholds* 1/eps of the world adaptation
levels, filtered in time. Filtering m = eps(L_da) * (1/eps(L_wa)) with a
constant display is the same as filtering 1/eps, and keeps the state free of
the display, so a resumed chunk may use another display.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .display import (DISPLAY_LINEAR_MAX, SHOULDER_KNEE, SIGNAL_CEILING, DisplaySpec,
                      apply_shoulder, scene_key)
from .ferwerda1996 import (LA_FLOOR, adapted_cone_luminance, threshold_cone,  # noqa: F401
                           threshold_rod)
from .integrators import exponential_step
from .photometry import RGB709_TO_XYZ, Y_WEIGHTS, neutral_scotopic_ratio, normalise_illuminant, xy_to_rgb
from .planckian import CCT_Duv_to_uv, uv_to_CCT_Duv

#: Light-adaptation time constants, Sec. 3.3 (Adelson 1982; Hayhoe et al. 1987), s.
TAU_ROD, TAU_CONE = 0.4, 0.1
#: Walraven & Valeton's semi-saturation for the mesopic factor, Eq. 4, cd/m^2.
SIGMA_MESOPIC = 100.0
#: Blue shift of rod signals, Eq. 5: Hunt's scotopic white x = y = 0.3 on an NTSC display.
BLUE_SHIFT = (1.05, 0.97, 1.27)
#: Default mode: half the excitation purity of Hunt's (0.3, 0.3), at a dominant
#: wavelength of 480 nm, xy (0.3009, 0.3185): CIELAB hue 260 (blue) where Hunt's
#: white is at 302 (violet), chroma 3.6 where Hunt's is 9 (docs/models.md).
BLUE_SHIFT_DEFAULT_XY = (0.3009, 0.3185)
#: Ferwerda et al. 1996: the display observer is adapted to half the display's maximum.
DISPLAY_ADAPT_FRACTION = 0.5
#: Look-up tables span 12 decades (Sec. 5), centred on the adaptation level here.
LUT_DECADES = 12.0
#: ``mode``: "default" (display adaptation following the scene's key, highlight
#: shoulder) or "paper" (L_da = L_dmax/2 for every scene, hard clip at white).
MODES = ("default", "paper")


def display_adaptation(display: DisplaySpec, L_adapted: float | None = None) -> float:
    """L_da, cd/m^2: Ferwerda et al.'s display observer, adapted to L_dmax / 2; with
    ``L_adapted`` (the default mode), L_dmax times the key of a scene adapted to it
    (:func:`display.scene_key`), so brighter scenes are shown brighter."""
    if L_adapted is None:
        return DISPLAY_ADAPT_FRACTION * display.white_cd
    return float(scene_key(L_adapted)) * display.white_cd


def mesopic_factor_walraven_valeton(L_waR):
    """k, Eq. 4 (Walraven & Valeton 1984): (sigma - 0.25 L)/(sigma + L), sigma = 100
    cd/m^2, clamped to [0, 1]: 1 in the dark, 0 from L_waR = 400 up."""
    L = np.maximum(np.asarray(L_waR, np.float64), 0.0)
    return np.clip((SIGMA_MESOPIC - 0.25 * L) / (SIGMA_MESOPIC + L), 0.0, 1.0)


# --- Time course, Sec. 3.3 ----------------------------------------------------------

def steady_state(G_rod: float, G_cone: float) -> dict:
    """Fully light-adapted: inverse thresholds at the goals (m = m_steady)."""
    return {"inv_eps_rod": float(1.0 / threshold_rod(G_rod)),
            "inv_eps_cone": float(1.0 / threshold_cone(G_cone)),
            "L_waR": float(G_rod), "L_wa": float(G_cone)}


def advance(values: dict, G_rod: float, G_cone: float, dt: float) -> dict:
    """Sec. 3.3: dm/dt = (m_steady - m)/tau, solved exactly over ``dt`` (goal held)."""
    return {"inv_eps_rod": exponential_step(values["inv_eps_rod"],
                                            float(1.0 / threshold_rod(G_rod)), dt, TAU_ROD),
            "inv_eps_cone": exponential_step(values["inv_eps_cone"],
                                             float(1.0 / threshold_cone(G_cone)), dt, TAU_CONE),
            "L_waR": float(G_rod), "L_wa": float(G_cone)}


def preadapted(L_cd: float, seconds: float | None) -> dict:
    """Adapted to a neutral field of ``L_cd``; with ``seconds``, starting from
    full dark adaptation and light-adapting that long (Sec. 3.3 models light
    adaptation only, so a few seconds already reach the steady state)."""
    G_rod, G_cone = L_cd * neutral_scotopic_ratio(), L_cd
    if seconds is None:
        return steady_state(G_rod, G_cone)
    dark = steady_state(0.0, 0.0)
    return advance(dark, G_rod, G_cone, seconds)



def response_slope(L_b, values: dict):
    """dL_d/dln L_w of Sec. 3.1's scaling, per display threshold, for a small neutral
    increment on a background of L_b cd/m^2 under the state ``values``: the
    observer's own gain for a visibility threshold (``adrian1989.transient_factor``),
    L_b ((1 - k) / eps_C + k L'/L / eps_R), k Eq. 4 at the current L_waR."""
    L = np.asarray(L_b, np.float64)
    k = mesopic_factor_walraven_valeton(values["L_waR"])
    return L * ((1.0 - k) * values["inv_eps_cone"]
                + k * neutral_scotopic_ratio() * values["inv_eps_rod"])


def steady_slope(L_b):
    """:func:`response_slope` of observers fully adapted to each neutral L_b (any shape)."""
    L = np.maximum(np.asarray(L_b, np.float64), 0.0)
    Lr = L * neutral_scotopic_ratio()
    return response_slope(L, {"inv_eps_rod": 1.0 / threshold_rod(Lr),
                              "inv_eps_cone": 1.0 / threshold_cone(L), "L_waR": Lr})


def adaptation_luminance(values: dict) -> float:
    """The cone adaptation level of the state: the luminance whose Eq. 2 threshold is
    the current eps_C (it lags L_wa by Sec. 3.3's time course)."""
    return adapted_cone_luminance(values["inv_eps_cone"])

# --- Per-frame scalars and the per-pixel pass ---------------------------------------

@dataclass(frozen=True)
class FrameParams:
    """Scalars of one frame's mapping (display-linear = cd/m^2 / unit_cd)."""

    m_cone: float          # m_C, current (filtered)
    m_rod: float           # m_R, current (filtered)
    k: float               # mesopic factor, Eq. 4
    tint: tuple            # rod signal colour, Eq. 5 (1.05, 0.97, 1.27)
    L_da: float            # display adaptation, cd/m^2
    L_wa: float            # this frame's metered cone adaptation level
    L_waR: float           # ... rod (scotopic)
    unit_cd: float         # cd/m^2 of display-linear 1.0
    lut: int = 0           # look-up table entries (0: direct evaluation)
    mode: str = "default"
    shoulder_knee: float = SHOULDER_KNEE   # 0: hard clip at display white (paper)
    white_signal: float = 1.0              # display-linear value of display white
    raw: bool = False                      # the smooth part alone (see map_reference)

    def as_dict(self) -> dict:
        return asdict(self)

    @property
    def rod_rgb(self) -> np.ndarray:
        """k m_R (tint) in display-linear units per scotopic cd/m^2."""
        return self.k * self.m_rod * np.asarray(self.tint, np.float64) / self.unit_cd


def blue_shift(mode: str = "default") -> tuple:
    """The rod signal colour of Eq. 5: the paper's (1.05, 0.97, 1.27), or in the
    default mode the 480 nm tint of :data:`BLUE_SHIFT_DEFAULT_XY`."""
    if mode == "paper":
        return BLUE_SHIFT
    return tuple(float(v) for v in xy_to_rgb(*BLUE_SHIFT_DEFAULT_XY))


def frame_params(state, display: DisplaySpec, tint=None, lut: int = 0,
                 mode: str = "default") -> FrameParams:
    """Per-frame scalars. ``mode="paper"``: L_da = L_dmax/2 and a hard clip at
    display white; default: L_da from the key of the adapted level, and the
    highlight shoulder (docs/models.md)."""
    if mode not in MODES:
        raise ValueError(f"durand00 mode must be one of {', '.join(MODES)} (got {mode!r})")
    v = state.values
    paper = mode == "paper"
    if tint is None:
        tint = blue_shift(mode)
    L_da = display_adaptation(display, None if paper
                              else adapted_cone_luminance(v["inv_eps_cone"]))
    e_d = float(threshold_cone(L_da))
    return FrameParams(e_d * v["inv_eps_cone"], e_d * v["inv_eps_rod"],
                       float(mesopic_factor_walraven_valeton(v["L_waR"])), tuple(float(t) for t in tint), L_da,
                       v["L_wa"], v["L_waR"], display.unit_cd, int(lut), mode,
                       0.0 if paper else SHOULDER_KNEE,
                       float(display.white_cd / display.unit_cd))


def map_reference(rgb: np.ndarray, Y: np.ndarray, Ys: np.ndarray, p: FrameParams) -> np.ndarray:
    """Float64 reference, Eq. 5: cone signals (already chromatically adapted,
    Eq. 6) times m_C plus the tinted rod signal k m_R s_w; display-linear."""
    rgb = np.asarray(rgb, np.float64)
    cone = rgb * (p.m_cone / p.unit_cd)
    rod = np.asarray(Ys, np.float64)[..., None] * p.rod_rgb
    if p.lut:
        cone, rod = _lut_reference(rgb, Ys, p)
    if p.raw:                  # before the shoulder and the clip (colour/export.py)
        return cone + rod
    out = apply_shoulder(np.minimum(cone + rod, SIGNAL_CEILING), p.white_signal,
                         p.shoulder_knee)
    return np.clip(out, 0.0, DISPLAY_LINEAR_MAX)


def lut_range(p: FrameParams) -> tuple[float, float]:
    """log10 cd/m^2 span of the tables: 12 decades centred on the adaptation level."""
    c = 0.5 * (math.log10(max(p.L_wa, LA_FLOOR)) + math.log10(max(p.L_waR, LA_FLOOR)))
    return c - LUT_DECADES / 2, c + LUT_DECADES / 2


def lut_tables(p: FrameParams) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Sec. 5's per-frame tables T_C(x) = m_C x and T_R(s) = k m_R s (display-linear),
    indexed by log10 of the input; entry i holds the value at lo + i*step."""
    lo, hi = lut_range(p)
    n = p.lut
    x = 10.0 ** np.linspace(lo, hi, n)
    step = (hi - lo) / (n - 1)
    return x * p.m_cone / p.unit_cd, x * p.k * p.m_rod / p.unit_cd, lo, step


def _lut_lookup(table, lo, step, x):
    """Nearest entry, no interpolation (Sec. 5); 0 for x <= 0; clamped at the ends."""
    x = np.asarray(x, np.float64)
    with np.errstate(divide="ignore"):
        idx = np.rint((np.log10(np.where(x > 0, x, 1.0)) - lo) / step)
    idx = np.clip(idx, 0, len(table) - 1).astype(np.int64)
    return np.where(x > 0, table[idx], 0.0)


def _lut_reference(rgb, Ys, p: FrameParams):
    tc, tr, lo, step = lut_tables(p)
    cone = _lut_lookup(tc, lo, step, rgb)
    rod = _lut_lookup(tr, lo, step, Ys)[..., None] * np.asarray(p.tint, np.float64)
    return cone, rod


# --- Chromatic adaptation, Sec. 3.4 and Eq. 6 -----------------------------------------

#: Chromatic adaptation time constant, s (Sec. 3.4; Fairchild & Reniff 1995).
TAU_CHROMA = 5.0

#: CIE 1931 xy chromaticities of named illuminants (CIE 15:2004).
ILLUMINANTS_XY = {
    "D50": (0.34567, 0.35850), "D55": (0.33242, 0.34743), "D65": (0.31270, 0.32900),
    "D75": (0.29902, 0.31485), "A": (0.44757, 0.40745), "TUNGSTEN": (0.44757, 0.40745),
    "F2": (0.37208, 0.37529), "F7": (0.31292, 0.32933), "F11": (0.38052, 0.37713),
    "LED-B3": (0.4474, 0.4066), "LED-B4": (0.4557, 0.4211),
}

def parse_illuminant(text: str) -> np.ndarray:
    """A name (D65, A, F2, ...) or ``x,y`` chromaticity -> normalised working RGB."""
    t = text.strip().upper()
    if t in ILLUMINANTS_XY:
        return xy_to_rgb(*ILLUMINANTS_XY[t])
    try:
        x, y = (float(v) for v in text.split(","))
        return xy_to_rgb(x, y)
    except ValueError:
        raise ValueError(f"bad --illuminant {text!r}: use x,y or one of "
                         f"{', '.join(sorted(ILLUMINANTS_XY))}") from None


def illuminant_estimate_reference(rgb: np.ndarray) -> np.ndarray:
    """Luminance-weighted grey world, sum(Y rgb) / sum(Y Y): bright regions and
    light sources dominate (they carry the illuminant's colour; Sec. 4.1 warns
    against the plain image average). Float64; the device does the same sums."""
    rgb = np.asarray(rgb, np.float64)
    Y = rgb @ Y_WEIGHTS
    return normalise_illuminant((Y[..., None] * rgb).reshape(-1, 3).sum(axis=0))


#: An estimated illuminant is held to the Planckian locus within ANSI C78.377's
#: tolerance for white light (|Duv| <= 0.006) and 1500-25000 K: real light sources
#: sit there, and coloured lamps or a green lawn must not read as a magenta or green
#: illuminant (which turned a lamp-lit night field purple).
ESTIMATE_DUV_MAX = 0.006
ESTIMATE_CCT_RANGE = (1500.0, 25000.0)


def plausible_illuminant(rgb) -> np.ndarray:
    """An illuminant estimate (working RGB) moved onto the band of real light
    sources around the Planckian locus (:data:`ESTIMATE_DUV_MAX`), normalised.
    CCT and Duv as Ohno 2013 defines them (:mod:`.planckian`)."""
    v = normalise_illuminant(rgb)
    if not ((RGB709_TO_XYZ @ v).sum() > 0):
        return v
    cct, duv = cct_duv(v)
    cct = float(np.clip(cct, *ESTIMATE_CCT_RANGE))
    duv = float(np.clip(duv, -ESTIMATE_DUV_MAX, ESTIMATE_DUV_MAX))
    u, w = CCT_Duv_to_uv(cct, duv)
    x, y = 3.0 * u / (2.0 * u - 8.0 * w + 4.0), 2.0 * w / (2.0 * u - 8.0 * w + 4.0)
    return xy_to_rgb(x, y)


def cct_duv(rgb) -> tuple[float, float]:
    """CCT (K) and Duv (Ohno 2013) of a working-RGB colour."""
    XYZ = RGB709_TO_XYZ @ np.asarray(rgb, np.float64)
    if not (XYZ.sum() > 0):
        return 6504.0, 0.0
    x, y = XYZ[:2] / XYZ.sum()
    d = -2.0 * x + 12.0 * y + 3.0                      # xy -> CIE 1960 (u, v)
    cct, duv = uv_to_CCT_Duv((4.0 * x / d, 6.0 * y / d))
    return float(cct), float(duv)


def illuminant_estimate(rgb: np.ndarray, source_limit: float | None = None):
    """The frame's illuminant, bounded (docs/models.md, "Chromatic adaptation"):
    the luminance-weighted grey world of :func:`illuminant_estimate_reference` over
    the pixels at most ``source_limit`` cd/m^2 (light sources left out: a setting
    sun must not be taken for the light on the scene), held to the Planckian band
    (:func:`plausible_illuminant`). Returns (normalised rgb, CCT in K, confidence):
    the confidence falls as the unbounded estimate leaves the locus,
    exp(-(Duv / ESTIMATE_DUV_MAX)^2 / 2), 1 on the locus, 0.61 at the band's edge."""
    rgb = np.asarray(rgb, np.float64).reshape(-1, 3)
    Y = rgb @ Y_WEIGHTS
    keep = Y <= source_limit if source_limit is not None else np.ones(len(Y), bool)
    if not keep.any() or not (Y[keep].sum() > 0):
        keep = np.ones(len(Y), bool)
    raw = illuminant_estimate_reference(rgb[keep])
    est = plausible_illuminant(raw)
    _, duv = cct_duv(raw)
    cct, _ = cct_duv(est)
    conf = math.exp(-0.5 * (duv / ESTIMATE_DUV_MAX) ** 2)
    return est, cct, conf


#: Incomplete adaptation to warm light: full at and above FULL_ADAPT_CCT, none at
#: NO_ADAPT_CCT and below, linear in mired (1e6 / CCT) between (docs/models.md).
FULL_ADAPT_CCT = 5000.0
NO_ADAPT_CCT = 2000.0
#: ... and to cool light (issue 67): full at and below COOL_FULL_CCT, none at
#: COOL_NO_ADAPT_CCT and above, linear in mired (Zhai & Luo 2018 find D falling for
#: CCTs above ~6500 K as below ~5000 K; a blue sky or a cool studio took out the
#: scene's own colour: its coloured mid-tones at 0.36x their saturation).
COOL_FULL_CCT = 6500.0
COOL_NO_ADAPT_CCT = 25000.0


def degree_of_adaptation(L_A: float, cct: float, confidence: float = 1.0,
                         surround_F: float = 1.0) -> float:
    """How far the eye adapts to an illuminant, 0..1: CAM16's D (Li et al. 2017,
    Eq. 5: F (1 - (1/3.6) exp((-L_A - 42) / 92)), L_A the adapting luminance in
    cd/m^2, F = 1 for an average surround) times the share kept for a warm
    illuminant (:data:`FULL_ADAPT_CCT`, :data:`NO_ADAPT_CCT`; Chen & Wei 2019 find
    D lower at 2700 and 3500 K) and for a cool one (:data:`COOL_FULL_CCT`,
    :data:`COOL_NO_ADAPT_CCT`) times the estimate's confidence."""
    D = surround_F * (1.0 - math.exp((-max(float(L_A), 0.0) - 42.0) / 92.0) / 3.6)
    m, m_full, m_none = 1e6 / max(cct, 1.0), 1e6 / FULL_ADAPT_CCT, 1e6 / NO_ADAPT_CCT
    warm = min(1.0, max(0.0, (m_none - m) / (m_none - m_full)))
    c_full, c_none = 1e6 / COOL_FULL_CCT, 1e6 / COOL_NO_ADAPT_CCT
    cool = min(1.0, max(0.0, (m - c_none) / (c_full - c_none)))
    return float(min(1.0, max(0.0, D * warm * cool * confidence)))


def partial_illuminant(illum, D: float) -> np.ndarray:
    """The white the eye adapts to with degree ``D``: gains 1 / result are CAT16's
    D / illum + (1 - D) (Li et al. 2017, Eq. 6), normalised."""
    g = D / np.asarray(illum, np.float64) + (1.0 - D)
    return normalise_illuminant(1.0 / g)


def chromatic_step(illum, goal, dt: float) -> np.ndarray:
    """Exponential filter of (r_wa, g_wa, b_wa) toward the goal, tau = 5 s (exact)."""
    return normalise_illuminant([exponential_step(float(a), float(g), dt, TAU_CHROMA)
                                 for a, g in zip(illum, goal)])


def von_kries_gains(illum) -> np.ndarray:
    """Eq. 6 (corrected, docs/models.md): the cone signals are divided by the
    normalised illuminant, r_d = m_C r_w / r_wa etc."""
    return 1.0 / np.asarray(illum, np.float64)


