"""What a frame gives back (:class:`FrameInfo`, :class:`FrameResult`) and the checks
every way in makes of what it is given (pixels, luminance scale)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..models.photometry import RepairCounts
from .state import AdaptationState


@dataclass
class FrameInfo:
    """What happened on one frame (also written to the output's metadata)."""

    frame: int | None
    time_s: float
    dt: float
    G_rod: float
    G_cone: float
    repairs: RepairCounts
    state: AdaptationState
    params: dict = field(default_factory=dict)
    effects: dict = field(default_factory=dict)
    #: The frame's mechanism plan: weights (mechanism -> 0..1), predictions, analysis.
    plan: dict = field(default_factory=dict)
    #: Host <-> device transfers of the frame (calls and bytes each way; None: no device).
    transfers: dict | None = None
    #: The tracked target's visibility on this frame (``run --target``; job/visibility_out.py).
    visibility: dict | None = None


def transfers_since(backend, before) -> dict | None:
    """The transfers ``backend`` made since its count ``before`` (``backend.transfers()``),
    as a dict; None for a backend without a device."""
    now = backend.transfers()
    return None if now is None or before is None else (now - before).as_dict()


@dataclass
class FrameResult:
    """One mapped frame, as a value (:meth:`Tonemapper.process_frame`)."""

    output: np.ndarray         # display-linear float32 (H x W x 3 or 4), or code values
    alpha: tuple | None        # (alpha, empty mask, premultiplied?) of an RGBA frame
    info: FrameInfo
    encoded: bool = False      # ``output`` holds code values of the frame's ``encoding``


def as_float_pixels(frame) -> np.ndarray:
    """Pixels as float32, integers normalised as OIIO does (unsigned: 0..max -> 0..1,
    signed: -max..max -> -1..1); booleans, complex and non-numeric arrays refused."""
    a = np.asarray(frame)
    if a.dtype == bool or not (np.issubdtype(a.dtype, np.number)) or \
            np.issubdtype(a.dtype, np.complexfloating):
        raise ValueError(f"frame pixels must be real numbers (got dtype {a.dtype})")
    if np.issubdtype(a.dtype, np.integer):
        return (a.astype(np.float64) / float(np.iinfo(a.dtype).max)).astype(np.float32)
    return a


def rgb_pixels(frame) -> tuple[np.ndarray, str | None]:
    """(H x W x 3 or 4 float pixels, the input's own grey layout: None, ``"2d"`` for
    H x W, ``"1"`` for H x W x 1, whose luminance is spread to RGB)."""
    pix = as_float_pixels(frame)
    grey = None
    if pix.ndim == 2:
        pix, grey = pix[..., None], "2d"
    if pix.ndim != 3 or pix.shape[2] not in (1, 3, 4) or pix.shape[0] < 1 or pix.shape[1] < 1:
        raise ValueError(f"frame must be H x W (luminance), H x W x 1, 3 or 4 "
                         f"(got shape {np.shape(frame)})")
    if pix.shape[2] == 1:
        pix, grey = np.repeat(pix, 3, axis=2), grey or "1"
    return pix, grey


def check_scale(scale) -> None:
    """The luminance scale (cd/m^2 of pixel value 1.0) every frame is given."""
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"luminance scale must be a positive finite number (got {scale})")
