"""The human data and the units that take them to the tool's (cd/m^2)."""

from __future__ import annotations

import csv
import functools
import math
import os
from dataclasses import dataclass

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
DATA = os.path.normpath(os.path.join(HERE, "..", "..", "data"))
HECHT_CSV = os.path.join(DATA, "hecht_haig_chase_1937.csv")

#: The pre-adapting intensities of Hecht, Haig & Chase 1937, trolands (the paper's
#: "photons"), by the CSV's labels.
HECHT_TD = {"263 photons": 263.0, "3800 photons": 3800.0, "19500 photons": 19500.0,
            "38900 photons": 38900.0, "400k photons": 400000.0}
#: cd/m^2 per micro-micro-lambert: 1e-12 L x 1e4/pi cd/m^2 per L.
CD_PER_UUL = 1e-12 * 1e4 / math.pi
#: Rows of the digitisation read as another observer's (data/README.md): (observer,
#: intensity label, minutes) -> observer.
RELABEL = {("C.H.", "263 photons", 29.6): "S.H."}


@dataclass(frozen=True)
class DarkPoint:
    observer: str
    td: float            # pre-adapting retinal illuminance, trolands
    minutes: float       # time in the dark
    log_uuL: float       # threshold, log10 micro-micro-lamberts


@functools.lru_cache(maxsize=1)
def load_hecht1937() -> tuple[DarkPoint, ...]:
    """The 359 points of ``data/hecht_haig_chase_1937.csv`` with :data:`RELABEL` applied."""
    out = []
    with open(HECHT_CSV, newline="") as fh:
        for r in csv.DictReader(fh):
            t = float(r["Time"])
            obs = RELABEL.get((r["Observer"], r["adaptation_I"], t), r["Observer"])
            out.append(DarkPoint(obs, HECHT_TD[r["adaptation_I"]], t, float(r["Log_I"])))
    return tuple(out)


def log_uuL_to_cd(log_uuL) -> np.ndarray:
    return 10.0 ** np.asarray(log_uuL, np.float64) * CD_PER_UUL


def cd_to_log_uuL(L_cd) -> np.ndarray:
    return np.log10(np.maximum(np.asarray(L_cd, np.float64), 1e-300) / CD_PER_UUL)


def pupil_area_mm2(L_cd) -> np.ndarray:
    """The natural pupil's area at a field of ``L_cd``: Moon & Spencer 1944's diameter
    (the tool's own, ``models/spencer1995.pupil_diameter``)."""
    from ocl_tonemap.models.spencer1995 import pupil_diameter
    return math.pi * (pupil_diameter(L_cd) / 2.0) ** 2


def trolands_to_cd(td: float) -> float:
    """The field luminance (cd/m^2) that gives ``td`` trolands through the natural pupil
    (:func:`pupil_area_mm2`): L x area(L) = td, solved by bisection in log L."""
    lo, hi = -6.0, 9.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        L = 10.0 ** mid
        if L * pupil_area_mm2(L) < td:
            lo = mid
        else:
            hi = mid
    return 10.0 ** (0.5 * (lo + hi))


@functools.lru_cache(maxsize=None)
def scotopic_photopic_ratio(nm: float) -> float:
    """L'/L of monochromatic light at ``nm``: 1700 V'(nm) / (683 V(nm)) (CIE 1951 and
    CIE 1924 by colour-science)."""
    V, Vs = luminous_efficiency_functions()
    return 1700.0 * float(np.interp(nm, *Vs)) / (683.0 * float(np.interp(nm, *V)))


@functools.lru_cache(maxsize=1)
def luminous_efficiency_functions():
    """((nm, V), (nm, V')): CIE 1924 photopic and CIE 1951 scotopic, 1 nm steps."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    p = colour.colorimetry.SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]
    s = colour.colorimetry.SDS_LEFS_SCOTOPIC["CIE 1951 Scotopic Standard Observer"]
    return ((np.asarray(p.wavelengths, float), np.asarray(p.values, float)),
            (np.asarray(s.wavelengths, float), np.asarray(s.values, float)))
