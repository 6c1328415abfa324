"""Chromatic adaptation: von Kries gains on the cone signals toward the illuminant,
Durand & Dorsey 2000, Eq. 6, filtered in time with tau = 5 s (Sec. 3.4).

Slot: seen, on the receptors: the schedule applies the gains to the cone signals
before its per-pixel map where its map separates cones from rods (the pointwise
operators: ``receptor_gains``), and they go on the working RGB after the state
step otherwise (ledda04, kirk11). Needs: the frame's illuminant (user > EXR
``adoptedNeutral`` > estimate). State: the adapted illuminant
(``AdaptationState.extra["illuminant_rgb"]``). The model is in
``models/durand2000.py``; :class:`ChromaticAdaptation` is the effect.
"""

from __future__ import annotations

import numpy as np

from ..models.durand2000 import (ILLUMINANTS_XY, cct_duv, chromatic_step,
                                 degree_of_adaptation, normalise_illuminant, parse_illuminant,
                                 partial_illuminant, plausible_illuminant, von_kries_gains)
from ..base.quantities import Numbers, Quantity, Text
from .base import Effect, EffectOption

STATE_KEY = "illuminant_rgb"
#: ``auto`` applies chromatic adaptation when a gain differs from 1 by more than this:
#: a gain of 1.004 moved the plan's lamp-lit test scene by 1.2 Delta E ITP at p99
#: (near display white ITP's steps are fine), so 0.2% keeps a skipped one within
#: about half a JND (tests/mechanisms/test_plan.py, test_auto_within_one_jnd_of_full).
CHROMA_AUTO_TOLERANCE = 0.002


def illuminant_goal(user_illuminant, frame_hint, estimate_fn):
    """(normalised rgb, source): user value > frame metadata > estimate."""
    if user_illuminant is not None:
        return user_illuminant, "user"
    if frame_hint is not None:
        return normalise_illuminant(frame_hint), "adoptedNeutral"
    return plausible_illuminant(estimate_fn()), "estimate"


def run(settings, extra: dict, goal, source: str, dt: float, fresh: bool, preadapted: bool,
        L_A: float | None = None):
    """Advance the illuminant state; returns (gains or None, info). The state is the
    white the eye adapts to: the goal moved toward the working white by the degree
    of adaptation D (``degree_of_adaptation``: CAM16's D at ``L_A`` cd/m^2, less for
    warm light; 1 with
    ``paper``, the paper's Eq. 6, or without ``L_A``)."""
    if settings.chromatic_adaptation == "off":
        return None, {"ran": False}
    full = np.asarray(goal, np.float64)
    D = 1.0
    if not settings.paper and L_A is not None:
        D = degree_of_adaptation(L_A, cct_duv(full)[0])
    goal = partial_illuminant(full, D)
    prev = extra.get(STATE_KEY)
    if fresh or prev is None:
        illum = np.ones(3) if preadapted else np.asarray(goal, np.float64)
    else:
        illum = chromatic_step(np.asarray(prev, np.float64), goal, dt)
    extra[STATE_KEY] = [float(v) for v in illum]
    g = von_kries_gains(illum)
    ran = settings.chromatic_adaptation == "on" or \
        float(np.max(np.abs(g - 1.0))) > CHROMA_AUTO_TOLERANCE
    info = {"ran": ran, "source": source, "estimate": [float(v) for v in full],
            "degree": D, "goal": [float(v) for v in goal],
            "illuminant": extra[STATE_KEY], "gains": [float(v) for v in g]}
    return (g if ran else None), info


def _illuminant(v) -> str:
    """``--illuminant``: a name (D65, A, F2 ...) or a chromaticity ``x,y`` (each 0..1,
    x + y < 1: within the diagram), kept as written."""
    t = str(v).strip()
    if t.upper() in ILLUMINANTS_XY:
        return t
    XY.check(t, "--illuminant")
    return t


XY = Numbers("illuminant's chromaticity", "x,y", rule=lambda xy: "" if xy[0] + xy[1] < 1.0
             else "x + y below 1 (a chromaticity)", parts=(
                 Quantity("x", "", 0.0, 1.0, above=True), Quantity("y", "", 0.0, 1.0, above=True)))


class ChromaticAdaptation(Effect):
    """Chromatic adaptation as an effect: the adapted illuminant advanced at the state
    step (:meth:`advance`: the gains, for the schedule's cone signals where it takes
    them), and the gains on the scene's working RGB after it otherwise (:meth:`host`,
    pointwise, band by band for frames in bands). Not gated: it costs nothing, and
    ``auto`` applies the degree of adaptation."""

    name = "chromatic_adaptation"
    mechanism = "chromatic-adaptation"
    slot = "seen"
    help = "von Kries adaptation to the illuminant, tau 5 s"
    blends = True
    capabilities = frozenset({"host", "device", "banded"})
    options = (
        EffectOption("illuminant", "--illuminant", "illuminant for chromatic adaptation: "
                     "x,y or a name (D65, D50, A, F2, F11, LED-B3 ...); default: EXR "
                     "adoptedNeutral, else estimated from the frame",
                     metavar="x,y|NAME", value=None,
                     decl=Text("illuminant", "x,y (each 0..1, x + y below 1) or a name: "
                               + ", ".join(sorted(ILLUMINANTS_XY)), _illuminant)),
    )

    def __init__(self, fx):
        super().__init__(fx)
        s = fx.settings
        self.user_illuminant = parse_illuminant(s.illuminant) if s.illuminant else None

    def illuminant_goal(self, frame_hint, estimate_fn):
        """(normalised rgb, source): user value > frame metadata > estimate (the scene
        analysis's bounded one; with ``paper``, the paper's: the backend's grey world
        ``estimate_fn``)."""
        est = estimate_fn
        if self.fx.estimate is not None and not self.fx.s.paper:
            est = lambda: self.fx.estimate[0]                 # noqa: E731
        return illuminant_goal(self.user_illuminant, frame_hint, est)

    def advance_gains(self, ctx, frame_hint, estimate_fn, L_A: float | None):
        """Advance the illuminant state over the frame; (gains or None), the record in
        ``ctx.eff``. ``L_A``: the adapting luminance of the degree of adaptation."""
        goal, src = self.illuminant_goal(frame_hint, estimate_fn)
        gains, ctx.eff[self.name] = run(self.fx.s, ctx.extra, goal, src, ctx.dt, ctx.fresh,
                                        ctx.preadapt is not None, L_A)
        return gains

    def scene_gains(self, ctx):
        """The gains on the scene's working RGB (float32), None where none apply."""
        ca = ctx.eff.get(self.name) or {}
        return np.asarray(ca["gains"], np.float32) if ca.get("ran") else None

    def host(self, ctx, rgb):
        g = self.scene_gains(ctx)
        if g is None:
            return None, ctx.eff.get(self.name) or {"ran": False}
        return (np.asarray(rgb) * g).astype(np.float32), ctx.eff[self.name]

    def device(self, ctx, img):
        """The gains in place on a frame held on the device (the same float32 products
        as :meth:`host`; the frame does not cross to the host and back)."""
        g = self.scene_gains(ctx)
        if g is None:
            return None, ctx.eff.get(self.name) or {"ran": False}
        out = self.fx.backend.scale_image(img, g)
        return (self.host(ctx, img)[0] if out is None else out), ctx.eff[self.name]

    def on_device(self) -> bool:
        """The gains alone keep no frame on the device (only a frame the flare or the
        Purkinje shift left there gets them there)."""
        return False
