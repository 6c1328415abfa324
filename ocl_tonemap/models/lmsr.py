"""Receptor responses LMSR (Kirk & O'Brien 2011, Sec. 3.2 and 4).

Sensitivities come from colour-science's datasets, not hand-typed tables:
Stockman & Sharpe 2000 2-degree cone fundamentals (L, M, S) and the CIE 1951
scotopic luminous efficiency V'(lambda) (rods).

Units. Each cone fundamental is scaled to the peak Kirk & O'Brien give for it
(l_max = 0.637, m_max = 0.392, s_max = 1.606, Sec. 3.2 after Eq. 12), and
radiance is weighted by 683 lm/W, so that L + M is close to photopic luminance
(cd/m^2) as in the cone-troland convention of Cao et al. 2008 the constants
come from; the rod response is scotopic luminance (1700 lm/W x V', scotopic
cd/m^2). ``kirk11`` scales them into the units of Eq. 10 (``model_scale``).

From spectral radiance (W sr^-1 m^-2 nm^-1 sampled at wavelengths), Eq. 8 is
integrated exactly for the piecewise-linear spectrum through the samples.
From RGB (linear BT.709, cd/m^2), a fitted 4x3 matrix H (Sec. 4): see
``benchmarks/lib/fit_lmsr.py`` and ``ocl_tonemap/data/rgb_to_lmsr.json``.
"""

from __future__ import annotations

import functools
import json
import warnings
from pathlib import Path

import numpy as np

from .photometry import RGB709_TO_XYZ

#: Peaks of the cone fundamentals in Kirk & O'Brien's units (Sec. 3.2).
L_MAX, M_MAX, S_MAX = 0.637, 0.392, 1.606
KM_PHOTOPIC, KM_SCOTOPIC = 683.0, 1700.0
#: Integration grid, nm (the cone fundamentals start at 390).
WL = np.arange(390.0, 781.0, 1.0)
FIT_FILE = Path(__file__).resolve().parent.parent / "data" / "rgb_to_lmsr.json"


def colour_module():
    """colour-science, imported quietly (it warns that SciPy is absent; we need none)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
        import colour.colorimetry  # noqa: F401
    return colour


def _on_grid(wl, values) -> np.ndarray:
    return np.interp(WL, np.asarray(wl, np.float64), np.asarray(values, np.float64),
                     left=0.0, right=0.0)


@functools.lru_cache(maxsize=1)
def sensitivities() -> np.ndarray:
    """(4, len(WL)): L, M, S scaled to l_max, m_max, s_max, times 683; rod V' x 1700."""
    colour = colour_module()
    from colour.colorimetry import MSDS_CMFS_LMS, SDS_LEFS_SCOTOPIC
    lms = MSDS_CMFS_LMS["Stockman & Sharpe 2 Degree Cone Fundamentals"]
    rod = SDS_LEFS_SCOTOPIC["CIE 1951 Scotopic Standard Observer"]
    out = []
    for k, peak in enumerate((L_MAX, M_MAX, S_MAX)):
        c = _on_grid(lms.wavelengths, lms.values[:, k])
        out.append(KM_PHOTOPIC * peak * c / c.max())
    out.append(KM_SCOTOPIC * _on_grid(rod.wavelengths, rod.values))
    del colour
    return np.array(out)


@functools.lru_cache(maxsize=1)
def xyz_cmfs() -> np.ndarray:
    """(3, len(WL)) CIE 1931 2-degree colour-matching functions x 683 (cd/m^2 for Y)."""
    colour = colour_module()
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    return np.array([KM_PHOTOPIC * _on_grid(cmfs.wavelengths, cmfs.values[:, k])
                     for k in range(3)])


def spectrum_weights(wavelengths, curves: np.ndarray | None = None) -> np.ndarray:
    """(n_curves, N) weights so that response = W @ samples, for a spectrum that is
    piecewise linear through samples at ``wavelengths`` (nm, increasing) and zero
    outside them: the exact integral of Eq. 8 for that spectrum."""
    lam = np.asarray(wavelengths, np.float64)
    if lam.ndim != 1 or len(lam) < 2 or np.any(np.diff(lam) <= 0):
        raise ValueError("spectral channels need at least two increasing wavelengths")
    curves = sensitivities() if curves is None else curves
    # hat function of sample i on the fine grid, then a trapezoid integral
    hats = np.stack([np.interp(WL, lam, np.eye(len(lam))[i], left=0.0, right=0.0)
                     for i in range(len(lam))])
    dw = np.gradient(WL)
    return (curves * dw) @ hats.T


def spectral_to_lmsr(wavelengths, spectra: np.ndarray) -> np.ndarray:
    """(..., N) spectral radiance -> (..., 4) LMSR (float64 reference)."""
    W = spectrum_weights(wavelengths)
    return np.asarray(spectra, np.float64) @ W.T


def spectral_to_rgb(wavelengths, spectra: np.ndarray) -> np.ndarray:
    """(..., N) spectral radiance -> (..., 3) linear BT.709 in cd/m^2 (CIE 1931 2-degree),
    for operators that take RGB."""
    W = np.linalg.inv(RGB709_TO_XYZ) @ spectrum_weights(wavelengths, xyz_cmfs())
    return np.asarray(spectra, np.float64) @ W.T


@functools.lru_cache(maxsize=1)
def fitted() -> dict:
    """The shipped fit: {"H": 4x3, "residual_rms": ..., "held_out": ...}."""
    doc = json.loads(FIT_FILE.read_text())
    doc["H"] = np.asarray(doc["H"], np.float64)
    return doc


def rgb_to_lmsr(rgb: np.ndarray, H: np.ndarray | None = None) -> np.ndarray:
    """(..., 3) linear BT.709 cd/m^2 -> (..., 4) LMSR through the fitted H (Sec. 4)."""
    H = fitted()["H"] if H is None else H
    return np.asarray(rgb, np.float64) @ H.T
