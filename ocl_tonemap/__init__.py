"""ocl-tonemap: how a human observer would see an HDR scene or shot.

Time-dependent visual adaptation operators (Pattanaik et al. 2000, Ledda et
al. 2004, Durand & Dorsey 2000, Kirk & O'Brien 2011) on
OpenCL, with a float64 NumPy reference, for OpenImageIO/OpenColorIO
pipelines. See README.md; the Python API is :class:`Tonemapper`.
"""

from . import moved
from .version import __version__

moved.install()              # the old import paths, one release (docs/architecture.md)

#: The public names, imported on first use (``import ocl_tonemap`` stays cheap for the
#: command line's quick paths: ``--version``, ``devices``).
_LAZY = {"Tonemapper": ".pipeline", "AdaptationState": ".pipeline.state", "DisplaySpec": ".models.display",
         "EffectSettings": ".effects", "MeteringSpec": ".models.metering",
         "OcioExport": ".colour.export", "process_imagebuf": ".job.imagebuf"}

__all__ = ["Tonemapper", "AdaptationState", "DisplaySpec", "EffectSettings", "MeteringSpec",
           "OcioExport", "process_imagebuf", "__version__"]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'ocl_tonemap' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_LAZY))
