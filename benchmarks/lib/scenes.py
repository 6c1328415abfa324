"""Generated HDR scenes for the benchmarks and the tests (linear Rec.709).

Each function returns an (H, W, 3) float32 array (``spectral_chart``: wavelengths
and an (H, W, N) cube).

The appearance scenes (:data:`SCENES`; relative units: ``benchmarks/appearance.py``,
``benchmarks/equivalence.py`` and the tests scale them to the level under test, so
only ratios matter):

* ``tunnel``: the built-in sample (Pattanaik 2000, Fig. 7) on the approach: a
  sunlit road and a dark tunnel mouth with sodium lamps inside (cd/m^2; ``t``
  picks another moment of the drive).
* ``patches``: a ColorChecker-like 6x4 grid of the 24 chart colours (and a grey
  surround) times a log-normal texture.
* ``lamp``: a small bright warm lamp (and its pool of light) on a dark,
  textured, slightly coloured wall.

The benchmarks' frames (cd/m^2): ``sky_gradient`` (bench_pattanaik),
``night_street_lamps`` (bench_durand), ``night_street_windows``, ``sky_sun``,
``log_noise`` (bench_bilateral), ``sine_texture`` and ``spectral_chart``
(bench_kirk); ``display_frame`` is display-linear (bench_display_table);
``exr_spec`` is the header of the EXR frames bench_memory and scale_out write.
"""

from __future__ import annotations

import numpy as np

#: ColorChecker Classic, sRGB 8-bit (BabelColor averages), row by row.
COLORCHECKER_SRGB8 = np.array([
    [115, 82, 68], [194, 150, 130], [98, 122, 157], [87, 108, 67], [133, 128, 177], [103, 189, 170],
    [214, 126, 44], [80, 91, 166], [193, 90, 99], [94, 60, 108], [157, 188, 64], [224, 163, 46],
    [56, 61, 150], [70, 148, 73], [175, 54, 60], [231, 199, 31], [187, 86, 149], [8, 133, 161],
    [243, 243, 242], [200, 200, 200], [160, 160, 160], [122, 122, 121], [85, 85, 85], [52, 52, 52],
], np.float64)


def srgb_decode(v):
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def _box_blur(a, r: int):
    """Separable box blur of radius r (edges wrap), twice (approximately Gaussian)."""
    for _ in range(2):
        for ax in (0, 1):
            c = np.cumsum(np.concatenate([np.take(a, range(-r - 1, 0), axis=ax), a,
                                          np.take(a, range(0, r), axis=ax)], axis=ax), axis=ax)
            n = a.shape[ax]
            a = (np.take(c, range(2 * r + 1, 2 * r + 1 + n), axis=ax)
                 - np.take(c, range(0, n), axis=ax)) / (2 * r + 1)
    return a


def lognormal_texture(h: int, w: int, sigma: float = 0.35, seed: int = 0) -> np.ndarray:
    """A multiplicative texture exp(N(0, sigma)) with fine and coarse grain, mean ~1."""
    rng = np.random.default_rng(seed)
    fine = _box_blur(rng.standard_normal((h, w)), 1)
    coarse = _box_blur(rng.standard_normal((h, w)), max(2, w // 40))
    g = fine / (fine.std() + 1e-12) + 0.7 * coarse / (coarse.std() + 1e-12)
    g = g / g.std()
    t = np.exp(sigma * g)
    return t / t.mean()


def tunnel(w: int = 256, h: int = 128, t: float = 1.2, seconds: float = 8.0) -> np.ndarray:
    """The built-in tunnel drive (``ocl_tonemap.io.sample.render_frame``) at ``t`` s of a
    ``seconds`` s drive, cd/m^2."""
    from ocl_tonemap.io.sample import render_frame
    return render_frame(t, w, h, seconds).astype(np.float32)


def patches(w: int = 256, h: int = 128) -> np.ndarray:
    lin = srgb_decode(COLORCHECKER_SRGB8 / 255.0)
    img = np.empty((h, w, 3))
    img[:] = srgb_decode(np.array([0.45, 0.45, 0.45]))     # grey surround
    m = max(2, w // 64)                                     # margin between patches
    cw, ch = (w - m) / 6.0, (h - m) / 4.0
    for i in range(24):
        r, c = divmod(i, 6)
        x0, y0 = int(round(m + c * cw)), int(round(m + r * ch))
        x1, y1 = int(round((c + 1) * cw)), int(round((r + 1) * ch))
        img[y0:y1, x0:x1] = lin[i]
    return (img * lognormal_texture(h, w, 0.3, seed=1)[..., None]).astype(np.float32)


def lamp(w: int = 256, h: int = 128) -> np.ndarray:
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    cx, cy, rad = 0.62 * w, 0.35 * h, max(2.0, 0.035 * w)
    d = np.hypot(xx - cx, yy - cy)
    wall = np.array([0.30, 0.24, 0.18]) * lognormal_texture(h, w, 0.45, seed=2)[..., None]
    # a green-blue painted strip and a red door, to have some colour in the dark
    wall[int(0.70 * h):int(0.85 * h), :] *= np.array([0.5, 1.1, 1.4])
    wall[int(0.45 * h):, int(0.12 * w):int(0.25 * w)] *= np.array([2.2, 0.6, 0.5])
    pool = 1.0 + 60.0 / (1.0 + (d / (4 * rad)) ** 2)        # light falling on the wall
    img = wall * pool[..., None]
    warm = np.array([1.0, 0.78, 0.5])
    img[d <= rad] = warm * 2.0e4                              # the lamp itself
    return img.astype(np.float32)


#: The appearance scenes: name -> (function, what it shows, natural level cd/m^2)
SCENES = {
    "tunnel": (tunnel, "generated: tunnel entrance in sun (ocl_tonemap.io.sample)", 3000.0),
    "patches": (patches, "generated: ColorChecker patches x log-normal texture", 100.0),
    "lamp": (lamp, "generated: bright lamp on a dark textured wall", 1.0),
}


# --- the benchmarks' frames -------------------------------------------------------------

def sky_gradient(w, h, seed=0):
    """Five decades from a bright sky (top) to a dark ground, a horizontal ripple,
    10% noise, a colour drift (bench_pattanaik)."""
    rng = np.random.default_rng(seed)
    y = np.linspace(0, 1, h)[:, None]
    x = np.linspace(0, 1, w)[None, :]
    lum = 10 ** (4 * (1 - y) - 1 + 0.5 * np.sin(12 * x)) * (1 + 0.1 * rng.standard_normal((h, w)))
    col = np.stack([0.8 + 0.2 * x + 0 * y, 0.9 + 0 * x * y, 1.1 - 0.3 * y + 0 * x], -1)
    return (np.abs(lum)[..., None] * col).astype(np.float32)


def night_street_lamps(w, h, seed=0):
    """A night street: dim surfaces (0.01-3 cd/m^2), a lit sky strip, street lamps
    (2e4 cd/m^2), a red and a green traffic light, car headlights (1e5) (bench_durand)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    base = 0.05 + 2.0 * np.exp(-((y - 0.55) ** 2) / 0.01) * (0.5 + 0.5 * np.sin(40 * x))
    img = base[..., None] * rng.uniform(0.3, 1.0, (h, w, 3))
    img[: h // 6] = [0.02, 0.03, 0.06]
    s = max(1, w // 320)
    for k in range(6):
        cx, cy = int((0.1 + 0.16 * k) * w), int(0.3 * h)
        img[cy - s:cy + s + 1, cx - s:cx + s + 1] = [2.4e4, 2.0e4, 1.2e4]
    img[int(0.45 * h):int(0.45 * h) + 2 * s, int(0.8 * w):int(0.8 * w) + 2 * s] = [3e3, 2e2, 1e2]
    img[int(0.45 * h):int(0.45 * h) + 2 * s, int(0.85 * w):int(0.85 * w) + 2 * s] = [1e2, 3e3, 1e3]
    for cx in (0.45, 0.55):
        img[int(0.6 * h):int(0.6 * h) + 2 * s, int(cx * w):int(cx * w) + 3 * s] = 1e5
    return img.astype(np.float32)


def night_street_windows(w, h, seed=0):
    """Dark street (0.01-0.1 cd/m^2) with lit windows (50-500) and lamps (1e4)
    (bench_bilateral)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / max(w, h)
    lum = 0.02 * (1 + 3 * y) * (1 + 0.2 * rng.standard_normal((h, w)) ** 2)
    for _ in range(40):
        cx, cy = rng.uniform(0, w), rng.uniform(0, 0.7 * h)
        sw, sh = rng.uniform(0.01, 0.05) * w, rng.uniform(0.02, 0.08) * h
        m = (np.abs(np.arange(w)[None, :] - cx) < sw) & (np.abs(np.arange(h)[:, None] - cy) < sh)
        lum[m] = rng.uniform(50, 500)
    for _ in range(8):
        cx, cy = rng.uniform(0, w), rng.uniform(0, 0.5 * h)
        r2 = (np.arange(w)[None, :] - cx) ** 2 + (np.arange(h)[:, None] - cy) ** 2
        lum += 1e4 * np.exp(-r2 / (2 * (0.004 * w) ** 2))
    col = np.stack([1.1 + 0 * lum, 1.0 + 0 * lum, 0.7 + 0 * lum], -1)
    return (lum[..., None] * col).astype(np.float32)


def sky_sun(w, h, seed=1):
    """Smooth sky gradient with a sun disc (1e8) over darker ground (textured)
    (bench_bilateral)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    sky = 10 ** (3.5 + 0.5 * x - y)
    ground = 10 ** (1.0 + 0.3 * np.sin(40 * x) + 0.1 * rng.standard_normal((h, w)))
    lum = np.where(y < 0.55, sky, ground)
    lum[(x - 0.7) ** 2 * (w / h) ** 2 + (y - 0.2) ** 2 < 0.02 ** 2] = 1e8
    col = np.stack([0.8 + 0.2 * y, 0.95 + 0 * y, 1.2 - 0.4 * y], -1)
    return (lum[..., None] * col).astype(np.float32)


def log_noise(w, h, seed=2):
    """White-noise HDR over 9 decades: the bilateral grid's worst case (bench_bilateral)."""
    rng = np.random.default_rng(seed)
    return (10 ** rng.uniform(-4, 5, (h, w, 1)) * rng.uniform(0.1, 1, (h, w, 3))).astype(np.float32)


def sine_texture(w, h, seed=0):
    """Four decades of smooth sine/cosine luminance times random per-pixel colours
    (bench_kirk)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    lum = 10.0 ** (2.0 * np.sin(6 * x) * np.cos(4 * y))
    return (lum[..., None] * rng.uniform(0.05, 1.0, (h, w, 3))).astype(np.float32)


def spectral_chart(w, h):
    """(wavelengths, (h, w, N) spectral radiance): the 24 ColorChecker patches under
    illuminant A in a 4x6 grid, times three decades of smooth luminance (bench_kirk)."""
    from ocl_tonemap.io.sample import spectral_patches
    lam, spectra, _ = spectral_patches("A", 1.0)
    idx = (np.arange(h)[:, None] * 6 // h) * 4 + (np.arange(w)[None, :] * 4 // w)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    lum = 10.0 ** (1.5 * np.sin(5 * x) * np.cos(3 * y))
    return lam, (spectra[idx % 24] * lum[..., None]).astype(np.float32)


def display_frame(w, h, seed=0):
    """A smooth display-linear frame like an operator's output: mostly [0, 1], deep
    shadows to 1e-4, highlights to 20, varied colour (bench_display_table)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    lum = 10.0 ** (1.3 * np.sin(6 * x) * np.cos(4 * y) - 0.7)
    chroma = 0.55 + 0.45 * np.stack([np.sin(3 * x + 1), np.cos(5 * y), np.sin(4 * (x + y))], -1)
    noise = rng.uniform(0.97, 1.03, (h, w, 3))
    return np.ascontiguousarray(lum[..., None] * chroma * noise, np.float32)


def exr_spec(w: int, h: int, fps: float | None = None, compression: str | None = None):
    """The header of a generated frame as the CLI reads it: half-float RGB, cd/m^2
    (``whiteLuminance`` 1), linear Rec.709; a frame rate and a compression when given."""
    import OpenImageIO as oiio
    spec = oiio.ImageSpec(w, h, 3, oiio.HALF)
    spec.attribute("whiteLuminance", 1.0)
    if fps is not None:
        spec.attribute("FramesPerSecond", oiio.TypeDesc("rational"), (int(round(fps * 1000)), 1000))
    spec.attribute("oiio:ColorSpace", "lin_rec709")
    if compression is not None:
        spec.attribute("compression", compression)
    return spec
