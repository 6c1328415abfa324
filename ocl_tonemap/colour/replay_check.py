"""The OCIO export's self-check (``export.py``): each frame's view replayed as a replay
does it -- OCIO's own processor on the written config, from the colour space the
frame's file is in -- over the frame's own pixels, against the run's own
display-encoded output of that frame (issue 67).

Up to :data:`CHECK_PIXELS` pixels every pixel of the frame is checked; a larger
frame is checked on every pixel of an evenly strided subsample of at most that many
(the lattices' extents cover every pixel whatever the size: ``lattice.extreme_rows``).
"""

from __future__ import annotations

import numpy as np

#: At most this many pixels of a frame are replayed for its check (every pixel of
#: frames up to this size: 2048 x 2048, UHD at every second pixel).
CHECK_PIXELS = 1 << 22
#: Rows replayed at a time (bounded memory).
CHUNK = 1 << 20


def check_step(n: int, limit: int = CHECK_PIXELS) -> int:
    """The stride of the rows checked of a frame of ``n`` pixels (1: every pixel)."""
    return max(1, -(-int(n) // int(limit)))


def rgb_rows(pixels, step: int = 1) -> np.ndarray:
    """Every ``step``-th pixel's RGB of ``pixels`` (H x W x C or N x C), (M, 3)."""
    a = np.asarray(pixels)
    return a.reshape(-1, a.shape[-1])[::step, :3]


def as_codes(output) -> np.ndarray:
    """Code values in [0, 1] (float32) of ``output``: float code values as they are,
    integer ones (an 8- or 16-bit output quantised where it was encoded) over their
    type's largest value."""
    a = np.asarray(output)
    if np.issubdtype(a.dtype, np.integer):
        return (a.astype(np.float64) / np.iinfo(a.dtype).max).astype(np.float32)
    return np.asarray(a, np.float32)


def apply_cpu(cpu, rgb: np.ndarray) -> np.ndarray:
    """(N, 3) ``rgb`` through an OCIO CPU processor, float32, :data:`CHUNK` rows at a time."""
    out = np.array(rgb, np.float32, order="C").reshape(-1, 3)
    for i in range(0, out.shape[0], CHUNK):
        part = np.ascontiguousarray(out[i:i + CHUNK])
        cpu.applyRGB(part)
        out[i:i + CHUNK] = part
    return out


def file_errors(got: np.ndarray, ref: np.ndarray) -> dict:
    """What an 8-bit replay (``oiiotool ... -d uint8``) shows against an 8-bit rendering:
    both clipped to [0, 1] and rounded to 8-bit codes, the difference's 99th percentile
    and maximum (whole codes)."""
    q = lambda x: np.rint(np.clip(x, 0.0, 1.0) * 255.0)      # noqa: E731
    d = np.abs(q(got) - q(ref)).reshape(-1)
    if not d.size:
        return {"files_p99_8bit": 0.0, "files_max_8bit": 0.0}
    return {"files_p99_8bit": float(np.percentile(d, 99)), "files_max_8bit": float(d.max())}


def frames_text(frames) -> str:
    """Frame numbers as runs: ``1-3, 5, 8-9``."""
    nums = sorted(int(f) for f in frames)
    runs: list = []
    for f in nums:
        if runs and f == runs[-1][1] + 1:
            runs[-1][1] = f
        else:
            runs.append([f, f])
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)


def lattices_text(frames: dict) -> str:
    """Which frames used which lattice (``report.json``'s frames): ``65^3 frames 1-3,
    33^3 frame 4``, in the order of their first frames."""
    by: dict = {}
    for f, rec in frames.items():
        by.setdefault(rec.get("lattice"), []).append(int(f))
    parts = sorted(by.items(), key=lambda kv: min(kv[1]))
    return ", ".join(f"{size}^3 frame{'s' if len(fs) > 1 else ''} {frames_text(fs)}"
                     for size, fs in parts)
