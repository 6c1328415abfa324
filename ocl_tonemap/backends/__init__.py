"""Backends: where and how a frame's stages run.

``reference``  float64 NumPy, straight from the equations (``models/``): the ground
               truth, and a backend like the other.
``opencl``     float32 kernels (``kernels/*.cl``) on an OpenCL device, in row bands
               when a frame does not fit (``plan.py``).

A backend gives each operator a *schedule* (:meth:`schedule`): the object that
runs the operator's measure / integrate / apply phases on this backend. Operators
whose only per-pixel stage is pointwise share the backend's pointwise schedule;
the others name theirs (``Operator.schedules``), which lets a plugin bring its own.
"""

from __future__ import annotations

import importlib


def make_backend(name: str = "opencl", device: str | None = None,
                 max_band_pixels: int | None = None):
    if name == "reference":
        from .reference import ReferenceBackend
        return ReferenceBackend()
    if name == "opencl":
        from .opencl import OpenCLBackend
        return OpenCLBackend(device, max_band_pixels)
    raise ValueError(f"unknown backend {name!r} (opencl | reference)")


def load_schedule(spec: str):
    """``"package.module:Class"`` (relative names start at ocl_tonemap.backends)."""
    mod, _, cls = spec.partition(":")
    module = importlib.import_module(mod, __name__) if mod.startswith(".") else \
        importlib.import_module(mod)
    return getattr(module, cls)
