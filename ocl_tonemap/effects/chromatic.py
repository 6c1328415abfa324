"""Chromatic adaptation: von Kries gains on the cone signals toward the illuminant,
Durand & Dorsey 2000, Eq. 6, filtered in time with tau = 5 s (Sec. 3.4).

Slot: receptor -- one slot: the schedule applies the gains to the cone signals
before its per-pixel map where its map separates cones from rods (the pointwise
operators), and to the working RGB before the operator otherwise (ledda04,
kirk11). Needs: the frame's illuminant (user > EXR ``adoptedNeutral`` > estimate).
State: the adapted illuminant (``AdaptationState.extra["illuminant_rgb"]``).
The model is in ``models/durand2000.py``.
"""

from __future__ import annotations

import numpy as np

from ..models.durand2000 import (cct_duv, chromatic_step, degree_of_adaptation,
                                 normalise_illuminant, partial_illuminant, plausible_illuminant,
                                 von_kries_gains)

NAME = "chromatic_adaptation"
SLOT = "receptor"
NEEDS = ("illuminant",)
HELP = "von Kries adaptation to the illuminant, tau 5 s"
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
