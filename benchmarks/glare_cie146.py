"""The flare's veil against the CIE's disability-glare equations (issue 48): one command.

    python -m benchmarks.glare_cie146 [--out-dir DIR]

A point source giving E lux at the eye, theta degrees from the line of sight, veils the
retinal image with L_veil = PSF(theta) E, PSF per steradian. The table sets the
flare's PSF (Spencer et al. 1995 as ``models/spencer1995.py`` has it: its four bases,
each of unit energy, weighted by the pupil of the adaptation level, Eq. 8; photopic
luminance of the per-channel halo) against CIE 146:2002's general equation for
observers of 25 and 70 (brown eyes) and its age-adjusted Stiles-Holladay equation.
Pure float64, a second. Writes ``glare_cie146.md``.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from ocl_tonemap.models import cie146
from ocl_tonemap.models import spencer1995 as fl
from ocl_tonemap.models.photometry import Y_WEIGHTS

ANGLES = (1.0, 2.0, 5.0, 10.0, 20.0, 30.0)
LEVELS = ((1000.0, "daylight"), (1.0, "dusk"), (0.01, "night"))
SR_PER_DEG2 = (180.0 / np.pi) ** 2


def spencer_psf(theta_deg, L_adapt: float) -> np.ndarray:
    """The flare's PSF at ``theta_deg`` per steradian (photopic: the halo's three
    channels weighted by Y) for an eye adapted to ``L_adapt`` cd/m^2."""
    th = np.asarray(theta_deg, np.float64)
    w = fl.flare_weights(float(fl.pupil_diameter(L_adapt)))
    out = np.zeros_like(th)
    for c in range(3):
        p = sum(wi * fl._basis(n)(th) / fl.basis_norm(n)
                for wi, n in zip(w, fl.channel_bases(c)))
        out += Y_WEIGHTS[c] * p
    return out * SR_PER_DEG2


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_out_args(ap, "glare_cie146.md")
    a = ap.parse_args(argv)
    th = np.array(ANGLES)
    young, old = cie146.veil_per_lux(th, 25), cie146.veil_per_lux(th, 70)
    sh = cie146.stiles_holladay(th, 25)
    lines = ["# The flare's veil against CIE 146's disability glare", "",
             "L_veil / E, (cd/m^2)/lx, of a point source theta degrees from the line of sight "
             "(`python -m benchmarks.glare_cie146`). CIE 146:2002 general equation, brown "
             "eyes (p = 0.5), at 25 and 70 years; its age-adjusted Stiles-Holladay equation "
             "(1-30 degrees) at 25; the flare's PSF (Spencer et al. 1995, "
             "`models/spencer1995.py`) at the pupil of each adaptation level, and its ratio "
             "to the CIE's 25- and 70-year-old.", "",
             "| theta (deg) | CIE 146, 25 y | CIE 146, 70 y | Stiles-Holladay, 25 y | " +
             " | ".join(f"flare, {n} (D {float(fl.pupil_diameter(L)):.1f} mm)"
                        for L, n in LEVELS) + " | " +
             " | ".join(f"{n} / CIE 25 y | {n} / CIE 70 y" for _, n in LEVELS) + " |",
             "|" + "---|" * (4 + 3 * len(LEVELS))]
    psf = {n: spencer_psf(th, L) for L, n in LEVELS}
    for i, t in enumerate(th):
        cells = [f"{t:g}", f"{young[i]:.4g}", f"{old[i]:.4g}", f"{sh[i]:.4g}"]
        cells += [f"{psf[n][i]:.4g}" for _, n in LEVELS]
        cells += [f"{psf[n][i] / young[i]:.2f} | {psf[n][i] / old[i]:.2f}" for _, n in LEVELS]
        lines.append("| " + " | ".join(cells) + " |")
    band = [(psf[n][1:5] / young[1:5]) for _, n in LEVELS]
    lines += ["", f"At 2-20 degrees the flare veils {min(b.min() for b in band):.2f}-"
              f"{max(b.max() for b in band):.2f}x as much as CIE 146's 25-year-old, and "
              f"{min((psf[n][1:5] / old[1:5]).min() for _, n in LEVELS):.2f}-"
              f"{max((psf[n][1:5] / old[1:5]).max() for _, n in LEVELS):.2f}x its "
              "70-year-old: Spencer's PSF is an older eye's, and has no age of its own "
              "(docs/models.md, \"Visibility\")."]
    out = out_path(a, "glare_cie146.md")
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
