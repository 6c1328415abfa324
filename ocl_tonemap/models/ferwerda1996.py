"""Ferwerda, Pattanaik, Shirley & Greenberg 1996: threshold-versus-intensity of
rods and cones, as printed in Durand & Dorsey 2000, Eqs. 1-2, and its inverse.

Units: cd/m^2 (scotopic for rods), thresholds in the same units.

>>> round(float(log_threshold_cone(100.0)), 3)     # photopic branch: log L - 1.255
0.745
>>> round(float(threshold_rod(1e-5)), 5)            # absolute rod threshold, 10^-2.86
0.00138
"""

from __future__ import annotations

import math

import numpy as np

#: Floor on adaptation luminances before the log, cd/m^2 (below every branch point).
LA_FLOOR = 1.0e-10


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


def mesopic_factor_ferwerda1996(L_wa):
    """Ferwerda et al.'s original k (Sec. 3.1), kept for comparison:
    (1 - (L_wa/2 - 0.01)/(10 - 0.01))^2 clamped to [0, 1]."""
    L = np.asarray(L_wa, np.float64)
    return np.clip(1.0 - (L / 2.0 - 0.01) / (10.0 - 0.01), 0.0, 1.0) ** 2
