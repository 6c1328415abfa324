"""One frame's graph, apart from the observer it advances.

Data flows one way:
    working pixels x luminance scale -> cd/m^2 (bad-value policy, the backend's
    colour stage) -> the plan (``mechanisms/``) -> optical effects -> **measure**
    -> **integrate** (the observer's state, the effects' time courses) -> seen
    effects -> **apply** (the operator, per pixel) -> display effects.
:class:`FrameGraph` runs it for whole frames (``banded.py``: frames in row bands);
the operator says what each phase computes, the backend's schedule how, the
effects' runner (``effects/runner.py``) what the effects do in each slot.
"""

from __future__ import annotations

import math

import numpy as np

from ..backends.base import Levels, settle
from ..effects import FrameContext
from ..effects.runner import changed_frame
from ..operators import registry
from ..operators.base import Frame, FrameStats
from .results import FrameInfo, FrameResult, transfers_since


class FrameGraph:
    """The per-frame work of one run: its operator and schedule, backend, effects,
    mechanism plan and metering, for the observer it advances."""

    def __init__(self, op, schedule, backend, effects, plan, metering, observer):
        self.op, self.schedule, self.backend = op, schedule, backend
        self.effects, self.plan, self.metering = effects, plan, metering
        self.observer = observer
        self.primaries = None             # display linear -> working RGB (kirk11)
        self.record: dict = {}            # this frame's plan record (FrameInfo.plan)
        self.frozen = None                # the last mapping (stats, params, gains)
        #: ``stored(frame_number, schedule)``: the frame's statistics as a shot's
        #: measure pass stored them (:class:`FrameStats` for that schedule, or None),
        #: for schedules that map from them (``applies_stored``): the apply pass
        #: meters nothing twice.
        self.stored = None

    # -- the three phases -----------------------------------------------------------------
    def measure(self, frame: Frame) -> FrameStats:
        """Per-frame statistics of ``frame`` (metering, the illuminant, local levels): of
        the light that reaches the eye (its optical effects included), never of the
        observer's state."""
        s = self.effects.settings
        return self.schedule.measure(frame, self.metering,
                                     s.chromatic_adaptation != "off" and self.grey_world())

    def grey_world(self) -> bool:
        """Whether chromatic adaptation takes the backend's grey-world sums (the paper's
        estimate, or no scene analysis); else the analysis's bounded estimate."""
        return self.effects.s.paper or not self.plan.active

    def own_chroma(self) -> bool:
        """Chromatic adaptation on the scene's colours (schedules without receptor gains)."""
        return not self.schedule.receptor_gains and \
            self.effects.settings.chromatic_adaptation != "off"

    def scene_stats(self, stats: FrameStats, levels) -> None:
        """``stats`` completed from the frame's scene pass (``levels``; None where no
        effect or plan runs): the goals of the frame before its optical effects (the
        seen effects' levels follow them) and the illuminant estimate (the analysis's
        bounded one, else the grey world)."""
        if levels is None:
            return
        stats.scene_goal = (float(levels.goal[0]), float(levels.goal[1]))
        stats.scene_max_Y = None if levels.max_Y is None else float(levels.max_Y)
        stats.scene_max_Ys = None if levels.max_Ys is None else float(levels.max_Ys)
        stats.scene_repairs = levels.repairs
        est = self.effects.estimate
        if est is not None and not self.effects.s.paper:
            stats.illuminant = lambda e=np.asarray(est[0], np.float64): e
        elif stats.illuminant is None:
            stats.illuminant = levels.illuminant

    def integrate(self, stats: FrameStats, time_s: float, frame_number, dt: float, fresh: bool,
                  illuminant, eff: dict):
        """Advance the observer over one frame's statistics: the operator's state, then
        the effects' time courses (their records into ``eff``). (params, receptor gains)."""
        obs = self.observer
        self.schedule.integrate(obs.scalars, stats, dt, fresh)
        obs.shown(time_s, frame_number)
        params = self.op.params(obs.scalars, stats) if self.schedule.receptor_gains else None
        G_rod, G_cone = stats.scene_goal or (stats.G_rod, stats.G_cone)
        ctx = FrameContext(G_rod, G_cone, eff=eff, max_Y=stats.scene_max_Y,
                           max_Ys=stats.scene_max_Ys, dt=dt, fresh=fresh,
                           extra=obs.scalars.extra, preadapt=obs.preadapt, frame=frame_number,
                           time_s=float(time_s))
        gains = self.effects.advance(ctx, self.schedule.receptor_gains,
                                     stats.scene_goal is not None, illuminant, stats.illuminant,
                                     stats.G_cone)
        peak = [r["peak_seen"] for r in eff.values() if isinstance(r, dict) and "peak_seen" in r]
        if peak:        # what the frame's brightest light keeps (operators that map it to white)
            stats.values["peak_seen"] = float(np.prod(peak))
        return params, gains

    def apply(self, frame: Frame, stats: FrameStats, params=None, gains=None, sink=None,
              encoding=None):
        """The per-pixel mapping of ``frame`` under the current state."""
        return self.schedule.apply(frame, self.observer.scalars, stats, params, gains, sink,
                                   encoding)

    # -- the plan -------------------------------------------------------------------------
    def begin_frame(self, scene: bool = True) -> bool:
        """A frame starts: the effects forget the last frame's plan (``scene`` False: a
        spectral frame, whose optical and seen effects are left out); returns whether
        the last frame's predictions were reused (the flare's early start waits for this
        one's)."""
        fx = self.effects
        reused = bool(self.record.get("reused", False))
        fx.drop_started()
        fx.begin_frame(None if scene else {m: 1.0 for m, n in fx.gated().items()
                                           if fx.effect(n).slot == "display"})
        self.record = {}
        return reused

    def begin_plan(self, levels, frame: Frame, dt: float, fresh: bool, measure_only: bool,
                   weights: dict | None = None, frame_number=None) -> None:
        """The frame's mechanism plan from its scene pass (``levels``), handed to the
        effects; the weights advance in the state's ``extra`` (not in a measure-only
        pass). ``weights``: the gated effects' weights to use instead (a shot's integrate
        pass measuring a frame again as the serial run's plan weighs it)."""
        if levels is None:
            return
        h, w = frame.shape[:2]
        pix = frame.pixels
        plan = self.plan.frame(levels, lambda a, b: pix[a:b], h, w, frame.scale,
                               None if measure_only else self.observer.scalars.extra, dt, fresh,
                               getattr(pix, "patches", None), frame_number)
        self.effects.begin_frame(weights if weights is not None else plan.get("weights"),
                                 plan.get("estimate"))
        self.record = plan.get("record", {})

    def advance_plan(self, predicted: dict, G_cone: float, dt: float, fresh: bool,
                     sig: list | None = None) -> dict:
        """Advance the plan over a frame's stored predictions and signature (the shot's
        integrate pass; a serial run does it in the frame): the weights, also handed to
        the effects for the frame's :meth:`integrate`."""
        weights = self.plan.advance(self.observer.scalars.extra, predicted, G_cone, dt, fresh,
                                    sig)[0]
        self.effects.begin_frame(weights)
        return weights

    def source_limit(self, levels) -> float:
        """The frame's flare source limit (``models/spencer1995.py`` source_limit): the
        paper's test, and beyond the display's white for an observer adapted to the
        frame (``MechanismPlan.flare_limit``: the flare changes the light that is
        metered, so its sources cannot depend on the state); inf where it cannot run."""
        if self.effects.settings.flare == "off":
            return math.inf
        return self.plan.flare_limit(*levels.goal)

    def working(self, frame: Frame, frame_number=None, stored: FrameStats | None = None):
        """The frame's colour stage and metering for the plan and the effects (the
        backend's :class:`~ocl_tonemap.backends.base.Levels`), or None where neither
        runs. The working frame stays on the device where an effect runs there (the
        flare whole, else the Purkinje shift): one upload, no round trip. ``stored``:
        the frame's statistics from a shot's measure pass; where they hold its scene
        metering and the plan is replayed, only the colour stage runs."""
        fx = self.effects
        if not self.plan.active and not fx.optical_active():
            return None
        pix = frame.pixels
        h, w = pix.shape[:2]
        on_dev = pix.shape[2] == 3 and fx.keeps_on_device(h, w)
        replayed = self.plan.replays(frame_number)
        known = None
        if stored is not None and replayed and stored.scene_goal is not None and \
                stored.scene_max_Y is not None and stored.scene_repairs is not None:
            known = Levels(None, stored.scene_repairs, stored.scene_goal, stored.illuminant,
                           stored.scene_max_Y, max_Ys=stored.scene_max_Ys)
        return self.backend.working(pix, frame.scale, self.metering,
                                    self.own_chroma() and self.grey_world(), on_device=on_dev,
                                    proxy_stride=0 if replayed else self.plan.proxy_stride(h, w),
                                    metered=known)

    # -- a whole frame --------------------------------------------------------------------
    def run(self, frame: Frame, dt, time_s, frame_number, illuminant, encoding=None,
            measure_only: bool = False, weights: dict | None = None):
        """One whole frame: the optical effects -> measure -> integrate -> the seen
        effects -> apply -> the display effects, and its record (``measure_only``: its
        statistics, the state untouched; ``weights``: the plan's weights of its gated
        effects instead of the frame's own, for a shot's integrate pass)."""
        rgb_in = frame.wavelengths is None
        if measure_only:
            step_dt, fresh = 0.0, True
        else:
            time_s, step_dt, fresh = self.observer.clock(dt, time_s)
        reused = self.begin_frame(rgb_in)
        moved = self.backend.transfers()
        fx = self.effects
        eff: dict = {}
        stats = None
        if self.stored is not None and not measure_only and self.schedule.applies_stored:
            stats = self.stored(frame_number, self.schedule)
        levels = self.working(frame, frame_number, stats) if rgb_in else None
        metered = frame
        if levels is not None:
            ctx = FrameContext(*levels.goal, eff=eff, lim=self.source_limit(levels),
                               max_Y=levels.max_Y, frame=frame_number)
            if levels.rgb is not None and not isinstance(levels.rgb, np.ndarray):
                h, w = frame.shape[:2]       # the device starts the flare while the host plans
                self.plan.sources_ahead(h, w, *levels.goal, (fresh or not reused) and
                                        frame_number not in self.plan.known)
                fx.start(ctx, levels.rgb)
            self.begin_plan(levels, frame, step_dt, fresh, measure_only, weights, frame_number)
            self.record["flare_metered"] = fx.metered_weights(levels.max_Y, ctx.lim)
            rgb, changed = fx.optical(ctx, levels.rgb)
            if changed or not isinstance(levels.rgb, (np.ndarray, type(None))):
                # (unchanged but on the device: measured where it is, not uploaded again)
                metered = changed_frame(frame, rgb, self.primaries)
        if stats is None:
            stats = self.measure(metered)
        self.scene_stats(stats, levels)
        if measure_only:
            return stats
        params, gains = self.integrate(stats, time_s, frame_number, step_dt, fresh, illuminant,
                                       eff)
        work = metered
        if levels is not None:
            ctx = FrameContext(*levels.goal, eff=eff, frame=frame_number)
            rgb, changed = fx.seen(ctx, levels.rgb if metered is frame else metered.pixels,
                                   self.own_chroma())
            if changed:
                work = changed_frame(metered, rgb, self.primaries)
        dctx = FrameContext(stats.G_rod, stats.G_cone, eff=eff, frame=frame_number,
                            time_s=float(time_s), width=stats.width)
        encoding, done = fx.display_encoding(dctx, encoding, self.schedule.encodes_output,
                                             stats.height, stats.width)
        out = self.apply(work, stats, params, gains, encoding=encoding)
        stats.handle = None              # the resident frame: its pixels are spent now
        self.frozen = (stats, params, gains)
        out = fx.display(dctx, out, encoding is not None, done)
        repairs = levels.repairs if metered is not frame else stats.repairs
        info = FrameInfo(frame_number, float(time_s), step_dt, stats.G_rod, stats.G_cone,
                         repairs, self.observer.scalars.copy(),
                         settle(self.schedule.summary(stats, params)), settle(eff), self.record,
                         transfers_since(self.backend, moved))
        return FrameResult(out, None, info, encoding is not None)

    def run_device(self, img, dt, time_s, frame_number, scale, illuminant, encoding,
                   measure_only: bool, weights: dict | None):
        """:meth:`run` of a frame already on the device (a device image): its
        display-linear output left there as a new device array (``encoding`` given:
        code values to the host as for host frames). Where a display effect works only
        on host pixels, the output comes back and goes up again (one upload)."""
        res = self.run(Frame(img, scale, None, self.primaries), dt, time_s, frame_number,
                       illuminant, encoding or self.backend.device_output(), measure_only,
                       weights)
        if measure_only:
            return res
        if encoding is None and not res.encoded:
            res.output = self.backend.device_array(res.output)
        res.encoded = encoding is not None and res.encoded
        return res


def spectral_frame(op, operator_name: str, effects, frame, wavelengths, scale,
                   primaries) -> Frame:
    """A spectral frame checked for the run (an operator that takes them; no optical or
    seen effect asked for ``on``, as they need RGB: on ``auto`` they are left out)."""
    if "spectral" not in op.inputs:
        which = [n for n, c in registry().items() if "spectral" in c.inputs]
        raise ValueError(f"operator {operator_name} takes RGB frames; spectral "
                         f"input needs --operator {' or '.join(which)}")
    rgb_only = [e.name for e in effects.all if e.slot != "display" and e.asked == "on"]
    if rgb_only:
        raise ValueError(f"{', '.join(n.replace('_', ' ') for n in rgb_only)} need RGB "
                         "input; switch them off for spectral frames")
    pix = np.ascontiguousarray(frame, np.float32)
    lam = np.asarray(wavelengths, np.float64)
    if pix.ndim != 3 or pix.shape[2] != len(lam) or len(lam) < 2:
        raise ValueError(f"spectral frame must be H x W x {len(lam)} (got {pix.shape})")
    return Frame(pix, scale, lam, primaries)
