"""The run of one observer over a sequence of frames (the Python API:
:class:`Tonemapper`).

``observer.py``   the observer apart from the frame: its state and its clock;
``frame.py``      one whole frame's graph: optical effects -> measure -> integrate
                  -> seen effects -> apply -> display effects;
``banded.py``     the same graph for a frame in row bands, never whole in memory;
``results.py``    what a frame gives back, and the checks of what it is given;
``tonemapper.py`` :class:`Tonemapper`, the façade over them.
"""

from .results import FrameInfo, FrameResult, as_float_pixels
from .tonemapper import Tonemapper

__all__ = ["FrameInfo", "FrameResult", "Tonemapper", "as_float_pixels"]
