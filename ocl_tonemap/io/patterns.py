"""Frame-number patterns in file names: a shot's files by frame, and ``--frames``.

Patterns follow oiiotool: a lone ``#`` is four digits of padding, ``@`` one digit
each, printf ``%04d``; a run of several ``#`` is one digit each (Nuke style, so
``####`` is also four).
"""

from __future__ import annotations

import glob
import os
import re

from ..base.quantities import MAX_FRAME, MAX_FRAMES, parse_frames  # noqa: F401 (re-exported)

_PAT = re.compile(r"(#+|@+|%0?(\d*)d)")


def is_sequence(pattern: str) -> bool:
    return bool(_PAT.search(os.path.basename(pattern)))


def without_frame_token(name: str) -> str:
    """A file name with its frame-number tokens and the separator before each
    removed (``shot.####.png`` -> ``shot.png``): names derived from a pattern."""
    return re.sub(r"[._-]?" + _PAT.pattern, "", name)


#: Frame numbers are padded to at most MAX_PAD digits (their range and a run's count:
#: ``quantities.MAX_FRAME``, ``MAX_FRAMES``; ``--frames``: ``quantities.parse_frames``).
MAX_PAD = 16


def _digits(tok: str) -> int:
    if tok[0] == "#":
        n = 4 if len(tok) == 1 else len(tok)
    elif tok[0] == "@":
        n = len(tok)
    else:
        m = re.fullmatch(r"%0?(\d*)d", tok)
        n = int(m.group(1)) if m and m.group(1) and len(m.group(1)) < 6 else \
            (MAX_PAD + 1 if m and m.group(1) else 0)
    if n > MAX_PAD:
        raise ValueError(f"frame pattern {tok[:12]!r}: at most {MAX_PAD} digits of padding")
    return n


def frame_path(pattern: str, frame: int) -> str:
    """The file name of ``frame`` in ``pattern`` (every token is replaced)."""
    def rep(m):
        n = _digits(m.group(0))
        s = f"{abs(frame):0{n}d}" if n else str(abs(frame))
        return ("-" if frame < 0 else "") + s
    d, b = os.path.split(pattern)
    return os.path.join(d, _PAT.sub(rep, b))


def find_frames(pattern: str) -> list[int]:
    """Frame numbers of the files on disk that match ``pattern``."""
    d, b = os.path.split(pattern)
    parts = _PAT.split(b)
    # re.split with 2 groups yields [text, tok, sub, text, tok, sub, ...]
    rx, gl = "", ""
    i = 0
    while i < len(parts):
        if i % 3 == 0:
            rx += re.escape(parts[i])
            gl += glob.escape(parts[i])
            i += 1
        else:
            n = _digits(parts[i])
            rx += r"(-?\d{%d,})" % max(n, 1) if n else r"(-?\d+)"
            gl += "*"
            i += 2
    rxc = re.compile(rx + r"\Z")
    frames = set()
    for p in glob.glob(os.path.join(glob.escape(d) if d else "", gl)):
        m = rxc.match(os.path.basename(p))
        if m:
            frames.add(int(m.group(1)))
    return sorted(frames)


def same_file(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.abspath(a) == os.path.abspath(b)
