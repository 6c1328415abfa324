"""Loss of acuity in the dark: Shaler 1937's data as used by Durand & Dorsey 2000,
Sec. 7 (Eqs. 9-11, Table 1).

Units. Table 1 is Shlaer's (the paper spells him "Shaler") grating acuity against the
luminance of his white test field: photometric units (photons, i.e. trolands, from
millilamberts), so *photopic* cd/m^2 of a tungsten white. The model's level is the
rods' adaptation L_waR in *scotopic* cd/m^2. ``mode="default"`` converts: the cones'
branch of the table (above Shlaer's rod-cone break, 4.8 cycles/degree) is read at the
photopic luminance of a working-space neutral, L_waR / :func:`neutral_scotopic_ratio`
(2.573); the rods' branch at the photopic luminance of a tungsten field that gives the
rods as much light, L_waR / :func:`source_scotopic_ratio` (illuminant A, 1.292); the
better of the two sets the cut-off. ``mode="paper"`` reads the table at L_waR itself,
as Eqs. 9-11 are printed. docs/models.md gives the sources and the numbers.

>>> float(acuity_cutoff(1000.0, mode="paper"))   # cycles/degree at 10^3 (Table 1)
50.0
>>> round(float(acuity_cutoff(0.1)), 2), float(acuity_cutoff(0.1, mode="paper"))
(10.31, 16.3)
>>> float(acuity_blend(0.5)), float(acuity_blend(2.0))
(1.0, 0.0)
"""

from __future__ import annotations

import math

import numpy as np

from .convolution import EDGE_CLAMP, blur_reference, gaussian_taps
from .photometry import neutral_scotopic_ratio, photopic_luminance, scotopic_luminance, xy_to_rgb

#: Shaler 1937 via Durand & Dorsey 2000, Table 1: log10 L (photopic cd/m^2 of Shlaer's
#: white field; the paper indexes it by L_waR) -> highest visible frequency omega
#: (cycles/degree).
SHALER_LOG_L = np.arange(-3.5, 3.01, 0.5)
SHALER_OMEGA = np.array([2.1, 2.9, 4.1, 5.5, 9.0, 16.3, 23.8, 32.5, 38.5, 43.1, 46.0, 48.0,
                         48.8, 50.0])
#: Eq. 10: a = 1.86 omega makes the Gaussian's transfer 10^-0.395 at omega.
ACUITY_A_PER_OMEGA = math.sqrt(-math.log(10.0 ** -0.395) / math.pi) ** -1
#: Sec. 7: blur below a = 1 px^-1, fade it in between 1.1 and 1 px^-1.
ACUITY_FULL, ACUITY_NONE = 1.0, 1.1

#: "default": the table read in Shlaer's units (photopic luminance of his white field)
#: converted from L_waR; "paper": the table indexed by L_waR as printed (Eqs. 9-11).
MODES = ("default", "paper")
#: Shlaer's source: a tungsten lamp, taken as CIE illuminant A (2856 K), CIE 1931 xy.
SHLAER_SOURCE_XY = (0.44757, 0.40745)
#: Shlaer's rod-cone break: visual acuity 0.16 (reciprocal minutes of one bar), rods
#: below it, cones above; a grating's cycle is two bars: 30 * 0.16 cycles/degree.
SHLAER_ROD_CONE_BREAK_CPD = 30.0 * 0.16


def _mode(mode: str) -> str:
    if mode not in MODES:
        raise ValueError(f"acuity mode {mode!r}: one of {MODES}")
    return mode


def source_scotopic_ratio() -> float:
    """Y'/Y of Shlaer's tungsten white (:data:`SHLAER_SOURCE_XY`) by the working
    space's scotopic luminance (Ward-Larson et al. 1997): 1.292 (CIE V' gives 1.41)."""
    rgb = xy_to_rgb(*SHLAER_SOURCE_XY)
    return float(scotopic_luminance(rgb) / photopic_luminance(rgb))


def table_cutoff(L) -> np.ndarray:
    """omega(L), cycles/degree: Table 1 at ``L`` in its own units (photopic cd/m^2 of
    Shlaer's white field), linear in log10 L, held at the ends."""
    x = np.log10(np.maximum(np.asarray(L, np.float64), 1e-30))
    return np.interp(x, SHALER_LOG_L, SHALER_OMEGA)


def acuity_cutoff(L_waR, mode: str = "default") -> np.ndarray:
    """omega(L_waR), cycles/degree, at the rods' adaptation ``L_waR`` (scotopic cd/m^2).

    ``mode="paper"``: Table 1 at L_waR. Default: the better of the cones, the table
    at the photopic luminance of a neutral, L_waR / 2.573, and the rods, the table at
    the photopic luminance of Shlaer's tungsten field with the same scotopic
    luminance, L_waR / 1.292, capped at his rod-cone break (4.8 cycles/degree).
    Monotone in L_waR; never above the paper's reading."""
    if _mode(mode) == "paper":
        return table_cutoff(L_waR)
    L = np.asarray(L_waR, np.float64)
    rods = np.minimum(table_cutoff(L / source_scotopic_ratio()), SHLAER_ROD_CONE_BREAK_CPD)
    return np.maximum(rods, table_cutoff(L / neutral_scotopic_ratio()))


def acuity_a_px(L_waR, fov_deg: float, width: int, mode: str = "default") -> np.ndarray:
    """Eq. 11: a in cycles per pixel, 1.86 omega fov / width."""
    return ACUITY_A_PER_OMEGA * acuity_cutoff(L_waR, mode) * fov_deg / width


#: The widest blur kept, in frame widths: a Gaussian of two frame widths is flat
#: across the frame to within 12 % (exp(-1/8)): nothing of the frame's detail is left
#: at the blend that reaches it (a < 1/(2 sqrt(2 pi) W) px^-1, far below ACUITY_FULL),
#: and a wider one costs taps in proportion (a field of view of 0.01 degrees at night
#: asks for ~1e4 frame widths).
SIGMA_MAX_WIDTHS = 2.0


def acuity_sigma_px(a_px, width: int | None = None) -> np.ndarray:
    """Standard deviation (px) of the unit-volume Gaussian a^2 exp(-pi (a r)^2); with
    ``width``, at most :data:`SIGMA_MAX_WIDTHS` frame widths."""
    s = 1.0 / (np.asarray(a_px, np.float64) * math.sqrt(2.0 * math.pi))
    return s if width is None else np.minimum(s, SIGMA_MAX_WIDTHS * max(int(width), 1))


def acuity_blend(a_px) -> np.ndarray:
    """Share of the blurred image: 1 below a = 1 px^-1, 0 above 1.1, linear between."""
    return np.clip((ACUITY_NONE - np.asarray(a_px, np.float64)) / (ACUITY_NONE - ACUITY_FULL),
                   0.0, 1.0)


def apply_acuity(img: np.ndarray, L_waR: float, fov_deg: float, blur=None,
                 mode: str = "default"):
    """Blur a displayed frame as the eye adapted to ``L_waR`` would (clamped edges).
    Returns (image, info); ``blur(img, taps)`` defaults to the float64 reference;
    ``mode``: :data:`MODES`."""
    h, w = img.shape[:2]
    a = float(acuity_a_px(L_waR, fov_deg, w, mode))
    t = float(acuity_blend(a))
    info = {"a_px": a, "cutoff_cpd": float(acuity_cutoff(L_waR, mode)), "blend": t,
            "sigma_px": float(acuity_sigma_px(a, w))}
    if t <= 0.0:
        return img, info
    taps = gaussian_taps(info["sigma_px"])
    blurred = blur(img, taps) if blur is not None else blur_reference(img, taps, EDGE_CLAMP)
    out = np.asarray(blurred, np.float64) * t + np.asarray(img, np.float64) * (1.0 - t)
    return out.astype(np.float32), info


def acuity_info(L_waR: float, fov_deg: float, width: int, mode: str = "default") -> dict:
    """What :func:`apply_acuity` reports for a frame ``width`` px wide (its blur:
    ``gaussian_taps(sigma_px)`` blended by ``blend``), without the frame."""
    a = float(acuity_a_px(L_waR, fov_deg, width, mode))
    return {"a_px": a, "cutoff_cpd": float(acuity_cutoff(L_waR, mode)),
            "blend": float(acuity_blend(a)),
            "sigma_px": float(acuity_sigma_px(a, width))}
