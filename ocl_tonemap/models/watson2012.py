"""Pupil diameter: Watson & Yellott 2012's unified formula, float64.

A. B. Watson and J. I. Yellott, "A unified formula for light-adapted pupil size",
Journal of Vision 12(10):12 (2012). The pupil (mm) of an observer of age y years
looking at a field of luminance L (cd/m^2) and area a (deg^2) with one or both eyes:

    F = L a M(e),  M = 1 for two eyes, 0.1 for one                     (Eq. 17)
    D_SD(F) = 7.75 - 5.75 (F/846)^0.41 / ((F/846)^0.41 + 2)             (Eq. 10, Stanley & Davies 1995)
    D_U = D_SD + (y - y0)(0.02132 - 0.009562 D_SD),  y0 = 28.58         (Eq. 22)

The age term is fitted to Winn et al. 1994's observers of 20-83 years; ages
outside are held at those ends (docs/models.md, "Observer age").

>>> round(float(pupil_diameter(1.0, 1400.0)), 3)      # dusk, a 50 x 28 degree view
5.561
>>> round(float(pupil_diameter(1.0, 1400.0, 70.0)) - float(pupil_diameter(1.0, 1400.0, 25.0)), 3)
-1.433
"""

from __future__ import annotations

import numpy as np

#: The age at which the age term vanishes, years (Eq. 22).
Y0 = 28.58
#: Winn et al.'s ages, the range of the age term's fit.
AGE_RANGE = (20.0, 83.0)


def stanley_davies(F) -> np.ndarray:
    """D_SD(F), mm, of the corneal flux density F = L a (cd/m^2 deg^2), Eq. 10."""
    x = (np.maximum(np.asarray(F, np.float64), 0.0) / 846.0) ** 0.41
    return 7.75 - 5.75 * x / (x + 2.0)


def pupil_diameter(L, area_deg2: float, age: float = Y0, eyes: int = 2) -> np.ndarray:
    """D_U, mm, Eqs. 17 and 22 (``age`` held to :data:`AGE_RANGE`)."""
    if eyes not in (1, 2):
        raise ValueError(f"eyes must be 1 or 2 (got {eyes})")
    M = 1.0 if eyes == 2 else 0.1
    D = stanley_davies(np.asarray(L, np.float64) * float(area_deg2) * M)
    y = min(max(float(age), AGE_RANGE[0]), AGE_RANGE[1])
    return D + (y - Y0) * (0.02132 - 0.009562 * D)
