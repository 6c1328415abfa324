"""A shot's chunks: the frames of one task (``--chunk A-B``), the shot cut into
tasks, the frames an interrupted chunk left, and the output lock a chunk shares
with the other chunks of its shot (``job.locks``)."""

from __future__ import annotations

import re
import shlex
from contextlib import nullcontext

from ..job.locks import output_lock
from ..job.options import run_fingerprint


def parse_chunk(text: str | None) -> tuple[int, int] | None:
    """``A-B`` (or ``A``): the frames of one task, inclusive."""
    if text is None:
        return None
    m = re.fullmatch(r"\s*(-?\d+)\s*(?:-\s*(-?\d+))?\s*", str(text))
    if not m:
        raise ValueError(f"bad --chunk {text!r}: use A-B (frame numbers)")
    a = int(m.group(1))
    b = int(m.group(2)) if m.group(2) is not None else a
    if b < a:
        raise ValueError(f"bad --chunk {text!r}: the end is before the start")
    return a, b


def chunk_jobs(jobs, chunk):
    if chunk is None:
        return list(jobs)
    a, b = chunk
    out = [j for j in jobs if a <= j[0] <= b]
    if not out:
        raise ValueError(f"--chunk {a}-{b} holds no frame of the shot "
                         f"({jobs[0][0]}-{jobs[-1][0]})")
    return out


def frames_after(jobs, last, end=None) -> tuple[int, int] | None:
    """(first, last) of the shot's frames after ``last`` up to ``end`` (None: the
    shot's end); None when none is left."""
    left = [j[0] for j in jobs if j[0] > last and (end is None or j[0] <= end)]
    return (left[0], left[-1]) if left else None


def chunks(frames, size: int) -> list[tuple[int, int]]:
    """The shot's frames cut into runs of ``size`` frames: [(first, last)]."""
    size = max(1, int(size))
    return [(frames[i], frames[min(i + size, len(frames)) - 1])
            for i in range(0, len(frames), size)]


def shot_lock(opts, store_path: str, todo, command: str, within: str | None = None):
    """The output frames' lock of a shot's writer (``job.locks``) over the frames of
    ``todo``: shared with the other chunks of this store and settings, refused to any
    other writer; ``within``: the token of the lock whose frames this writer's are a
    part of (a Dask run's, for its apply tasks)."""
    chunk = None if not todo else (todo[0][0], todo[-1][0])
    lock = output_lock(opts.output, command, (store_path, run_fingerprint(opts)), chunk,
                       within)
    return lock if lock is not None else nullcontext()


def command_line(argv, drop=(), add=()) -> str:
    """``ocl-tonemap`` and ``argv`` quoted for a shell, without the flags (and their
    values) in ``drop``, with ``add`` after them: the command an interrupted one
    leaves to finish its work."""
    out, skip = [], False
    for x in argv:
        if skip:
            skip = False
            continue
        if x.split("=", 1)[0] in drop:
            skip = "=" not in x
            continue
        out.append(x)
    return "ocl-tonemap " + " ".join(shlex.quote(x) for x in [*out, *add])


def finish_apply(argv, jobs, last_frame, chunk=None) -> str | None:
    """The command that writes the frames an ``apply`` interrupted after
    ``last_frame`` left (its ``--chunk`` from the next frame to its end; the state
    there comes from the store: the frames of one run); None: none is left."""
    left = frames_after(jobs, last_frame, chunk[1] if chunk else None)
    if left is None:
        return None
    return command_line(argv, drop=("--chunk",), add=("--chunk", f"{left[0]}-{left[1]}"))
