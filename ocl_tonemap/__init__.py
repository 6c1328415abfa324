"""ocl-tonemap: how a human observer would see an HDR scene or shot.

Time-dependent visual adaptation operators (Pattanaik et al. 2000, Ledda et
al. 2004, Durand & Dorsey 2000, Kirk & O'Brien 2011) on
OpenCL, with a float64 NumPy reference, for OpenImageIO/OpenColorIO
pipelines. See README.md; the Python API is :class:`Tonemapper`.
"""

__version__ = "0.1.0"

from .state import AdaptationState  # noqa: E402
from .models.display import DisplaySpec  # noqa: E402
from .effects import EffectSettings  # noqa: E402
from .models.metering import MeteringSpec  # noqa: E402
from .pipeline import Tonemapper  # noqa: E402

__all__ = ["Tonemapper", "AdaptationState", "DisplaySpec", "EffectSettings", "MeteringSpec",
           "__version__"]
