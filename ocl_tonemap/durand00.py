"""Durand & Dorsey 2000: Ferwerda's threshold operator, extended and made time-dependent.

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

Chromatic adaptation (Eq. 6) is the shared effect in ``effects.py``: it
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

from .adaptation import exponential_step
from .display import (DISPLAY_LINEAR_MAX, SHOULDER_KNEE, SIGNAL_CEILING, DisplaySpec,
                      apply_shoulder, scene_key)
from .photometry import neutral_scotopic_ratio, xy_to_rgb

NAME = "durand00"

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
#: Floor on adaptation luminances before the log, cd/m^2 (below every branch point).
LA_FLOOR = 1.0e-10
#: Ferwerda et al. 1996: the display observer is adapted to half the display's maximum.
DISPLAY_ADAPT_FRACTION = 0.5
#: Look-up tables span 12 decades (Sec. 5), centred on the adaptation level here.
LUT_DECADES = 12.0
#: Options a caller may pass to ``frame_params`` (``Tonemapper(options=...)``).
OPTIONS = ("tint", "lut", "mode")
#: ``mode``: "default" (display adaptation following the scene's key, highlight
#: shoulder) or "paper" (L_da = L_dmax/2 for every scene, hard clip at white).
MODES = ("default", "paper")


# --- Threshold-versus-intensity (Ferwerda et al. 1996), Eqs. 1-2 -----------------

def log_threshold_rod(L_aR):
    """log10 eps_R(L_aR), Eq. 1: rod threshold (scotopic cd/m^2) at adaptation L_aR."""
    x = np.log10(np.maximum(np.asarray(L_aR, np.float64), LA_FLOOR))
    mid = np.maximum(0.405 * x + 1.6, 0.0) ** 2.18 - 2.86
    return np.where(x <= -3.94, -2.86, np.where(x >= -1.44, x - 0.395, mid))


def log_threshold_cone(L_aC):
    """log10 eps_C(L_aC), Eq. 2: cone threshold (cd/m^2). The photopic branch,
    printed "log L_wa - 1.255", is log L_aC - 1.255 (docs/models.md)."""
    x = np.log10(np.maximum(np.asarray(L_aC, np.float64), LA_FLOOR))
    mid = np.maximum(0.249 * x + 0.65, 0.0) ** 2.7 - 0.72
    return np.where(x <= -2.6, -0.72, np.where(x >= 1.9, x - 1.255, mid))


def threshold_rod(L_aR):
    """eps_R(L_aR), scotopic cd/m^2 (Eq. 1)."""
    return 10.0 ** log_threshold_rod(L_aR)


def threshold_cone(L_aC):
    """eps_C(L_aC), cd/m^2 (Eq. 2)."""
    return 10.0 ** log_threshold_cone(L_aC)


def display_adaptation(display: DisplaySpec, L_adapted: float | None = None) -> float:
    """L_da, cd/m^2: Ferwerda et al.'s display observer, adapted to L_dmax / 2; with
    ``L_adapted`` (the default mode), L_dmax times the key of a scene adapted to it
    (:func:`display.scene_key`), so brighter scenes are shown brighter."""
    if L_adapted is None:
        return DISPLAY_ADAPT_FRACTION * display.white_cd
    return float(scene_key(L_adapted)) * display.white_cd


def adapted_cone_luminance(inv_eps_cone: float) -> float:
    """The cone adaptation level (cd/m^2) whose threshold (Eq. 2) is 1/``inv_eps_cone``:
    Eq. 2 inverted (its flat scotopic branch maps to its end, 10^-2.6)."""
    le = -math.log10(max(inv_eps_cone, 1e-300))
    if le >= 1.9 - 1.255:
        return 10.0 ** (le + 1.255)
    if le <= -0.72 + 1e-12:
        return 10.0 ** -2.6
    return 10.0 ** (((le + 0.72) ** (1.0 / 2.7) - 0.65) / 0.249)


def scale_factors(L_wa, L_waR, L_da):
    """Steady (m_C, m_R), Sec. 3.1: m_C = eps_C(L_da)/eps_C(L_wa), m_R = eps_C(L_da)/eps_R(L_waR)."""
    e_d = threshold_cone(L_da)
    return e_d / threshold_cone(L_wa), e_d / threshold_rod(L_waR)


def mesopic_factor(L_waR):
    """k, Eq. 4 (Walraven & Valeton 1984): (sigma - 0.25 L)/(sigma + L), sigma = 100
    cd/m^2, clamped to [0, 1]: 1 in the dark, 0 from L_waR = 400 up."""
    L = np.maximum(np.asarray(L_waR, np.float64), 0.0)
    return np.clip((SIGMA_MESOPIC - 0.25 * L) / (SIGMA_MESOPIC + L), 0.0, 1.0)


def ferwerda_mesopic_factor(L_wa):
    """Ferwerda et al.'s original k (Sec. 3.1), kept for comparison:
    (1 - (L_wa/2 - 0.01)/(10 - 0.01))^2 clamped to [0, 1]."""
    L = np.asarray(L_wa, np.float64)
    return np.clip(1.0 - (L / 2.0 - 0.01) / (10.0 - 0.01), 0.0, 1.0) ** 2


# --- Scheduler hooks ------------------------------------------------------------------

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
                       float(mesopic_factor(v["L_waR"])), tuple(float(t) for t in tint), L_da,
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


def map_opencl(rt, rgb_buf, y_buf, ys_buf, out_buf, n_pixels: int, p: FrameParams):
    """Enqueue the per-pixel pass (kernels/durand00.cl): direct, or through the
    per-frame tables when ``p.lut`` > 0."""
    from .runtime import round_up
    f = np.float32
    wg = 64
    gsz = (round_up(max(n_pixels, 1), wg),)
    rod = p.rod_rgb
    if not p.lut:
        knl = rt.kernel("durand00.cl", "durand00_map")
        knl(rt.queue, gsz, (wg,), rgb_buf, ys_buf, out_buf, np.int32(n_pixels),
            f(p.m_cone / p.unit_cd), f(rod[0]), f(rod[1]), f(rod[2]),
            f(1.0 / p.white_signal), f(p.shoulder_knee))
        return
    import pyopencl as cl
    tc, tr, lo, step = lut_tables(p)
    tables = np.concatenate([tc, tr]).astype(np.float32)
    buf = _lut_buffer(rt, tables.nbytes)
    cl.enqueue_copy(rt.queue, buf, tables)
    knl = rt.kernel("durand00.cl", "durand00_map_lut")
    knl(rt.queue, gsz, (wg,), rgb_buf, ys_buf, out_buf, np.int32(n_pixels), buf,
        np.int32(p.lut), f(lo), f(1.0 / step), f(p.tint[0]), f(p.tint[1]), f(p.tint[2]),
        f(1.0 / p.white_signal), f(p.shoulder_knee))


_LUT_BUFS: dict = {}


def _lut_buffer(rt, nbytes: int):
    import pyopencl as cl
    key = (id(rt.context), nbytes)
    if key not in _LUT_BUFS:
        _LUT_BUFS[key] = cl.Buffer(rt.context, cl.mem_flags.READ_ONLY, nbytes)
    return _LUT_BUFS[key]
