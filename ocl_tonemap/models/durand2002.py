"""Durand & Dorsey 2002: fast bilateral filtering for the display of HDR images --
the base/detail range reduction on log luminance (kirk11's range reduction).

>>> import numpy as np
>>> out = range_reduce(np.array([0.0, 4.0]), np.array([0.0, 4.0]), 100.0)
>>> [round(float(v), 6) for v in out]        # a 4-decade base compressed to 2 decades
[-2.0, 0.0]
"""

from __future__ import annotations

import math

import numpy as np


def range_reduce(logY: np.ndarray, base: np.ndarray, target_contrast: float) -> np.ndarray:
    """Durand & Dorsey 2002: log10 of the output luminance relative to display white:
    the base compressed to ``target_contrast`` with its maximum at white, detail kept."""
    span = float(base.max() - base.min())
    c = min(1.0, math.log10(target_contrast) / span) if span > 0 else 1.0
    return c * (base - base.max()) + (logY - base)
