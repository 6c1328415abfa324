"""The per-frame mechanism plan: which mechanisms of vision a frame gets, and how much.

Every mechanism an operator offers has a weight in [0, 1] per frame (0 skipped,
1 fully applied, between: blended in or out). With ``--model auto`` the gated
mechanisms on ``auto`` (flare, acuity, the Purkinje shift: the ones whose
skipping saves time) are skipped where their predicted effect is small: the
predicted p99 Delta E ITP of each (``predict.py``, x :data:`SAFETY`) is summed
over the skipped ones, smallest first, up to one budget of :data:`BUDGET` JND for
the whole frame against ``--model full``. The mechanisms that cost nothing to run
(rods, chromatic adaptation, time integration, ledda04's local adaptation, whose
bilateral filter every frame of it needs) keep weight 1 where offered: skipping
them could only add error. docs/models.md, "The mechanism plan".

Over time the plan is filtered so that it never flickers: a mechanism that runs
is kept until its prediction falls below :data:`HYSTERESIS` of what switched it
on, and a weight moves by at most dt / :data:`RAMP_S` a frame (1/3 at 30 fps); a
fresh observer (the first frame, a cut) takes the targets at once. The weights
are kept in the adaptation state (``extra["plan"]``) and so resume with it.
"""

from __future__ import annotations

import math

from ..effects.settings import registry
from . import predict

#: The mechanisms of the operators and the built-in effects, in the order the plan
#: lists them (``ocltm:plan``); installed effects follow (:func:`mechanisms`).
MECHANISMS = ("rods", "purkinje", "acuity", "flare", "chromatic-adaptation", "local",
              "temporal")
#: The gated mechanisms whose predictions are made together here (the flare's veil
#: moves the levels the others are predicted at); installed gated effects predict
#: themselves (``Effect.predict``).
JOINT = ("purkinje", "acuity", "flare")


def gated() -> dict:
    """Gated mechanisms -> their effect (``EffectSettings`` switch): the effects the
    plan may skip, built-in and installed."""
    return {cls.mechanism_name(): name for name, cls in registry().items() if cls.gated}


def mechanisms() -> tuple:
    """Every mechanism the plan can list, in order."""
    return MECHANISMS + tuple(m for m in (cls.mechanism_name() for cls in registry().values())
                              if m not in MECHANISMS)
#: ``--model``: the plan (auto), every mechanism on (full), the operator alone (none).
MODELS = ("auto", "full", "none")
#: Delta E ITP budget of everything skipped on a frame (1 JND, BT.2124).
BUDGET = 1.0
#: Predictions are multiplied by this before they are counted (their error on
#: the test scenes and photographs: up to 2.4x, tests/mechanisms/test_plan.py,
#: benchmarks/results/scene_driven.md).
SAFETY = 3.0
#: A running mechanism is skipped again only below this share of the budget it
#: would take (switching off needs a clearly smaller prediction than on).
HYSTERESIS = 0.7
#: Seconds for a weight to go from 1 to 0 (out), and from 0 to 1 (in: faster, the
#: most the no-pop rule allows at 30 fps, 0.5 a frame; a frame between is where
#: the bound is not kept while a mechanism comes in).
RAMP_S = 0.1
RAMP_IN_S = 1.0 / 15.0
#: A mechanism whose predicted effect (x SAFETY) is beyond this many JND comes in
#: at once: its effect arrives with the scene (a lamp switched on, a tunnel's
#: mouth in view), ``full`` shows it in that frame too, and a ramp would only add
#: frames beyond the bound (and, for ledda04, a memory of them in its state).
JUMP_JND = 10.0
STATE_KEY = "plan"
#: Acuity is also predicted at this share of the frame's rod level: 0.1 decade, one
#: frame at 30 fps of a fall of 3 decades a second (the benchmark's day-to-night
#: fade falls 0.083 decade a frame; dusk falls far slower).
ACUITY_AHEAD = 10.0 ** -0.1
#: Predictions are reused while the frame's signature (``analysis.signature``)
#: stays within this many SIGNATURE_STEPs (0.01 decade) of the one they were made
#: on, in every entry: a held shot or a still costs the analysis alone. The
#: reference (signature and predictions) is kept in the state, so a resumed or
#: split run reuses where the serial run did.
REUSE_STEPS = 2


def reusable(ref: dict | None, sig: list | None, gated) -> bool:
    """Whether the predictions in ``ref`` hold for a frame of signature ``sig``."""
    if not ref or sig is None or ref.get("sig") is None:
        return False
    old = ref["sig"]
    if len(old) != len(sig) or set(ref.get("predicted", {})) != set(gated):
        return False
    return max((abs(a - b) for a, b in zip(old, sig)), default=0) <= REUSE_STEPS


def offered(operator, settings) -> dict:
    """mechanism -> "auto" | "on" for the mechanisms this run can apply (absent: not
    offered or switched off). ``settings``: the run's ``EffectSettings``."""
    out = {"rods": "on", "temporal": "on"}
    for name, cls in registry().items():
        mode = getattr(settings, name)
        if mode != "off":
            out[cls.mechanism_name()] = mode if cls.gated else "on"
    if "purkinje" in operator.own_effects:
        out["purkinje"] = "on"              # its own model of the shift (kirk11: LMSR)
    if operator.metering == "local":
        out["local"] = "on"
    return {m: out[m] for m in mechanisms() if m in out}


def predictions(an, operator, display, settings, gated_list) -> dict:
    """Predicted p99 Delta E ITP of each gated mechanism (full against none).
    Acuity, whose effect starts steeply (its blend goes from 0 to 1 within ~0.3
    decade of L_waR as the cutoff passes the display's Nyquist: 0 to 2.3 JND in one
    frame of a fast fade), is predicted at the larger of the frame's rod level and
    :data:`ACUITY_AHEAD` times it, so that its ramp starts a frame before ``full``
    shows it rather than a frame after (the frame itself, no state: the shot's
    measure pass predicts what the serial run does)."""
    resp = predict.DisplayResponse(operator, display, an.G_rod, an.G_cone)
    out = {}
    levels = flared = None
    if "flare" in gated_list or settings.flare == "on":
        d, flared = predict.flare(an, resp, settings.fov_deg, settings.age)
        if flared is not None and not resp.own:
            # a stand-in response cannot see what a local operator makes of the veil
            # (it lifts a dark tunnel mouth that the stand-in shows black): any
            # source's flare runs for ledda04 and kirk11
            d = math.inf
        if "flare" in gated_list:
            out["flare"] = d
        # the flare runs for sure (on, or beyond the whole budget): the others are
        # predicted at the levels it leaves (its veil raises them)
        if flared is not None and (settings.flare == "on" or SAFETY * d > BUDGET):
            levels = predict.flared_levels(an, flared)
            resp = predict.DisplayResponse(operator, display, *levels)
    if "purkinje" in gated_list:
        out["purkinje"] = predict.purkinje(an, resp, None if levels is None else flared)
    if "acuity" in gated_list:
        G = an.G_rod if levels is None else levels[0]
        out["acuity"] = predict.acuity(an, resp, settings.fov_deg, settings.paper, G)
        out["acuity"] = max(out["acuity"], predict.acuity(
            an, resp, settings.fov_deg, settings.paper, G * ACUITY_AHEAD))
    own = gated()
    for m in gated_list:
        if m not in JOINT:                  # an installed effect's own prediction
            out[m] = float(registry()[own[m]].predict(an, resp, settings))
    return out


def targets(offer: dict, predicted: dict, running: dict | None = None) -> dict:
    """mechanism -> target weight 0 or 1: the ``auto`` ones skipped smallest
    prediction first while SAFETY x their sum stays within BUDGET (a running one
    counts 1 / HYSTERESIS times its prediction)."""
    running = running or {}
    out = {m: 1.0 for m in offer}
    cost = {m: SAFETY * predicted.get(m, 0.0) / (HYSTERESIS if running.get(m, 0.0) > 0 else 1.0)
            for m, mode in offer.items() if mode == "auto"}
    spent = 0.0
    order = mechanisms()
    for m in sorted(cost, key=lambda k: (cost[k], order.index(k))):
        if spent + cost[m] <= BUDGET:
            spent += cost[m]
            out[m] = 0.0
    return out


def step(prev: dict | None, target: dict, dt: float, fresh: bool,
         predicted: dict | None = None) -> dict:
    """The weights after a frame ``dt`` s after the last: toward ``target`` by at most
    dt / RAMP_IN_S up and dt / RAMP_S down (at once when ``fresh`` or there is no
    last plan)."""
    if fresh or not prev:
        return dict(target)
    dt = max(0.0, dt) if math.isfinite(dt) else math.inf
    up, down = min(1.0, dt / RAMP_IN_S), min(1.0, dt / RAMP_S)
    out = {}
    for m, t in target.items():
        w = float(prev.get(m, t))
        if t > w and SAFETY * (predicted or {}).get(m, 0.0) > JUMP_JND:
            out[m] = float(t)               # arrives with the scene: at once
            continue
        out[m] = round(min(1.0, max(0.0, w + max(-down, min(up, t - w)))), 6)
    return out
