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

from ..backends.planes import band_readable
from ..base.quantities import Quantity

STATE_FORMAT = "ocl-tonemap.adaptation-state/1"
#: AdaptationState.extra key of the ``auto`` calibration constant of a run.
AUTO_SCALE_KEY = "luminance_scale_auto"

# -- the fields of a state, declared once (checked on load: a file, a frame's header) ------
#: Adaptation levels, cd/m^2: photometry.L_MAX (1e10, the largest pixel luminance)
#: times the largest scotopic/photopic ratio of any light (~600, violet at 400 nm),
#: with room: a rod level of the brightest violet scene is still a state.
ADAPT_MAX = 1.0e15
#: A frame's time, s: a frame number over the fps, or a file's timestamp (Unix time
#: included).
TIME_MAX = 1.0e12
#: A frame number (``patterns.MAX_FRAME``).
FRAME_MAX = 999_999_999

_LEVEL = "adaptation level"
#: The scalar values (``AdaptationState.values``) the built-in operators keep, by name
#: (an operator's ``StateSpec.scalars`` names them; ``tests/job/test_state_checks.py``
#: checks that every one is declared here).
VALUES = {
    "A_rod": Quantity(f"rods' {_LEVEL} A_rod", "cd/m^2 scotopic", 0.0, ADAPT_MAX),
    "A_cone": Quantity(f"cones' {_LEVEL} A_cone", "cd/m^2", 0.0, ADAPT_MAX),
    "B_rod": Quantity("rods' unbleached pigment fraction B_rod", "", 0.0, 1.0),
    "B_cone": Quantity("cones' unbleached pigment fraction B_cone", "", 0.0, 1.0),
    "inv_eps_rod": Quantity("rods' inverse threshold 1/eps_R", "m^2/cd", 0.0, 1.0e6,
                            above=True),
    "inv_eps_cone": Quantity("cones' inverse threshold 1/eps_C", "m^2/cd", 0.0, 1.0e6,
                             above=True),
    "L_waR": Quantity("rods' adaptation luminance L_waR", "cd/m^2 scotopic", 0.0, ADAPT_MAX),
    "L_wa": Quantity("cones' adaptation luminance L_wa", "cd/m^2", 0.0, ADAPT_MAX),
    "logmean_I_A_cone": Quantity("cones' log-average adaptation luminance", "cd/m^2", 0.0,
                                 ADAPT_MAX),
    "logmean_I_A_rod": Quantity("rods' log-average adaptation luminance",
                                "cd/m^2 scotopic", 0.0, ADAPT_MAX),
}
#: Values kept together, all or none (the receptor levels: kirk11's paper mode keeps
#: none; the Purkinje shift's ``extra["purkinje_levels"]`` all four).
TOGETHER = (("A_rod", "A_cone", "B_rod", "B_cone"),)
#: The fields of the JSON document (:meth:`AdaptationState.to_json`): every one must be
#: there (``time_s`` and ``frame`` may be null: before the first frame, a still).
FIELDS = {
    "format": "the document's format, " + repr(STATE_FORMAT),
    "operator": "the operator that owns the values",
    "time_s": Quantity("time of the last frame shown", "s", -TIME_MAX, TIME_MAX),
    "frame": Quantity("number of the last frame shown", "", -FRAME_MAX, FRAME_MAX),
    "values": "the operator's scalar state (VALUES)",
    "extra": "the run's other state (_EXTRA_CHECKS)",
}


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def check_field(q: Quantity, v, name: str) -> float:
    """A state's number ``v`` checked against its declaration: a JSON number (not a
    string or a boolean) within ``q``'s range, or ValueError naming ``name``."""
    if not _is_number(v):
        raise ValueError(f"{name} must be a number, {q.range_text()}: the {q.what} "
                         f"(got {str(json.dumps(v))[:60]})")
    return q.check(v, name)


def check_values(values, operator: str | None, where: str = "values") -> dict:
    """The scalar values of ``operator``'s state: each a declared field (its range
    checked; an installed operator's own undeclared fields: finite numbers), none
    missing (values kept together all or none), none foreign. Empty: an observer
    that has seen no frame."""
    if not isinstance(values, dict):
        raise ValueError(f"{where} must be an object of named numbers (got "
                         f"{str(json.dumps(values))[:60]})")
    spec = _operator_scalars(operator) if operator is not None else None
    out = {}
    for k, v in values.items():
        name = f"{where}.{k}"
        if spec is not None and k not in spec:
            raise ValueError(f"{name} is not a field of {operator}'s state (its fields: "
                             f"{', '.join(spec) or 'none'})")
        q = VALUES.get(k)
        if q is not None:
            out[k] = check_field(q, v, name)
        elif not (_is_number(v) and math.isfinite(v)):
            raise ValueError(f"{name} must be a finite number (got {str(json.dumps(v))[:60]})")
        else:
            out[k] = float(v)
    if out and spec is not None:
        together = {k: g for g in TOGETHER for k in g}
        for k in spec:
            g = together.get(k, ())
            if k not in out and not (g and not any(x in out for x in g)):
                raise ValueError(f"{where}.{k} is missing ({operator}'s state keeps "
                                 + (f"{', '.join(g)} together" if g else
                                    f"{', '.join(spec)}") + ")")
    return out


def _operator_scalars(operator: str) -> tuple | None:
    """The scalar fields ``operator`` declares (``StateSpec.scalars``), or None for a
    name that is not an operator (refused by :meth:`AdaptationState.from_json`)."""
    from ..operators import registry  # lazy: the state module loads no operator
    cls = registry().get(operator)
    return None if cls is None else tuple(cls.state.scalars)


def _pigment_ok(v) -> bool:
    """``extra["pigment"]``: the shared pigment course's state (``models/bleaching``)."""
    from ..models import bleaching  # lazy: the state module loads no model until checked
    return bleaching.check(v)


def _check_levels(v) -> bool:
    """``extra["purkinje_levels"]``: the four receptor levels (:data:`VALUES`)."""
    if not isinstance(v, dict) or set(v) != set(TOGETHER[0]):
        raise ValueError(f"extra.purkinje_levels must hold {', '.join(TOGETHER[0])} (got "
                         f"{str(json.dumps(v))[:60]})")
    for k, x in v.items():
        check_field(VALUES[k], x, f"extra.purkinje_levels.{k}")
    return True


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
    "purkinje_levels": _check_levels,
    "pigment": lambda v: _pigment_ok(v),
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
        """A state document checked field by field (:data:`FIELDS`, :data:`VALUES`):
        ValueError in one line naming the field and what is wrong with it."""
        if not isinstance(doc, dict) or doc.get("format") != STATE_FORMAT:
            got = doc.get("format") if isinstance(doc, dict) else None
            raise ValueError(f"not an ocl-tonemap adaptation state (format {got!r}, "
                             f"expected {STATE_FORMAT!r})")
        missing = [k for k in FIELDS if k not in doc]
        if missing:
            raise ValueError(f"{missing[0]} is missing (a state holds {', '.join(FIELDS)})")
        op = doc["operator"]
        from ..operators import registry  # lazy: the state module loads no operator
        if not isinstance(op, str) or op not in registry():
            raise ValueError(f"operator {str(json.dumps(op))[:60]} is not an operator (one of "
                             f"{', '.join(registry())})")
        t = doc["time_s"]
        t = None if t is None else check_field(FIELDS["time_s"], t, "time_s")
        frame = doc["frame"]
        if frame is not None:
            if not isinstance(frame, int) or isinstance(frame, bool):
                raise ValueError(f"frame must be a whole number, "
                                 f"{FIELDS['frame'].range_text()}: the "
                                 f"{FIELDS['frame'].what} (got {str(json.dumps(frame))[:60]})")
            frame = int(check_field(FIELDS["frame"], frame, "frame"))
        vals = check_values(doc["values"], op)
        extra = doc["extra"]
        if not isinstance(extra, dict):
            raise ValueError(f"extra must be an object (got {str(json.dumps(extra))[:60]})")
        extra = dict(extra)
        for key, check in _EXTRA_CHECKS.items():
            if key in extra and not check(extra[key]):
                raise ValueError(f"extra.{key} is malformed (got "
                                 f"{str(json.dumps(extra[key], default=str))[:60]})")
        return cls(op, vals, t, frame, extra)
