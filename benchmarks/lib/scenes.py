"""Small generated scenes for the appearance benchmark (linear Rec.709, relative units).

Each function returns an (H, W, 3) float32 array; ``benchmarks/appearance.py`` and the tests
scales it to the level under test, so only ratios matter.

* ``tunnel``: the built-in sample (Pattanaik 2000, Fig. 7) on the approach: a
  sunlit road and a dark tunnel mouth with sodium lamps inside.
* ``patches``: a ColorChecker-like 6x4 grid of the 24 chart colours (and a grey
  surround) times a log-normal texture.
* ``lamp``: a small bright warm lamp (and its pool of light) on a dark,
  textured, slightly coloured wall.
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


def tunnel(w: int = 256, h: int = 128) -> np.ndarray:
    from ocl_tonemap.sample import render_frame
    return render_frame(1.2, w, h, 8.0).astype(np.float32)


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


#: name -> (function, what it shows, natural level cd/m^2)
SCENES = {
    "tunnel": (tunnel, "generated: tunnel entrance in sun (ocl_tonemap.sample)", 3000.0),
    "patches": (patches, "generated: ColorChecker patches x log-normal texture", 100.0),
    "lamp": (lamp, "generated: bright lamp on a dark textured wall", 1.0),
}
