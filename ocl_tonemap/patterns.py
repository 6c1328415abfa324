"""Frame-number patterns in file names: a shot's files by frame, and ``--frames``.

Patterns follow oiiotool: a lone ``#`` is four digits of padding, ``@`` one digit
each, printf ``%04d``; a run of several ``#`` is one digit each (Nuke style, so
``####`` is also four).
"""

from __future__ import annotations

import glob
import os
import re

_PAT = re.compile(r"(#+|@+|%0?(\d*)d)")


def is_sequence(pattern: str) -> bool:
    return bool(_PAT.search(os.path.basename(pattern)))


def without_frame_token(name: str) -> str:
    """A file name with its frame-number tokens and the separator before each
    removed (``shot.####.png`` -> ``shot.png``): names derived from a pattern."""
    return re.sub(r"[._-]?" + _PAT.pattern, "", name)


#: Frame numbers are within +-MAX_FRAME, padded to at most MAX_PAD digits, and a
#: run renders at most MAX_FRAMES of them (a day at 30 fps is 2.6 M; bounded so
#: that a typo cannot take the memory or the time of the machine).
MAX_FRAME = 999_999_999
MAX_PAD = 16
MAX_FRAMES = 1_000_000


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


def parse_frames(text: str) -> list[int]:
    """``"1001-1100"``, ``"1-10x2"`` or ``"1,5,9-12"`` -> frame numbers."""
    out: list[int] = []
    if len(text) > 100_000:
        raise ValueError("--frames: more than 100 000 characters")
    for part in text.split(","):
        part = part.strip()
        m = re.fullmatch(r"(-?\d{1,10})(?:-(-?\d{1,10})(?:x(\d{1,10}))?)?", part)
        if not m:
            raise ValueError(f"bad --frames {text[:80]!r} (use A-B, A-BxSTEP or a comma list)")
        a = int(m.group(1))
        b = int(m.group(2)) if m.group(2) is not None else a
        step = int(m.group(3) or 1)
        if b < a or step < 1:
            raise ValueError(f"bad --frames range {part!r}")
        if max(abs(a), abs(b)) > MAX_FRAME:
            raise ValueError(f"--frames {part}: frame numbers are within +-{MAX_FRAME}")
        if len(out) + (b - a) // step + 1 > MAX_FRAMES:
            raise ValueError(f"--frames {text[:80]}: more than {MAX_FRAMES} frames in one run; "
                             "split the shot")
        out.extend(range(a, b + 1, step))
    return out


def same_file(a: str, b: str) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.abspath(a) == os.path.abspath(b)
