"""Visibility of a target: Adrian 1989's threshold luminance difference, float64.

W. Adrian, "Visibility of targets: model for calculation", Lighting Research and
Technology 21(4):181-188 (1989); the same model as ANSI/IES RP-8's small target
visibility and van Bommel, *Road Lighting* (2015), Appendix. A target of angular
size alpha (arcmin, the diameter of a disc of the same area) on a background of
luminance L_b (cd/m^2, the eye adapted to it) is seen when it differs from it by
at least

    dL_th = k (sqrt(Phi)/alpha + sqrt(L))^2 F_cp (a(alpha, L_b) + t) / t AF(A)

- sqrt(Phi) (Ricco's law, small targets) and sqrt(L) (Weber's law, large ones):
  three ranges of L_b, :func:`sqrt_phi`, :func:`sqrt_weber` (Eqs. 1-3 of the
  model as RP-8 and van Bommel print it);
- F_cp: negative contrast (a target darker than its background) against positive,
  :func:`polarity_factor`;
- (a + t)/t: observation time t (s), a(alpha, L_b) the time constant,
  :func:`time_factor`; its limit for long looks is 1;
- AF(A): the observer's age, :func:`age_factor` (1 at 23, 1.77 at 60);
- k: 2.6, the field factor that takes the laboratory's 50 % threshold to the
  99.93 % of a driver's detection (RP-8; ``k=1``: the laboratory's).

The visibility level of a target of luminance difference dL is VL = dL / dL_th
(CIE 140: 1 the threshold, road lighting asks 5 to 10).

Reconstructions and the ranges taken beyond Adrian's data are in docs/models.md
("Visibility: Adrian 1989").
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

#: RP-8's field factor: the 50 % threshold of the laboratory to 99.93 % detection.
FIELD_FACTOR = 2.6
#: The ranges of L_b (cd/m^2) of the model's three fits.
L_LOW, L_HIGH = 0.00418, 0.6
#: Adrian's ages: AF's fits hold for 23 .. 75 years; younger observers take AF(23),
#: older ones the second fit continued (docs/models.md).
AGE_MIN, AGE_MID, AGE_MAX = 23.0, 64.0, 75.0


def _log(L) -> np.ndarray:
    return np.log10(np.maximum(np.asarray(L, np.float64), 1e-12))


def sqrt_phi(L_b) -> np.ndarray:
    """sqrt(Phi), Ricco's part (luminous flux at threshold of a point target), by
    the range of L_b."""
    L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
    x = _log(L)
    hi = np.log10(4.1925 * L ** 0.1556) + 0.1684 * L ** 0.5867       # L_b >= 0.6
    mid = 10.0 ** (-0.072 + 0.3372 * x + 0.0866 * x * x)            # 0.00418 .. 0.6
    lo = 10.0 ** (0.028 + 0.173 * x)                                 # <= 0.00418
    return np.where(L >= L_HIGH, hi, np.where(L > L_LOW, mid, lo))


def sqrt_weber(L_b) -> np.ndarray:
    """sqrt(L), Weber's part (the luminance difference at threshold of a large
    target), by the range of L_b.

    >>> round(float(sqrt_weber(1.0)), 5)          # 0.05946 L_b^0.466 at 1 cd/m^2
    0.05946
    """
    L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
    x = _log(L)
    hi = 0.05946 * L ** 0.466                                        # L_b >= 0.6
    mid = 10.0 ** (-1.256 + 0.319 * x)                               # 0.00418 .. 0.6
    lo = 10.0 ** (-0.891 + 0.5275 * x + 0.0227 * x * x)              # <= 0.00418
    return np.where(L >= L_HIGH, hi, np.where(L > L_LOW, mid, lo))


def basic_threshold(L_b, alpha) -> np.ndarray:
    """(sqrt(Phi)/alpha + sqrt(L))^2, cd/m^2: the 50 % threshold of a positive
    target seen for a long time by a young observer (k = 1)."""
    a = np.maximum(np.asarray(alpha, np.float64), 1e-6)
    return (sqrt_phi(L_b) / a + sqrt_weber(L_b)) ** 2


def polarity_factor(L_b, alpha, dL_positive) -> np.ndarray:
    """F_cp of a negative-contrast target: 1 - m alpha^-beta / (2.4 dL_pos), with
    m = 10^-(10^-(c (log L_b + 1)^2 + 0.0245)), c = 0.125 (L_b >= 0.1) or 0.075, and
    beta = 0.6 L_b^-0.1488. ``dL_positive``: the positive target's threshold, the
    field factor included (as TU Berlin's implementation of the model takes it:
    docs/models.md)."""
    L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
    c = np.where(L >= 0.1, 0.125, 0.075)
    m = 10.0 ** (-(10.0 ** (-(c * (_log(L) + 1.0) ** 2 + 0.0245))))
    beta = 0.6 * L ** -0.1488
    a = np.maximum(np.asarray(alpha, np.float64), 1e-6)
    return 1.0 - m * a ** -beta / (2.4 * np.asarray(dL_positive, np.float64))


def time_constant(L_b, alpha) -> np.ndarray:
    """a(alpha, L_b), s: sqrt(a(alpha)^2 + a(L_b)^2) / 2.1 with
    a(alpha) = 0.36 - 0.0972 u^2 / (u^2 - 2.513 u + 2.7895), u = log alpha + 0.523;
    a(L_b) = 0.355 - 0.1217 v^2 / (v^2 - 10.4 v + 52.28), v = log L_b + 6."""
    u = _log(np.maximum(np.asarray(alpha, np.float64), 1e-6)) + 0.523
    a_alpha = 0.36 - 0.0972 * u * u / (u * u - 2.513 * u + 2.7895)
    v = _log(L_b) + 6.0
    a_L = 0.355 - 0.1217 * v * v / (v * v - 10.4 * v + 52.28)
    return np.sqrt(a_alpha ** 2 + a_L ** 2) / 2.1


def time_factor(L_b, alpha, t) -> np.ndarray:
    """(a(alpha, L_b) + t) / t: a look of t seconds against a long one (1 for t ->
    inf; Adrian's own data go to 2 s)."""
    t = np.maximum(np.asarray(t, np.float64), 1e-3)
    return (time_constant(L_b, alpha) + t) / t


def age_factor(age) -> np.ndarray:
    """AF(A): (A - 19)^2 / 2160 + 0.99 for 23 <= A < 64, (A - 56.6)^2 / 116.3 + 1.43
    for 64 <= A <= 75; AF(23) below 23, the second fit continued above 75.

    >>> round(float(age_factor(23)), 4), round(float(age_factor(60)), 4)
    (0.9974, 1.7682)
    """
    A = np.maximum(np.asarray(age, np.float64), AGE_MIN)
    return np.where(A < AGE_MID, (A - 19.0) ** 2 / 2160.0 + 0.99,
                    (A - 56.6) ** 2 / 116.3 + 1.43)


#: The largest transient factor kept (an eye adapted 14 decades away: seen as blind).
TAF_MAX = 1.0e6


def transient_factor(slope_steady, slope_now) -> np.ndarray:
    """TAF: how much higher the threshold is while the eye is adapted elsewhere than
    the background (Adrian 1987; CIE 88's threshold zone). Reconstructed as the
    ratio of the observer's response gain dR/dln L at L_b when adapted to L_b to its
    gain under its present state (each operator's own response: docs/models.md,
    "Transient adaptation"), never below 1 (an eye off its level sees no better),
    at most :data:`TAF_MAX`."""
    s_now = np.maximum(np.asarray(slope_now, np.float64), 1e-300)
    return np.clip(np.asarray(slope_steady, np.float64) / s_now, 1.0, TAF_MAX)


@dataclass(frozen=True)
class Threshold:
    """dL_th and its terms (cd/m^2 and factors), for a table or JSON."""

    L_b: float
    alpha_arcmin: float
    age: float
    time_s: float
    polarity: str
    k: float
    sqrt_phi: float
    sqrt_weber: float
    basic: float                 # (sqrt(Phi)/alpha + sqrt(L))^2
    F_cp: float
    time_factor: float
    age_factor: float
    dL_th: float

    @property
    def contrast(self) -> float:
        """The threshold as a contrast, dL_th / L_b."""
        return self.dL_th / self.L_b if self.L_b > 0 else math.inf

    def as_dict(self) -> dict:
        return {**asdict(self), "C_th": self.contrast}


def threshold(L_b: float, alpha: float = 10.0, age: float = 23.0, t: float = 2.0,
              polarity: str = "positive", k: float = FIELD_FACTOR) -> Threshold:
    """Adrian's dL_th with its terms. ``polarity`` "positive" (brighter than the
    background) or "negative"; ``t`` the observation time, s (math.inf: a long look)."""
    if polarity not in ("positive", "negative"):
        raise ValueError(f"polarity must be positive or negative (got {polarity!r})")
    L_b, alpha = float(L_b), float(alpha)
    if not (L_b > 0 and math.isfinite(L_b)):
        raise ValueError(f"the background luminance must be > 0 cd/m^2 (got {L_b})")
    if not alpha > 0:
        raise ValueError(f"the target size must be > 0 arcmin (got {alpha})")
    base = float(basic_threshold(L_b, alpha))
    fcp = float(polarity_factor(L_b, alpha, k * base)) if polarity == "negative" else 1.0
    tf = 1.0 if math.isinf(t) else float(time_factor(L_b, alpha, t))
    af = float(age_factor(age))
    return Threshold(L_b, alpha, float(age), float(t), polarity, float(k),
                     float(sqrt_phi(L_b)), float(sqrt_weber(L_b)), base, fcp, tf, af,
                     k * base * fcp * tf * af)


def visibility_level(dL: float, th: Threshold) -> float:
    """VL = |dL| / dL_th (CIE 140), the target's difference from its background over
    the threshold of its polarity."""
    return abs(float(dL)) / th.dL_th
