"""Experiment 4: the Purkinje peak (CIE 1924 V peaks at 555 nm, CIE 1951 V' at 507 nm),
and each operator's rod weight against CIE 191:2010's mesopic m(L).

Peak: a spectral OpenEXR (``S0.<wl>nm`` channels, the tool's spectral input) holds one
block of columns per wavelength band, each block the same spectral radiance in its own
5 nm band only; the whole frame is scaled so that its mean photopic luminance is L. kirk11
(its spectral path: rods and cones from the spectra, Eq. 8) renders it through the
command line to a float EXR; the block shown brightest (display Y) is where the
simulated observer is most sensitive, refined by a parabola through the log Y of the
brightest block and its neighbours.
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile

import numpy as np

#: Sampled wavelengths of the spectral file, nm.
SAMPLES = np.arange(400.0, 701.0, 5.0)
#: The blocks' wavelengths: each block is one sample (a 5 nm band), 420 to 680 nm.
BANDS = SAMPLES[(SAMPLES >= 420.0) & (SAMPLES <= 680.0)]
BLOCK_W, HEIGHT = 8, 8
LEVELS = 10.0 ** np.arange(2.0, -4.01, -1.0)        # mean photopic L, cd/m^2


def spectral_chart() -> np.ndarray:
    """(H, W, len(SAMPLES)) radiance: block k is 1 at its own sample, 0 elsewhere."""
    cube = np.zeros((HEIGHT, BLOCK_W * len(BANDS), len(SAMPLES)), np.float32)
    for k, c in enumerate(BANDS):
        cube[:, k * BLOCK_W:(k + 1) * BLOCK_W, SAMPLES == c] = 1.0
    return cube


def mean_photopic(cube: np.ndarray) -> float:
    """The frame's mean photopic luminance by the tool's own spectral conversion."""
    from ocl_tonemap.models.lmsr import spectral_to_rgb
    from ocl_tonemap.models.photometry import Y_WEIGHTS
    return float(np.mean(spectral_to_rgb(SAMPLES, cube) @ Y_WEIGHTS))


def write_spectral_exr(path: str, cube: np.ndarray) -> None:
    import OpenImageIO as oiio
    h, w, n = cube.shape
    spec = oiio.ImageSpec(w, h, n, oiio.FLOAT)
    spec.channelnames = tuple(f"S0.{int(v)}nm" for v in SAMPLES)
    out = oiio.ImageOutput.create(path)
    if out is None or not out.open(path, spec) or not out.write_image(cube) or not out.close():
        raise RuntimeError(f"cannot write {path}: {oiio.geterror()}")


def render(L: float, folder: str, extra=()) -> np.ndarray:
    """kirk11's display-linear output of the chart at mean photopic ``L`` (CLI)."""
    import OpenImageIO as oiio
    cube = spectral_chart()
    cube *= L / mean_photopic(cube)
    src, dst = os.path.join(folder, "chart.exr"), os.path.join(folder, "out.exr")
    write_spectral_exr(src, cube)
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", src, dst, "--operator",
                        "kirk11", "--luminance-scale", "1", "--model", "none", "-q", *extra],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"ocl-tonemap failed at L={L}: {r.stderr[-1500:]}")
    return oiio.ImageBuf(dst).get_pixels(oiio.FLOAT)[..., :3]


def peak_nm(out: np.ndarray) -> float:
    """The brightest block's wavelength, refined by a parabola in log Y."""
    from ocl_tonemap.models.photometry import Y_WEIGHTS
    Y = np.array([np.mean(out[:, k * BLOCK_W:(k + 1) * BLOCK_W] @ Y_WEIGHTS)
                  for k in range(len(BANDS))])
    k = int(np.argmax(Y))
    if 0 < k < len(BANDS) - 1 and np.all(Y[k - 1:k + 2] > 0):
        a, b, c = np.log(Y[k - 1:k + 2])
        den = a - 2.0 * b + c
        if den < 0:
            return float(BANDS[k] + 0.5 * (a - c) / den * (BANDS[1] - BANDS[0]))
    return float(BANDS[k])


def purkinje_peaks(levels=LEVELS) -> list[tuple[float, float]]:
    """[(L, peak nm)] of kirk11 from bright to dark."""
    with tempfile.TemporaryDirectory(prefix="ocltm_purkinje_") as d:
        return [(float(L), peak_nm(render(float(L), d))) for L in levels]


# --- CIE 191:2010 mesopic photometry ---------------------------------------------------

#: CIE 191:2010: m = a + b log10(L_mes), 0.005 <= L_mes <= 5 cd/m^2; V'(555 nm) = 0.402.
CIE191_A, CIE191_B, CIE191_V555 = 0.7670, 0.3334, 0.402
CIE191_LOW, CIE191_HIGH = 0.005, 5.0


def cie191_m(L_p: float, sp: float) -> float:
    """m of CIE 191:2010 (its recommended system, the iteration of Sec. 3) for a field of
    photopic luminance ``L_p`` and scotopic/photopic ratio ``sp``: L_mes =
    (m L_p + (1-m) L_s V'(555)) / (m + (1-m) V'(555)), m = a + b log10 L_mes, m_0 = 0.5,
    clamped to [0, 1]; above 5 cd/m^2 photopic (m = 1), below 0.005 scotopic (m = 0)."""
    L_s = L_p * sp
    if L_p >= CIE191_HIGH:
        return 1.0
    m = 0.5
    for _ in range(200):
        L_mes = (m * L_p + (1 - m) * L_s * CIE191_V555) / (m + (1 - m) * CIE191_V555)
        if L_mes <= CIE191_LOW:
            return 0.0
        if L_mes >= CIE191_HIGH:
            return 1.0
        m_new = min(1.0, max(0.0, CIE191_A + CIE191_B * math.log10(L_mes)))
        if abs(m_new - m) < 1e-12:
            break
        m = m_new
    return m


MESOPIC_LEVELS = 10.0 ** np.linspace(math.log10(0.005), math.log10(5.0), 10)


def rod_weight(op: str, L: float, backend=None) -> float:
    """The share of rods in ``op``'s response to a steady neutral field of ``L`` cd/m^2,
    from the frame's record (``Tonemapper.last.params``): durand00 k (Eq. 4), kirk11 its
    rod gain (k), ledda04 1 - mes (Eq. 11) at the cone adaptation, pattanaik00 the rods'
    part of R_rod + R_cone (Eq. 2) at the field."""
    from ocl_tonemap import Tonemapper
    from ocl_tonemap.models.photometry import neutral_scotopic_ratio
    tm = Tonemapper(op, backend=backend, preadapt=(float(L), None), model="none")
    tm.process(np.full((8, 8, 3), L, np.float32))
    p = tm.last.params
    p = p if isinstance(p, dict) else vars(p)
    if op == "durand00":
        return float(p["k"])
    if op == "kirk11":
        return float(p["rod_gain"])
    if op == "ledda04":
        from ocl_tonemap.models.ledda2004 import mesopic_factor_ledda2004
        return 1.0 - float(mesopic_factor_ledda2004(p["logmean_I_A_cone"]))
    if op == "pattanaik00":
        from ocl_tonemap.models import pattanaik2000 as P
        r = float(P.response(L * neutral_scotopic_ratio(), p["sigma_rod"], p["B_rod"]))
        c = float(P.response(L, p["sigma_cone"], p["B_cone"]))
        return r / (r + c)
    raise ValueError(op)


def mesopic_table(operators=("durand00", "pattanaik00", "ledda04", "kirk11"), backend=None,
                  levels=MESOPIC_LEVELS):
    """[(L, CIE rod weight 1 - m, {op: rod weight})] for a neutral (the working white)."""
    from ocl_tonemap.models.photometry import neutral_scotopic_ratio
    sp = neutral_scotopic_ratio()
    return [(float(L), 1.0 - cie191_m(float(L), sp),
             {op: rod_weight(op, float(L), backend) for op in operators}) for L in levels]
