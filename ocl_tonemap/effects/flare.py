"""Flare: light sources scattered in the eye (Spencer et al. 1995, as Durand & Dorsey
2000, Sec. 6 use it), added to the scene in cd/m^2 before tone mapping.

Slot: scene. Needs: the frame's adaptation levels; on the device, a blur.
The model is ``models/spencer1995.py``.
"""

from __future__ import annotations

import numpy as np

from ..models import spencer1995 as fl
from ..models.convolution import EDGE_ZERO
from ..models.photometry import Y_WEIGHTS

NAME = "flare"
SLOT = "scene"
NEEDS = ("adaptation levels", "blur")
HELP = "glare of light sources (Spencer et al. 1995)"


def run(settings, rgb: np.ndarray, G_rod: float, G_cone: float, blur=None):
    """(new rgb or None, info) for one frame in cd/m^2; ``blur(img, taps, edge)``."""
    if settings.flare == "off":
        return None, {"ran": False}
    if settings.flare == "auto":
        Ymax = float(np.max(rgb.reshape(-1, 3) @ Y_WEIGHTS, initial=0.0))
        if not Ymax > settings.flare_threshold * G_cone:
            return None, {"ran": False, "reason": "no light sources"}
    dev = None if blur is None else (lambda img, taps: blur(img, taps, EDGE_ZERO))
    out, info = fl.apply_flare(rgb, G_cone, G_rod, settings.fov_deg, settings.flare_method,
                               settings.flare_threshold, settings.flare_per_octave, dev)
    info["ran"] = info["sources"] > 0
    return out.astype(np.float32), info
