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

The two public implementations of the model (TU Berlin's ``calcDeltaL.m``, Adrian
1989, and ``calcDeltaL_RP800.m``, ANSI/IESNA RP-8-00 with its errata) differ in
seven places (D1-D7); :class:`Variant` holds each choice, :data:`ADRIAN_1989` this
project's (``--adrian 1989``, the default) and :data:`RP8` RP-8-00's as printed
(``--adrian rp8``, what North American road-lighting software computes).
docs/models.md ("Adrian's choices") gives each choice and its reason.
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
#: The fits' coefficients, named once.
#: sqrt(Phi): log10(c L^PHI_HIGH[0]) + PHI_HIGH[1] L^PHI_HIGH[2] above L_HIGH (c the
#: variant's ricco_high, D1); 10^(PHI_MID . (1, x, x^2)) between; 10^(PHI_LOW . (1, x))
#: below (x = log10 L_b).
PHI_HIGH = (0.1556, 0.1684, 0.5867)
PHI_MID = (-0.072, 0.3372, 0.0866)
PHI_LOW = (0.028, 0.173)
#: sqrt(L): WEBER_HIGH[0] L^WEBER_HIGH[1] above L_HIGH; 10^(WEBER_MID . (1, x)) between;
#: 10^(WEBER_LOW . (1, x, x^2)) below.
WEBER_HIGH = (0.05946, 0.466)
WEBER_MID = (-1.256, 0.319)
WEBER_LOW = (-0.891, 0.5275, 0.0227)
#: F_cp: c = FCP_C[0] at L_b >= FCP_C_SPLIT, else FCP_C[1]; m = 10^-(10^-(c (x + 1)^2
#: + FCP_M_OFFSET)); beta = FCP_BETA[0] L_b^FCP_BETA[1]; F_cp = 1 - m alpha^-beta /
#: (FCP_DIVISOR dL_pos).
FCP_C = (0.125, 0.075)
FCP_C_SPLIT = 0.1
FCP_M_OFFSET = 0.0245
FCP_BETA = (0.6, -0.1488)
FCP_DIVISOR = 2.4
#: a(alpha) = A_ALPHA[0] - A_ALPHA[1] u^2 / (u^2 - A_ALPHA[2] u + c), u = log alpha +
#: A_ALPHA[3] (c the variant's, D7); a(L_b) = A_LUM[0] - A_LUM[1] w^2 / (w^2 - A_LUM[2] w
#: + A_LUM[3]), w = log L_b + A_LUM[4]; a = sqrt(a(alpha)^2 + a(L_b)^2) / A_DIVISOR.
A_ALPHA = (0.36, 0.0972, 2.513, 0.523)
A_LUM = (0.355, 0.1217, 10.4, 52.28, 6.0)
A_DIVISOR = 2.1
#: AF: (A - AGE_LOW[0])^2 / AGE_LOW[1] + AGE_LOW[2] up to AGE_MID; (A - c)^2 /
#: AGE_HIGH[0] + AGE_HIGH[1] above (c the variant's, D5).
AGE_LOW = (19.0, 2160.0, 0.99)
AGE_HIGH = (116.3, 1.43)
#: F_cp is taken with its dL_pos at a field factor of at least this: both public
#: implementations put k into dL_pos, and below RP-8's 2.6 (the laboratory's k = 1)
#: F_cp turns negative for 4-60 arcmin targets at mesopic levels (docs/models.md, D2).
FCP_MIN_FIELD_FACTOR = FIELD_FACTOR


@dataclass(frozen=True)
class Variant:
    """Where the public forms of Adrian's model differ (docs/models.md, D1-D7)."""

    name: str
    ricco_high: float         # D1: the Ricco fit's constant above L_HIGH
    fcp_time: float | None    # D2: F_cp's dL_pos at this look (s); None: a long one
    fcp_low: float | None     # D3: F_cp at L_b <= fcp_low_L; None: the fit held at its edge
    fcp_low_L: float          # D3: where F_cp's fit ends below
    age_hi_centre: float      # D5: the upper age fit's centre, (A - c)^2/116.3 + 1.43
    a_alpha_c: float          # D7: the constant of a(alpha)'s denominator

    def as_dict(self) -> dict:
        return asdict(self)


#: This project's reading (``--adrian 1989``): D1 RP-8's constant (the fits join
#: within 0.3 %; Adrian's printed 4.1925 leaves a 1-2 % step at 0.6 cd/m^2), D2 a
#: long look (Adrian's), D3 the fit held at its edge (continuous; TU Berlin's 1 and
#: RP-8's 0.5 are steps), D4 every look (no 7 % jump at 2 s: both variants), D5 RP-8's
#: 56.5 (the smaller step at 64: both), D7 Adrian's 2.7895.
ADRIAN_1989 = Variant("1989", ricco_high=4.2841, fcp_time=None, fcp_low=None,
                      fcp_low_L=0.004, age_hi_centre=56.5, a_alpha_c=2.7895)
#: ANSI/IESNA RP-8-00 with its errata, as ``calcDeltaL_RP800.m`` computes it.
RP8 = Variant("rp8", ricco_high=4.2841, fcp_time=2.0, fcp_low=0.5,
              fcp_low_L=10.0 ** -2.4, age_hi_centre=56.5, a_alpha_c=2.789)
VARIANTS = {v.name: v for v in (ADRIAN_1989, RP8)}


def variant(name) -> Variant:
    """A :class:`Variant` by name (``1989``, ``rp8``), or one given as it is."""
    if isinstance(name, Variant):
        return name
    try:
        return VARIANTS[str(name)]
    except KeyError:
        raise ValueError(f"--adrian must be {' or '.join(VARIANTS)} (got {name!r})") from None


def _log(L) -> np.ndarray:
    return np.log10(np.maximum(np.asarray(L, np.float64), 1e-12))


def sqrt_phi(L_b, v: Variant = ADRIAN_1989) -> np.ndarray:
    """sqrt(Phi), Ricco's part (luminous flux at threshold of a point target), by
    the range of L_b."""
    L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
    x = _log(L)
    a, b, e = PHI_HIGH
    hi = np.log10(v.ricco_high * L ** a) + b * L ** e                   # L_b >= 0.6
    mid = 10.0 ** (PHI_MID[0] + PHI_MID[1] * x + PHI_MID[2] * x * x)    # 0.00418 .. 0.6
    lo = 10.0 ** (PHI_LOW[0] + PHI_LOW[1] * x)                          # <= 0.00418
    return np.where(L >= L_HIGH, hi, np.where(L > L_LOW, mid, lo))


def sqrt_weber(L_b) -> np.ndarray:
    """sqrt(L), Weber's part (the luminance difference at threshold of a large
    target), by the range of L_b.

    >>> round(float(sqrt_weber(1.0)), 5)          # 0.05946 L_b^0.466 at 1 cd/m^2
    0.05946
    """
    L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
    x = _log(L)
    hi = WEBER_HIGH[0] * L ** WEBER_HIGH[1]                                 # L_b >= 0.6
    mid = 10.0 ** (WEBER_MID[0] + WEBER_MID[1] * x)                         # 0.00418 .. 0.6
    lo = 10.0 ** (WEBER_LOW[0] + WEBER_LOW[1] * x + WEBER_LOW[2] * x * x)   # <= 0.00418
    return np.where(L >= L_HIGH, hi, np.where(L > L_LOW, mid, lo))


def basic_threshold(L_b, alpha, v: Variant = ADRIAN_1989) -> np.ndarray:
    """(sqrt(Phi)/alpha + sqrt(L))^2, cd/m^2: the 50 % threshold of a positive
    target seen for a long time by a young observer (k = 1)."""
    a = np.maximum(np.asarray(alpha, np.float64), 1e-6)
    return (sqrt_phi(L_b, v) / a + sqrt_weber(L_b)) ** 2


def negative_gain(L_b, alpha) -> np.ndarray:
    """m alpha^-beta / 2.4, cd/m^2: how much less a negative target's threshold is
    than a positive one's (F_cp = 1 - this / dL_pos), with m = 10^-(10^-(c (log L_b
    + 1)^2 + 0.0245)), c = 0.125 (L_b >= 0.1) or 0.075, beta = 0.6 L_b^-0.1488."""
    L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
    c = np.where(L >= FCP_C_SPLIT, *FCP_C)
    m = 10.0 ** (-(10.0 ** (-(c * (_log(L) + 1.0) ** 2 + FCP_M_OFFSET))))
    beta = FCP_BETA[0] * L ** FCP_BETA[1]
    a = np.maximum(np.asarray(alpha, np.float64), 1e-6)
    return m * a ** -beta / FCP_DIVISOR


def polarity_factor(L_b, alpha, k: float = FIELD_FACTOR,
                    v: Variant = ADRIAN_1989) -> np.ndarray:
    """F_cp of a negative-contrast target, 1 - m alpha^-beta / (2.4 dL_pos)
    (:func:`negative_gain`): dL_pos the positive target's threshold with the field
    factor (at least :data:`FCP_MIN_FIELD_FACTOR`), at ``v.fcp_time`` (a long look:
    None); below ``v.fcp_low_L`` the variant's constant, or (None) the fit's value at
    that edge."""
    L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
    a = np.asarray(alpha, np.float64)
    kk = max(float(k), FCP_MIN_FIELD_FACTOR)

    def fcp(Lx):
        pos = kk * basic_threshold(Lx, a, v)
        if v.fcp_time is not None:
            pos = pos * time_factor(Lx, a, v.fcp_time, v)
        return 1.0 - negative_gain(Lx, a) / pos
    low = L <= v.fcp_low_L
    if v.fcp_low is not None:
        return np.where(low, v.fcp_low, fcp(np.where(low, 1.0, L)))
    return fcp(np.maximum(L, np.nextafter(v.fcp_low_L, np.inf)))


def time_constant(L_b, alpha, v: Variant = ADRIAN_1989) -> np.ndarray:
    """a(alpha, L_b), s: sqrt(a(alpha)^2 + a(L_b)^2) / 2.1 with
    a(alpha) = 0.36 - 0.0972 u^2 / (u^2 - 2.513 u + 2.7895), u = log alpha + 0.523;
    a(L_b) = 0.355 - 0.1217 v^2 / (v^2 - 10.4 v + 52.28), v = log L_b + 6."""
    w = _log(L_b) + A_LUM[4]
    a_L = A_LUM[0] - A_LUM[1] * w * w / (w * w - A_LUM[2] * w + A_LUM[3])
    return np.sqrt(a_alpha(alpha, v) ** 2 + a_L ** 2) / A_DIVISOR


def a_alpha(alpha, v: Variant = ADRIAN_1989) -> np.ndarray:
    """a(alpha), s: the size's part of the time constant (D7: the variant's constant)."""
    u = _log(np.maximum(np.asarray(alpha, np.float64), 1e-6)) + A_ALPHA[3]
    return A_ALPHA[0] - A_ALPHA[1] * u * u / (u * u - A_ALPHA[2] * u + v.a_alpha_c)


def time_factor(L_b, alpha, t, v: Variant = ADRIAN_1989) -> np.ndarray:
    """(a(alpha, L_b) + t) / t: a look of t seconds against a long one (1 for t ->
    inf; Adrian's own data go to 2 s). For every t and size in both variants (D4:
    TU Berlin's transcription of the paper applies it below 2 s and 60 arcmin only,
    a 7 % step at 2 s)."""
    t = np.maximum(np.asarray(t, np.float64), 1e-3)
    return (time_constant(L_b, alpha, v) + t) / t


def age_factor(age, v: Variant = ADRIAN_1989) -> np.ndarray:
    """AF(A): (A - 19)^2 / 2160 + 0.99 up to 64, (A - 56.5)^2 / 116.3 + 1.43 above
    (D5: RP-8's centre and boundary; TU Berlin's transcription takes 56.6 from 64 on);
    AF(23) below 23, the second fit continued above 75.

    >>> round(float(age_factor(23)), 4), round(float(age_factor(60)), 4)
    (0.9974, 1.7682)
    """
    A = np.maximum(np.asarray(age, np.float64), AGE_MIN)
    return np.where(A > AGE_MID, (A - v.age_hi_centre) ** 2 / AGE_HIGH[0] + AGE_HIGH[1],
                    (A - AGE_LOW[0]) ** 2 / AGE_LOW[1] + AGE_LOW[2])


def threshold_of(L_b, alpha, age, t, negative, k: float = FIELD_FACTOR,
                 v: Variant = ADRIAN_1989) -> np.ndarray:
    """dL_th, cd/m^2, of backgrounds ``L_b`` (any shape; the eye adapted to each),
    ``negative`` per element (True: a target darker than its background), a look of
    ``t`` s (math.inf: a long one)."""
    L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
    neg = np.asarray(negative, bool)
    fcp = np.where(neg, polarity_factor(L, alpha, k, v), 1.0) if neg.any() else 1.0
    tf = 1.0 if math.isinf(float(t)) else time_factor(L, alpha, t, v)
    return k * basic_threshold(L, alpha, v) * fcp * tf * age_factor(age, v)


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
    adrian: str = ADRIAN_1989.name

    @property
    def contrast(self) -> float:
        """The threshold as a contrast, dL_th / L_b."""
        return self.dL_th / self.L_b if self.L_b > 0 else math.inf

    def as_dict(self) -> dict:
        return {**asdict(self), "C_th": self.contrast}


def threshold(L_b: float, alpha: float = 10.0, age: float = 23.0, t: float = 2.0,
              polarity: str = "positive", k: float = FIELD_FACTOR,
              v: Variant | str = ADRIAN_1989) -> Threshold:
    """Adrian's dL_th with its terms. ``polarity`` "positive" (brighter than the
    background) or "negative"; ``t`` the observation time, s (math.inf: a long look)."""
    v = variant(v)
    if polarity not in ("positive", "negative"):
        raise ValueError(f"polarity must be positive or negative (got {polarity!r})")
    L_b, alpha = float(L_b), float(alpha)
    if not (L_b > 0 and math.isfinite(L_b)):
        raise ValueError(f"the background luminance must be > 0 cd/m^2 (got {L_b})")
    if not (alpha > 0 and math.isfinite(alpha)):
        raise ValueError(f"the target size must be > 0 arcmin (got {alpha})")
    if not (k > 0 and math.isfinite(k)):
        raise ValueError(f"the field factor k must be > 0 (got {k})")
    base = float(basic_threshold(L_b, alpha, v))
    fcp = float(polarity_factor(L_b, alpha, k, v)) if polarity == "negative" else 1.0
    tf = 1.0 if math.isinf(t) else float(time_factor(L_b, alpha, t, v))
    af = float(age_factor(age, v))
    dl = float(threshold_of(L_b, alpha, age, t, polarity == "negative", k, v))
    return Threshold(L_b, alpha, float(age), float(t), polarity, float(k),
                     float(sqrt_phi(L_b, v)), float(sqrt_weber(L_b)), base, fcp, tf, af,
                     dl, v.name)


def visibility_level(dL: float, th: Threshold) -> float:
    """VL = |dL| / dL_th (CIE 140), the target's difference from its background over
    the threshold of its polarity."""
    return abs(float(dL)) / th.dL_th
