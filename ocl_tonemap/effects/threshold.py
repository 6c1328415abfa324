"""The observer's absolute threshold as an effect on any operator
(``models/absolute_threshold.py``): each pixel's light weighted by the share of it
the observer sees beyond the threshold, so that the display shows the minutes of dark
adaptation (issue 66): after daylight, a faint target stays black until the
observer's threshold has fallen below it.

Slot: seen (after the state step: the thresholds come from the pigment state the
operator's step has just advanced, ``AdaptationState.extra["pigment"]``; the
metering sees the light). ``auto`` (the default) runs it wherever the operator runs
the shared pigment course (every operator's default mode; ``--mode paper`` keeps
the papers' displays, which have no such threshold); ``on`` also runs it there,
with an observer adapted for good to the frame. On the device, in place
(``colour.cl:absolute_threshold_rgb``); pointwise, so band by band alike.
"""

from __future__ import annotations

import numpy as np

from ..models import absolute_threshold as at, bleaching
from ..operators.pigment import PIGMENT_KEY
from .base import Effect


def advance(mode: str, G_rod: float, G_cone: float, extra: dict | None,
            max_Y: float | None = None, max_Ys: float | None = None) -> dict:
    """The frame's thresholds (Eq. 1) from the pigment state in ``extra``, whether the
    frame is weighted (``ran``) and, where its largest luminance ``max_Y`` is known (and
    its largest scotopic one ``max_Ys``), the share of that light that is shown
    (``peak_seen``: kirk11 maps its peak to white)."""
    if mode == "off":
        return {"ran": False}
    pig = (extra or {}).get(PIGMENT_KEY)
    if not bleaching.check(pig):
        if mode == "auto":
            return {"ran": False, "reason": "no pigment course"}
        pig = bleaching.steady(G_rod, G_cone)
    T_rod, T_cone = at.thresholds(pig, G_rod, G_cone)
    info = {"ran": True, "T_rod": float(T_rod), "T_cone": float(T_cone)}
    if max_Y is not None:
        info["peak_seen"] = float(at.peak_seen(max_Y, T_rod, T_cone, max_Ys))
    return info


def weigh(rgb, info: dict, backend=None):
    """(rgb weighted by the share of each pixel seen beyond the threshold, info): in
    place on the device where ``rgb`` is a device image there, else float32 from the
    float64 reference."""
    if backend is not None and not isinstance(rgb, np.ndarray):
        out = backend.threshold_image(rgb, info["T_rod"], info["T_cone"], at.BETA, at.X_SURE)
        if out is not None:
            return out, info
        rgb = np.asarray(rgb)
    out = at.apply_reference(rgb, info["T_rod"], info["T_cone"])
    return out.astype(np.float32), info


class AbsoluteThreshold(Effect):
    """What lies below the observer's absolute threshold is not seen."""

    name = "threshold"
    slot = "seen"
    help = ("the observer's absolute threshold: light it cannot see yet is not shown "
            "(the minutes of dark adaptation; Hecht 1937, Crawford 1947)")
    capabilities = frozenset({"host", "device", "banded"})

    def advance(self, ctx) -> None:
        ctx.eff[self.name] = advance(self.mode, ctx.G_rod, ctx.G_cone, ctx.extra, ctx.max_Y,
                                     ctx.max_Ys)

    def host(self, ctx, rgb):
        info = ctx.eff.get(self.name) or {"ran": False}
        if not info.get("ran"):
            return None, info
        return weigh(rgb, info)

    def device(self, ctx, img):
        info = ctx.eff.get(self.name) or {"ran": False}
        if not info.get("ran"):
            return None, info
        return weigh(img, info, self.fx.backend)

    def on_device(self) -> bool:
        """It alone keeps no frame on the device (one the flare or the Purkinje shift
        left there is weighted there)."""
        return False

    def banded(self, ctx, height: int):
        info = ctx.eff.get(self.name) or {"ran": False}
        if not info.get("ran"):
            return None, []
        return (lambda y0, rgb: weigh(rgb, info)[0]), []
