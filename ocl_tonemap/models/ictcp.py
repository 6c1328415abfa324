"""ICtCp (ITU-R BT.2100-2, Table 6, PQ) and Delta E ITP (ITU-R BT.2124-0, Eq. 1).

The perceptual measure of the mechanism plan (``ocl_tonemap/plan/``): what a
mechanism changes on the display is measured in Delta E ITP of the light the
display emits, 1 = one just noticeable difference (BT.2124, Sec. 2). Float64
NumPy; equal to colour-science's ``RGB_to_ICtCp`` / ``delta_E(method="ITP")``
(tested), without its import time (~0.5 s) on every start of the tool.
"""

from __future__ import annotations

import numpy as np

#: Linear BT.709 -> BT.2020 (both D65; BT.2087-0, Eq. 4).
BT709_TO_BT2020 = np.array([[0.6274039, 0.3292830, 0.0433131],
                            [0.0690973, 0.9195404, 0.0113623],
                            [0.0163914, 0.0880133, 0.8955953]])
#: BT.2100 Table 6: linear BT.2020 RGB -> LMS.
RGB2020_TO_LMS = np.array([[1688, 2146, 262], [683, 2951, 462], [99, 309, 3688]]) / 4096.0
#: BT.2100 Table 6: PQ-encoded L'M'S' -> ICtCp.
LMS_P_TO_ICTCP = np.array([[2048, 2048, 0], [6610, -13613, 7003],
                           [17933, -17390, -543]]) / 4096.0
#: PQ (SMPTE ST 2084; BT.2100 Table 4) constants.
PQ_M1, PQ_M2 = 2610.0 / 16384.0, 2523.0 / 4096.0 * 128.0
PQ_C1, PQ_C2, PQ_C3 = 3424.0 / 4096.0, 2413.0 / 4096.0 * 32.0, 2392.0 / 4096.0 * 32.0
#: BT.2124 Eq. 1: Delta E ITP = 720 sqrt(dI^2 + dT^2 + dP^2), T = 0.5 Ct, P = Cp.
DE_ITP_SCALE = 720.0


def pq_inverse_eotf(L_cd) -> np.ndarray:
    """Absolute luminance (cd/m^2, clipped to 0..10000) -> PQ signal 0..1."""
    Y = np.clip(np.asarray(L_cd, np.float64) / 10000.0, 0.0, 1.0)
    Ym = Y ** PQ_M1
    return ((PQ_C1 + PQ_C2 * Ym) / (1.0 + PQ_C3 * Ym)) ** PQ_M2


def rgb709_to_ictcp(rgb_cd) -> np.ndarray:
    """Linear BT.709 light in cd/m^2 (... x 3) -> ICtCp (BT.2100, PQ)."""
    rgb = np.maximum(np.asarray(rgb_cd, np.float64), 0.0)
    lms = rgb @ (RGB2020_TO_LMS @ BT709_TO_BT2020).T
    return pq_inverse_eotf(lms) @ LMS_P_TO_ICTCP.T


def delta_e_itp(ictcp_a, ictcp_b) -> np.ndarray:
    """BT.2124 Eq. 1 between two ICtCp arrays (... x 3).

    A 1% step of a grey at 100 cd/m^2 is under one JND; the same step at 1 cd/m^2
    is smaller still (the eye resolves less in the dark):

    >>> g = lambda L: rgb709_to_ictcp([L, L, L])
    >>> round(float(delta_e_itp(g(100.0), g(101.0))), 2)
    0.72
    >>> float(delta_e_itp(g(1.0), g(1.01))) < float(delta_e_itp(g(100.0), g(101.0)))
    True
    """
    d = np.asarray(ictcp_a, np.float64) - np.asarray(ictcp_b, np.float64)
    return DE_ITP_SCALE * np.sqrt(d[..., 0] ** 2 + (0.5 * d[..., 1]) ** 2 + d[..., 2] ** 2)
