"""Photometry in the working space: luminances and the bad-value policy.

The working space is linear light with ITU-R BT.709 primaries and a D65 white
(OCIO name ``lin_rec709``), in absolute units: 1.0 = 1 cd/m^2 after the
luminance scale is applied. All functions here are the float64 reference; the
OpenCL versions live in ``kernels/colour.cl`` and must agree with these.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: BT.709 / sRGB linear RGB -> CIE XYZ (D65), IEC 61966-2-1 at float64.
RGB709_TO_XYZ = np.array([
    [0.4123907992659595, 0.3575843393838780, 0.1804807884018343],
    [0.2126390058715104, 0.7151686787677560, 0.0721923153607337],
    [0.0193308187155918, 0.1191947797946260, 0.9505321522496606],
])

#: Photopic luminance weights of the working space (the Y row above).
Y_WEIGHTS = RGB709_TO_XYZ[1]

#: Ward-Larson, Rushmeier & Piatko 1997's scotopic luminance from XYZ (scotopic_luminance):
#: Y' = Y (WARD97_GAIN (1 + (Y + Z) / X) - WARD97_OFFSET).
WARD97_GAIN, WARD97_OFFSET = 1.33, 1.68

#: Ceiling applied to scene values, cd/m^2 (+Inf maps here). The brief's
#: range of vision is 1e-6 .. 1e8 cd/m^2; two decades of headroom.
L_MAX = 1.0e10

#: Smallest normal float32; positive values below it are flushed to 0.
FLT_MIN = float(np.finfo(np.float32).tiny)


def photopic_luminance(rgb: np.ndarray) -> np.ndarray:
    """CIE photopic luminance Y (cd/m^2) of working-space RGB (cd/m^2)."""
    return np.asarray(rgb, np.float64)[..., :3] @ Y_WEIGHTS


def scotopic_luminance(rgb: np.ndarray) -> np.ndarray:
    """Scotopic luminance Y' (scotopic cd/m^2) of working-space RGB.

    Ward-Larson, Rushmeier & Piatko 1997 (Pattanaik 2000 ref. [26]), the
    approximation the tone-mapping literature uses for CIE V'(lambda):
    ``Y' = Y * (1.33 * (1 + (Y + Z) / X) - 1.68)``.
    For non-negative RGB, X >= 0.18 (R+G+B) so the ratio is bounded; X == 0
    only for black, where Y' = 0.
    """
    xyz = np.asarray(rgb, np.float64)[..., :3] @ RGB709_TO_XYZ.T
    X, Y, Z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        ys = Y * (WARD97_GAIN * (1.0 + (Y + Z) / X) - WARD97_OFFSET)
    return np.where(X > 0, np.maximum(ys, 0.0), 0.0)


def neutral_scotopic_ratio() -> float:
    """Y'/Y of the working-space white (D65): a neutral field of L cd/m^2
    has scotopic luminance ``L * neutral_scotopic_ratio()``."""
    return float(scotopic_luminance(np.ones(3)))


@dataclass
class RepairCounts:
    """How many channel values the bad-value policy repaired, by kind."""

    nan: int = 0
    pos_inf: int = 0
    neg_inf: int = 0
    negative: int = 0
    denormal: int = 0
    over_max: int = 0

    KEYS = ("nan", "pos_inf", "neg_inf", "negative", "denormal", "over_max")

    @property
    def total(self) -> int:
        return sum(getattr(self, k) for k in self.KEYS)

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.KEYS}

    def __iadd__(self, other: "RepairCounts"):
        for k in self.KEYS:
            setattr(self, k, getattr(self, k) + getattr(other, k))
        return self

    def summary(self) -> str:
        parts = [f"{k}={getattr(self, k)}" for k in self.KEYS if getattr(self, k)]
        return ", ".join(parts) if parts else "none"



def sanitize(rgb: np.ndarray, scale: float) -> tuple[np.ndarray, RepairCounts]:
    """Apply the bad-value policy and the luminance scale (float64 reference).

    Policy, per channel, classified on the *input* value:
      NaN -> 0; -Inf -> 0; finite negative -> 0; positive float32 denormal
      (0 < x < FLT_MIN) -> 0; +Inf -> L_MAX. Then ``x * scale``; results above
      L_MAX are clamped to L_MAX (counted as ``over_max``).
    Returns the repaired, scaled copy (cd/m^2) and the counts.
    """
    x = np.asarray(rgb, np.float64)
    c = RepairCounts()
    nan = np.isnan(x)
    pinf = np.isposinf(x)
    ninf = np.isneginf(x)
    neg = (x < 0) & ~ninf
    den = (x > 0) & (x < FLT_MIN)
    c.nan, c.pos_inf, c.neg_inf = int(nan.sum()), int(pinf.sum()), int(ninf.sum())
    c.negative, c.denormal = int(neg.sum()), int(den.sum())
    y = np.where(nan | ninf | neg | den, 0.0, x)
    y = np.where(pinf, L_MAX, y * scale)
    over = (y > L_MAX) & ~pinf
    c.over_max = int(over.sum())
    return np.minimum(y, L_MAX), c


# --- chromaticities ---------------------------------------------------------------

def xy_to_rgb(x: float, y: float) -> np.ndarray:
    """Working-space (BT.709) RGB of chromaticity (x, y), normalised to luminance 1."""
    if not (y > 0 and x >= 0 and x + y <= 1):
        raise ValueError(f"bad chromaticity ({x}, {y})")
    XYZ = np.array([x / y, 1.0, (1.0 - x - y) / y])
    return normalise_illuminant(np.linalg.solve(RGB709_TO_XYZ, XYZ))


def normalise_illuminant(rgb) -> np.ndarray:
    """(r_wa, g_wa, b_wa): the illuminant's colour at luminance 1, channels >= 1e-3
    (a pure primary would need an infinite von Kries gain)."""
    v = np.maximum(np.asarray(rgb, np.float64), 0.0)
    Y = float(v @ Y_WEIGHTS)
    if not (Y > 0 and np.all(np.isfinite(v))):
        return np.ones(3)
    v = np.maximum(v / Y, 1e-3)
    return v / float(v @ Y_WEIGHTS)
