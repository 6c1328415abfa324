"""Experiment 2: acuity against luminance (Shlaer 1937; the table in
``ocl_tonemap/models/shaler1937.py``, and Ward Larson et al. 1997's fit).

A chart of vertical sine gratings (one band of rows per frequency, 20% modulation
around La, a neutral) at a stated field of view goes through the command line twice,
``--acuity on`` and ``--acuity off`` (an operator, durand00 by default: the effect is
from its paper; ``--model none`` otherwise); each band's transfer is the ratio of the two outputs'
modulation at its frequency (display-linear luminance projected on the grating). The
measured cut-off is where the transfer crosses 10^-0.395, the paper's own criterion
(Eq. 10: the blur's transfer at omega), interpolated in log frequency.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile

import numpy as np

CRITERION = 10.0 ** -0.395
FOV_DEG = 4.0                         # the chart's width, degrees
WIDTH, BAND_H = 1024, 72              # px: 256 px a degree (Nyquist 128 cycles/degree);
#: the bands are tall against the widest blur (sigma ~20 px at 1e-3 cd/m^2): rows blurred
#: from the next band are left out of the measure
FREQS = 10.0 ** np.linspace(math.log10(0.5), math.log10(80.0), 24)   # cycles/degree
MODULATION = 0.2
LEVELS = 10.0 ** np.arange(-3.0, 2.01, 0.5)                          # La, cd/m^2


def shlaer(L) -> np.ndarray:
    """Shlaer's grating acuity (cycles/degree) at photopic ``L`` (Table 1, interpolated)."""
    from ocl_tonemap.models.shaler1937 import table_cutoff
    return table_cutoff(L)


def ward_fit(L) -> np.ndarray:
    """Ward Larson, Rushmeier & Piatko 1997's fit to Shlaer: 17.25 atan(1.4 log10 L +
    0.35) + 25.72 cycles/degree."""
    return 17.25 * np.arctan(1.4 * np.log10(np.asarray(L, np.float64)) + 0.35) + 25.72


def chart(La: float, width: int = WIDTH, fov: float = FOV_DEG) -> np.ndarray:
    ppd = width / fov
    x = np.arange(width)
    rows = [La * (1.0 + MODULATION * np.sin(2.0 * np.pi * f * x / ppd)) for f in FREQS]
    img = np.repeat(np.asarray(rows), BAND_H, axis=0)
    return np.repeat(img[..., None], 3, axis=2).astype(np.float32)


def _modulation(Y: np.ndarray, f: float, ppd: float) -> float:
    x = np.arange(Y.shape[-1])
    w = 2.0 * np.pi * f * x / ppd
    # whole cycles only, from the middle rows of the band
    n = int(math.floor(Y.shape[-1] * f / ppd)) or 1
    m = min(Y.shape[-1], int(round(n * ppd / f)))
    y = Y[..., :m].mean(axis=0)
    s, c = np.sin(w[:m]), np.cos(w[:m])
    amp = 2.0 * math.hypot(np.mean((y - y.mean()) * s), np.mean((y - y.mean()) * c))
    return amp / max(float(y.mean()), 1e-30)


def _run(src: str, dst: str, acuity: str, fov: float, operator: str) -> np.ndarray:
    import OpenImageIO as oiio
    from ocl_tonemap.models.photometry import Y_WEIGHTS
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", src, dst, "--operator",
                        operator, "--luminance-scale", "1", "--model", "none", "--acuity",
                        acuity, "--fov", str(fov), "-q"], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"ocl-tonemap failed: {r.stderr[-1500:]}")
    return oiio.ImageBuf(dst).get_pixels(oiio.FLOAT)[..., :3] @ Y_WEIGHTS


def transfer(La: float, fov: float = FOV_DEG, width: int = WIDTH,
             operator: str = "durand00") -> np.ndarray:
    """The acuity blur's measured transfer at each of FREQS (on / off modulation)."""
    import OpenImageIO as oiio
    with tempfile.TemporaryDirectory(prefix="ocltm_acuity_") as d:
        src = os.path.join(d, "chart.exr")
        img = chart(La, width, fov)
        buf = oiio.ImageBuf(oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.FLOAT))
        buf.set_pixels(oiio.ROI(), img)
        if not buf.write(src):
            raise RuntimeError(buf.geterror())
        on = _run(src, os.path.join(d, "on.exr"), "on", fov, operator)
        off = _run(src, os.path.join(d, "off.exr"), "off", fov, operator)
    ppd = width / fov
    out = []
    for k, f in enumerate(FREQS):
        rows = slice(k * BAND_H + BAND_H // 3, (k + 1) * BAND_H - BAND_H // 3)
        m_off = _modulation(off[rows], f, ppd) if f < ppd / 2 else 0.0
        out.append(_modulation(on[rows], f, ppd) / m_off if m_off > 0 else np.nan)
    return np.asarray(out)


def cutoff(tr: np.ndarray) -> float | None:
    """Where the transfer first falls through CRITERION (log-frequency interpolation);
    None where it never does within FREQS (no blur that low)."""
    below = np.nonzero(tr < CRITERION)[0]
    if len(below) == 0:
        return None
    k = int(below[0])
    if k == 0:
        return float(FREQS[0])
    t0, t1 = tr[k - 1], tr[k]
    a = (t0 - CRITERION) / (t0 - t1)
    return float(10.0 ** (math.log10(FREQS[k - 1]) + a * math.log10(FREQS[k] / FREQS[k - 1])))


def run_all(levels=LEVELS, operator: str = "durand00"):
    """[(La, measured cut-off or None, Shlaer's table, Ward's fit, the model's omega)]."""
    from ocl_tonemap.models.photometry import neutral_scotopic_ratio
    from ocl_tonemap.models.shaler1937 import acuity_cutoff
    rows = []
    for La in levels:
        tr = transfer(float(La), operator=operator)
        rows.append((float(La), cutoff(tr), float(shlaer(La)), float(ward_fit(La)),
                     float(acuity_cutoff(La * neutral_scotopic_ratio()))))
    return rows
