"""The weight image of ``mask:`` metering (``--metering mask:WEIGHTS.exr``), read
through OIIO where the metering runs, resized to the frame."""

from __future__ import annotations

import functools
import os

import numpy as np
import OpenImageIO as oiio

from ..base.safeio import check_input


@functools.lru_cache(maxsize=8)
def read_weight_mask(path: str, width: int, height: int) -> np.ndarray:
    """A ``mask:`` metering weight image resized to (height, width), float32 weights >= 0."""
    check_input(path)                     # a FIFO is refused, never opened
    if not os.path.exists(path):
        raise ValueError(f"metering mask {path}: no such file")
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        raise ValueError(f"metering mask {path}: cannot read: {buf.geterror().strip()}")
    spec = buf.spec()
    if (spec.width, spec.height) != (width, height):
        buf = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, width, 0, height, 0, 1, 0,
                                                           spec.nchannels))
    px = np.asarray(buf.get_pixels(oiio.FLOAT), np.float64).reshape(height, width, -1)
    nc = px.shape[2]
    colour = [i for i in range(nc) if i != spec.alpha_channel] or [0]
    w = np.nan_to_num(px[..., colour[:3]].mean(axis=2), nan=0.0, posinf=0.0, neginf=0.0)
    w = np.maximum(w, 0.0)
    if not w.sum() > 0:
        raise ValueError(f"metering mask {path}: no positive weight")
    return w.astype(np.float32)
