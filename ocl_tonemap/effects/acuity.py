"""Loss of acuity in the dark: a Gaussian blur of the displayed image (Durand & Dorsey
2000, Sec. 7, Eqs. 9-11 with Shaler's Table 1).

Slot: display. Needs: the adapted scotopic level; the field of view; a blur.
The model is ``models/shaler1937.py``.
"""

from __future__ import annotations

import numpy as np

from ..models.convolution import EDGE_CLAMP
from ..models.shaler1937 import acuity_a_px, acuity_blend, apply_acuity

NAME = "acuity"
SLOT = "display"
NEEDS = ("scotopic level", "field of view", "blur")
HELP = "loss of acuity in the dark (Shaler 1937)"


def needed(settings, G_rod: float, width: int) -> bool:
    """Whether a frame of ``width`` pixels at ``G_rod`` gets any blur."""
    return float(acuity_blend(acuity_a_px(G_rod, settings.fov_deg, width))) > 0


def run(settings, img: np.ndarray, G_rod: float, blur=None):
    if settings.acuity == "off":
        return img, {"ran": False}
    dev = None if blur is None else (lambda im, taps: blur(im, taps, EDGE_CLAMP))
    out, info = apply_acuity(img, G_rod, settings.fov_deg, dev)
    info["ran"] = info["blend"] > 0
    return out, info
