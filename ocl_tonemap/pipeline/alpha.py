"""Alpha: colour straightened (divided by alpha) for the operators, which are not
linear, and premultiplied again after them (OIIO's and OpenEXR's convention)."""

from __future__ import annotations

import numpy as np


def restore_alpha(rgb: np.ndarray, alpha_info) -> np.ndarray:
    """(..., 4): colour multiplied by alpha again where it had been divided
    (``alpha_info`` from :func:`straight_colour`), empty pixels exactly zero."""
    alpha, empty, premultiplied = alpha_info
    out = np.array(rgb[..., :3], np.float32)
    if premultiplied:
        a = alpha[..., None]
        out = np.where(a > 0, out * a, out).astype(np.float32)
    out[empty] = 0.0
    return np.concatenate([out, alpha[..., None]], axis=2)


def straight_colour(pix: np.ndarray, premultiplied: bool):
    """(frame with straight colour, (alpha, empty mask, premultiplied)): colour
    divided by alpha where alpha > 0 when ``premultiplied``; ``empty`` marks
    zero-alpha pixels with zero colour (they stay zero)."""
    alpha = np.nan_to_num(pix[..., 3], nan=0.0, posinf=1.0, neginf=0.0).astype(np.float32)
    rgb = pix[..., :3]
    empty = (alpha == 0) & np.all(rgb == 0, axis=2)
    if premultiplied:
        a = alpha[..., None]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rgb = np.where(a > 0, rgb / np.where(a > 0, a, 1.0), rgb)
        pix = np.concatenate([rgb.astype(np.float32), alpha[..., None]], axis=2)
    return np.ascontiguousarray(pix, np.float32), (alpha, empty, bool(premultiplied))
