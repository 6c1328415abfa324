"""Loss of acuity in the dark: Shaler 1937's data as used by Durand & Dorsey 2000,
Sec. 7 (Eqs. 9-11, Table 1).

>>> float(acuity_cutoff(1000.0))          # cycles/degree at 10^3 cd/m^2 (Table 1)
50.0
>>> float(acuity_blend(0.5)), float(acuity_blend(2.0))
(1.0, 0.0)
"""

from __future__ import annotations

import math

import numpy as np

from .convolution import EDGE_CLAMP, blur_reference, gaussian_taps

#: Shaler 1937 via Durand & Dorsey 2000, Table 1: log10 L_wa (cd/m^2) -> highest
#: visible frequency omega (cycles/degree).
SHALER_LOG_L = np.arange(-3.5, 3.01, 0.5)
SHALER_OMEGA = np.array([2.1, 2.9, 4.1, 5.5, 9.0, 16.3, 23.8, 32.5, 38.5, 43.1, 46.0, 48.0,
                         48.8, 50.0])
#: Eq. 10: a = 1.86 omega makes the Gaussian's transfer 10^-0.395 at omega.
ACUITY_A_PER_OMEGA = math.sqrt(-math.log(10.0 ** -0.395) / math.pi) ** -1
#: Sec. 7: blur below a = 1 px^-1, fade it in between 1.1 and 1 px^-1.
ACUITY_FULL, ACUITY_NONE = 1.0, 1.1


def acuity_cutoff(L_waR) -> np.ndarray:
    """omega(L_waR), cycles/degree: Table 1, linear in log10 L, held at the ends."""
    x = np.log10(np.maximum(np.asarray(L_waR, np.float64), 1e-30))
    return np.interp(x, SHALER_LOG_L, SHALER_OMEGA)


def acuity_a_px(L_waR, fov_deg: float, width: int) -> np.ndarray:
    """Eq. 11: a in cycles per pixel, 1.86 omega fov / width."""
    return ACUITY_A_PER_OMEGA * acuity_cutoff(L_waR) * fov_deg / width


def acuity_sigma_px(a_px) -> np.ndarray:
    """Standard deviation (px) of the unit-volume Gaussian a^2 exp(-pi (a r)^2)."""
    return 1.0 / (np.asarray(a_px, np.float64) * math.sqrt(2.0 * math.pi))


def acuity_blend(a_px) -> np.ndarray:
    """Share of the blurred image: 1 below a = 1 px^-1, 0 above 1.1, linear between."""
    return np.clip((ACUITY_NONE - np.asarray(a_px, np.float64)) / (ACUITY_NONE - ACUITY_FULL),
                   0.0, 1.0)


def apply_acuity(img: np.ndarray, L_waR: float, fov_deg: float, blur=None):
    """Blur a displayed frame as the eye adapted to ``L_waR`` would (clamped edges).
    Returns (image, info); ``blur(img, taps)`` defaults to the float64 reference."""
    h, w = img.shape[:2]
    a = float(acuity_a_px(L_waR, fov_deg, w))
    t = float(acuity_blend(a))
    info = {"a_px": a, "cutoff_cpd": float(acuity_cutoff(L_waR)), "blend": t,
            "sigma_px": float(acuity_sigma_px(a))}
    if t <= 0.0:
        return img, info
    taps = gaussian_taps(info["sigma_px"])
    blurred = blur(img, taps) if blur is not None else blur_reference(img, taps, EDGE_CLAMP)
    out = np.asarray(blurred, np.float64) * t + np.asarray(img, np.float64) * (1.0 - t)
    return out.astype(np.float32), info


def acuity_info(L_waR: float, fov_deg: float, width: int) -> dict:
    """What :func:`apply_acuity` reports for a frame ``width`` px wide (its blur:
    ``gaussian_taps(sigma_px)`` blended by ``blend``), without the frame."""
    a = float(acuity_a_px(L_waR, fov_deg, width))
    return {"a_px": a, "cutoff_cpd": float(acuity_cutoff(L_waR)), "blend": float(acuity_blend(a)),
            "sigma_px": float(acuity_sigma_px(a))}
