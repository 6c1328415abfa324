"""Kirk & O'Brien 2011: perceptually based tone mapping for low-light conditions.

"Perceptually Based Tone Mapping for Low-Light Conditions", ACM TOG 30(4)
(SIGGRAPH 2011). Equation numbers are the paper's. The Purkinje shift is
Cao, Pokorny, Smith & Zele 2008's model of rod signals in the cone pathways.

Per pixel::

    q = (L, M, S, R)                  from a spectrum (Eq. 8) or RGB via H (Sec. 4)
    g_L = (1 + 0.33 (q_L + k1 q_R))^-1/2, g_M likewise, g_S with k2   (Eq. 10, K q)
    delta o (Eq. 12), o = A q^ (Eq. 11), q^ = q_LMS + A^-1 delta o    (Eq. 13)
    p* = argmin ||M p - q^||, p >= 0                                   (Eqs. 14-15)
    w = alpha g_L/l_max + (1 - alpha) g_M/m_max                        (Eq. 16)

then Durand & Dorsey 2002 range reduction on log luminance (bilateral base /
detail, ``bilateral.py``), the mesopic dimming by w, and for RGB input the
paper's blend from the source image (photopic) to the mesopic image by w.

The float64 functions here are the reference; ``kernels/kirk11.cl`` is the
device pass (``backends/opencl/kirk11.py``). Reconstructions of the seed text are
in docs/models.md.

>>> w = white_norm()
>>> q = lmsr.rgb_to_lmsr(np.ones(3)) * w
>>> round(float(q[0] - q[1]), 9), round(float(q[2] - (q[0] + q[1])), 9)   # white: opponent 0
(0.0, 0.0)
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import asdict, dataclass

import numpy as np

from . import lmsr
from .display import DisplaySpec, scene_key
from .durand2000 import mesopic_factor_walraven_valeton
from .durand2002 import range_reduce
from .photometry import Y_WEIGHTS

#: Rod mixing at full scotopic adaptation (Eq. 10; Cao et al. 2008).
KAPPA1, KAPPA2 = 0.25, 0.4
#: Eq. 10's 0.33 (Cao et al. 2008): g = (1 + 0.33 (q + kappa q_R))^-1/2.
REGULATION_C = 0.33
#: Eq. 12 constants (Cao et al. 2008 fits).
RHO = (1.111, 0.939, 0.4, 0.15)
ALPHA = 0.619
#: Shift scales x, y, z. The paper's examples use 15, 15, 5 in its own units; in the
#: white-referenced opponent space below, x = y = 15 still puts the rod signal of any
#: colour outside the spectral locus (L/(L+M) 0.24 < 0.475) once g -> 1, so x = y are
#: recalibrated: 1.5 is the largest value for which the unconstrained solve of Eq. 15
#: holds at every level from 1e-3 to 1e4 cd/m^2 for every ColorChecker patch (D65)
#: that is inside sRGB in daylight ("in most cases", as the paper reports). The
#: default takes a third of that, 0.5: a neutral at 1e-3 cd/m^2 then turns a
#: desaturated blue-green (CIELAB C* 5, hue 181; 15.5 at 1.5), as pale as durand00's
#: blue shift, so night pictures are less colourful than day ones. z unchanged.
SHIFT_XYZ = (0.5, 0.5, 5.0)
#: The paper's shift scales (``--mode paper``).
SHIFT_XYZ_PAPER = (15.0, 15.0, 5.0)
#: ``mode``: "default" (white-referenced opponent space, recalibrated x = y, gamut map
#: for Eq. 15, display anchored to the adapted level with the receptor scheduler's
#: time course, highlight shoulder) or "paper" (Eqs. 10-16 as printed, fixed kappa,
#: exact NNLS, each frame's base maximum at white, steady state).
MODES = ("default", "paper")
#: Naka-Rushton exponent of the transient response (Hunt's n): a frame at L seen
#: while adapted to A shows at (L/A)^n of its steady level.
TRANSIENT_N = 0.73
#: Eq. 11: o = A q^ with rows red/green, blue/yellow, luminance.
A = np.array([[-1.0, 1.0, 0.0],
              [-1.0, -1.0, 1.0],
              [1.0, 1.0, 0.0]])
A_INV = np.linalg.inv(A)
#: Mesopic dimming (Sec. 3.2): w at which a pixel is fully scotopic, and the
#: floor of the range a pixel keeps (the paper's gamma, 0.25-0.5 in its examples).
BETA, GAMMA = 1.0, 0.25
#: Durand & Dorsey 2002: base-layer contrast after compression, and the range
#: sigma of their bilateral filter on log10 luminance.
TARGET_CONTRAST = 5.0
#: Default mode: base contrast kept 300:1 (the display's shoulder takes the rest); at
#: 5:1 the base compression reordered luminances (Spearman 0.73, gradient reversal
#: 8% on photographs; 100:1: 0.93 and 1.4%; 300:1: under 1% on the lamp scene).
TARGET_CONTRAST_DEFAULT = 300.0
#: Default mode: the base layer's range for the compression and the white anchor
#: from its 1st and 99th percentiles (as pfstools' ``pfstmo_durand02``), not its
#: extremes (the paper's, ``--mode paper``): a small lamp then neither sets the
#: frame's exposure nor, smoothed differently by the bilateral grid than by the
#: exact filter, moves it (models/durand2002.py, BaseRange; docs/models.md).
BASE_PERCENTILES_DEFAULT = (1.0, 99.0)
BASE_PERCENTILES_PAPER = (0.0, 100.0)
SIGMA_RANGE_LOG10 = 0.4
#: Floor on luminances before the log, cd/m^2.
Y_FLOOR = 1.0e-10
#: Floor before the logs of the log-averages (logmean, anchor_gain): the absolute
#: threshold of vision, cd/m^2 (as metering.LOG_FLOOR).
LOG_FLOOR = 1.0e-6



#: CIE mesopic range (CIE 191:2010): 0.005 to 5 cd/m^2.
MESOPIC_LOWER_CD, MESOPIC_UPPER_CD = 0.005, 5.0


@functools.lru_cache(maxsize=1)
def white_norm() -> np.ndarray:
    """D_W (4,): the per-receptor scale under which the working white is the zero of
    Eq. 11's chromatic rows: D_W q_W = (Y_W/2, Y_W/2, Y_W, R_W) with Y_W = L_W + M_W.
    o_RG = M - L and o_BY = S - (L + M) measure redness and blueness, so a neutral
    must give zero; in our LMS units (L + M = luminance) the white has L = 1.9 M and
    S = 0.89 (L + M), and the printed A would make Eq. 12's luminance term (the
    largest, z w q_R) add a saturated cyan (L = M, S = L + M), not light."""
    w = lmsr.rgb_to_lmsr(np.ones(3))
    y = w[0] + w[1]
    return np.array([y / (2.0 * w[0]), y / (2.0 * w[1]), y / w[2], 1.0])


@functools.lru_cache(maxsize=1)
def model_scale() -> float:
    """Units of Eq. 10 per cd/m^2 of our LMSR. The paper leaves the absolute scale to
    its exposure control; we fix it so that the paper's own mesopic measure, w of
    Eq. 16, equals beta = 1 ("fully scotopic") for the working white at the CIE lower
    mesopic limit, 0.005 cd/m^2. It then falls to 0.04 at the upper limit, 5 cd/m^2
    (docs/models.md)."""
    q = lmsr.rgb_to_lmsr(np.full(3, MESOPIC_LOWER_CD)) * white_norm()
    lo, hi = 1e-3, 1e9
    for _ in range(200):
        mid = math.sqrt(lo * hi)
        w = float(mesopic_weight(regulated_signals(q * mid, KAPPA1, KAPPA2)))
        lo, hi = (mid, hi) if w > BETA else (lo, mid)
    return math.sqrt(lo * hi)


# --- Eqs. 10-13, 16 ----------------------------------------------------------------

def regulated_signals(q_td: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """g, Eq. 10 (q in model units, K x LMSR, (..., 4)) -> (..., 3)."""
    q = np.asarray(q_td, np.float64)
    r = q[..., 3]
    c = REGULATION_C
    return np.stack([(1.0 + c * (q[..., 0] + k1 * r)) ** -0.5,
                     (1.0 + c * (q[..., 1] + k1 * r)) ** -0.5,
                     (1.0 + c * (q[..., 2] + k2 * r)) ** -0.5], axis=-1)


def mesopic_weight(g: np.ndarray) -> np.ndarray:
    """w, Eq. 16: 0 photopic, growing toward scotopic."""
    return ALPHA * g[..., 0] / lmsr.L_MAX + (1.0 - ALPHA) * g[..., 1] / lmsr.M_MAX


def opponent_shift(g: np.ndarray, q_rod: np.ndarray, k1: float, xyz=SHIFT_XYZ,
                   rod_gain: float = 1.0) -> np.ndarray:
    """delta o, Eq. 12 (same units as q_rod). ``rod_gain`` scales all three terms
    (1 as printed; the adaptive mode's mesopic factor)."""
    x, y, z = xyz
    r1, r2, r3, r4 = RHO
    gl, gm, gs = g[..., 0] / lmsr.L_MAX, g[..., 1] / lmsr.M_MAX, g[..., 2] / lmsr.S_MAX
    lum = ALPHA * gl + (1.0 - ALPHA) * gm
    rod = rod_gain * np.asarray(q_rod, np.float64)
    return np.stack([x * k1 * (r1 * gm - r2 * gl) * rod,
                     y * (r3 * gs - r4 * lum) * rod,
                     z * lum * rod], axis=-1)


def purkinje_shift(q: np.ndarray, scale: float, k1: float = KAPPA1, k2: float = KAPPA2,
                   xyz=SHIFT_XYZ, rod_gain: float = 1.0, white: bool = True):
    """Eqs. 10-13 for (..., 4) LMSR in cd/m^2 units: returns (q^ (..., 3) in the
    same units, w). ``scale``: model units per cd/m^2 (``model_scale()``). Eqs. 10-13
    run on D_W q (``white_norm``), so that Eq. 12's luminance row adds light of the
    white's colour and only the red/green and blue/yellow rows tint."""
    q = np.asarray(q, np.float64)
    d = white_norm() if white else np.ones(4)
    qt = q * (d * scale)
    g = regulated_signals(qt, k1, k2)
    d_o = opponent_shift(g, qt[..., 3], k1, xyz, rod_gain)
    q_hat = q[..., :3] + (d_o @ A_INV.T) / (d[:3] * scale)
    return q_hat, mesopic_weight(g)


# --- Eq. 15: non-negative display values ----------------------------------------------

SUBSETS = [s for n in (3, 2, 1) for s in itertools.combinations(range(3), n)]


def subset_solvers(M: np.ndarray) -> np.ndarray:
    """(7, 3, 3): for each support set (all three channels first), the matrix that
    maps q^ to the least-squares p on that support (zeros off it)."""
    out = []
    for s in SUBSETS:
        Ms = M[:, list(s)]
        P = np.zeros((3, 3))
        P[list(s), :] = np.linalg.pinv(Ms)
        out.append(P)
    return np.array(out)


def nnls3(M: np.ndarray, q_hat: np.ndarray):
    """Exact per-pixel NNLS for 3 unknowns: the unconstrained solve first; where it
    has a negative, the best feasible least-squares solution over the 6 smaller
    supports (one of them is the optimum). Returns (p (..., 3), used_fallback)."""
    q = np.asarray(q_hat, np.float64)
    P = subset_solvers(M)
    best = q @ P[0].T
    ok = np.all(best >= 0, axis=-1)
    fallback = ~ok
    best = np.where(ok[..., None], best, 0.0)
    best_res = np.where(ok, np.sum((best @ M.T - q) ** 2, axis=-1), np.sum(q * q, axis=-1))
    for Pk in P[1:]:
        p = q @ Pk.T
        feas = fallback & np.all(p >= -1e-12 * np.abs(q).max(initial=1.0), axis=-1)
        p = np.maximum(p, 0.0)
        res = np.sum((p @ M.T - q) ** 2, axis=-1)
        better = feas & (res < best_res)
        best = np.where(better[..., None], p, best)
        best_res = np.where(better, res, best_res)
    return best, fallback


def gamut_map(M: np.ndarray, q_hat: np.ndarray):
    """Eq. 15 where the unconstrained solve p = M^-1 q^ is non-negative (the paper's
    "most cases"); elsewhere, instead of the least-squares point in LMS (which drops a
    channel and changes the hue: a teal for every colour in the dark), the point where
    the line from the neutral of the same L + M to M^-1 q^ enters the display gamut:
    cone luminance and hue line kept, chroma reduced. Returns (p, used_fallback)."""
    q = np.asarray(q_hat, np.float64)
    p = q @ np.linalg.inv(M).T
    wm = M @ np.ones(3)
    pn = (np.maximum(q[..., 0] + q[..., 1], 0.0) / (wm[0] + wm[1]))[..., None]
    neg = p < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(neg, pn / (pn - p), 1.0)
    t = np.clip(np.min(t, axis=-1), 0.0, 1.0)
    return np.maximum(pn + t[..., None] * (p - pn), 0.0), np.any(neg, axis=-1)


def display_matrix(D: np.ndarray) -> np.ndarray:
    """M of Eq. 14: display RGB -> LMS, the LMS rows of H through the display
    primaries ``D`` (display linear RGB -> working linear RGB)."""
    return lmsr.fitted()["H"][:3] @ np.asarray(D, np.float64)


def solve_display(M: np.ndarray, q_hat: np.ndarray, exact: bool):
    """Eq. 15: the paper's exact NNLS (``exact``) or the hue-keeping gamut map."""
    return nnls3(M, q_hat) if exact else gamut_map(M, q_hat)


def anchor_gain(Y_out: np.ndarray, L_wa: float, A_cone: float, seen: float = 1.0) -> float:
    """Absolute level: the factor that brings the frame's log-average display
    luminance (relative to white) to display.scene_key of the adapted cone level
    ``A_cone`` (Krawczyk et al. 2005's key, as durand00 and ledda04 use), times
    (L_wa/A_cone)^n for a frame seen before the eye has adapted to it: darker
    entering a tunnel, brighter (dazzle) leaving it. The range reduction maps every
    frame's base maximum to white whatever its level; without this a 0.1 cd/m^2
    scene was shown at 0.86x its daylight brightness. ``seen``: the share of the frame's
    brightest light that the observer sees (``models/absolute_threshold.py`` peak_seen;
    the range reduction would show a lone target below threshold at white)."""
    return anchor_key(L_wa, A_cone, seen) / logmean(Y_out)


def anchor_key(L_wa: float, A_cone: float, seen: float = 1.0) -> float:
    """:func:`anchor_gain` times the frame's log-average: the scene key of the adapted
    cone level times the transient factor (L_wa/A_cone)^n and ``seen`` (what a device
    divides by the log-average it reduces: kernels/kirk11.cl kirk11_gain)."""
    return float(scene_key(A_cone)) * (max(L_wa, 1e-10) / max(A_cone, 1e-10)) ** TRANSIENT_N \
        * float(seen)


# --- settings and the per-frame pieces -------------------------------------------------

@dataclass(frozen=True)
class KirkSettings:
    kappa: str | None = None         # adaptive (mesopic) | full (the paper); None: by mode
    shift_xyz: tuple | None = None   # None: by mode
    gamma: float = GAMMA
    beta: float = BETA
    target_contrast: float | None = None   # None: 5 (paper) or 300 (default)
    sigma_spatial: float | None = None   # px; default 2% of the larger side
    mode: str = "default"
    base_percentiles: tuple | None = None  # None: (1, 99) default, (0, 100) paper


    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"kirk11 mode must be one of {', '.join(MODES)} (got {self.mode!r})")
        if self.kappa is None:
            object.__setattr__(self, "kappa", "full" if self.mode == "paper" else "adaptive")
        if self.target_contrast is None:
            object.__setattr__(self, "target_contrast",
                               TARGET_CONTRAST if self.mode == "paper" else TARGET_CONTRAST_DEFAULT)
        if self.base_percentiles is None:
            object.__setattr__(self, "base_percentiles", BASE_PERCENTILES_PAPER
                               if self.mode == "paper" else BASE_PERCENTILES_DEFAULT)
        object.__setattr__(self, "base_percentiles",
                           tuple(float(v) for v in self.base_percentiles))
        if len(self.base_percentiles) != 2 or not (
                0 <= self.base_percentiles[0] < self.base_percentiles[1] <= 100):
            raise ValueError("--base-percentiles needs LO,HI with 0 <= LO < HI <= 100")
        if self.shift_xyz is None:
            object.__setattr__(self, "shift_xyz",
                               SHIFT_XYZ_PAPER if self.mode == "paper" else SHIFT_XYZ)
        if self.kappa not in ("full", "adaptive"):
            raise ValueError(f"--kappa must be full or adaptive (got {self.kappa!r})")
        if len(self.shift_xyz) != 3 or min(self.shift_xyz) < 0:
            raise ValueError("--shift-scale needs three numbers >= 0 (x,y,z)")
        if not (0 <= self.gamma <= 1):
            raise ValueError(f"--night-dim must be in [0, 1] (got {self.gamma})")
        if not (self.target_contrast > 1):
            raise ValueError("--target-contrast must be > 1")

    def sigma_px(self, width: int, height: int) -> float:
        return self.sigma_spatial if self.sigma_spatial else max(1.0, 0.02 * max(width, height))

    @property
    def paper(self) -> bool:
        return self.mode == "paper"

    def as_dict(self) -> dict:
        return asdict(self)


def kappas(settings: KirkSettings, L_waR: float) -> tuple[float, float, float]:
    """(k1, k2, rod_gain): fixed at full scotopic values (the paper), or scaled by
    the Walraven-Valeton mesopic factor of the frame's scotopic level."""
    if settings.kappa == "full":
        return KAPPA1, KAPPA2, 1.0
    k = float(mesopic_factor_walraven_valeton(L_waR))
    return KAPPA1 * k, KAPPA2 * k, k


def logmean(x: np.ndarray, lit: np.ndarray | None = None) -> float:
    """exp(mean ln x) over the lit pixels (``lit``, default x above LOG_FLOOR: the
    metering rule of ``models/metering.py``, exact zeros do not pull it down);
    LOG_FLOOR where none is lit."""
    x = np.asarray(x, np.float64)
    lit = x > LOG_FLOOR if lit is None else np.asarray(lit, bool)
    if not lit.any():
        return LOG_FLOOR
    return float(np.exp(np.mean(np.log(np.maximum(x[lit], LOG_FLOOR)))))


def level_logmeans(q: np.ndarray) -> tuple[float, float]:
    """(log-average of R, of L+M) of LMSR ``q``, over the pixels where either is
    above LOG_FLOOR (the frame's levels; ``kirk11.cl`` kirk11_sums LOG_LEVELS)."""
    q = np.asarray(q, np.float64)
    R, LM = q[..., 3], q[..., 0] + q[..., 1]
    lit = np.maximum(R, LM) > LOG_FLOOR
    return logmean(R, lit), logmean(LM, lit)


def mean_exp(log_sum: float, count: float) -> float:
    """exp(log_sum / count) of device sums over ``count`` lit pixels (LOG_FLOOR: none)."""
    return math.exp(log_sum / count) if count > 0 else LOG_FLOOR


def compose_reference(src_rgb, shift_rgb, w, logY, base, settings: KirkSettings,
                      display: DisplaySpec, blend: bool):
    """Range reduction of the mesopic image (its own log luminance ``logY``, base
    ``base``), for RGB input the blend from the source by w (the source's colour at
    the same output luminance), the mesopic dimming of the pixel (Sec. 3.2: "a pixel
    with mesopic factor w is linearly mapped into [0, x]", the blended pixel, not only
    its mesopic part), and the absolute level (``anchor_gain``). Display-linear."""
    logY_out = range_reduce(logY, base, settings.target_contrast,
                            settings.base_percentiles)
    s = 10.0 ** (logY_out - logY)                                    # per-pixel scale
    dim = np.maximum(1.0 - w / settings.beta, settings.gamma)         # Sec. 3.2 (see docs)
    out = shift_rgb * (s if not settings.paper else s * dim)[..., None]
    if blend:
        t = np.clip(w / settings.beta, 0.0, 1.0)[..., None]
        ys = np.maximum(np.asarray(src_rgb, np.float64) @ Y_WEIGHTS, Y_FLOOR)
        out = (1.0 - t) * src_rgb * (10.0 ** logY_out / ys)[..., None] + t * out
    if not settings.paper:
        out = out * dim[..., None]
    return np.maximum(out * (display.white_cd / display.unit_cd), 0.0)


