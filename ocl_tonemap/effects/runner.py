"""The effects of one observer, run slot by slot (``base.py`` says what a slot is).

:class:`Effects` holds the run's settings, each registered effect's instance, the
backend's device blur they share, and per frame the plan's weights. A frame's
effects run by one loop per slot, for whole frames (:meth:`Effects.optical`,
:meth:`~Effects.advance`, :meth:`~Effects.seen`, :meth:`~Effects.display`) and
for frames in row bands (:meth:`~Effects.optical_banded`, :meth:`~Effects.seen_banded`,
:meth:`~Effects.display_banded`): each effect through the method of its
capability (``host``, ``device``, ``banded``).

* **optical** effects change the light that reaches the eye, before it is metered:
  the flare (light scattered in the eye: its veil adapts the eye as the scene does,
  Ward Larson et al. 1997, CIE's veiling luminance added to the background). Their
  strength may not depend on the observer's state (a shot's measure pass knows
  none): the flare's sources are those of an observer adapted to the frame, its
  weight the mechanism plan's;
* **seen** effects change what the observer makes of that light, after its state
  step, their strength part of the state: the Purkinje shift (rods joining the cone
  pathways) and chromatic adaptation's gains where the schedule cannot put them on
  the cone signals. The metering sees the light, not them;
* **display** effects change the display-linear output: acuity.

docs/models.md, "Effects before and after the metering".
"""

from __future__ import annotations

import functools

import numpy as np

from ..operators.base import Frame
from .base import FrameContext
from .settings import BUILT_IN, EffectSettings, in_flow_order


def changed_frame(frame: Frame, rgb, primaries) -> Frame:
    """A new frame of working ``rgb`` (cd/m^2, scale 1; a host array or a device image,
    RGB only), with ``frame``'s alpha."""
    pix = frame.pixels
    if isinstance(rgb, np.ndarray):
        rgb = np.asarray(rgb, np.float32)[..., :3]
        if pix.shape[2] == 4:
            rgb = np.concatenate([rgb, np.asarray(pix[..., 3:4], np.float32)], axis=2)
        rgb = np.ascontiguousarray(rgb, np.float32)
    return Frame(rgb, 1.0, None, primaries)


def _blend(old, new, w: float) -> np.ndarray:
    old = np.asarray(old, np.float32)[..., :3]
    return (old + w * (np.asarray(new, np.float32)[..., :3] - old)).astype(np.float32)


class Effects:
    """The effects of one observer: settings, each effect's instance, the backend's
    device blur, and this frame's plan (weights of the gated effects, the scene
    analysis's illuminant estimate)."""

    def __init__(self, settings: EffectSettings, backend):
        self.s = self.settings = settings
        #: This frame's plan weights of the gated effects (name -> 0..1) and the scene
        #: analysis's illuminant estimate (rgb, CCT, confidence): :meth:`begin_frame`.
        self.weights: dict = {}
        self.estimate = None
        self.backend = backend
        self._blur_pixels = backend.max_band_pixels
        #: What the run has said once (warnings not repeated per frame).
        self.said: set = set()
        self.all = [cls(self) for cls in in_flow_order()]
        self.by_name = {e.name: e for e in self.all}

    # -- shared device help ---------------------------------------------------------
    @functools.cached_property
    def device_blur(self):
        """The backend's device blur (flare, acuity) or None, made on first use: its
        program build is ~40 ms of a start on PoCL, for runs that may never blur. Its
        band size is the backend's when the effects were made (a streamed frame narrows
        the backend's own bands later: the blur keeps its whole-frame passes)."""
        return self.backend.device_blur(self._blur_pixels)

    @property
    def blur(self):
        """``blur(img, taps, edge)`` on the device, or None (the effects' NumPy path)."""
        dev = self.device_blur
        return None if dev is None else dev.blur

    # -- the run's effects --------------------------------------------------------------
    def effect(self, name: str):
        return self.by_name.get(name)

    def in_slot(self, slot: str) -> list:
        return [e for e in self.all if e.slot == slot]

    @property
    def plugins(self) -> list:
        """The installed effects the run has on (not built in)."""
        return [e for e in self.all if type(e) not in BUILT_IN and e.asked != "off"]

    def gated(self) -> dict:
        """mechanism -> effect name of the effects the plan may skip."""
        return {type(e).mechanism_name(): e.name for e in self.all if e.gated}

    def set_settings(self, settings: EffectSettings) -> None:
        self.settings = self.s = settings

    def begin_frame(self, weights: dict | None, estimate=None) -> None:
        """This frame's plan: ``weights`` (mechanism -> 0..1, ``mechanisms.planner``)
        switch the gated effects on ``auto`` on or off for the frame and blend them
        in; ``estimate``: the analysis's (illuminant rgb, CCT, confidence)."""
        self.estimate = estimate
        if not weights:
            self.s, self.weights = self.settings, {}
            return
        modes, self.weights = {}, {}
        for mech, name in self.gated().items():
            if getattr(self.settings, name) == "auto":
                w = float(weights.get(mech, 0.0))
                modes[name] = "on" if w > 0.0 else "off"
                self.weights[name] = w
        self.s = self.settings.replace(**modes)

    def weight(self, name: str) -> float:
        return self.weights.get(name, 1.0)

    def stream_blocker(self) -> str | None:
        """Why frames cannot stream in bands for these effects (None: they can)."""
        for e in self.all:
            if e.asked != "off" and "banded" not in e.capabilities:
                return f"the effect {e.name} needs the whole frame"
        return None

    def keeps_on_device(self, h: int, w: int) -> bool:
        """Whether a frame's working pixels stay on the device: where the first of its
        effects that work on the device, in flow order, runs there whole (the flare;
        without it, the Purkinje shift)."""
        for e in self.all:
            if e.slot != "display" and "device" in e.capabilities and e.asked != "off":
                return e.on_device(h, w) if e.slot == "optical" else e.on_device()
        return False

    def optical_active(self) -> bool:
        """Whether an optical effect other than the built-in ones runs (the frame's
        colour stage is then needed even without a plan)."""
        return any(e.slot == "optical" for e in self.plugins)

    # -- whole frames ---------------------------------------------------------------------
    def start(self, ctx: FrameContext, rgb) -> None:
        """Before the frame is planned: what the optical effects can start on the device."""
        for e in self.in_slot("optical"):
            if e.asked != "off":
                e.start(ctx, rgb)

    def drop_started(self) -> None:
        """Drop what :meth:`start` began for a frame that failed before its effects."""
        for e in self.in_slot("optical"):
            e.drop_started()

    def _runs(self, e) -> bool:
        return type(e) in BUILT_IN or e.mode != "off"

    def _one(self, e, ctx, rgb):
        """Effect ``e`` on ``rgb`` through its capability: (new or None, info)."""
        if not isinstance(rgb, np.ndarray) and "device" not in e.capabilities:
            rgb = np.asarray(rgb)             # the host's effects work on host pixels
        new, info = (e.device if not isinstance(rgb, np.ndarray) else e.host)(ctx, rgb)
        w = self.weight(e.name)
        if new is not None and not e.blends and w < 1.0:
            new = _blend(rgb, new, w)
            info = {**info, "weight": w}
        return rgb, new, info

    def optical(self, ctx: FrameContext, rgb):
        """The optical effects on a whole frame's working ``rgb`` (cd/m^2; a host array or
        a device image): (the frame's rgb after them, changed?)."""
        changed = False
        for e in self.in_slot("optical"):
            if not self._runs(e):
                ctx.eff[e.name] = {"ran": False}
                continue
            rgb, new, ctx.eff[e.name] = self._one(e, ctx, rgb)
            if new is not None:
                rgb, changed = (new if type(e) in BUILT_IN else np.asarray(new, np.float32)), True
        return rgb, changed

    def metered_weights(self, max_Y: float | None, lim: float) -> float | None:
        """The flare's weight in the frame that is metered (``Flare.metered_weight``),
        None where none can change it."""
        flare = self.effect("flare")
        return None if flare is None else flare.metered_weight(max_Y, lim)

    def advance(self, ctx: FrameContext, receptor: bool, scene_goal: bool, frame_hint,
                estimate_fn, L_A_metered: float):
        """The effects' time courses over the frame (the state step): their records into
        ``ctx.eff``; returns the chromatic gains for the schedule's cone signals where
        it takes them (``receptor``), else None (the scene's gains stay in the record
        for :meth:`seen`). ``scene_goal``: the frame's scene levels are known (the
        gains then go on the scene where the schedule does not take them)."""
        gains = None
        for e in self.all:
            if e.slot != "seen":
                continue
            if e.name == "chromatic_adaptation":
                if e.mode == "off" or not (receptor or scene_goal):
                    continue
                # the adapting luminance: the metered frame's on the cone signals; the
                # frame's own metering where the gains go on the scene
                g = e.advance_gains(ctx, frame_hint, estimate_fn,
                                    L_A_metered if receptor else ctx.G_cone)
                gains = g if receptor else None
            else:
                e.advance(ctx)
        return gains

    def seen(self, ctx: FrameContext, rgb, own_chroma: bool):
        """The seen effects on a whole frame's working ``rgb`` after the state step:
        (rgb, changed?). ``own_chroma``: the chromatic gains go on the scene."""
        todo = [e for e in self.in_slot("seen") if self._seen_runs(e, ctx, own_chroma)]
        if not todo:
            return rgb, False
        if isinstance(rgb, np.ndarray):
            rgb = rgb[..., :3]
        for e in todo:
            rgb, new, info = self._one(e, ctx, rgb)
            if new is not None:
                rgb = new
                ctx.eff[e.name] = info
        return rgb, True

    def _seen_runs(self, e, ctx, own_chroma: bool) -> bool:
        if e.name == "chromatic_adaptation":
            return own_chroma and e.scene_gains(ctx) is not None
        if type(e) in BUILT_IN:
            return bool((ctx.eff.get(e.name) or {}).get("ran"))
        return e.mode != "off"

    def display_encoding(self, ctx: FrameContext, encoding, encodes_output: bool,
                         h: int, w: int):
        """(the encoding the schedule may apply on the device, the display effects'
        records made before it): None where a display effect needs display-linear
        pixels first; the acuity blur on the device before the encoding where it can."""
        if encoding is None:
            return None, {}
        if not encodes_output or any(self._runs(e) and "device" not in e.capabilities
                                     for e in self.in_slot("display")):
            return None, {}
        done = {}
        for e in self.in_slot("display"):
            if "device" in e.capabilities and e.needed(ctx, w):
                encoding, done[e.name] = e.encoding(ctx, encoding, h, w)
                if encoding is None:
                    return None, {}
        return encoding, done

    def display(self, ctx: FrameContext, out, encoded: bool, done: dict):
        """The display effects on a whole frame's display-linear ``out`` (``encoded``:
        code values came back, blurred before the encoding where ``done`` says so)."""
        for e in self.in_slot("display"):
            if e.name in done:
                ctx.eff[e.name] = done[e.name]
            elif not self._runs(e):
                ctx.eff[e.name] = {"ran": False}
            elif encoded:
                ctx.eff[e.name] = e.report(ctx, ctx.width)
            else:
                _, new, ctx.eff[e.name] = self._one(e, ctx, out)
                out = out if new is None else np.asarray(new, np.float32)
        return out

    # -- frames in row bands ------------------------------------------------------------
    def optical_banded(self, ctx: FrameContext, rows, band_px: int, block_px: int):
        """The optical effects of a frame in bands, before its metering pass: (the
        banded source of its rows after them or None, functions to call once the
        metering pass has swept the frame)."""
        bands, sweep = None, []
        for e in self.in_slot("optical"):
            if e.asked == "off" and type(e) not in BUILT_IN:
                continue
            made, after = e.banded(ctx, rows, band_px, block_px)
            if made is not None:
                bands, sweep = made, sweep + after
        return bands, sweep

    def seen_banded(self, ctx: FrameContext, height: int, own_chroma: bool):
        """The seen effects of a frame in bands: (``per_band(y0, rgb)`` or None,
        functions to call once its bands have been made)."""
        steps, after = [], []
        for e in self.in_slot("seen"):
            if e.name == "chromatic_adaptation":
                g = e.scene_gains(ctx) if own_chroma else None
                if g is not None:
                    steps.append(lambda y0, rgb, g=g: (rgb * g).astype(np.float32))
                continue
            if not self._runs(e):
                continue
            step, finish = e.banded(ctx, height)
            if step is not None:
                steps.append(step)
                after += finish
        if not steps:
            return None, after

        def per_band(y0, rgb):
            for step in steps:
                rgb = step(y0, rgb)
            return rgb
        return per_band, after

    def display_banded(self, ctx: FrameContext, sink, shape, block_px: int):
        """The sink the display effects of a frame in bands put in front of ``sink``."""
        for e in reversed(self.in_slot("display")):
            if not self._runs(e):
                ctx.eff[e.name] = {"ran": False}
                continue
            sink, ctx.eff[e.name] = e.banded(ctx, sink, shape, block_px)
        return sink
