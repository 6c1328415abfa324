"""The main job: tone map an image or a frame sequence file to file.

read (OIIO) -> OCIO to working space -> x luminance scale = cd/m^2 -> meter ->
advance state -> per-pixel operator -> display-linear -> OCIO display/view ->
write (OIIO, atomic). Every failure names its file and frame.
"""

from __future__ import annotations

import json
import logging
import math
import os
import re
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from . import __version__
from .state import AUTO_SCALE_KEY, AdaptationState
from .calibration import ASSUMED_HELP, CalibrationRequest, Calibrator
from .colour import (ColourPipeline, InputColour, is_builtin_source, load_config,
                     resolve_config_source, resolve_input)
from .models.display import display_for
from .imageio import illuminant_from_metadata
from .imageio import (LINEAR_FORMATS, PNG_FILTERS, FrameError, find_frames, frame_path, is_sequence,
                      output_bits, read_frame, same_file, write_frame)
from .models.photometry import Y_WEIGHTS
from .backends.plan import quality_tier
from .pipeline import NeedsWholeFrame, Tonemapper, restore_alpha
from .models.photometry import RepairCounts

log = logging.getLogger("ocl_tonemap")
#: A frame-number token in a file name (imageio's pattern), with a separator before it.
_PAT_TOKEN = re.compile(r"[._-]?(#+|@+|%0?\d*d)")

DEFAULT_FPS = 24.0
#: What a gap in a sequence does (``--missing``).
MISSING_POLICIES = ("error", "hold", "skip")


class Interrupted(RuntimeError):
    """A run stopped by SIGINT/SIGTERM after a complete frame (checkpoint written)."""

    def __init__(self, signum: int, done: int, total: int, last_frame, checkpoint: str | None):
        self.signum, self.done, self.total = signum, done, total
        self.last_frame, self.checkpoint = last_frame, checkpoint
        super().__init__(f"interrupted after {done} of {total} frame(s)")

    @property
    def exit_code(self) -> int:
        return 128 + int(self.signum)


@dataclass
class JobOptions:
    input: str
    output: str
    frames: list[int] | None = None
    fps: float | None = None
    operator: str = "pattanaik00"
    metering: str = "logmean"
    luminance_scale: float | str | None = None    # S, or "auto:LEVEL" (calibration.py)
    exposure: float = 0.0
    colorconfig: str | None = None
    iscolorspace: str | None = None
    display: str | None = None
    view: str | None = None
    display_model: str = "display"
    display_white: float | None = None
    display_peak: float = 1000.0
    display_black: float | None = None
    unpremult: bool | None = None       # None: from the file (oiio:UnassociatedAlpha)
    encode: bool = False                # float outputs: display-encoded, not display-linear
    preadapt: tuple[float, float | None] | None = None
    state_in: str | None = None
    state_out: str | None = None
    backend: str | None = None          # None: the --quality tier's (opencl but for reference)
    device: str | None = None
    out_bits: str | None = None
    plot: str | None = None
    plot_frames: list[int] | None = None
    max_band_pixels: int | None = None
    progress: bool = False
    operator_options: dict | None = None
    effects: object | None = None   # effects.EffectSettings; None: the operator's defaults
    missing: str = "error"          # a gap in a sequence: error | hold | skip
    channels: list[str] | None = None   # --channels: names used as R,G,B (or one: luminance)
    png_level: int = 1                  # zlib level of PNG outputs (imageio.PNG_LEVEL)
    png_filter: str = "sub"             # PNG row filter (imageio.PNG_FILTERS)
    max_memory: float | None = None     # MiB: frames that would take more stream in bands
    resume: bool = False            # continue from the checkpoint of an earlier run
    checkpoint: bool = True         # write the state after every frame ...
    checkpoint_every: int = 1       # ... or every N frames (local operators: per-pixel planes)
    overlap_io: bool = True         # read the next frame and write the last one beside the work
    display_encode: str | None = None   # auto | table (device) | ocio (CPU); None: the tier's
    quality: str | None = None      # --quality: draft | balanced (None) | reference
    cuts: list[int] | str | None = None  # --cuts: frames where the eyes start afresh, or "detect"

    def __post_init__(self):
        tier = quality_tier(self.quality)          # the defaults a knob not given takes
        self.quality = tier.name
        self.backend = self.backend or tier.backend
        self.display_encode = self.display_encode or tier.display_encode
        if self.fps is not None and not (math.isfinite(self.fps) and 0 < self.fps <= 1e6):
            raise ValueError(f"--fps must be a positive number of frames per second, at most "
                             f"1e6 (got {self.fps:g})")
        if not math.isfinite(self.exposure) or abs(self.exposure) > 100:
            raise ValueError(f"--exposure must be a number of stops in [-100, 100] "
                             f"(got {self.exposure:g})")
        if self.max_memory is not None and not (math.isfinite(self.max_memory)
                                                and self.max_memory >= 8):
            raise ValueError(f"--max-memory must be at least 8 MiB (got {self.max_memory:g})")
        if not (isinstance(self.checkpoint_every, int) and self.checkpoint_every >= 1):
            raise ValueError(f"--checkpoint-every must be >= 1 (got {self.checkpoint_every})")
        if not (isinstance(self.png_level, int) and 0 <= self.png_level <= 9):
            raise ValueError(f"--png-level must be 0..9 (got {self.png_level})")
        if self.png_filter not in PNG_FILTERS:
            raise ValueError(f"--png-filter must be {', '.join(PNG_FILTERS)} "
                             f"(got {self.png_filter!r})")
        if self.display_encode not in ("auto", "table", "ocio"):  # colour.DISPLAY_ENCODE_MODES
            raise ValueError(f"--display-encode must be auto, table or ocio "
                             f"(got {self.display_encode!r})")
        if isinstance(self.cuts, str) and self.cuts != "detect":
            raise ValueError(f"cuts must be frame numbers or 'detect' (got {self.cuts!r})")
        if self.missing not in MISSING_POLICIES:
            raise ValueError(f"--missing must be one of {', '.join(MISSING_POLICIES)} "
                             f"(got {self.missing!r})")


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


def _sequence_frames(opts: JobOptions) -> tuple[list[int], list[int]]:
    """(frames to render, the missing ones among them) for a sequence input: the
    --frames list, or every frame between the first and last on disk (step: the
    common step of those present)."""
    present = set(find_frames(opts.input))
    if opts.frames is not None:
        frames = list(opts.frames)
    else:
        if not present:
            raise FrameError(opts.input, None, "no frames found for this pattern")
        have = sorted(present)
        step = 0
        for a, b in zip(have, have[1:]):
            step = math.gcd(step, b - a)
        step = step or 1
        frames = list(range(have[0], have[-1] + 1, step))
    missing = [f for f in frames if f not in present and not os.path.exists(frame_path(opts.input, f))]
    return frames, missing


def frame_jobs(opts: JobOptions) -> list[tuple[int | None, str, str, bool]]:
    """(frame, input path, output path, held) for every frame to render; ``held``:
    the input is the previous frame's (``--missing hold``). Every input is
    checked before the first frame is processed."""
    if is_sequence(opts.input):
        if not is_sequence(opts.output):
            raise FrameError(opts.output, None, "input is a sequence, so the output needs a "
                             "frame pattern too (#, @ or %04d)")
        frames, missing = _sequence_frames(opts)
        if missing and opts.missing == "error":
            more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
            raise FrameError(frame_path(opts.input, missing[0]), missing[0],
                             f"missing frame{more} between {frames[0]} and {frames[-1]}; nothing "
                             "was processed. --missing hold repeats the previous frame, "
                             "--missing skip leaves the gap (time still follows frame numbers)")
        jobs, prev = [], None
        gone = set(missing)
        for f in frames:
            if f in gone:
                if opts.missing == "skip":
                    log.warning("%s: missing, skipped (--missing skip)", frame_path(opts.input, f))
                    continue
                if prev is None:
                    raise FrameError(frame_path(opts.input, f), f, "missing, and no earlier frame "
                                     "to hold (--missing hold)")
                log.warning("%s: missing, frame %d held (--missing hold)",
                            frame_path(opts.input, f), prev)
                jobs.append((f, frame_path(opts.input, prev), frame_path(opts.output, f), True))
                continue
            jobs.append((f, frame_path(opts.input, f), frame_path(opts.output, f), False))
            prev = f
        if not jobs:
            raise FrameError(opts.input, None, "no frames to process")
    else:
        if opts.frames is not None and len(opts.frames) != 1:
            raise FrameError(opts.input, None, "--frames needs a sequence pattern in INPUT")
        if not os.path.exists(opts.input):
            raise FrameError(opts.input, None, "no such file")
        f = opts.frames[0] if opts.frames else None
        if f is None and is_sequence(opts.output):
            raise FrameError(opts.output, None, "the output has a frame pattern but the input "
                             "is one image; give --frames N or a plain output name")
        jobs = [(f, opts.input, frame_path(opts.output, f) if (f is not None and is_sequence(opts.output))
                 else opts.output, False)]
    numbered = [f for f, _, _, _ in jobs if f is not None]
    if any(b <= a for a, b in zip(numbered, numbered[1:])):
        raise FrameError(opts.input, None, "--frames must go forward in time (increasing "
                         "frame numbers, each once)")
    import OpenImageIO as oiio
    if oiio.ImageOutput.create(jobs[0][2]) is None:
        raise FrameError(jobs[0][2], None, "no image format for this output name (use .exr, "
                         ".png, .tif, .jpg, .hdr ...)")
    inputs = {i for _, i, _, _ in jobs}
    for f, _, o, _ in jobs:
        for j in inputs:
            if same_file(o, j):
                raise FrameError(o, f, "output would overwrite an input file; choose another OUTPUT")
    return jobs


#: AdaptationState.extra key of the settings a run's frames depend on (--resume checks).
RUN_KEY = "run"


def run_fingerprint(opts: JobOptions) -> dict:
    """The settings that decide a run's frames, kept in its checkpoint: a resumed
    run must use the same to give the same frames."""
    import dataclasses
    fx = opts.effects
    return {"input": opts.input, "output": opts.output, "operator": opts.operator,
            "fps": opts.fps, "metering": opts.metering,
            "luminance_scale": None if opts.luminance_scale is None else str(opts.luminance_scale),
            "exposure": opts.exposure, "colorconfig": opts.colorconfig,
            "iscolorspace": opts.iscolorspace, "display": opts.display, "view": opts.view,
            "display_model": opts.display_model, "display_white": opts.display_white,
            "display_black": opts.display_black, "backend": opts.backend,
            "quality": opts.quality, "display_encode": opts.display_encode,
            "options": json.loads(json.dumps(opts.operator_options or {}, default=str)),
            "effects": json.loads(json.dumps(dataclasses.asdict(fx), default=str))
            if dataclasses.is_dataclass(fx) else None,
            "missing": opts.missing, "channels": opts.channels, "unpremult": opts.unpremult,
            "encode": opts.encode, "out_bits": opts.out_bits,
            "cuts": opts.cuts if isinstance(opts.cuts, str) else
            (sorted(opts.cuts) if opts.cuts else None)}


def checkpoint_path(opts: JobOptions) -> str:
    """Where the state is checkpointed after every frame: ``--state-out``, else the
    output name without its frame number + ``.state.json``
    (``out/shot.####.png`` -> ``out/shot.png.state.json``)."""
    if opts.state_out:
        return opts.state_out
    d, b = os.path.split(opts.output)
    b = _PAT_TOKEN.sub("", b)
    root, dot, ext = b.rpartition(".")
    if not dot:
        root, ext = b, ""
    root = root.rstrip("._-") or "ocl-tonemap"
    return os.path.join(d, f"{root}.{ext}.state.json" if ext else f"{root}.state.json")


def _resume_point(opts: JobOptions, jobs, ckpt: str, operator: str):
    """(state to start from, jobs still to do) for ``--resume``."""
    if not os.path.exists(ckpt):
        log.warning("--resume: no checkpoint %s; starting from the first frame", ckpt)
        return None, jobs
    st = AdaptationState.load(ckpt)
    if st.operator != operator:
        raise ValueError(f"--resume: the checkpoint {ckpt} belongs to operator {st.operator!r}, "
                         f"not {operator!r}")
    was, now = st.extra.get(RUN_KEY), run_fingerprint(opts)
    if isinstance(was, dict):
        # keys added since the checkpoint was written are not compared
        diff = [k for k in sorted(was) if was.get(k) != now.get(k)]
        if diff:
            raise ValueError("--resume: the checkpoint " + ckpt + " was written by a run with "
                             "other settings (" + "; ".join(
                                 f"{k}: {was.get(k)!r} then, {now.get(k)!r} now" for k in diff)
                             + "); resume with the same options, or start again without "
                             "--resume")
    if st.frame is None:
        raise ValueError(f"--resume: the checkpoint {ckpt} has no frame number (a still); "
                         "run it again")
    st.extra.pop(RUN_KEY, None)
    todo = [j for j in jobs if j[0] is not None and j[0] > st.frame]
    log.warning("resuming after frame %d from %s: %d of %d frame(s) left", st.frame, ckpt,
                len(todo), len(jobs))
    return st, todo


class RunSetup:
    """What one run decides once: colour, display, calibration, and the notices
    already given (an assumption is reported once per run, not per frame)."""

    def __init__(self, opts: JobOptions, tm_state_extra: dict | None = None):
        self.opts = opts
        self.config_source = resolve_config_source(opts.colorconfig)
        self.cfg = load_config(opts.colorconfig)
        self.colour = _colour(self.cfg, opts)
        # --display-encode: the baked device table or OCIO's CPU processor (encode_pixels)
        log.info("%s", self.colour.set_display_encode(opts.display_encode, opts.backend,
                                                      opts.device))
        self.disp = display_for(self.colour.display, opts.display_white, opts.display_peak,
                                opts.display_model, opts.display_black)
        self.request = CalibrationRequest.parse(opts.luminance_scale)
        self.calibrator = Calibrator(self.request, (tm_state_extra or {}).get(AUTO_SCALE_KEY))
        self._said: set = set()

    def once(self, level: int, msg: str, *args) -> None:
        key = (level, msg % args if args else msg)
        if key not in self._said:
            self._said.add(key)
            log.log(level, msg, *args)

    def input_colour(self, fr, path) -> InputColour:
        ic = resolve_input(self.cfg, path, fr.colorspace, self.opts.iscolorspace,
                           fr.chromaticities if fr.format_name == "openexr" else None,
                           rules_from_user_config=not is_builtin_source(self.config_source))
        self.once(logging.WARNING if ic.assumed else logging.INFO,
                  "input colour: %s (%s)", ic.colorspace, ic.why)
        return ic

    def calibrate(self, fr, pix_fn) -> tuple[float, str]:
        cal = self.calibrator.frame(fr.spec, fr.format_name, pix_fn)
        if cal.assumed:
            self.once(logging.WARNING, "calibration: 1.0 = %.6g cd/m^2 (%s); %s",
                      cal.scale, cal.source, ASSUMED_HELP)
        else:
            self.once(logging.INFO, "calibration: 1.0 = %.6g cd/m^2 (%s)", cal.scale, cal.source)
        return cal.scale * 2.0 ** self.opts.exposure, cal.source

    def premultiplied(self, fr) -> bool:
        """Whether the frame's colour is premultiplied (to be divided by alpha)."""
        if self.opts.unpremult is not None:
            return bool(self.opts.unpremult)
        return not fr.unassociated_alpha




def load_state_in(opts: JobOptions) -> AdaptationState | None:
    """``--state-in``, without the settings of the run that wrote it (``RUN_KEY``)."""
    if not opts.state_in:
        return None
    st = AdaptationState.load(opts.state_in)
    st.extra.pop(RUN_KEY, None)
    return st


def setup_run(opts: JobOptions, state: AdaptationState | None):
    """What a run sets up once: (RunSetup, Tonemapper from ``state``)."""
    run = RunSetup(opts, state.extra if state is not None else None)
    tm = make_tonemapper(opts, run.colour, state, run.disp)
    run.device_band_pixels = getattr(tm.backend, "max_band_pixels", None)
    return run, tm


def run_job(opts: JobOptions, jobs=None, state: AdaptationState | None = None) -> JobResult:
    """The main job. Writes the state after every frame (``checkpoint_path``); SIGINT
    and SIGTERM end it after the frame in flight (:class:`Interrupted`).
    ``jobs`` (a slice of ``frame_jobs(opts)``) and ``state`` (to start from, over
    ``--state-in``): one chunk of a shot (``shot/passes.py`` apply)."""
    t_start = time.perf_counter()
    jobs = frame_jobs(opts) if jobs is None else list(jobs)
    ckpt = checkpoint_path(opts) if (opts.checkpoint or opts.resume) else None
    _remove_stale_temps(jobs, [p for p in {ckpt, opts.state_out} if p])
    _check_state_paths(jobs, [p for p in {ckpt, opts.state_out} if p])
    if state is None:
        state = load_state_in(opts)
    else:
        state.extra.pop(RUN_KEY, None)
    if opts.resume:
        st, jobs = _resume_point(opts, jobs, ckpt, opts.operator)
        state = st if st is not None else state
    run, tm = setup_run(opts, state)
    _check_output_depth(opts, run.disp, jobs)
    fingerprint = run_fingerprint(opts)
    result = JobResult([], [])
    fps = opts.fps
    t_prev = tm.state.time_s
    n = len(jobs)
    rows_of: dict = {}
    if opts.cuts == "detect":
        raise ValueError("--cuts detect finds cuts in the shot's statistics: it needs the "
                         "measure and integrate passes (ocl-tonemap measure / integrate / "
                         "apply, or run --scheduler dask); give a file of frame numbers for "
                         "a serial run")
    cuts = set(opts.cuts or ())

    def rows(k):                       # streamed in bands? (decided once per frame)
        if k not in rows_of:
            rows_of[k] = stream_rows(opts, tm, jobs[k][1], jobs[k][0])
        return rows_of[k]

    with _StopSignals() as stop, _FrameIO(opts.overlap_io) as io:
        for k, (f, inp, outp, held) in enumerate(jobs):
            if k + 1 < n and not rows(k + 1):         # read-ahead of the next frame
                _, inp1, _, _ = jobs[k + 1]
                io.prefetch(k + 1, lambda inp1=inp1, f1=jobs[k + 1][0]:
                            read_frame(inp1, f1, opts.channels))
            try:
                if f in cuts and tm.adapted:     # a scene cut: the eyes start afresh
                    tm.reset_adaptation()
                    log.info("frame %s: scene cut, adaptation reset", f)
                if rows(k):
                    io.drain()                        # a streamed frame writes in bands
                    streamed = stream_frame(run, tm, inp, outp, f, held, rows(k), fps, t_prev)
                else:
                    streamed = None
                if streamed is not None:
                    t, info, fps = streamed
                    write = None
                else:
                    fr = io.read(k, lambda: read_frame(inp, f, opts.channels))
                    t, info, fps, write = _whole_frame(run, tm, fr, inp, outp, f, held, fps,
                                                       t_prev)
            except BaseException:
                io.drain()                 # the frames before this one are complete
                raise
            snap = None
            if ckpt and ((k + 1) % opts.checkpoint_every == 0 or k + 1 == n
                         or stop.signum is not None):
                snap = _checkpoint_state(tm, fingerprint)

            def after(snap=snap, f=f):
                if snap is not None:
                    try:
                        snap.save(ckpt, checkpoint=True)
                    except Exception as exc:                      # noqa: BLE001
                        raise FrameError(ckpt, f, f"cannot write the checkpoint: {exc}") \
                            from exc
            io.write(write, after)
            if info.repairs.total:
                log.warning("%s%s: repaired bad values (%s)", inp,
                            "" if f is None else f" frame {f}", info.repairs.summary())
            result.repairs += info.repairs
            result.frames.append(f)
            result.outputs.append(outp)
            result.infos.append(info)
            t_prev = t
            if opts.progress:
                _progress(k + 1, n, time.perf_counter() - t_start)
            if stop.signum is not None and k + 1 < n:
                io.drain()
                if opts.progress:
                    sys.stderr.write("\n")
                raise Interrupted(stop.signum, k + 1, n, f, ckpt)
        io.drain()
    if opts.progress and n:
        sys.stderr.write("\n")
    if opts.state_out:
        tm.state.save(opts.state_out)
    if opts.plot:
        from .plot import plot_adaptation
        plot_adaptation(opts.plot, result.infos, tm, opts.plot_frames)
    result.seconds = time.perf_counter() - t_start
    return result


def frame_time(fr, f, held: bool, fps, t_prev) -> tuple[float, float]:
    """(the frame's time in seconds, the run's fps): its timestamp metadata (not for
    a held frame), else frame number / fps; fps: ``--fps``, else the first frame's
    FramesPerSecond, else 24."""
    if fps is None:
        fps = fr.fps or DEFAULT_FPS
        if fr.fps is None:
            log.info("no --fps and no FramesPerSecond metadata: %g fps", fps)
    if fr.timestamp is not None and not held:
        t = fr.timestamp
    elif f is not None:
        t = f / fps
    else:
        t = t_prev if t_prev is not None else 0.0
    if t_prev is not None and t < t_prev:
        raise ValueError(f"frame time {t:.6g} s is before the previous frame's "
                         f"{t_prev:.6g} s (frames out of order, or --state-in from a "
                         "later chunk)")
    return t, fps


def _whole_frame(run: RunSetup, tm: Tonemapper, fr, inp, outp, f, held, fps, t_prev):
    """One frame (read whole) mapped; returns (time, info, fps, write): ``write()``
    encodes it for the display and writes it (on the writer thread when the I/O
    overlaps), from what this frame left, whatever the next frame does."""
    try:
        t, fps = frame_time(fr, f, held, fps, t_prev)
        pix, lam, cs_text, scale, scale_why = frame_input(run, tm, fr, inp)
        linear = output_is_linear(run.opts, outp)
        u8 = output_bits(outp, run.opts.out_bits) == "8"
        # encoded outputs: the display table runs where the operator's output is, and
        # only code values come back (encode_pixels, below, for frames that cannot)
        tm.output_encoding = None if linear else run.colour.device_output_encoding(
            u8, getattr(tm.backend, "rt", None))
        tm.process(pix, time_s=t, frame_number=f, luminance_scale=scale,
                   illuminant=illuminant_from_metadata(fr.spec), wavelengths=lam,
                   premultiplied=run.premultiplied(fr))
        extra = {"ocltm:held_from": os.path.basename(inp)} if held else None
        disp_lin, alpha_info, info = tm.last_output, tm.last_alpha, tm.last
        encoded = tm.last_output_encoded
        meta = output_metadata(run, tm, fr, t, cs_text, scale, scale_why, extra, linear,
                               disp_lin.shape[2] == 4)
    except FrameError:
        raise
    except Exception as exc:
        raise FrameError(inp, f, exc) from exc

    def write():
        try:
            pixels = disp_lin if encoded else \
                encode_pixels(run.colour, disp_lin, alpha_info, linear, u8)
            _, out_cs, chroma, white, straight = meta
            write_frame(outp, pixels, fr.spec, out_cs, meta[0], run.opts.out_bits, f,
                        chromaticities=chroma, white_luminance=white, straight_alpha=straight,
                        png_level=run.opts.png_level, png_filter=run.opts.png_filter)
        except FrameError:
            raise
        except Exception as exc:
            raise FrameError(outp, f, exc) from exc
    return t, info, fps, write


class _FrameIO:
    """Read-ahead and write-behind: the next frame is read and the last one encoded
    and written on two threads (one frame each way in flight: memory stays bounded)
    while the device works; OIIO and OCIO release Python's lock while they decode,
    encode and write. A failure surfaces at its own frame; ``drain`` waits for the
    write in flight and then runs what follows it (the checkpoint), so outputs and
    checkpoints keep their order. ``enabled`` False: everything on the caller."""

    def __init__(self, enabled: bool = True):
        from concurrent.futures import ThreadPoolExecutor
        self._r = ThreadPoolExecutor(1, "ocltm-read") if enabled else None
        self._w = ThreadPoolExecutor(1, "ocltm-write") if enabled else None
        self._reads: dict = {}
        self._pending = None

    def prefetch(self, key, fn) -> None:
        if self._r is not None and key not in self._reads:
            self._reads[key] = self._r.submit(fn)

    def read(self, key, fn):
        fut = self._reads.pop(key, None)
        return fn() if fut is None else fut.result()

    def write(self, fn, after) -> None:
        """Run ``fn`` (None: nothing to write) and then ``after``, behind the caller."""
        self.drain()
        if fn is None or self._w is None:
            if fn is not None:
                fn()
            after()
            return
        def both():
            fn()
            after()
        self._pending = self._w.submit(both)

    def drain(self) -> None:
        if self._pending is not None:
            fut, self._pending = self._pending, None
            fut.result()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for fut in self._reads.values():
            fut.cancel()
        self._reads.clear()
        for ex in (self._r, self._w):
            if ex is not None:
                ex.shutdown(wait=True)      # a write in flight completes (renamed whole)
        return False


def _checkpoint_state(tm: Tonemapper, fingerprint: dict) -> AdaptationState:
    """The state after a frame, with the run's settings (checked by --resume)."""
    st = tm.state
    st.extra[RUN_KEY] = fingerprint
    return st


def _check_state_paths(jobs, paths) -> None:
    """The state files must not be an input or an output, and their folder must exist."""
    files = {p for _, i, o, _ in jobs for p in (i, o)}
    for p in paths:
        d = os.path.dirname(os.path.abspath(p))
        if not os.path.isdir(d):
            raise FrameError(p, None, f"the state's folder {d} does not exist")
        for q in files:
            if same_file(p, q):
                raise FrameError(p, None, "the state file would overwrite an input or output "
                                 "frame; choose another --state-out")


def _check_output_depth(opts: JobOptions, disp, jobs) -> None:
    """An HDR (PQ/HLG) encoding in 8 bits bands visibly: say so."""
    from pathlib import Path
    from .imageio import DEFAULT_BITS
    if not jobs or not disp.hdr:
        return
    out = jobs[0][2]
    bits = opts.out_bits or DEFAULT_BITS.get(Path(out).suffix.lower(), "float")
    if bits == "8" and not output_is_linear(opts, out):
        log.warning("%s: an HDR display encoding (%s) in 8 bits bands in smooth gradients; "
                    "use --out-bits 16 (PNG, TIFF) or EXR", out, disp.name)


#: Host memory of the whole-frame path, in frames of float32 RGB (measured: 12x for
#: pattanaik00 and durand00 at 6000x4000, PoCL's device buffers included), and of the
#: streaming path per pixel of a band (reads, colour, device buffers, encode, write).
WHOLE_FRAME_COPIES = 12.0
STREAM_BYTES_PER_PIXEL = 160.0


def stream_rows(opts: JobOptions, tm: Tonemapper, inp: str, f) -> int | None:
    """Rows per band when this frame is to be streamed, else None: when it would
    take more than ``--max-memory`` whole (or more than the machine can hold),
    for operators that can stream (``Tonemapper.can_stream``)."""
    from .imageio import max_frame_bytes
    if opts.max_memory is None and not os.path.exists(inp):
        return None
    try:
        import OpenImageIO as oiio
        i = oiio.ImageInput.open(inp)
        if i is None:
            oiio.geterror()          # (this thread's; read_frame reports it properly)
            return None
        spec = i.spec()
        i.close()
    except Exception:  # noqa: BLE001 -- read_frame reports it properly
        return None
    from .imageio import spectral_channels
    if spectral_channels(spec.channelnames):
        return None                                   # spectra are read whole
    frame_bytes = float(spec.width) * spec.height * 12.0
    budget = opts.max_memory * 2**20 if opts.max_memory else max_frame_bytes()
    if WHOLE_FRAME_COPIES * frame_bytes <= budget or spec.width < 1:
        return None
    why = tm.can_stream()
    if why:
        log.warning("%s: %.0f MiB would be needed whole, over the budget of %.0f MiB, but it "
                    "cannot be streamed (%s)", inp, WHOLE_FRAME_COPIES * frame_bytes / 2**20,
                    budget / 2**20, why)
        return None
    rows = int(max(1, min(spec.height, (budget / 4) // (STREAM_BYTES_PER_PIXEL * spec.width))))
    log.info("%s: streamed in bands of %d rows (budget %.0f MiB)", inp, rows, budget / 2**20)
    return rows


class _WorkingBands:
    """A frame file as working-space bands for ``Tonemapper.process_stream``: rows
    read on demand, colour converted, colour straightened (divided by alpha)
    where it was premultiplied; the alpha of the last bands is kept for the sink."""

    def __init__(self, reader, colour, ic, premultiplied: bool):
        self.reader, self.colour, self.ic = reader, colour, ic
        self.premultiplied = premultiplied
        self.shape = reader.shape
        self._alpha: dict = {}

    def __getitem__(self, sl: slice) -> np.ndarray:
        from .pipeline import straight_colour
        y0, y1 = sl.start or 0, sl.stop
        band = self.colour.convert_input(self.reader.read(y0, y1), self.ic)
        if band.shape[2] == 4:
            band, alpha = straight_colour(band, self.premultiplied)
            self._alpha = {y0: alpha}
        return band

    def alpha(self, y0: int):
        return self._alpha.get(y0)


def stream_frame(run: RunSetup, tm: Tonemapper, inp, outp, f, held, rows, fps, t_prev,
                  measure_only: bool = False):
    """One frame read, mapped and written in bands of ``rows`` rows; returns (time, info,
    fps). ``measure_only``: its statistics only, (time, FrameStats, fps, illuminant
    hint), nothing written (``shot/passes.py``)."""
    from .imageio import BandReader, BandWriter
    reader = BandReader(inp, f, run.opts.channels)
    writer = None
    try:
        fr = reader.header
        t, fps = frame_time(fr, f, held, fps, t_prev)
        ic = run.input_colour(fr, inp)
        if fr.channel_note:
            run.once(logging.WARNING, "%s: %s", inp, fr.channel_note)
        h, w, _ = reader.shape

        def logavg():                 # auto:LEVEL: the log-average, band by band
            tot, cnt = 0.0, 0
            for y0 in range(0, h, rows):
                b = run.colour.convert_input(reader.read(y0, min(h, y0 + rows)), ic)
                Y = b[..., :3].astype(np.float64) @ Y_WEIGHTS
                Y = Y[np.isfinite(Y) & (Y > 0)]
                tot, cnt = tot + float(np.log(Y).sum()), cnt + Y.size
            la = math.exp(tot / cnt) if cnt else None
            return np.full((1, 1, 3), la if la else 0.0, np.float32)

        scale, why = run.calibrate(fr, logavg)
        _remember_auto(tm, run)
        premult = run.premultiplied(fr)
        source = _WorkingBands(reader, run.colour, ic, premult)
        linear = output_is_linear(run.opts, outp)
        has_alpha = reader.shape[2] == 4

        def sink(y0, band):
            nonlocal writer
            if writer is None:
                extra = {"ocltm:held_from": os.path.basename(inp)} if held else {}
                extra["ocltm:streamed"] = f"row bands of {rows}"
                meta, out_cs, chroma, white, straight = output_metadata(
                    run, tm, fr, t, ic.describe(), scale, why, extra, linear, has_alpha)
                writer = BandWriter(outp, fr.spec, 4 if has_alpha else 3, out_cs, meta,
                                    run.opts.out_bits, f, chroma, white, straight,
                                    run.opts.png_level, run.opts.png_filter)
            px = run.colour.linear(band) if linear else run.colour.encode_fast(band)
            a = source.alpha(y0)
            if a is not None:
                px = restore_alpha(px, a)
            writer.write(y0, px)

        tm.backend.max_band_pixels = rows * w
        # per-pixel planes of local operators (their state and levels) go to a file
        # beside the output, read and written by bands (backends/planes.py)
        tm.backend.spill_dir = os.path.dirname(os.path.abspath(outp))
        if measure_only:
            hint = illuminant_from_metadata(fr.spec)
            stats = tm.process_stream(source, None, time_s=t, frame_number=f,
                                      luminance_scale=scale, illuminant=hint,
                                      measure_only=True)
            return t, stats, fps, hint
        try:
            tm.process_stream(source, sink, time_s=t, frame_number=f, luminance_scale=scale,
                              illuminant=illuminant_from_metadata(fr.spec))
        except NeedsWholeFrame as exc:
            log.warning("%s%s: not streamed, %s; read whole", inp,
                        "" if f is None else f" frame {f}", exc)
            return None
        writer.commit()
        writer = None
        return t, tm.last, fps
    except FrameError:
        raise
    except Exception as exc:
        raise FrameError(inp, f, exc) from exc
    finally:
        tm.backend.max_band_pixels = run.device_band_pixels
        tm.backend.spill_dir = None
        if writer is not None:
            writer.abort()
        reader.close()


class _StopSignals:
    """SIGINT / SIGTERM set ``signum``; the run stops after the frame in flight. A
    second signal stops at once (the frame in flight is discarded: outputs are
    written to temporary files and renamed, so nothing partial is left)."""

    def __init__(self):
        self.signum = None
        self._old = {}

    def _handler(self, signum, frame):
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum

    def __enter__(self):
        import signal
        import threading
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc):
        import signal
        for sig, h in self._old.items():
            signal.signal(sig, h)
        return False


def _remove_stale_temps(jobs, state_paths=()) -> None:
    """Temporary files a killed earlier run may have left beside the outputs and
    the state files (``.<name>.tmp<pid>[<ext>]``, only those of this run's files,
    and only when that process is gone)."""
    from pathlib import Path
    mine: dict = {}
    for _, _, o, _ in jobs:
        mine.setdefault(os.path.dirname(os.path.abspath(o)), set()).add(Path(o).stem)
    prefixes: dict = {}
    for sp in state_paths:                  # the JSON itself and its per-pixel planes
        d, name = os.path.split(os.path.abspath(sp))
        mine.setdefault(d, set()).add(name)
        prefixes.setdefault(d, []).append(name[:-5] + ".pixels." if name.endswith(".json")
                                          else name + ".pixels.")
    rx = re.compile(r"^\.(.+)\.tmp(\d+)(\.[A-Za-z0-9]+)?$")
    for d, stems in mine.items():
        try:
            names = os.listdir(d)
        except OSError:
            continue
        for name in names:
            m = rx.match(name)
            if not m or int(m.group(2)) == os.getpid():
                continue
            if m.group(1) not in stems and not any(m.group(1).startswith(pfx)
                                                   for pfx in prefixes.get(d, ())):
                continue                       # not a temporary of one of this run's files
            try:
                os.kill(int(m.group(2)), 0)
                continue                       # that process is alive: not ours to remove
            except PermissionError:
                continue                       # alive, another user's
            except (ProcessLookupError, OverflowError):
                pass
            try:
                os.unlink(os.path.join(d, name))
            except OSError:
                pass


def _remember_auto(tm: Tonemapper, run: RunSetup) -> None:
    """Keep the run's ``auto`` calibration constant in the state (resume uses it)."""
    if run.calibrator.auto_scale is not None:
        tm.remember(AUTO_SCALE_KEY, float(run.calibrator.auto_scale))


def _frame_input(run: RunSetup, tm: Tonemapper, fr, path):
    """(pixels, wavelengths or None, description of the input colour) for one frame:
    the spectrum for an operator that takes spectra, else working-space RGB (from
    the spectrum through the CIE 1931 observer when the file has no RGB)."""
    if fr.wavelengths is not None and "spectral" in tm.op.inputs:
        lam = fr.wavelengths
        return fr.spectral, lam, (f"spectral, {len(lam)} channels {lam[0]:g}-{lam[-1]:g} nm "
                                  "(radiance, W sr^-1 m^-2 nm^-1)")
    if fr.rgb_from_spectrum:
        return fr.pixels, None, f"{run.colour.working} (from the spectrum, CIE 1931 2-degree)"
    ic = run.input_colour(fr, path)
    return run.colour.convert_input(fr.pixels, ic), None, ic.describe()


def _colour(cfg, opts: JobOptions) -> ColourPipeline:
    colour = ColourPipeline(cfg, opts.display, opts.view)
    if not colour.view_is_plain:
        log.warning("view %r may apply its own tone curve on top of the operator's; the "
                    "un-tone-mapped view is the one meant for display-linear output", colour.view)
    return colour


def make_tonemapper(opts: JobOptions, colour: ColourPipeline, state, disp) -> Tonemapper:
    tm = Tonemapper(opts.operator, opts.backend, opts.metering, disp, opts.preadapt, state,
                    opts.device, opts.max_band_pixels, opts.operator_options, opts.effects,
                    quality=opts.quality)
    tm.set_display_primaries(colour.display_primaries())
    log.info("quality %s; backend: %s", tm.quality, tm.backend.describe())
    log.info("OCIO: working %s, display %r view %r -> %s", colour.working, colour.display,
             colour.view, colour.output_colorspace)
    log.info("display: white %g cd/m^2, black %g cd/m^2%s", disp.white_cd, disp.black_cd,
             " (Pattanaik 2000's CRT)" if disp.paper_crt else "")
    return tm


def output_is_linear(opts: JobOptions, path: str) -> bool:
    """Float outputs (EXR, .hdr) hold display-linear light unless ``--encode``."""
    from pathlib import Path
    return (not opts.encode) and Path(path).suffix.lower() in LINEAR_FORMATS


@dataclass
class Rendered:
    """The last processed frame, ready to write: pixels in the output colourspace
    and what to tag them with (shared by the CLI and ``Tonemapper.process_imagebuf``)."""

    pixels: np.ndarray
    colorspace: str
    metadata: dict
    chromaticities: tuple
    white_luminance: float | None
    straight_alpha: bool


def output_metadata(run: RunSetup, tm: Tonemapper, fr, t, cs_text, scale, scale_why,
                    extra: dict | None, linear: bool, alpha: bool):
    """(metadata, output colourspace, chromaticities, whiteLuminance, straight alpha)
    of the last processed frame (``tm.last``)."""
    colour, disp = run.colour, tm.display
    info = tm.last
    out_cs = colour.linear_output()[0] if linear else colour.output_colorspace
    premult = run.premultiplied(fr)
    meta = {
        "Software": f"ocl-tonemap {__version__}",
        "ocltm:operator": tm.operator_name,
        "ocltm:backend": tm.backend.name,
        "ocltm:quality": tm.quality,
        "ocltm:metering": tm.metering.describe() if tm.op.metering != "local"
        else "local (bilateral)",
        "ocltm:input_colorspace": cs_text,
        "ocltm:output_colorspace": out_cs,
        "ocltm:output_encoding": (f"display-linear light, 1.0 = {disp.unit_cd:g} cd/m^2"
                                  if linear else "display-encoded (OCIO display/view)"),
        "ocltm:view": f"{colour.display} / {colour.view}",
        "ocltm:luminance_scale": float(scale),
        "ocltm:luminance_scale_source": scale_why,
        "ocltm:display": json.dumps(disp.as_dict(), sort_keys=True),
        "ocltm:time_s": float(t),
        "ocltm:goal": json.dumps({"G_rod": info.G_rod, "G_cone": info.G_cone}),
        "ocltm:state": json.dumps(info.state.to_json(), sort_keys=True),
        "ocltm:params": json.dumps(info.params, sort_keys=True, default=float),
        "ocltm:repairs": json.dumps(info.repairs.as_dict(), sort_keys=True),
        "ocltm:effects": json.dumps(info.effects, sort_keys=True, default=float),
        "ocltm:effects_ran": ",".join(k for k, v in info.effects.items() if v.get("ran")) or "none",
    }
    if fr.channel_note:
        meta["ocltm:channels"] = fr.channel_note
    if alpha:
        meta["ocltm:alpha"] = ("premultiplied: colour divided by alpha for the operator, "
                               "multiplied again" if premult else
                               ("straight (unassociated)" if fr.unassociated_alpha else
                                "tone mapped as stored (--no-unpremult)"))
    meta.update(extra or {})
    return (meta, out_cs, colour.output_chromaticities(encoded=not linear),
            disp.unit_cd if linear else None, alpha and not premult)


def encode_pixels(colour, disp_lin: np.ndarray, alpha_info, linear: bool,
                  u8: bool = False) -> np.ndarray:
    """Display-linear light (with alpha) to the output's values: the display's linear
    colourspace, or the display encoding (``colour.encode_fast``: the baked device table
    chosen by ``--display-encode``, else OCIO's CPU processor). ``u8``: the output is
    an 8-bit file; with the device table the code values come back as the bytes OIIO
    would write (quantised on the device: a quarter of the download, no conversion)."""
    rgb = disp_lin[..., :3]
    alpha = disp_lin.shape[2] == 4
    pm = alpha and alpha_info is not None and alpha_info[2]
    if u8 and not linear and not pm and getattr(colour, "device_table", None) is not None:
        return colour.encode_fast(disp_lin, u8=True)
    encode = getattr(colour, "encode_fast", colour.encode)
    if pm and not linear:
        # a display encoding is not linear: encode the straight colour, then
        # premultiply the code values again (encode(c) a, not encode(c a))
        a = disp_lin[..., 3:4]
        rgb = np.where(a > 0, rgb / np.where(a > 0, a, 1.0), rgb).astype(np.float32)
        return restore_alpha(encode(rgb), alpha_info)
    pixels = colour.linear(rgb) if linear else encode(rgb)
    if alpha:
        pixels = np.concatenate([pixels, disp_lin[..., 3:4]], axis=2)
    return pixels


def render_output(run: RunSetup, tm: Tonemapper, fr, t, cs_text, scale, scale_why,
                  extra: dict | None, linear: bool) -> Rendered:
    """Encode the last processed frame (display-linear light in the display's
    linear colourspace, or the display encoding) with its ``ocltm:*`` metadata."""
    disp_lin = tm.last_output
    pixels = encode_pixels(run.colour, disp_lin, tm.last_alpha, linear)
    meta, out_cs, chroma, white, straight = output_metadata(
        run, tm, fr, t, cs_text, scale, scale_why, extra, linear, disp_lin.shape[2] == 4)
    return Rendered(pixels, out_cs, meta, chroma, white, straight)


def _write_output(run: RunSetup, tm: Tonemapper, fr, outp, f, t, cs_text, scale, scale_why,
                  extra: dict | None):
    """Encode the last processed frame for the display and write it with its metadata."""
    r = render_output(run, tm, fr, t, cs_text, scale, scale_why, extra,
                      output_is_linear(run.opts, outp))
    write_frame(outp, r.pixels, fr.spec, r.colorspace, r.metadata, run.opts.out_bits, f,
                chromaticities=r.chromaticities, white_luminance=r.white_luminance,
                straight_alpha=r.straight_alpha, png_level=run.opts.png_level,
                png_filter=run.opts.png_filter)
    return tm.last


def frame_input(run: RunSetup, tm: Tonemapper, fr, path):
    """The front door for one frame: its pixels in the working space (or spectrum),
    the description of its colour, and its calibration. Returns
    (pixels, wavelengths or None, colour text, scale, scale source)."""
    if fr.channel_note:
        run.once(logging.WARNING, "%s: %s", path, fr.channel_note)
    pix, lam, cs_text = _frame_input(run, tm, fr, path)

    def working_rgb():
        if lam is None:
            return pix
        from .models.lmsr import spectral_to_rgb
        return spectral_to_rgb(lam, pix)
    scale, why = run.calibrate(fr, working_rgb)
    _remember_auto(tm, run)
    return pix, lam, cs_text, scale, why


def parse_times(text: str) -> list[float]:
    """``T1,T2,...`` in seconds; an ``m`` suffix means minutes."""
    out = []
    for item in text.split(","):
        item = item.strip()
        try:
            v = float(item[:-1]) * 60.0 if item.endswith("m") else float(item.rstrip("s"))
        except ValueError:
            raise ValueError(f"bad --at value {item!r}: use seconds or minutes (e.g. 30,2m)") from None
        if not (v >= 0 and math.isfinite(v)):
            raise ValueError(f"bad --at value {item!r}: times must be >= 0")
        out.append(v)
    if not out:
        raise ValueError("--at needs at least one time")
    return out


def _time_label(seconds: float) -> str:
    return f"{seconds:g}s".replace(".", "p")


def simulate_outputs(output: str, times: list[float]) -> list[tuple[int | None, str]]:
    """(frame, path) per time: a pattern gets frames 1..n, a plain name ``_t<T>s``."""
    if is_sequence(output):
        return [(k + 1, frame_path(output, k + 1)) for k in range(len(times))]
    root, dot, ext = output.rpartition(".")
    if not dot:
        root, ext = output, ""
    return [(None, f"{root}_t{_time_label(t)}{'.' + ext if dot else ''}") for t in times]


def run_simulate(opts: JobOptions, times: list[float]) -> JobResult:
    """A still image seen over time: the observer was pre-adapted (``opts.preadapt``),
    starts looking at INPUT at t = 0, and one output is rendered per elapsed time."""
    t_start = time.perf_counter()
    if is_sequence(opts.input):
        raise FrameError(opts.input, None, "simulate takes one still image, not a sequence")
    if opts.preadapt is None:
        raise ValueError("simulate needs --preadapt CD_M2[:SECONDS] (what the observer saw before)")
    outs = simulate_outputs(opts.output, times)
    for _, o in outs:
        if same_file(o, opts.input):
            raise FrameError(o, None, "output would overwrite the input file; choose another OUTPUT")
    state = AdaptationState.load(opts.state_in) if opts.state_in else None
    run, tm = setup_run(opts, state)
    fr = read_frame(opts.input, None, opts.channels)
    result = JobResult([], [])
    try:
        pix, lam, cs_text, scale, scale_why = frame_input(run, tm, fr, opts.input)
        t_now = 0.0
        hint = illuminant_from_metadata(fr.spec)
        pm = run.premultiplied(fr)
        tm.process(pix, time_s=0.0, luminance_scale=scale, illuminant=hint,
                   wavelengths=lam, premultiplied=pm)                   # the switch
        order = sorted(range(len(times)), key=lambda k: times[k])
        for k in order:
            t = times[k]
            if t > t_now:
                tm.process(pix, time_s=t, luminance_scale=scale, illuminant=hint,
                           wavelengths=lam, premultiplied=pm)
                t_now = t
            f, outp = outs[k]
            info = _write_output(run, tm, fr, outp, f, t, cs_text, scale, scale_why,
                                 {"ocltm:elapsed_s": float(t),
                                  "ocltm:preadapt": json.dumps(opts.preadapt)})
            result.frames.append(f)
            result.outputs.append(outp)
            result.infos.append(info)
            result.repairs += info.repairs
            log.info("t = %g s -> %s", t, outp)
    except FrameError:
        raise
    except Exception as exc:
        raise FrameError(opts.input, None, exc) from exc
    if opts.state_out:
        tm.state.save(opts.state_out)
    result.seconds = time.perf_counter() - t_start
    return result


def _progress(done: int, total: int, elapsed: float) -> None:
    width = 30
    filled = int(width * done / total)
    rate = done / elapsed if elapsed > 0 else 0.0
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} frames "
                     f"{rate:5.1f} fps")
    sys.stderr.flush()
