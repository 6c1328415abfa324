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
import logging

log = logging.getLogger("ocl_tonemap")


def resolve_backend(name: str | None, device: str | None = None) -> str:
    """The backend to use where none was named explicitly: ``"opencl"`` on the first
    working device, else ``"reference"`` with one warning line (why, how much slower,
    how to get OpenCL). ``name`` other than ``"auto"``/None is returned as it is: a
    backend asked for by name gets no fallback, and neither does a ``device`` spec
    (both fail with one clear error where the device is missing or broken)."""
    if name not in (None, "auto"):
        return name
    from .opencl.runtime import device_status
    dev, why = device_status(device)
    if dev is not None:
        return "opencl"
    log.warning("%s. Running on the float64 reference backend instead (correct, "
                "10-100x slower; --backend reference silences this); %s", why.detail,
                why.fix or "fix: install an OpenCL driver")
    return "reference"


def make_backend(name: str = "opencl", device: str | None = None,
                 max_band_pixels: int | None = None):
    """``name``: ``"opencl"``, ``"reference"``, or ``"auto"`` (:func:`resolve_backend`)."""
    name = resolve_backend(name, device) if name == "auto" else name
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
