"""Predicted effect of each mechanism on a frame: p99 Delta E ITP (BT.2124) of the
display light, the mechanism fully on against off, from the scene analysis.

Each prediction runs the mechanism's float64 model on the analysis's proxy (or,
for acuity, on its full-resolution patches) and maps both through a display
response at the frame's adaptation levels: the operator's own per-pixel map
where it has one (pattanaik00, durand00), else pattanaik00's at the same levels
(ledda04 and kirk11 adapt per pixel; their global response is the stand-in).
Display light: display-linear x the display's unit, clipped at its white, over
a black of white / 1000 (ICtCp of that, ``models/ictcp.py``). The derivations
are in docs/models.md ("The mechanism plan").
"""

from __future__ import annotations

import math

import numpy as np

from ..backends.flare_exec import apply_flare, convolve_exact_cached
from ..effects.purkinje import apply_purkinje
from ..models import spencer1995 as fl
from ..models.convolution import EDGE_CLAMP, blur_reference, gaussian_taps
from ..models.ictcp import delta_e_itp, rgb709_to_ictcp
from ..models.metering import LOG_FLOOR
from ..models.photometry import Y_WEIGHTS, scotopic_luminance
from ..models.shaler1937 import acuity_info
from ..operators import get_operator
from ..operators.base import FrameStats, ModelOperator
from .analysis import block_stride

#: The quantile of the frame's Delta E the budget bounds.
QUANTILE = 99.0
#: The Delta E of the flare and the Purkinje shift is taken on at most this many
#: of the proxy's blocks and as many of the patches' pixels, evenly strided (the
#: p99 of ~4000 values: ~40 above it). A prediction costs ~1/7 of the whole
#: proxy and patches (~30 000 values at 640x360), and its spread on the test
#: scenes stays within the safety factor (tests/mechanisms/test_plan.py).
SAMPLE = 2048


class DisplayResponse:
    """Scene cd/m^2 -> ICtCp of the display light, steady-state adapted to the
    frame's levels (``op``: the run's operator, used where it maps pixel by pixel)."""

    def __init__(self, op, display, G_rod: float, G_cone: float):
        #: the operator's own response (else a stand-in: its predictions are less sure)
        self.own = isinstance(op, ModelOperator)
        self.op = op if self.own else get_operator("pattanaik00")({}, display)
        self.display = display
        stats = FrameStats(1, 1, float(G_rod), float(G_cone))

        class _State:
            values = self.op.steady_state(stats)
        self.params = self.op.params(_State, stats)

    def at(self, G_rod: float, G_cone: float) -> "DisplayResponse":
        """The same response adapted to other levels."""
        return DisplayResponse(self.op, self.display, G_rod, G_cone)

    def display_linear(self, rgb_cd: np.ndarray) -> np.ndarray:
        rgb = np.asarray(rgb_cd, np.float64).reshape(-1, 3)
        return np.asarray(self.op.map_reference(rgb, rgb @ Y_WEIGHTS, scotopic_luminance(rgb),
                                                self.params), np.float64)

    def ictcp(self, rgb_cd: np.ndarray) -> np.ndarray:
        return display_ictcp(self.display_linear(rgb_cd), self.display)


def sampled(a: np.ndarray, n: int = SAMPLE) -> np.ndarray:
    """Every k-th row of (N, 3) ``a``, at most about ``n`` of them."""
    a = np.asarray(a).reshape(-1, 3)
    return a[::max(1, len(a) // n)]


def p99(a, b) -> float:
    d = delta_e_itp(a, b).ravel()
    d = d[np.isfinite(d)]
    return float(np.percentile(d, QUANTILE)) if len(d) else 0.0


def purkinje(an, resp: DisplayResponse, pixels=None) -> float:
    """The Purkinje shift at the frame's scotopic level, rods fully sensitive, as the
    run makes it: its strength from the levels metered before the flare, on the
    flared pixels where the flare runs (``pixels``, the flared proxy), shown at the
    levels the operator meters (``resp``: the flared frame's where the flare runs).
    The shift comes after the metering, so it does not move them."""
    P = sampled(an.proxy if pixels is None else pixels)
    sample = [P]
    if an.patches:           # single pixels too: block means hide a texture's darks
        sample.append(sampled(patch_pixels(an, None if pixels is None else pixels)))
    P = np.concatenate(sample)
    shifted, info = apply_purkinje(P, an.G_rod, an.G_cone)
    if info["rod_gain"] <= 0.0:
        return 0.0
    return p99(resp.ictcp(P), resp.ictcp(np.asarray(shifted, np.float64)))


def _gm(a) -> float:
    """The log-average as the metering takes it: over the values above its floor
    (``models/metering.py``: exact zeros, a black border, do not pull it down)."""
    a = np.asarray(a, np.float64)
    a = a[a > LOG_FLOOR]
    return float(np.exp(np.mean(np.log(a)))) if a.size else LOG_FLOOR


def patch_pixels(an, flared=None) -> np.ndarray:
    """The patches' pixels (N x 3); with ``flared`` (the flared proxy), as the flare
    leaves them: each pixel less its own source part, plus its block's flare
    (flared - proxy + the block's source part)."""
    memo = an.pixel_memo
    for key, value in memo:                     # the same pixels, asked again (flare, levels)
        if key is flared:
            return value
    out = []
    s = block_stride(an.height, an.width)
    for y, x, patch in an.patches:
        px = np.asarray(patch, np.float64)
        if flared is not None:
            h, w = px.shape[:2]
            by = np.minimum((y + np.arange(h)) // s, an.proxy.shape[0] - 1)
            bx = np.minimum((x + np.arange(w)) // s, an.proxy.shape[1] - 1)
            S_blk = an.sources_proxy if an.sources_proxy is not None else 0.0
            F = (flared - an.proxy + S_blk)[by][:, bx]
            px = np.maximum(px - fl.source_part(px, 1.0, an.flare_limit) + F, 0.0)
        out.append(px.reshape(-1, 3))
    out = np.concatenate(out)
    memo.append((flared, out))
    return out


def flare(an, resp: DisplayResponse, fov_deg: float, age: float | None = None):
    """The flare of the frame's sources, exact method at the proxy's pixel angle:
    (p99 Delta E, the flared proxy or None). The sources are the block means of each
    pixel's source part (above the analysis's ``flare_limit``) where the backend made them (``an.sources_proxy``: a lamp
    smaller than a block keeps its flux), else the source part of the proxy
    (``Backend.source_proxy``: frames in bands)."""
    P = an.proxy
    S = an.sources_proxy
    lim = an.flare_limit
    if not (0.0 < lim < np.inf):
        return 0.0, None
    if S is None:
        if not (float((P @ Y_WEIGHTS).max(initial=0.0)) > lim):
            # sources smaller than a block (a lamp the block means hide) where the
            # metering saw a pixel beyond the limit: not predictable here, so it runs
            return (math.inf if an.max_Y is not None and an.max_Y > lim else 0.0), None
        out, _ = apply_flare(P, an.G_cone, an.G_rod, fov_deg, "exact", lim=lim, age=age)
    else:
        if not np.any(S > 0):
            return 0.0, None
        D = fl.observer_pupil(an.G_cone, an.G_rod, fov_deg, P.shape, age)
        # (>= 0: the device's float32 block sums of S can pass the proxy's by a rounding)
        out = np.maximum(P - S + convolve_exact_cached(S, fov_deg / P.shape[1], D, age), 0.0)
    # shown at the levels the operator meters on the flared frame (a veil over a
    # dark texture moves them by orders of magnitude), single pixels included
    after = resp.at(*flared_levels(an, out))
    a, b = [sampled(P)], [sampled(out)]
    if an.patches:
        a.append(sampled(patch_pixels(an)))
        b.append(sampled(patch_pixels(an, out)))
    return p99(resp.ictcp(np.concatenate(a)), after.ictcp(np.concatenate(b))), out


def flared_levels(an, flared: np.ndarray) -> tuple[float, float]:
    """(G_rod, G_cone) after the flare: the metering goals scaled by the change of the
    log-averages (the veil raises the level the eye adapts to) of single pixels where
    there are patches (a block mean hides the dark pixels the veil fills, which rule
    a log-average), else of the proxy."""
    if an.patches:
        P, flared = patch_pixels(an), patch_pixels(an, flared)
    else:
        P = an.proxy
    k_cone = _gm(flared @ Y_WEIGHTS) / _gm(P @ Y_WEIGHTS)
    k_rod = _gm(scotopic_luminance(flared)) / _gm(scotopic_luminance(P))
    return an.G_rod * k_rod, an.G_cone * k_cone


def acuity(an, resp: DisplayResponse, fov_deg: float, paper: bool = False,
           G_rod: float | None = None) -> float:
    """The blur at the frame's scotopic level (``G_rod`` where the flare moves it) on
    the full-resolution patches (their interiors: the blur's edges are the patch's,
    not the frame's)."""
    G = an.G_rod if G_rod is None else G_rod
    info = acuity_info(G, fov_deg, an.width, mode="paper" if paper else "default")
    if info["blend"] <= 0.0 or not an.patches:
        return 0.0
    taps = gaussian_taps(info["sigma_px"])
    R = len(taps) - 1
    a, b = [], []
    shown = resp.display_linear(np.concatenate([p.reshape(-1, 3) for _, _, p in an.patches]))
    k = 0
    for _, _, patch in an.patches:
        h, w = patch.shape[:2]
        img = shown[k:k + h * w].reshape(h, w, 3)
        k += h * w
        blurred = blur_reference(img, taps, EDGE_CLAMP) * info["blend"] + \
            img * (1.0 - info["blend"])
        m = min(R, max(0, (min(h, w) - 4) // 2))
        a.append(img[m:h - m, m:w - m].reshape(-1, 3))
        b.append(blurred[m:h - m, m:w - m].reshape(-1, 3))
    d = resp.display
    return p99(display_ictcp(np.concatenate(a), d), display_ictcp(np.concatenate(b), d))


def display_ictcp(out: np.ndarray, display) -> np.ndarray:
    """ICtCp of the light a display shows for display-linear ``out`` (the plan's
    display model: x unit, clipped at white, over a black of white / 1000)."""
    rgb = np.asarray(out, np.float64)[..., :3]
    light = np.clip(rgb * display.unit_cd, 0.0, display.white_cd) + display.white_cd / 1000.0
    return rgb709_to_ictcp(light)


def frame_delta_e(out_a: np.ndarray, out_b: np.ndarray, display) -> float:
    """p99 Delta E ITP between two display-linear frames on ``display`` (the bound)."""
    return p99(display_ictcp(out_a, display), display_ictcp(out_b, display))
