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

import numpy as np

from ..models.convolution import EDGE_CLAMP, blur_reference, gaussian_taps
from ..models.ictcp import delta_e_itp, rgb709_to_ictcp
from ..models.photometry import Y_WEIGHTS, scotopic_luminance
from ..models.shaler1937 import acuity_info
from ..operators.base import FrameStats

#: The quantile of the frame's Delta E the budget bounds.
QUANTILE = 99.0


class DisplayResponse:
    """Scene cd/m^2 -> ICtCp of the display light, steady-state adapted to the
    frame's levels (``op``: the run's operator, used where it maps pixel by pixel)."""

    def __init__(self, op, display, G_rod: float, G_cone: float):
        from ..operators import get_operator
        from ..operators.base import ModelOperator
        self.op = op if isinstance(op, ModelOperator) else \
            get_operator("pattanaik00")({}, display)
        self.display = display
        stats = FrameStats(1, 1, float(G_rod), float(G_cone))

        class _State:
            values = self.op.steady_state(stats)
        self.params = self.op.params(_State, stats)

    def display_linear(self, rgb_cd: np.ndarray) -> np.ndarray:
        rgb = np.asarray(rgb_cd, np.float64).reshape(-1, 3)
        return np.asarray(self.op.map_reference(rgb, rgb @ Y_WEIGHTS, scotopic_luminance(rgb),
                                                self.params), np.float64)

    def ictcp(self, rgb_cd: np.ndarray) -> np.ndarray:
        return display_ictcp(self.display_linear(rgb_cd), self.display)


def p99(a, b) -> float:
    d = delta_e_itp(a, b).ravel()
    d = d[np.isfinite(d)]
    return float(np.percentile(d, QUANTILE)) if len(d) else 0.0


def purkinje(an, resp: DisplayResponse, levels=None) -> float:
    """The Purkinje shift at the frame's scotopic level (``levels``: (G_rod, G_cone)
    where the flare moves them), rods fully sensitive."""
    from ..effects.purkinje import apply_purkinje
    P = an.proxy.reshape(-1, 3)
    G_rod, G_cone = levels or (an.G_rod, an.G_cone)
    shifted, info = apply_purkinje(P, G_rod, G_cone)
    if info["rod_gain"] <= 0.0:
        return 0.0
    return p99(resp.ictcp(P), resp.ictcp(np.asarray(shifted, np.float64)))


def flare(an, resp: DisplayResponse, fov_deg: float, threshold: float):
    """The flare of the proxy's sources (exact method on the proxy, its pixel's angle):
    (p99 Delta E, the flared proxy or None)."""
    from ..backends.flare_exec import apply_flare
    P = an.proxy
    if not (float((P @ Y_WEIGHTS).max(initial=0.0)) > threshold * an.G_cone):
        return 0.0, None
    out, _ = apply_flare(P, an.G_cone, an.G_rod, fov_deg, "exact", threshold)
    return p99(resp.ictcp(P), resp.ictcp(out)), out


def flared_levels(an, flared: np.ndarray) -> tuple[float, float]:
    """(G_rod, G_cone) after the flare: the metering goals scaled by the change of the
    proxy's log-averages (the veil raises the level the eye adapts to)."""
    def gm(a):
        return float(np.exp(np.mean(np.log(np.maximum(a, 1e-12)))))
    P = an.proxy
    k_cone = gm(flared @ Y_WEIGHTS) / gm(P @ Y_WEIGHTS)
    k_rod = gm(scotopic_luminance(flared)) / gm(scotopic_luminance(P))
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
    for patch in an.patches:
        h, w = patch.shape[:2]
        img = resp.display_linear(patch).reshape(h, w, 3)
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
