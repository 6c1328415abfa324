"""Disability glare of a point source: CIE 146:2002 (CIE equations for disability
glare), float64; the age term CIE 180:2010 takes up for road lighting.

A source that gives the illuminance E (lx) at the eye, theta degrees from the line of
sight, veils the retinal image with an equivalent luminance L_veil (cd/m^2):

    general (0.1 < theta < 100 deg):
        L_veil / E = 10/theta^3 + (5/theta^2 + 0.1 p/theta) (1 + (A/62.5)^4) + 0.0025 p
    age-adjusted Stiles-Holladay (1 < theta < 30 deg):
        L_veil / E = 10/theta^2 (1 + (A/70)^4)

A: age in years; p: the eye's pigmentation (0 black, 0.5 brown, 1 light blue-green,
1.2 very light): it matters beyond ~30 degrees.
"""

from __future__ import annotations

import numpy as np

#: CIE 146's pigmentation factors.
PIGMENT = {"black": 0.0, "brown": 0.5, "light": 1.0, "very light": 1.2}
#: Brown eyes: the pigmentation of most of the world's drivers (CIE 146's 0.5).
DEFAULT_PIGMENT = 0.5


def veil_per_lux(theta_deg, age=25.0, p: float = DEFAULT_PIGMENT) -> np.ndarray:
    """L_veil / E, (cd/m^2)/lx, CIE 146's general equation (theta held at >= 0.1 deg).

    >>> round(float(veil_per_lux(10.0, 25, 0.5)), 4)   # 0.01 + 0.055 x 1.0256 + 0.00125
    0.0677
    """
    t = np.maximum(np.asarray(theta_deg, np.float64), 0.1)
    A = np.asarray(age, np.float64)
    return 10.0 / t ** 3 + (5.0 / t ** 2 + 0.1 * p / t) * (1.0 + (A / 62.5) ** 4) + 0.0025 * p


def stiles_holladay(theta_deg, age=25.0) -> np.ndarray:
    """L_veil / E, CIE 146's age-adjusted Stiles-Holladay equation (1 .. 30 deg).

    >>> round(float(stiles_holladay(10.0, 70)), 3)      # 10/theta^2 x 2
    0.2
    """
    t = np.asarray(theta_deg, np.float64)
    return 10.0 / t ** 2 * (1.0 + (np.asarray(age, np.float64) / 70.0) ** 4)


def age_glare_factor(age) -> np.ndarray:
    """How much more an observer of ``age`` is veiled than a young one at the angles
    that rule a road's glare: (1 + (A/62.5)^4) (CIE 146's general equation)."""
    return 1.0 + (np.asarray(age, np.float64) / 62.5) ** 4
