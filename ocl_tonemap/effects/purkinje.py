"""The Purkinje shift of Kirk & O'Brien 2011 (Cao et al. 2008) as an effect on any
operator: the scene's chromaticity shifted as rods add to the cone pathways, each
pixel's photopic luminance kept (the operator models rod luminance itself).

Slot: seen (after the state step: the metering sees the light, not the shift).
Needs: the shared receptor levels (``models/pattanaik2000.py``: the adapted
scotopic level), kept in ``AdaptationState.extra["purkinje_levels"]``, and the rods'
dark adaptation: the operator's shared pigment course where it runs one
(``extra["pigment"]``, ``bleaching.rod_sensitivity``), else those levels' own
bleaching (Eq. 7, ``--mode paper``); on the device, kirk11's shift kernel.
:class:`PurkinjeShift` is the effect.
"""

from __future__ import annotations

import numpy as np

from ..models import bleaching, kirk2011 as ko, lmsr
from ..models.pattanaik2000 import (receptor_levels_advance, receptor_levels_preadapted,
                                    receptor_levels_steady, rod_sensitivity)
from ..models.photometry import Y_WEIGHTS, neutral_scotopic_ratio
from ..backends.base import Later, settle
from ..operators.pigment import PIGMENT_KEY
from .base import Effect

LEVELS_KEY = "purkinje_levels"

#: ``auto`` skips the shift when rods carry less than this share (photopic frames).
PURKINJE_AUTO_GAIN = 0.01


def apply_purkinje(rgb: np.ndarray, G_rod: float, G_cone: float, device=None,
                   sensitivity: float = 1.0):
    """Shift working RGB (cd/m^2) as kirk11 does with ``--kappa adaptive`` and keep
    each pixel's photopic luminance. ``G_rod``: the (adapted) scotopic level;
    ``sensitivity``: how far the rods are dark adapted (0..1, scales the rods'
    share). ``device``: a KirkDevice (``rgb`` may then be a device image, shifted in
    place), else float64."""
    area = ko.model_scale()
    k1, k2, gain = ko.kappas(ko.KirkSettings(kappa="adaptive"), G_rod)
    k1, k2, gain = k1 * sensitivity, k2 * sensitivity, gain * sensitivity
    M = lmsr.fitted()["H"][:3]
    if gain <= 0.0:
        return rgb, {"rod_gain": 0.0, "fallback_fraction": 0.0}
    info = {"rod_gain": float(gain), "k1": float(k1)}
    if device is not None:              # one pass on the device, the luminance kept there
        p, fb = device.purkinje(rgb, area, k1, k2, gain, M, ko.SHIFT_XYZ)
        return p, {**info, "fallback_fraction": Later(fb)}     # (comes with the output)
    rgb = np.asarray(rgb)
    q = lmsr.rgb_to_lmsr(rgb)
    qh, _ = ko.purkinje_shift(q, area, k1, k2, ko.SHIFT_XYZ, gain)
    p, fbm = ko.gamut_map(M, qh)
    fb = float(fbm.mean())
    y_in = np.asarray(rgb, np.float64) @ Y_WEIGHTS
    y_p = p @ Y_WEIGHTS
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(y_p > 0, y_in / np.where(y_p > 0, y_p, 1.0), 0.0)
    out = np.where((y_p > 0)[..., None], p * k[..., None], rgb)
    return out.astype(np.float32), {**info, "fallback_fraction": float(fb)}


def _levels(settings, G_rod, G_cone, extra, dt, fresh, preadapt):
    """Advance the shared receptor levels over one frame (kept in ``extra``);
    returns (levels, rods' sensitivity)."""
    prev = (extra or {}).get(LEVELS_KEY)
    if prev is None or fresh:
        lv = (receptor_levels_preadapted(preadapt[0] * neutral_scotopic_ratio(),
                                         preadapt[0], preadapt[1])
              if (fresh and preadapt is not None) else receptor_levels_steady(G_rod, G_cone))
    else:
        lv = receptor_levels_advance(prev, G_rod, G_cone, dt)
    if extra is not None:
        extra[LEVELS_KEY] = {k: float(v) for k, v in lv.items()}
    pig = (extra or {}).get(PIGMENT_KEY)
    if bleaching.check(pig):           # the operator's own pigment course (this frame's)
        return lv, bleaching.rod_sensitivity(pig, G_rod, G_cone)
    return lv, rod_sensitivity(lv)


def advance(settings, G_rod: float, G_cone: float, extra: dict | None = None, dt: float = 0.0,
            fresh: bool = True, preadapt=None, weight: float = 1.0,
            skipped: bool = False) -> dict:
    """The shift's time course over one frame, part of the observer's state step
    (``Tonemapper.integrate``): the shared receptor levels advanced toward the
    frame's metering goals (G_rod, G_cone of the unchanged frame; ``extra`` keeps
    them in the adaptation state, without it: steady state at the frame), and
    whether and how strongly the frame is shifted. Returns the frame's info:
    ``ran`` (then :func:`shift` makes the pixels), the levels, the rods'
    sensitivity (dark adaptation x the plan's ``weight``), the rod gain.
    ``skipped``: the plan skips the shift this frame (its levels still advance, so
    that the shift comes back where a run that never skipped it would have it)."""
    if settings.purkinje == "off":
        return {"ran": False}
    lv, sens = _levels(settings, G_rod, G_cone, extra, dt, fresh, preadapt)
    if skipped:
        return {"ran": False, "reason": "plan", "A_rod": lv["A_rod"], "rod_sensitivity": sens}
    sens *= float(weight)
    k1, _, gain = ko.kappas(ko.KirkSettings(kappa="adaptive"), lv["A_rod"])
    k1, gain = k1 * sens, gain * sens
    info = {"A_rod": float(lv["A_rod"]), "A_cone": float(lv["A_cone"]), "rod_sensitivity": sens,
            "rod_gain": float(max(gain, 0.0)), "k1": float(k1)}
    if settings.purkinje == "auto" and gain <= PURKINJE_AUTO_GAIN:
        return {"ran": False, "reason": "photopic", **info}
    if gain <= 0.0:                          # on, but no rod signal: nothing to shift
        return {"ran": False, "reason": "no rod signal", **info}
    return {"ran": True, **info}


def shift(rgb, info: dict, device=None):
    """(shifted rgb, info) of a frame :func:`advance` shifts: each pixel's chromaticity
    moved as the rods join, its photopic luminance kept (``rgb`` a device image:
    shifted in place there)."""
    out, sh = apply_purkinje(rgb, info["A_rod"], info["A_cone"], device, info["rod_sensitivity"])
    return out, {**info, "fallback_fraction": sh["fallback_fraction"]}


class BandedPurkinje:
    """The shift of a frame in row bands (``Tonemapper.process_stream``): pointwise
    once the frame's levels are known, so each band is shifted as the whole frame
    is; ``fallback_fraction`` is summed over the first sweep of the frame."""

    def __init__(self, info: dict, device, height: int):
        self.info, self.device, self.h = info, device, int(height)
        self._fb, self._swept = 0.0, 0

    def __call__(self, y0: int, rgb: np.ndarray) -> np.ndarray:
        out, info = shift(rgb, self.info, self.device)
        y1 = y0 + len(rgb)
        if y0 <= self._swept < y1:
            self._fb += settle(info["fallback_fraction"]) * (y1 - self._swept)
            self._swept = y1
        return np.asarray(out, np.float32)

    def fallback_fraction(self) -> float | None:
        return self._fb / self.h if self._swept >= self.h else None


class PurkinjeShift(Effect):
    """The shift as an effect: its time course at the state step (:meth:`advance`,
    also on frames the plan skips, so that it comes back where a run that never
    skipped it would have it), then the pixels, on the device in place where it
    has kirk11's kernel, pointwise band by band for frames in bands."""

    name = "purkinje"
    slot = "seen"
    help = "rod colour shift of kirk11 on the scene's colours (Kirk & O'Brien 2011)"
    gated = True
    blends = True
    capabilities = frozenset({"host", "device", "banded"})

    def __init__(self, fx):
        super().__init__(fx)
        self._dev = None

    def _device(self):
        if self._dev is None:
            self._dev = self.fx.backend.purkinje_device()
        return self._dev

    def on_device(self) -> bool:
        """Whether the shift runs on the device (then in place on a device image: the
        working frame can stay there)."""
        return self.asked != "off" and self._device() is not None

    def advance(self, ctx) -> None:
        """Its receptor levels over the frame, toward the levels of the frame before its
        optical effects (``ctx.G_rod``, ``ctx.G_cone``); the record in ``ctx.eff``."""
        skipped = self.asked != "off" and self.mode == "off"    # the plan's: levels advance
        ctx.eff[self.name] = advance(self.fx.settings if skipped else self.fx.s, ctx.G_rod,
                                     ctx.G_cone, ctx.extra, ctx.dt, ctx.fresh, ctx.preadapt,
                                     self.fx.weight(self.name), skipped)

    def host(self, ctx, rgb):
        info = ctx.eff[self.name]
        if not info.get("ran"):
            return None, info
        return shift(rgb, info, self._device() if self.mode != "off" else None)

    device = host

    def banded(self, ctx, height: int):
        """(a :class:`BandedPurkinje` for a frame whose shift runs, else None; the
        function that records its gamut fallbacks once the bands are made)."""
        info = ctx.eff[self.name]
        if not info.get("ran"):
            return None, []
        band = BandedPurkinje(info, self._device() if self.mode != "off" else None, height)

        def done():
            fb = band.fallback_fraction()
            if fb is not None:
                info["fallback_fraction"] = fb
        return band, [done]
