"""The effects a run can have (:func:`registry`: the built-in ones and those installed
packages add through the ``ocl_tonemap.effects`` entry point group) and their
settings (:class:`EffectSettings`): one field per declared option of every
registered effect, so that an effect's option is at once a field here, an API
keyword (``Tonemapper(..., flare="off")``) and a command-line flag
(``cli/options.py`` builds them from the same declarations)."""

from __future__ import annotations

import functools

from ..operators import get_operator
from .acuity import Acuity
from .base import Effect, EffectOption, mode_option, MODES, SLOTS
from .chromatic import ChromaticAdaptation
from .flare import Flare
from .purkinje import PurkinjeShift
from .threshold import AbsoluteThreshold

#: --model -> the mode of every effect the operator can take (a mode given wins).
MODEL_DEFAULTS = {"auto": "auto", "full": "on", "none": "off"}
#: The built-in effects, in data-flow order (slot, then as listed).
BUILT_IN = (Flare, PurkinjeShift, ChromaticAdaptation, AbsoluteThreshold, Acuity)
#: Settings that are no effect's option: ``paper``, the papers' literal forms
#: (``--mode paper``: complete chromatic adaptation to the frame's grey world,
#: Shaler's table indexed by L_waR itself).
GENERAL = {"paper": False}


@functools.lru_cache(maxsize=1)
def registry() -> dict:
    """name -> effect class, built-in first, then installed plugins (entry point group
    ``ocl_tonemap.effects``), each checked against the protocol (``base.py``)."""
    from importlib.metadata import entry_points
    out = {cls.name: cls for cls in BUILT_IN}
    for ep in entry_points(group="ocl_tonemap.effects"):
        cls = ep.load()
        if not (isinstance(cls, type) and issubclass(cls, Effect)):
            raise ValueError(f"effect plugin {ep.name}: not an ocl_tonemap.effects.base.Effect")
        if cls.slot not in SLOTS or not cls.name or cls.name in out or \
                cls.name in GENERAL or "host" not in cls.capabilities:
            raise ValueError(f"effect plugin {ep.name}: needs a new name, a slot of "
                             f"{', '.join(SLOTS)} and the host capability")
        out[cls.name] = cls
    return out


def in_flow_order() -> list:
    """The registered effects by slot, in registry order within a slot."""
    reg = list(registry().values())
    return sorted(reg, key=lambda c: SLOTS.index(c.slot))


@functools.lru_cache(maxsize=1)
def options() -> dict:
    """name -> (EffectOption, the effects it belongs to): every effect's switch and
    parameters; a parameter two effects declare (``fov_deg``) is one option of both."""
    out: dict = {}
    for cls in registry().values():
        out[cls.name] = (mode_option(cls.name, cls.help), (cls.name,))
        for o in cls.options:
            prev = out.get(o.name)
            out[o.name] = (o, (prev[1] if prev else ()) + (cls.name,))
    return out


def switch_names() -> tuple:
    """The effects' switches (their names), registry order."""
    return tuple(registry())


class EffectSettings:
    """Switches and parameters of the effects, read as attributes (``.flare``,
    ``.fov_deg`` ...): one field per option of every registered effect
    (:func:`options`) plus ``paper``. Frozen; :meth:`replace` makes another. An
    option not given takes its declared ``value`` (switches: off); each given value
    is checked by its option (one ValueError naming the flag)."""

    __slots__ = ("_v",)

    def __init__(self, **given):
        opts = options()
        unknown = [k for k in given if k not in opts and k not in GENERAL]
        if unknown:
            raise ValueError(f"no effect option {', '.join(sorted(unknown))} (the effects' "
                             f"options: {', '.join(sorted(opts))})")
        v = {k: o.value for k, (o, _) in opts.items()}
        v.update(GENERAL)
        v.update(given)
        object.__setattr__(self, "_v", v)
        for k in sorted(opts, key=lambda k: (k not in registry(), list(opts).index(k))):
            o = opts[k][0]
            if o.check is not None and (k in given or o.value is not None):
                checked = o.check(v[k])
                if o.decl is not None and k in given:     # the declared value (text parsed)
                    v[k] = checked

    def __getattr__(self, name):
        try:
            return object.__getattribute__(self, "_v")[name]
        except KeyError:
            raise AttributeError(f"EffectSettings has no field {name!r}") from None

    def __setattr__(self, name, value):
        raise AttributeError("EffectSettings is frozen: use .replace(...)")

    def __eq__(self, other):
        return isinstance(other, EffectSettings) and self._v == other._v

    def __hash__(self):
        return hash(tuple(sorted((k, repr(v)) for k, v in self._v.items())))

    def __repr__(self):
        return "EffectSettings(" + ", ".join(f"{k}={v!r}" for k, v in self._v.items()) + ")"

    def __reduce__(self):                      # (Dask sends a run's options to workers)
        return (_rebuild, (dict(self._v),))

    def replace(self, **changes) -> "EffectSettings":
        return EffectSettings(**{**self._v, **changes})

    def as_dict(self) -> dict:
        return dict(self._v)

    @classmethod
    def for_operator(cls, operator: str, model: str = "auto", paper: bool = False,
                     **given) -> "EffectSettings":
        """Defaults of ``--model`` (:data:`MODEL_DEFAULTS`) for the effects the operator
        can take (kirk11 models the Purkinje shift itself); ``paper`` (``--mode
        paper``): the paper's operator alone, effects off, complete chromatic
        adaptation when asked for. A value given wins."""
        if model not in MODEL_DEFAULTS:
            raise ValueError(f"--model must be one of {', '.join(MODEL_DEFAULTS)} (got {model!r})")
        mode = "off" if paper else MODEL_DEFAULTS[model]
        own = get_operator(operator).own_effects
        base = {k: mode for k in switch_names() if k not in own}
        return cls(**{**base, "paper": paper, **{k: v for k, v in given.items() if v is not None}})

    @property
    def any(self) -> bool:
        return any(getattr(self, k) != "off" for k in switch_names())


def _rebuild(values: dict) -> EffectSettings:
    return EffectSettings(**values)


def effect_option(name: str) -> EffectOption:
    return options()[name][0]


__all__ = ["EffectSettings", "MODEL_DEFAULTS", "MODES", "registry", "options",
           "switch_names", "in_flow_order", "effect_option"]
