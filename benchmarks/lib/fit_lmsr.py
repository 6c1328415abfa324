"""Fit the RGB -> LMSR matrix H of Kirk & O'Brien 2011, Sec. 4, on real spectra.

    python -m benchmarks.lib.fit_lmsr         # rewrites ocl_tonemap/data/rgb_to_lmsr.json

Training spectra: reflectances shipped with colour-science (the 24 patches of
the ColorChecker, Ohta's measurements; the 14 CIE 1995 test colour samples of
the colour-rendering index) under daylight (D65), tungsten (A), fluorescent
(FL2) and LED (LED-B3) illuminants, plus each illuminant's white. Each stimulus
E = reflectance x illuminant gives RGB (CIE 1931 XYZ -> linear BT.709) and LMSR
(lmsr.sensitivities), both normalised to luminance 1 so that every colour
weighs the same; H solves Q = H P by least squares.

Held out: the 15 NIST CQS 9.0 samples under the training illuminants and under
D50, FL11 and LED-B1, which the fit never saw.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from ocl_tonemap.models import lmsr
from ocl_tonemap.models.photometry import RGB709_TO_XYZ

TRAIN_REFLECTANCES = (("colourchecker", "ColorChecker N Ohta"), ("tcs", "CIE 1995"))
HELD_OUT_REFLECTANCES = (("vs", "NIST CQS 9.0"),)
TRAIN_ILLUMINANTS = ("D65", "A", "FL2", "LED-B3")
HELD_OUT_ILLUMINANTS = ("D65", "A", "FL2", "LED-B3", "D50", "FL11", "LED-B1")


def _reflectances(kind: str, name: str) -> list[np.ndarray]:
    colour = lmsr.colour_module()
    if kind == "colourchecker":
        sds = colour.SDS_COLOURCHECKERS[name]
    elif kind == "tcs":
        from colour.quality.datasets import SDS_TCS
        sds = SDS_TCS[name]
    else:
        from colour.quality.datasets import SDS_VS
        sds = SDS_VS[name]
    out = []
    for sd in sds.values():
        wl, v = sd.wavelengths, sd.values
        out.append(np.interp(lmsr.WL, wl, v, left=v[0], right=v[-1]))
    return out


def _illuminant(name: str) -> np.ndarray:
    colour = lmsr.colour_module()
    sd = colour.SDS_ILLUMINANTS[name]
    return np.interp(lmsr.WL, sd.wavelengths, sd.values, left=0.0, right=0.0)


def stimuli(reflectance_sets, illuminants, with_white: bool = True):
    """(P 3xN RGB, Q 4xN LMSR), each stimulus at luminance 1."""
    S = lmsr.sensitivities()
    cmf = lmsr.xyz_cmfs()
    to_rgb = np.linalg.inv(RGB709_TO_XYZ)
    P, Q = [], []
    refl = [r for kind, name in reflectance_sets for r in _reflectances(kind, name)]
    if with_white:
        refl.append(np.ones_like(lmsr.WL))
    for il in illuminants:
        E0 = _illuminant(il)
        for r in refl:
            E = r * E0
            xyz = cmf @ E
            P.append(to_rgb @ xyz / xyz[1])
            Q.append(S @ E / xyz[1])
    return np.array(P).T, np.array(Q).T


def fit():
    P, Q = stimuli(TRAIN_REFLECTANCES, TRAIN_ILLUMINANTS)
    H = np.linalg.lstsq(P.T, Q.T, rcond=None)[0].T                  # Q ~ H P
    def report(P_, Q_):
        E = H @ P_ - Q_
        scale = np.sqrt(np.mean(Q_ ** 2, axis=1))
        return {"rms_relative": dict(zip("LMSR", (np.sqrt(np.mean(E ** 2, axis=1)) / scale).round(6).tolist())),
                "max_abs_over_luminance": dict(zip("LMSR", np.abs(E).max(axis=1).round(6).tolist())),
                "samples": int(P_.shape[1])}
    Ph, Qh = stimuli(HELD_OUT_REFLECTANCES, HELD_OUT_ILLUMINANTS, with_white=False)
    colour = lmsr.colour_module()
    return {
        "H": H.tolist(),
        "rows": ["L", "M", "S", "R"], "columns": ["R", "G", "B (linear BT.709, cd/m^2)"],
        "train": report(P, Q), "held_out": report(Ph, Qh),
        "train_set": {"reflectances": [n for _, n in TRAIN_REFLECTANCES],
                      "illuminants": list(TRAIN_ILLUMINANTS)},
        "held_out_set": {"reflectances": [n for _, n in HELD_OUT_REFLECTANCES],
                         "illuminants": list(HELD_OUT_ILLUMINANTS)},
        "colour_science": colour.__version__,
    }


def main(argv=None) -> int:
    doc = fit()
    path = lmsr.FIT_FILE if not argv else argv[0]
    with open(path, "w") as fh:
        json.dump(doc, fh, indent=2)
        fh.write("\n")
    print(json.dumps({k: doc[k] for k in ("H", "train", "held_out")}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
