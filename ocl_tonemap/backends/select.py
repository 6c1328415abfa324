"""Which backend a run gets: ``resolve_backend`` (OpenCL on the first working
device, else the float64 reference with one warning) and ``make_backend``."""

from __future__ import annotations

import logging

from .reference import ReferenceBackend

log = logging.getLogger("ocl_tonemap")


def resolve_backend(name: str | None, device: str | None = None) -> str:
    """The backend to use where none was named explicitly: ``"opencl"`` on the first
    working device, else ``"reference"`` with one warning line (why, how much slower,
    how to get OpenCL). ``name`` other than ``"auto"``/None is returned as it is: a
    backend asked for by name gets no fallback, and neither does a ``device`` spec
    (both fail with one clear error where the device is missing or broken)."""
    if name not in (None, "auto"):
        return name
    from .opencl.runtime import device_status  # lazy: the device modules once chosen
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
        return ReferenceBackend()
    if name == "opencl":
        from .opencl import OpenCLBackend  # lazy: the device modules once chosen
        return OpenCLBackend(device, max_band_pixels)
    raise ValueError(f"unknown backend {name!r} (opencl | reference)")
