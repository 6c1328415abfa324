"""``run --visibility OUT.####.exr``: what the observer can see, per frame.

Reads the frame the run mapped (its scene luminance, the operator's state after
it, the flare's record) and writes ``ocl_tonemap.visibility.PLANES`` as a float32
EXR, the channels' meaning and units in its header. The planes are made on the
host in float64 from what every backend gives alike (the frame's input and the
state), so both backends write the same planes.
"""

from __future__ import annotations

import os

import numpy as np
import OpenImageIO as oiio

from .. import safeio
from ..backends import flare_exec as fx
from ..models import spencer1995 as fl
from ..models.photometry import Y_WEIGHTS
from ..patterns import frame_path, is_sequence, same_file
from ..imageio import FrameError
from ..imagewrite import verify_written
from ..visibility import MAP_TIME_S, PLANES, Viewing, frame_planes

#: The veil is made at 1/VEIL_STEP of the frame's width (it is smooth at the angles
#: where it matters: CIE 146's 1-30 degrees), then spread back.
VEIL_STEP = 8


def viewing(opts) -> Viewing:
    return Viewing(opts.target_size, opts.age, MAP_TIME_S).check()


def _block_mean(a: np.ndarray, s: int) -> np.ndarray:
    h, w = a.shape[:2]
    H, W = -(-h // s), -(-w // s)
    pad = np.pad(a, ((0, H * s - h), (0, W * s - w)) + ((0, 0),) * (a.ndim - 2), mode="edge")
    return pad.reshape(H, s, W, s, *a.shape[2:]).mean(axis=(1, 3))


def veil(rgb_cd: np.ndarray, flare: dict, settings) -> np.ndarray | None:
    """The flare's veil (cd/m^2, H x W) of a frame whose flare ran: Spencer's PSF at
    the frame's pupil over its sources above the frame's source limit, on a grid
    VEIL_STEP times coarser (fast method), less the sources themselves."""
    if not flare or not flare.get("ran") or "pupil_mm" not in flare:
        return None
    lim = float(flare.get("source_limit_cd", np.inf))
    h, w = rgb_cd.shape[:2]
    s = VEIL_STEP if min(h, w) >= 4 * VEIL_STEP else 1
    small = _block_mean(np.asarray(rgb_cd, np.float64), s)
    S = fl.source_part(small, 1.0, lim)
    if not S.any():
        return None
    F = fx.convolve_fast(S, settings.fov_deg / small.shape[1], float(flare["pupil_mm"]),
                         settings.flare_per_octave, None)
    V = np.maximum((F - S) @ Y_WEIGHTS, 0.0)
    return np.repeat(np.repeat(V, s, axis=0), s, axis=1)[:h, :w]


def frame_visibility(tm, fin, info, opts) -> dict:
    """The planes of one mapped frame."""
    if fin.wavelengths is not None:
        raise ValueError("--visibility needs the frame's luminance: this operator takes "
                         "the spectrum (give RGB input, or an operator that maps RGB)")
    rgb = np.asarray(fin.pixels[..., :3], np.float64) * fin.scale
    Y = rgb @ Y_WEIGHTS
    V = veil(rgb, info.effects.get("flare"), tm.effects.settings)
    w = Y.shape[1]
    px_per_arcmin = w / (tm.effects.settings.fov_deg * 60.0)
    # a local operator's observer is its per-pixel state (from the schedule: a download)
    obs = tm.op.observer_of(tm.state if tm.op.observer_per_pixel else info.state)
    return frame_planes(tm.op, obs, Y, V, viewing(opts), px_per_arcmin)


def write_visibility(path: str, planes: dict, f, view: Viewing, operator: str,
                     fov_deg: float) -> None:
    """The planes as a float32 EXR, channels named and described in the header,
    verified before it counts."""
    names = [n for n, _, _ in PLANES]
    h, w = planes[names[0]].shape
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    # uncompressed: zip took a quarter of a 1080p frame's time (0.26 s of ~1 s)
    spec.attribute("compression", "none")
    for n, unit, what in PLANES:
        spec.attribute(f"ocltm:visibility:{n}", f"{what} [{unit}]")
    spec.attribute("ocltm:visibility:target_arcmin", float(view.size_arcmin))
    spec.attribute("ocltm:visibility:age", float(view.age))
    spec.attribute("ocltm:visibility:observation_s", float(view.time_s))
    spec.attribute("ocltm:visibility:k", float(view.k))
    spec.attribute("ocltm:visibility:fov_deg", float(fov_deg))
    spec.attribute("ocltm:operator", operator)
    if f is not None:
        spec.attribute("ocltm:frame", int(f))
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise FrameError(path, f, f"cannot write: no folder {folder}")
    tmp = safeio.temp_path(path, ".exr")
    try:
        out = oiio.ImageOutput.create(tmp)
        if out is None or not out.open(tmp, spec):
            raise FrameError(path, f, f"cannot write: {oiio.geterror() or 'no EXR writer'}")
        data = np.ascontiguousarray(np.stack([planes[n] for n in names], axis=-1),
                                    dtype=np.float32)
        ok = out.write_image(data)
        ok = bool(out.close()) and ok
        if not ok:
            raise FrameError(path, f, "cannot write: " + (
                "no space left on device" if safeio.disk_full(tmp) else
                (out.geterror() or "failed")))
        verify_written(tmp, path, f, w, h, len(names))
        safeio.commit(tmp, path)
    finally:
        safeio.remove(tmp)


def check_visibility(opts, jobs) -> None:
    """Refuse a bad ``--visibility`` before the first frame: its name, its pattern
    against the run's frames, an input it would overwrite, the viewing."""
    if not opts.visibility:
        return
    viewing(opts)
    p = opts.visibility
    if not p.lower().endswith(".exr"):
        raise ValueError(f"--visibility writes OpenEXR: name it .exr (got {p})")
    numbered = any(f is not None for f, *_ in jobs)
    if numbered and not is_sequence(p):
        raise ValueError(f"--visibility {p}: the run has numbered frames; give a frame "
                         "pattern (#, @ or %04d)")
    if not numbered and is_sequence(p):
        raise ValueError(f"--visibility {p}: a frame pattern, but the input is one image")
    for f, inp, outp, _ in jobs:
        v = visibility_path(opts, f)
        if same_file(v, inp) or same_file(v, outp) or os.path.abspath(v) == \
                os.path.abspath(outp):
            raise FrameError(v, f, "--visibility would overwrite the frame's input or output")


def visibility_path(opts, f) -> str:
    return frame_path(opts.visibility, f) if f is not None and is_sequence(opts.visibility) \
        else opts.visibility
