"""Which frames a run renders, from which files to which, and at what time."""

from __future__ import annotations

import logging
import math
import os

from ..io.imageio import FrameError, check_readable
from ..io.imagewrite import check_output

from ..io.patterns import find_frames, frame_path, is_sequence
from .options import DEFAULT_FPS, JobOptions

log = logging.getLogger("ocl_tonemap")

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
    missing = [f for f in frames if f not in present]
    if opts.missing == "error" and len(missing) > 1000 and len(missing) > len(frames) // 2:
        # a range far beyond the files (--frames 1-100000000): said at once, not looked up
        # frame by frame
        have = sorted(present)
        raise FrameError(opts.input, None, f"--frames asks for {len(frames)} frames; "
                         f"{len(missing)} of them are not on disk (found "
                         + (f"{len(have)}: {have[0]}-{have[-1]}" if have else "none") + ")")
    missing = [f for f in missing if not os.path.exists(frame_path(opts.input, f))]
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
    check_output(jobs[0][2])             # a folder, no format, a read-only folder: refused
    for f, i, _, _ in jobs:              # a FIFO among the frames: refused before any frame
        check_readable(i, f)             # is made (each is checked again as it is read)
    inputs = input_identities({i for _, i, _, _ in jobs})
    for f, _, o, _ in jobs:
        if inputs(o):
            raise FrameError(o, f, "output would overwrite an input file; choose another OUTPUT")
    return jobs


def input_identities(paths):
    """``is_input(path)``: whether ``path`` is one of ``paths`` (the same file, as
    ``os.path.samefile`` says: a link or another name of it; else the same absolute
    path). One stat per file: a 10 000-frame shot's check is not 10^8 comparisons
    (each task of a distributed shot makes it)."""
    ids, names = set(), set()
    for p in paths:
        names.add(os.path.abspath(p))
        try:
            st = os.stat(p)
        except OSError:
            continue
        ids.add((st.st_dev, st.st_ino))

    def is_input(path) -> bool:
        try:
            st = os.stat(path)
            if (st.st_dev, st.st_ino) in ids:
                return True
        except OSError:
            pass
        return os.path.abspath(path) in names
    return is_input


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


#: Digits of a simulate output's whole seconds, at least (``out_t0060s.png``).
TIME_DIGITS = 4
#: Most decimals of a simulate output's time (microseconds).
TIME_DECIMALS = 6


def _decimals(t: float) -> int:
    """The decimals ``t`` needs to be written exactly (at most :data:`TIME_DECIMALS`)."""
    for d in range(TIME_DECIMALS):
        if abs(round(t, d) - t) <= 1e-9 * max(1.0, abs(t)):
            return d
    return TIME_DECIMALS


def time_labels(times: list[float]) -> list[str]:
    """Each time's ``<T>s`` of a simulate output's name, written alike so that the names
    sort in time order: the whole seconds zero-padded to the largest's width (at least
    :data:`TIME_DIGITS`), and where any time has a fraction, the same decimals in each,
    the point written ``p`` (0.5, 1, 600: ``0000p5s``, ``0001p0s``, ``0600p0s``)."""
    d = max((_decimals(t) for t in times), default=0)
    text = [f"{t:.{d}f}" for t in times]
    width = max([TIME_DIGITS] + [len(x.split(".")[0]) for x in text])
    return [x.zfill(width + (d + 1 if d else 0)).replace(".", "p") + "s" for x in text]


def simulate_outputs(output: str, times: list[float]) -> list[tuple[int | None, str]]:
    """(frame, path) per time: a pattern gets frames 1..n, a plain name ``_t<T>s``
    (:func:`time_labels`: the names sort in time order)."""
    if is_sequence(output):
        return [(k + 1, frame_path(output, k + 1)) for k in range(len(times))]
    root, dot, ext = output.rpartition(".")
    if not dot:
        root, ext = output, ""
    return [(None, f"{root}_t{label}{'.' + ext if dot else ''}")
            for label in time_labels(times)]
