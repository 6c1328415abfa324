"""Scene analysis of one frame: what the mechanism plan decides from.

The frame is reduced to a *proxy* in the backend's metering pass (on the device
for OpenCL: ``metering.cl:block_means_log16``): the means of s x s blocks of the
working frame in cd/m^2 (energy kept, so small lamps still carry their flux), at most
:data:`PROXY_SIDE` blocks along its longer side, held as 16-bit log codes
(``models/metering.log16_encode``: 0.07 %).
From it: the adaptation goals with the run's metering, photopic and scotopic
percentiles, the light sources (pixels above the flare threshold x the
adaptation level: count, area, share of the energy), the scene's dynamic range
against the display's, the illuminant estimate with its confidence
(``models/durand2000.py``) and how fast adaptation is moving (goal against the
adapted state). A few full-resolution patches are kept for the mechanisms that
act on fine detail (acuity).

The analysis itself is host float64 on a few thousand values.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..models import durand2000 as dd
from ..models import spencer1995 as fl
from ..models.photometry import Y_WEIGHTS, sanitize, scotopic_luminance

#: Blocks along the proxy's longer side.
PROXY_SIDE = 128
#: Full-resolution patches kept (a grid of PATCH_GRID x PATCH_GRID), and their side.
PATCH_GRID = 3
PATCH_SIDE = 48
#: Light sources: photopic luminance above this many times the adaptation level
#: (the flare threshold of Spencer et al. 1995's default, ``spencer1995.DEFAULT_THRESHOLD``).
SOURCE_FACTOR = fl.DEFAULT_THRESHOLD
#: The illuminant estimate leaves out pixels above this many times the adaptation
#: level: the lamps and the sun themselves (a bright sky or a lit wall, a few times
#: the level, is what the scene's light looks like and stays in).
ILLUMINANT_SOURCE_FACTOR = 30.0


#: The frame's signature (:func:`signature`): a coarse grid of the proxy's log10 block
#: means, each channel, quantised to SIGNATURE_STEP decades; with the patches' log
#: mean and log spread (fine detail) and the metering goals.
SIGNATURE_GRID = 12
SIGNATURE_STEP = 0.01


def block_stride(h: int, w: int, side: int = PROXY_SIDE) -> int:
    return max(1, -(-max(h, w) // side))


def patches_of(get_rows, h: int, w: int, scale: float, side: int = PATCH_SIDE,
               grid: int = PATCH_GRID, get_patches=None) -> list:
    """Full-resolution patches on a grid (cd/m^2, float64), for fine detail and as
    a sample of single pixels: [(y, x, patch)]. ``get_patches(ys, xs, ph, pw)``: the
    frame's own way to give them ({(y, x): patch}: a frame on a device reads them
    alone, not their rows)."""
    ph, pw = min(side, h), min(side, w)
    ys = sorted(set(np.linspace(0, h - ph, grid).round().astype(int).tolist()))
    xs = sorted(set(np.linspace(0, w - pw, grid).round().astype(int).tolist()))
    if get_patches is not None:
        got = get_patches(ys, xs, ph, pw)
        return [(y, x, sanitize(np.asarray(got[y, x])[..., :3], scale)[0])
                for y in ys for x in xs]
    out = []
    for y in ys:
        rows = np.asarray(get_rows(y, y + ph))[..., :3]
        for x in xs:
            out.append((y, x, sanitize(rows[:, x:x + pw], scale)[0]))
    return out


@dataclass
class SceneAnalysis:
    """What the plan knows of a frame (JSON-able through :meth:`as_dict`)."""

    width: int
    height: int
    G_rod: float                     # metering goals of the frame, scotopic / photopic cd/m^2
    G_cone: float
    Y_p: tuple                       # photopic percentiles 1, 50, 99 (cd/m^2)
    Ys_p: tuple                      # scotopic percentiles 1, 50, 99
    sources: dict                    # area (share of pixels), energy (share of light), count
    dynamic_range: float             # log10 p99 / p1 of the scene ...
    display_range: float             # ... and of the display (white / black)
    illuminant: tuple                # normalised working RGB: on the Planckian band, moved
                                     # toward the working white by (1 - confidence)
    illuminant_cct: float
    illuminant_confidence: float
    adapting: float                  # decades per second the cones' goal moves (0: still)
    proxy: np.ndarray = field(repr=False, default=None)
    patches: list = field(repr=False, default_factory=list)
    sources_proxy: np.ndarray | None = field(repr=False, default=None)
    flare_limit: float = 0.0         # the flare's source threshold, cd/m^2 (where it runs)
    max_Y: float | None = None       # the frame's largest luminance, where the metering knows it
    pixel_memo: list = field(repr=False, default_factory=list)   # predict.patch_pixels'

    def as_dict(self) -> dict:
        d = asdict(self)
        for k in ("proxy", "patches", "sources_proxy", "pixel_memo"):
            d.pop(k)
        return d


def _log_q(a) -> np.ndarray:
    return np.round(np.log10(np.maximum(np.asarray(a, np.float64), 1e-9)) / SIGNATURE_STEP)


def signature(an: "SceneAnalysis") -> list:
    """What the predictions depend on, coarsely: a SIGNATURE_GRID^2 grid of the proxy's
    cell means per channel, each patch's per-channel mean and standard deviation (its
    fine detail: what the blur of acuity removes) and the metering goals, as integers
    of SIGNATURE_STEP decades. Two frames whose signatures differ by at most
    ``planner.REUSE_STEPS`` in every entry have the same predictions within a few per
    cent (``planner`` reuses them: a held shot, a still, a slow pan)."""
    P = np.asarray(an.proxy, np.float64)
    gh, gw = min(SIGNATURE_GRID, P.shape[0]), min(SIGNATURE_GRID, P.shape[1])
    ey = np.linspace(0, P.shape[0], gh + 1).astype(int)
    ex = np.linspace(0, P.shape[1], gw + 1).astype(int)
    sums = np.add.reduceat(np.add.reduceat(P, ey[:-1], axis=0), ex[:-1], axis=1)
    cells = sums / (np.diff(ey)[:, None, None] * np.diff(ex)[None, :, None])
    parts = [_log_q(cells).ravel(), _log_q([an.G_rod, an.G_cone])]
    for _, _, patch in an.patches:
        p = np.asarray(patch, np.float64).reshape(-1, 3)
        parts.append(_log_q(p.mean(axis=0)))
        parts.append(_log_q(p.std(axis=0) + 1e-6 * np.maximum(p.mean(axis=0), 1e-9)))
    return [int(v) for v in np.concatenate(parts)]


def percentiles(a: np.ndarray) -> tuple:
    return tuple(float(v) for v in np.percentile(a, (1, 50, 99)))


def analyse(proxy: np.ndarray, G_rod: float, G_cone: float, width: int, height: int, display,
            patches: list = ()) -> SceneAnalysis:
    """The analysis of one frame: its proxy (block means, cd/m^2, from the backend's
    metering pass), its metering goals, the full-resolution ``patches``."""
    P = np.asarray(proxy, np.float64)
    Y = P @ Y_WEIGHTS
    Ys = scotopic_luminance(P)
    lim = SOURCE_FACTOR * max(G_cone, 1e-12)
    src = Y > lim
    total = float(Y.sum())
    s = block_stride(height, width)
    sources = {"area": float(src.mean()), "energy": float(Y[src].sum() / total) if total > 0 else 0.0,
               "pixels": int(round(float(src.sum()) * s * s))}
    Yp = percentiles(Y)
    est, cct, conf = dd.illuminant_estimate(P, ILLUMINANT_SOURCE_FACTOR * max(G_cone, 1e-12))
    est = dd.partial_illuminant(est, conf)      # an uncertain estimate counts for less
    black = max(display.white_cd / 1000.0, 1e-6)
    dr = math.log10(max(Yp[2], 1e-9) / max(Yp[0], 1e-9))
    return SceneAnalysis(width, height, float(G_rod), float(G_cone), Yp, percentiles(Ys), sources,
                         dr, math.log10(display.white_cd / black),
                         tuple(float(v) for v in est), float(cct), float(conf), 0.0, P,
                         list(patches))
