"""Adaptation state: small, explicit, serialisable.

A dict of named float64 scalars per operator plus the time (s) and number of the
last frame shown. It serialises to a short JSON document so a shot can be split
into chunks and resumed; per-pixel state (local operators) travels in a side file
named in the JSON.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from .backends.planes import band_readable

STATE_FORMAT = "ocl-tonemap.adaptation-state/1"
#: AdaptationState.extra key of the ``auto`` calibration constant of a run.
AUTO_SCALE_KEY = "luminance_scale_auto"


def _num(v, lo=-math.inf, hi=math.inf) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) \
        and lo <= v <= hi


def _num_dict(d, lo=-math.inf, hi=math.inf) -> bool:
    return isinstance(d, dict) and all(isinstance(k, str) and _num(v, lo, hi)
                                       for k, v in d.items())


def plan_state_ok(p) -> bool:
    if not isinstance(p, dict) or not _num_dict(p.get("weights", {}), 0.0, 1.0):
        return False
    if "G_cone" in p and not _num(p["G_cone"], 0.0):
        return False
    ref = p.get("ref")
    if ref is None:
        return True
    return isinstance(ref, dict) and _num_dict(ref.get("predicted", {}), 0.0) and (
        ref.get("sig") is None or (isinstance(ref["sig"], list) and all(
            isinstance(x, int) and not isinstance(x, bool) for x in ref["sig"])))


#: The ``extra`` entries the run reads back, checked on load (a hand-edited or
#: damaged state is refused in one line rather than failing inside a frame).
_EXTRA_CHECKS = {
    "run": lambda v: isinstance(v, dict),
    "luminance_scale_auto": lambda v: _num(v, 1e-30),
    "illuminant_rgb": lambda v: isinstance(v, list) and len(v) == 3 and all(_num(x, 0.0) for x in v),
    "purkinje_levels": lambda v: _num_dict(v),
    "plan": plan_state_ok,
    "pixel_state": lambda v: isinstance(v, str),
}


@dataclass
class AdaptationState:
    """Serialisable adaptation state of one observer.

    Attributes
    ----------
    operator : name of the operator that owns ``values`` (``pattanaik00`` ...).
    values : named scalars in the papers' terms (``A_rod`` cd/m^2, ``B_rod`` 0..1 ...).
    time_s : time of the last frame shown, seconds; None before the first frame.
    frame : number of the last frame shown, or None.
    extra : operator-specific JSON-able data (e.g. the path of per-pixel state).
    pixels : per-pixel state of local operators: name -> float32 (h, w) array,
        saved beside the JSON as ``<name>.pixels.exr`` (one channel per plane,
        ``state_files.save_state``); or,
        for frames too large to hold whole, a band-readable view
        (``backends/planes.py``: a spilled store, or the side file opened lazily),
        which ``copy`` shares rather than copies.
    """

    operator: str
    values: dict = field(default_factory=dict)
    time_s: float | None = None
    frame: int | None = None
    extra: dict = field(default_factory=dict)
    pixels: dict | None = None

    def copy(self) -> "AdaptationState":
        px = self.pixels
        if px is not None and not band_readable(px):
            px = {k: np.array(v, copy=True) for k, v in px.items()}
        return AdaptationState(self.operator, dict(self.values), self.time_s, self.frame,
                               json.loads(json.dumps(self.extra)), px)

    def to_json(self) -> dict:
        return {"format": STATE_FORMAT, "operator": self.operator, "time_s": self.time_s,
                "frame": self.frame, "values": self.values, "extra": self.extra}

    @classmethod
    def from_json(cls, doc: dict) -> "AdaptationState":
        if doc.get("format") != STATE_FORMAT:
            raise ValueError(f"not an ocl-tonemap adaptation state (format {doc.get('format')!r}, "
                             f"expected {STATE_FORMAT!r})")
        try:
            vals = {str(k): float(v) for k, v in dict(doc.get("values") or {}).items()}
            op = str(doc["operator"])
            t = doc.get("time_s")
            t = None if t is None else float(t)
            frame = doc.get("frame")
            frame = None if frame is None else int(frame)
            extra = dict(doc.get("extra") or {})
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"malformed adaptation state ({exc!r})") from None
        for k, v in vals.items():
            if not math.isfinite(v):
                raise ValueError(f"state value {k} is not finite ({v})")
        if t is not None and not math.isfinite(t):
            raise ValueError(f"state time {t} is not finite")
        for key, check in _EXTRA_CHECKS.items():
            if key in extra and not check(extra[key]):
                raise ValueError(f"malformed adaptation state (extra {key!r}: "
                                 f"{str(extra[key])[:60]})")
        return cls(op, vals, t, frame, extra)
