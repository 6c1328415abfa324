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

from . import planner
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

    def backend_sources(self, h: int, w: int, lim: float):
        """The source part's block means from the backend (None where it cannot)."""
        if self.backend is None:
            return None
        return self.backend.source_proxy((h, w), block_stride(h, w), lim)

    def flare_limit(self, G_cone: float) -> float:
        """The flare's source threshold, cd/m^2, where the plan predicts from it (else 0)."""
        if "flare" in self.gated or self.settings.flare == "on":
            return self.settings.flare_threshold * G_cone
        return 0.0

    def sources_ahead(self, h: int, w: int, G_cone: float, predicts: bool) -> None:
        """Have the backend start the source proxy :meth:`frame` will read, where the
        frame's plan ``predicts`` (its predictions not reused from the last frame), so
        that work enqueued meanwhile runs before the plan waits for it."""
        lim = self.flare_limit(G_cone)
        if self.active and self.gated and predicts and lim > 0 and self.backend is not None:
            self.backend.source_proxy_ahead((h, w), block_stride(h, w), lim)

    def proxy_stride(self, h: int, w: int) -> int:
        """The block size of the frame's proxy (0: no plan for this run)."""
        return block_stride(h, w) if self.active else 0

    def frame(self, levels, get_rows, h: int, w: int, scale: float, extra: dict | None,
              dt: float, fresh: bool) -> dict:
        """{"weights", "estimate", "record"} of one frame: ``levels`` its backend's
        :class:`~ocl_tonemap.backends.base.Levels` with the proxy; ``get_rows(a, b)`` its
        working-space rows (full-resolution patches, for acuity); ``extra``: the state's,
        where the weights advance (None: a measure-only pass, targets only)."""
        if not self.active or levels.proxy is None:
            return {}
        G_rod, G_cone = levels.goal
        patches = patches_of(get_rows, h, w, scale) if self.gated else []
        an = analyse(levels.proxy, G_rod, G_cone, w, h, self.display, patches)
        an.flare_limit = self.flare_limit(G_cone)
        prev = (extra or {}).get(planner.STATE_KEY) or {}
        if prev.get("G_cone") and dt > 0:
            an.adapting = abs(math.log10(max(an.G_cone, 1e-12) / max(prev["G_cone"], 1e-12))) / dt
        sig = signature(an) if self.gated else None

        def predict() -> dict:
            if an.flare_limit > 0:
                an.sources_proxy = self.backend_sources(h, w, an.flare_limit)
            p = planner.predictions(an, self.op, self.display, self.settings, self.gated)
            return {k: round(min(float(v), 1e9), 6) for k, v in p.items()}   # JSON: no inf

        weights, target, predicted, reused = self.advance(
            extra, predict if self.gated else {}, an.G_cone, dt, fresh or extra is None, sig)
        record = {"weights": weights, "target": target, "predicted_dE_p99": predicted,
                  "reused": reused, "sig": sig, "analysis": an.as_dict()}
        return {"weights": weights, "record": record,
                "estimate": (an.illuminant, an.illuminant_cct, an.illuminant_confidence)}

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
