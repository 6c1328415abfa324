"""Model only what a scene requires: the per-frame mechanism plan.

``analysis.py``  the frame reduced to a proxy and scene statistics (levels,
                 percentiles, light sources, dynamic range, illuminant);
``predict.py``   each mechanism's predicted effect, p99 Delta E ITP;
``planner.py``   the weights: the one-JND budget, hysteresis, ramps, state.

:class:`MechanismPlan` is what a :class:`~ocl_tonemap.pipeline.Tonemapper` runs
per frame; docs/models.md ("The mechanism plan") has the rules and their sources.
"""

from __future__ import annotations

import math

from ..models import spencer1995 as fl
from . import planner, predict
from .analysis import analyse, block_stride, patches_of, signature


class MechanismPlan:
    """The plan of one run: what the operator and the effects offer, and per frame
    the analysis, the predictions and the weights."""

    def __init__(self, operator, settings, display, metering, backend=None):
        self.op, self.settings, self.display, self.metering = operator, settings, display, metering
        self.backend = backend
        self.offer = planner.offered(operator, settings)
        self.gated = [m for m, mode in self.offer.items() if mode == "auto"]
        #: An analysis is made where an effect may run (its illuminant estimate too).
        self.active = settings.any
        #: Frame number -> its predictions, as a shot's measure pass stored them (the
        #: apply pass: used where a frame's predictions would be made again; they
        #: depend on the frame alone, so the frames are the serial run's).
        self.known: dict = {}
        #: Frame number -> (its analysis as ``SceneAnalysis.as_dict`` gave it, its
        #: signature), as the measure pass stored them: the apply pass replays them
        #: (no proxy, no patches, no analysis made again; the analysis depends on the
        #: frame alone, the weights are advanced here from the state as ever).
        self.replay: dict = {}
        self._limit = None              # flare_limit's last (levels, limit)

    def backend_sources(self, h: int, w: int, lim: float):
        """The source part's block means from the backend (None where it cannot)."""
        if self.backend is None:
            return None
        return self.backend.source_proxy((h, w), block_stride(h, w), lim)

    def white_luminance(self, G_rod: float, G_cone: float, lo: float = 0.0) -> float:
        """Where an observer adapted to these levels runs out of display: the scene
        luminance of a uniform neutral region it shows at display white (the
        operator's own model, ``Operator.white_luminance_at``, else pattanaik00's at
        the same levels: ``predict.DisplayResponse``'s stand-in)."""
        own = self.op.white_luminance_at(G_rod, G_cone, lo)
        if own is not None:
            return own
        resp = predict.DisplayResponse(self.op, self.display, G_rod, G_cone)
        return resp.op.white_luminance(resp.params, lo)

    def flare_limit(self, G_rod: float, G_cone: float) -> float:
        """The flare's source limit, cd/m^2, where the plan predicts the flare (else 0):
        ``spencer1995.source_limit`` with the display's white for a steady observer at
        the frame's levels (state-free, so that a shot's measure pass predicts what the
        serial run does; the flare itself takes the observer's current state)."""
        if not ("flare" in self.gated or self.settings.flare == "on"):
            return 0.0
        key = (float(G_rod), float(G_cone))
        if self._limit is None or self._limit[0] != key:
            k = self.settings.flare_threshold
            self._limit = (key, fl.source_limit(G_cone, k,
                                                self.white_luminance(G_rod, G_cone, k * G_cone)))
        return self._limit[1]

    def sources_ahead(self, h: int, w: int, G_rod: float, G_cone: float, predicts: bool) -> None:
        """Have the backend start the source proxy :meth:`frame` will read, where the
        frame's plan ``predicts`` (its predictions not reused from the last frame), so
        that work enqueued meanwhile runs before the plan waits for it."""
        if not (self.active and self.gated and predicts and self.backend is not None):
            return
        lim = self.flare_limit(G_rod, G_cone)
        if 0 < lim < math.inf:
            self.backend.source_proxy_ahead((h, w), block_stride(h, w), lim)

    def proxy_stride(self, h: int, w: int) -> int:
        """The block size of the frame's proxy (0: no plan for this run)."""
        return block_stride(h, w) if self.active else 0

    def frame(self, levels, get_rows, h: int, w: int, scale: float, extra: dict | None,
              dt: float, fresh: bool, get_patches=None, frame_number=None) -> dict:
        """{"weights", "estimate", "record"} of one frame: ``levels`` its backend's
        :class:`~ocl_tonemap.backends.base.Levels` with the proxy; ``get_rows(a, b)`` its
        working-space rows (full-resolution patches, for acuity; ``get_patches``: the
        frame's own way to give the patches alone, a device image's); ``extra``: the state's,
        where the weights advance (None: a measure-only pass, targets only)."""
        if self.replays(frame_number):
            return self._replayed(frame_number, extra, dt, fresh)
        if not self.active or levels.proxy is None:
            return {}
        G_rod, G_cone = levels.goal
        patches = patches_of(get_rows, h, w, scale, get_patches=get_patches) \
            if self.gated else []
        an = analyse(levels.proxy, G_rod, G_cone, w, h, self.display, patches)
        an.flare_limit = self.flare_limit(G_rod, G_cone)
        an.max_Y = levels.max_Y
        prev = (extra or {}).get(planner.STATE_KEY) or {}
        if prev.get("G_cone") and dt > 0:
            an.adapting = abs(math.log10(max(an.G_cone, 1e-12) / max(prev["G_cone"], 1e-12))) / dt
        sig = signature(an) if self.gated else None

        def predict() -> dict:
            if frame_number in self.known:
                return dict(self.known[frame_number])
            if 0 < an.flare_limit < math.inf:
                an.sources_proxy = self.backend_sources(h, w, an.flare_limit)
            p = planner.predictions(an, self.op, self.display, self.settings, self.gated)
            return {k: round(min(float(v), 1e9), 6) for k, v in p.items()}   # JSON: no inf

        weights, target, predicted, reused = self.advance(
            extra, predict if self.gated else {}, an.G_cone, dt, fresh or extra is None, sig)
        record = {"weights": weights, "target": target, "predicted_dE_p99": predicted,
                  "reused": reused, "sig": sig, "analysis": an.as_dict()}
        return {"weights": weights, "record": record,
                "estimate": (an.illuminant, an.illuminant_cct, an.illuminant_confidence)}

    def replays(self, frame_number) -> bool:
        """Whether :meth:`frame` replays this frame's stored analysis (its proxy is
        then not needed)."""
        return self.active and frame_number in self.replay and frame_number in self.known

    def _replayed(self, frame_number, extra: dict | None, dt: float, fresh: bool) -> dict:
        """:meth:`frame` from the stored analysis and signature: the same weights,
        record and estimate as the frame's own analysis would give."""
        an, sig = self.replay[frame_number]
        an = dict(an)
        prev = (extra or {}).get(planner.STATE_KEY) or {}
        if prev.get("G_cone") and dt > 0:
            an["adapting"] = abs(math.log10(max(an["G_cone"], 1e-12) /
                                            max(prev["G_cone"], 1e-12))) / dt
        weights, target, predicted, reused = self.advance(
            extra, (lambda: dict(self.known[frame_number])) if self.gated else {},
            an["G_cone"], dt, fresh or extra is None, sig)
        record = {"weights": weights, "target": target, "predicted_dE_p99": predicted,
                  "reused": reused, "sig": sig, "analysis": an}
        est = (tuple(an["illuminant"]), an["illuminant_cct"], an["illuminant_confidence"])
        return {"weights": weights, "record": record, "estimate": est}

    def advance(self, extra: dict | None, predicted, G_cone: float, dt: float,
                fresh: bool, sig: list | None = None) -> tuple[dict, dict, dict, bool]:
        """The weights of a frame from its predictions and the last frame's weights in
        ``extra`` (advanced there): the serial run's step, also the shot's integrate
        pass over the predictions its measure pass stored. ``predicted``: the frame's
        predictions, or a function that makes them (called only where the state's
        reference cannot be reused: ``planner.reusable``); ``sig``: the frame's
        signature. Returns (weights, targets, the predictions used, reused)."""
        prev = (extra or {}).get(planner.STATE_KEY) or {}
        ref = prev.get("ref")
        reused = not fresh and planner.reusable(ref, sig, self.gated)
        if reused:
            predicted = dict(ref["predicted"])
        else:
            predicted = predicted() if callable(predicted) else dict(predicted)
            ref = {"sig": sig, "predicted": predicted} if sig is not None else None
        target = planner.targets(self.offer, predicted, prev.get("weights"))
        weights = planner.step(prev.get("weights"), target, dt, fresh, predicted)
        if extra is not None:
            extra[planner.STATE_KEY] = {"weights": weights, "G_cone": float(G_cone)}
            if ref is not None:
                extra[planner.STATE_KEY]["ref"] = ref
        return weights, target, predicted, reused
