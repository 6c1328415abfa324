"""Operator registry: ``--operator NAME`` -> the class implementing it.

The built-in operators, and any that other installed packages add in the
``ocl_tonemap.operators`` entry-point group (``NAME = "package.module:Class"``, a
subclass of :class:`~ocl_tonemap.operators.base.Operator`). The protocol is in
``base.py`` and docs/architecture.md.
"""

from __future__ import annotations

import functools
import importlib

from .base import Operator

#: name -> "module:Class" of the built-in operators (in this order in --help).
BUILTIN = {
    "pattanaik00": "ocl_tonemap.operators.pattanaik00:Pattanaik00",
    "ledda04": "ocl_tonemap.operators.ledda04:Ledda04",
    "durand00": "ocl_tonemap.operators.durand00:Durand00",
    "kirk11": "ocl_tonemap.operators.kirk11:Kirk11",
}
ENTRY_POINT_GROUP = "ocl_tonemap.operators"


def _load(spec: str):
    mod, _, cls = spec.partition(":")
    return getattr(importlib.import_module(mod), cls)


@functools.lru_cache(maxsize=1)
def registry() -> dict:
    """name -> operator class: the built-ins, then installed plugins."""
    from importlib.metadata import entry_points
    out = {name: _load(spec) for name, spec in BUILTIN.items()}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in out:
            continue                       # a plugin cannot replace a built-in
        cls = ep.load()
        if not (isinstance(cls, type) and issubclass(cls, Operator)):
            raise TypeError(f"operator plugin {ep.name} ({ep.value}) is not an Operator subclass")
        out[ep.name] = cls
    return out


def get_operator(name: str):
    """The operator class registered as ``name``."""
    reg = registry()
    try:
        return reg[name]
    except KeyError:
        raise ValueError(f"unknown operator {name!r}; available: {', '.join(sorted(reg))}") from None


def descriptions() -> dict:
    return {name: cls.description for name, cls in registry().items()}
