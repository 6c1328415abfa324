"""The main job: tone map an image or a frame sequence file to file.

read (OIIO) -> OCIO to working space -> x luminance scale = cd/m^2 -> meter ->
advance state -> per-pixel operator -> display-linear -> OCIO display/view ->
write (OIIO, atomic). Every failure names its file and frame.
"""

from __future__ import annotations

import json
import logging
import math
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from . import __version__
from .adaptation import AdaptationState
from .colour import ColourPipeline, input_colorspace, load_config
from .display import display_for
from .imageio import (FrameError, default_scale, find_frames, frame_path, is_sequence,
                      read_frame, same_file, write_frame)
from .pipeline import Tonemapper
from .photometry import RepairCounts

log = logging.getLogger("ocl_tonemap")

DEFAULT_FPS = 24.0


@dataclass
class JobOptions:
    input: str
    output: str
    frames: list[int] | None = None
    fps: float | None = None
    operator: str = "pattanaik00"
    metering: str = "logmean"
    luminance_scale: float | None = None
    exposure: float = 0.0
    colorconfig: str | None = None
    iscolorspace: str | None = None
    display: str | None = None
    view: str | None = None
    display_model: str = "display"
    display_white: float | None = None
    display_peak: float = 1000.0
    preadapt: tuple[float, float | None] | None = None
    state_in: str | None = None
    state_out: str | None = None
    backend: str = "opencl"
    device: str | None = None
    out_bits: str | None = None
    plot: str | None = None
    plot_frames: list[int] | None = None
    max_band_pixels: int | None = None
    progress: bool = False


@dataclass
class JobResult:
    frames: list[int | None]
    outputs: list[str]
    infos: list = field(default_factory=list)
    repairs: RepairCounts = field(default_factory=RepairCounts)
    seconds: float = 0.0


def parse_preadapt(text: str) -> tuple[float, float | None]:
    """``L`` or ``L:SECONDS`` (``m`` suffix: minutes)."""
    lum, _, sec = text.partition(":")
    try:
        L = float(lum)
        s = None
        if sec:
            s = float(sec[:-1]) * 60.0 if sec.endswith("m") else float(sec)
    except ValueError:
        raise ValueError(f"bad --preadapt {text!r}: use CD_M2 or CD_M2:SECONDS") from None
    if not (L >= 0 and math.isfinite(L)) or (s is not None and not (s >= 0 and math.isfinite(s))):
        raise ValueError(f"bad --preadapt {text!r}: luminance and seconds must be >= 0")
    return L, s


def _jobs(opts: JobOptions) -> list[tuple[int | None, str, str]]:
    """(frame, input path, output path) for every frame to process."""
    if is_sequence(opts.input):
        frames = opts.frames if opts.frames is not None else find_frames(opts.input)
        if not frames:
            raise FrameError(opts.input, None, "no frames found for this pattern")
        if not is_sequence(opts.output):
            raise FrameError(opts.output, None, "input is a sequence, so the output needs a "
                             "frame pattern too (#, @ or %04d)")
        jobs = [(f, frame_path(opts.input, f), frame_path(opts.output, f)) for f in frames]
    else:
        if opts.frames is not None and len(opts.frames) != 1:
            raise FrameError(opts.input, None, "--frames needs a sequence pattern in INPUT")
        f = opts.frames[0] if opts.frames else None
        jobs = [(f, opts.input, frame_path(opts.output, f) if (f is not None and is_sequence(opts.output))
                 else opts.output)]
    inputs = [i for _, i, _ in jobs]
    for f, i, o in jobs:
        for j in inputs:
            if same_file(o, j):
                raise FrameError(o, f, "output would overwrite an input file; choose another OUTPUT")
    return jobs


def run_job(opts: JobOptions) -> JobResult:
    t_start = time.perf_counter()
    jobs = _jobs(opts)
    cfg = load_config(opts.colorconfig)
    colour = ColourPipeline(cfg, opts.display, opts.view)
    if not colour.view_is_plain:
        log.warning("view %r may apply its own tone curve on top of the operator's; the "
                    "un-tone-mapped view is the one meant for display-linear output", colour.view)
    disp = display_for(colour.display, opts.display_white, opts.display_peak, opts.display_model)
    state = AdaptationState.load(opts.state_in) if opts.state_in else None
    tm = Tonemapper(opts.operator, opts.backend, opts.metering, disp, opts.preadapt, state,
                    opts.device, opts.max_band_pixels)
    log.info("backend: %s", tm.backend.describe())
    log.info("OCIO: working %s, display %r view %r -> %s", colour.working, colour.display,
             colour.view, colour.output_colorspace)
    result = JobResult([], [])
    fps = opts.fps
    t_prev = tm.state.time_s
    n = len(jobs)
    for k, (f, inp, outp) in enumerate(jobs):
        fr = read_frame(inp, f)
        try:
            if fps is None:
                fps = fr.fps or DEFAULT_FPS
                if fr.fps is None:
                    log.info("no --fps and no FramesPerSecond metadata: %g fps", fps)
            if fr.timestamp is not None:
                t = fr.timestamp
            elif f is not None:
                t = f / fps
            else:
                t = t_prev if t_prev is not None else 0.0
            if t_prev is not None and t < t_prev:
                raise ValueError(f"frame time {t:.6g} s is before the previous frame's {t_prev:.6g} s "
                                 "(frames out of order, or --state-in from a later chunk)")
            cs, why = input_colorspace(cfg, inp, fr.colorspace, opts.iscolorspace)
            pix = colour.to_working(fr.pixels, cs)
            scale, scale_why = (opts.luminance_scale, "--luminance-scale") if opts.luminance_scale \
                else default_scale(fr)
            scale *= 2.0 ** opts.exposure
            disp_lin = tm.process(pix, time_s=t, frame_number=f, luminance_scale=scale)
            info = tm.last
            encoded = colour.encode(disp_lin[..., :3])
            if disp_lin.shape[2] == 4:
                encoded = np.concatenate([encoded, disp_lin[..., 3:4]], axis=2)
            meta = {
                "Software": f"ocl-tonemap {__version__}",
                "ocltm:operator": opts.operator,
                "ocltm:backend": opts.backend,
                "ocltm:metering": tm.metering.describe(),
                "ocltm:input_colorspace": f"{cs} ({why})",
                "ocltm:output_colorspace": colour.output_colorspace,
                "ocltm:view": f"{colour.display} / {colour.view}",
                "ocltm:luminance_scale": float(scale),
                "ocltm:luminance_scale_source": scale_why,
                "ocltm:display": json.dumps(disp.as_dict(), sort_keys=True),
                "ocltm:time_s": float(t),
                "ocltm:goal": json.dumps({"G_rod": info.G_rod, "G_cone": info.G_cone}),
                "ocltm:state": json.dumps(info.state.to_json(), sort_keys=True),
                "ocltm:params": json.dumps(info.params, sort_keys=True, default=float),
                "ocltm:repairs": json.dumps(info.repairs.as_dict(), sort_keys=True),
            }
            write_frame(outp, encoded, fr.spec, colour.output_colorspace, meta, opts.out_bits, f)
        except FrameError:
            raise
        except Exception as exc:
            raise FrameError(inp, f, exc) from exc
        if info.repairs.total:
            log.warning("%s frame %s: repaired bad values (%s)", inp, f, info.repairs.summary())
        result.repairs += info.repairs
        result.frames.append(f)
        result.outputs.append(outp)
        result.infos.append(info)
        t_prev = t
        if opts.progress:
            _progress(k + 1, n, time.perf_counter() - t_start)
    if opts.progress:
        sys.stderr.write("\n")
    if opts.state_out:
        tm.state.save(opts.state_out)
    if opts.plot:
        from .plot import plot_adaptation
        plot_adaptation(opts.plot, result.infos, tm, opts.plot_frames)
    result.seconds = time.perf_counter() - t_start
    return result


def _progress(done: int, total: int, elapsed: float) -> None:
    width = 30
    filled = int(width * done / total)
    rate = done / elapsed if elapsed > 0 else 0.0
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} frames "
                     f"{rate:5.1f} fps")
    sys.stderr.flush()
