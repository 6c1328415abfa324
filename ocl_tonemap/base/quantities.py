"""Inputs a user gives, each declared once: what it is, its unit and its range.

A declaration checks a value the same way wherever it comes in (a flag's parser, the
API, a state file, a calculator), says its range in the help, in ``docs/cli.md`` and
in one error line, and warns where a value is accepted but lies beyond the data a
model was fitted to (the extrapolation named). Three kinds:

* :class:`Quantity`: one number (a unit, a range, integers only where it counts);
* :class:`Numbers`: comma-separated numbers, each place its own quantity
  (``--blue-shift R,G,B``, ``--target X,Y,SIZE``) or any count of one;
* :class:`Text`: a value with a syntax of its own (``--preadapt CD_M2[:SECONDS]``,
  ``--size WxH``), parsed by a function that says what is wrong in the same words.

Each has ``check(value, flag)`` (the value, or ValueError: one line naming the flag,
its range and what was given), ``arg(flag)`` (an argparse ``type`` doing the same;
the parser prints argparse's one line, exit 2) and ``range_text()`` (the help's and
the docs' words). No number is NaN or infinite unless its declaration allows it.

The run's options are declared here (:data:`RUN`, by their ``JobOptions`` field),
the operators' and the effects' with their options (``operators/``, ``effects/``),
the visibility's in :data:`VISIBILITY`, the sample's in :data:`SAMPLE`.
"""

from __future__ import annotations

import argparse
import logging
import math
import re
from dataclasses import dataclass
from typing import Any, Callable

log = logging.getLogger("ocl_tonemap")


def _num(v: float, integer: bool = False) -> str:
    """A number as the help and the errors write it: whole numbers below 1e7 in full."""
    if math.isfinite(v) and v == int(v) and (integer or abs(v) < 1e7):
        return str(int(v))
    return f"{v:g}"


class _Declared:
    """What the kinds share: ``check``, ``arg`` and the help's words."""

    what: str

    def _parse(self, v) -> tuple[Any, str]:           # (value, "") or (None, why)
        raise NotImplementedError

    def range_text(self) -> str:
        raise NotImplementedError

    def check(self, v, flag: str):
        """``v`` (text or a value) checked: the value, or ValueError in one line naming
        ``flag``, what is accepted and what was given."""
        x, why = self._parse(v)
        if why:       # (a syntax's own parser may name the flag itself)
            raise ValueError(why if why.startswith(flag) else f"{flag} {why}")
        return x

    def arg(self, flag: str):
        """An argparse ``type`` that parses and checks the flag's text (an error is
        argparse's one line naming the flag, exit 2)."""
        def parse(text: str):
            x, why = self._parse(text)
            if why:
                raise argparse.ArgumentTypeError(why)
            return x
        parse.__name__ = self.what
        parse.declared = self             # (docs/cli.md, the property test)
        return parse

    def help(self, text: str) -> str:
        """A flag's help (argparse's: ``%`` written ``%%``): ``text`` and the accepted
        values."""
        return f"{text}; {self.range_text().replace('%', '%%')}"


@dataclass(frozen=True)
class Quantity(_Declared):
    """One number: ``what`` it is, its ``unit``, the accepted range ``lo``..``hi``
    (``above``: lo itself excluded), with 0 (``zero``) or +inf (``inf``) accepted
    besides, ``integer`` where only whole numbers mean something, and the range of
    the data its model was fitted to (``data``; outside, a warning naming
    ``data_note``)."""

    what: str
    unit: str = ""
    lo: float = -math.inf
    hi: float = math.inf
    above: bool = False
    zero: bool = False
    inf: bool = False
    data: tuple[float, float] | None = None
    data_note: str = ""
    integer: bool = False

    def range_text(self) -> str:
        """The accepted values as the help and the errors say them, e.g.
        ``1e-06..1e+08 cd/m^2`` or ``> 0 and at most 100``."""
        u = f" {self.unit}" if self.unit else ""
        kind = "a whole number " if self.integer else ""
        lo, hi = _num(self.lo, self.integer), _num(self.hi, self.integer)
        if self.above and math.isinf(self.hi):
            text = f"{kind}> {lo}{u}"
        elif self.above:
            text = f"{kind}> {lo} and at most {hi}{u}"
        elif math.isinf(self.hi):
            text = f"{kind}>= {lo}{u}"
        else:
            text = f"{kind}{lo}..{hi}{u}"
        extra = [w for w, ok in (("0", self.zero), ("inf", self.inf)) if ok]
        return text + (f" (or {' or '.join(extra)})" if extra else "")

    def accepts(self, v: float) -> bool:
        if math.isnan(v):
            return False
        if (self.zero and v == 0.0) or (self.inf and v == math.inf):
            return True
        if not math.isfinite(v) or v > self.hi:
            return False
        if self.integer and v != int(v):
            return False
        return v > self.lo if self.above else v >= self.lo

    def _parse(self, v) -> tuple[float, str]:
        """(value, "") or (nan, why it is refused: "must be ...")."""
        if isinstance(v, bool):
            v = str(v)
        try:
            x = float(v.strip()) if isinstance(v, str) else float(v)
        except (TypeError, ValueError, OverflowError):
            return math.nan, (f"must be a number, {self.range_text()}: the {self.what} "
                              f"(got {v!r})")
        if not self.accepts(x):
            return x, f"must be {self.range_text()}: the {self.what} (got {_num(x)})"
        return (int(x) if self.integer and math.isfinite(x) else x), ""

    def warn_beyond_data(self, x: float, flag: str) -> None:
        """One warning where an accepted ``x`` lies beyond the model's data."""
        if self.data is None or (self.zero and x == 0.0):
            return
        lo, hi = self.data
        if not lo <= x <= hi:
            log.warning("%s %s%s is beyond %s (%s..%s%s): extrapolated", flag, _num(x),
                        f" {self.unit}" if self.unit else "", self.data_note, _num(lo),
                        _num(hi), f" {self.unit}" if self.unit else "")


@dataclass(frozen=True)
class Numbers(_Declared):
    """Comma-separated numbers written as ``syntax`` (``R,G,B``): ``parts``, the
    quantity of each place, or ``each``, one quantity for any count in ``count``;
    ``rule(values)``, where the places depend on each other, returns why they do not
    fit ("" when they do)."""

    what: str
    syntax: str
    parts: tuple = ()
    each: Quantity | None = None
    count: tuple[int, int] = (1, 1 << 16)
    rule: Callable | None = None

    def range_text(self) -> str:
        if self.parts:
            names = self.syntax.split(",")
            places = [f"{n} {q.range_text()}" for n, q in zip(names, self.parts)]
            if len(set(q.range_text() for q in self.parts)) == 1:
                return f"{self.syntax}, each {self.parts[0].range_text()}"
            return f"{self.syntax}: " + ", ".join(places)
        return f"{self.syntax}, each {self.each.range_text()}"

    def _parse(self, v) -> tuple[tuple, str]:
        items = [s.strip() for s in v.split(",")] if isinstance(v, str) else v
        try:
            items = list(items)
        except TypeError:
            items = [items]
        n = len(items)
        lo, hi = (len(self.parts),) * 2 if self.parts else self.count
        if not lo <= n <= hi:
            return (), f"must be {self.range_text()}: the {self.what} (got {v!r})"
        out = []
        for i, item in enumerate(items):
            q = self.parts[i] if self.parts else self.each
            x, why = q._parse(item)
            if why:
                name = self.syntax.split(",")[i] if self.parts else f"value {i + 1}"
                given = v if isinstance(v, str) else tuple(items)
                return (), (f"must be {self.range_text()}: the {self.what} (its {name} is "
                            f"{item}; got {given!r})")
            out.append(x)
        t = tuple(out)
        why = self.rule(t) if self.rule else ""
        if why:
            return (), f"must be {self.range_text()}: {why} (got {v!r})"
        return t, ""


@dataclass(frozen=True)
class Text(_Declared):
    """A value with a syntax of its own: ``parse(value)`` returns it checked or raises
    ValueError saying what is wrong without the flag (``must be ...``); ``syntax``
    is the help's and the docs' words for what is accepted."""

    what: str
    syntax: str
    parse: Callable

    def range_text(self) -> str:
        return self.syntax

    def _parse(self, v) -> tuple[Any, str]:
        try:
            return self.parse(v), ""
        except ValueError as e:
            return None, str(e)


def word_or(q: Quantity, *words: str) -> Callable:
    """A parser for ``Text``: one of ``words`` (case-insensitive) or a number of ``q``."""
    def parse(v):
        if isinstance(v, str) and v.strip().lower() in words:
            return v.strip().lower()
        x, why = q._parse(v)
        if why:
            raise ValueError(f"must be {' or '.join(words)} or {q.range_text()}: the "
                             f"{q.what} (got {v!r})")
        return x
    return parse


def seconds_text(q: Quantity) -> Callable:
    """A parser of durations: seconds (an ``s`` suffix allowed) or minutes (``m``),
    checked as ``q``."""
    def parse(v):
        if isinstance(v, str):
            t = v.strip().lower()
            try:
                x = float(t[:-1]) * 60.0 if t.endswith("m") else float(t.rstrip("s"))
            except ValueError:
                raise ValueError(f"must be seconds or minutes (30, 2m), {q.range_text()}: "
                                 f"the {q.what} (got {v!r})") from None
            v = x
        x, why = q._parse(v)
        if why:
            raise ValueError(why)
        return x
    return parse


# --- physical ranges --------------------------------------------------------------------

#: Luminances a user gives for a scene or an observer, cd/m^2 (
#: starlight ~1e-4 to beyond any sunlit surface; 0: darkness; the sun's disc is ~1e9
#: but no eye adapts to it).
LUMINANCE_RANGE = (1e-6, 1e8)
#: Durations a user gives, s (115 days).
SECONDS_MAX = 1e7
_LO, _HI = LUMINANCE_RANGE

#: The observer's age (the flare's pupil and glare, the lens, Adrian's AF).
AGE = Quantity("observer's age", "years", 1.0, 100.0, data=(23.0, 75.0),
               data_note="the ages of Adrian's age factor")

#: The visibility's default target, arcmin (RP-8's small target is 7.5 at 83 m).
TARGET_ARCMIN = 10.0
#: The observer's look, s, wherever none is given (the calculator's ``--time``, the
#: run's ``--observation-time``): RP-8's 0.2 s fixation of a driver.
OBSERVATION_S = 0.2

#: An adaptation luminance a user gives (0: darkness).
ADAPT_CD = Quantity("adaptation luminance", "cd/m^2", _LO, _HI, zero=True)
#: A duration a user gives.
DURATION_S = Quantity("duration", "s", 0.0, SECONDS_MAX)

#: Every number the visibility takes (the calculator's flags, the run's, and
#: ``visibility.Viewing.check``).
VISIBILITY = {
    "background": Quantity("background luminance L_b", "cd/m^2", _LO, _HI),
    "target": Quantity("target luminance L_t", "cd/m^2", _LO, _HI, zero=True),
    "veil": Quantity("veiling luminance", "cd/m^2", 0.0, _HI),
    "adapted_to": Quantity("luminance the eye was adapted to", "cd/m^2", _LO, _HI,
                           zero=True),
    "for": Quantity("time the eye was adapted", "s", 0.0, SECONDS_MAX, above=True),
    "after": Quantity("time after the step", "s", 0.0, SECONDS_MAX),
    "size": Quantity("target size", "arcmin", 0.1, 600.0, data=(1.0, 60.0),
                     data_note="the sizes Adrian's fits are used for"),
    "age": AGE,
    "time": Quantity("observation time", "s", 0.001, SECONDS_MAX, inf=True,
                     data=(0.01, math.inf), data_note="the looks of Adrian's time factor"),
    "k": Quantity("field factor k", "", 0.0, 100.0, above=True),
}
VISIBILITY["times_after"] = Numbers("times after the step", "T1,T2,...",
                                    each=VISIBILITY["after"], count=(1, 1000))
VISIBILITY["pixel"] = Numbers("pixel", "X,Y", parts=(
    Quantity("column", "px", 0, 1 << 20, integer=True),
    Quantity("row", "px", 0, 1 << 20, integer=True)))


# --- the run's options (by their JobOptions field) --------------------------------------

#: Largest frame edge a run or the sample makes, pixels (OIIO's and OpenCL's images
#: are addressed with 32-bit ints; 1 << 20 is far beyond any camera).
MAX_EDGE = 1 << 20
#: Decode/encode threads at most.
MAX_THREADS = 256


#: Lattice sizes of an OCIO export (``--ocio-export-size``).
EXPORT_SIZES = (17, 25, 33, 49, 65)


def _export_size(v):
    t = str(v).strip().lower()
    if t == "auto":
        return "auto"
    try:
        n = int(t)
    except ValueError:
        n = None
    if n not in EXPORT_SIZES:
        raise ValueError(f"must be auto or one of {', '.join(map(str, EXPORT_SIZES))}: nodes "
                         f"per axis of the exported LUTs (got {v!r})")
    return n


def _preadapt(v):
    """``CD_M2`` or ``CD_M2:SECONDS`` (an ``m`` suffix: minutes), or a (L, s) pair."""
    if isinstance(v, str):
        lum, _, sec = v.strip().partition(":")
    else:
        try:
            lum, sec = v
        except (TypeError, ValueError):
            raise ValueError(f"must be CD_M2 or (CD_M2, SECONDS) (got {v!r})") from None
    L, why = ADAPT_CD._parse(lum) if lum != "" else (None, "is missing")
    if why:
        raise ValueError(f"must be CD_M2 or CD_M2:SECONDS; its CD_M2 {why} (got {v!r})")
    try:
        return L, (seconds_text(DURATION_S)(sec) if sec not in ("", None) else None)
    except ValueError as e:
        raise ValueError(f"must be CD_M2 or CD_M2:SECONDS; its SECONDS {e}") from None


def _times(v):
    """``T1,T2,...``: elapsed times, seconds or minutes (``m``), 1 to 10000 of them."""
    items = [t for t in v.split(",")] if isinstance(v, str) else list(v)
    if not 1 <= len(items) <= 10_000:
        raise ValueError(f"must be 1 to 10000 times T1,T2,... (got {len(items)})")
    return [seconds_text(ELAPSED_S)(t) for t in items]


#: A time after a switch (``simulate --at``).
ELAPSED_S = Quantity("elapsed time", "s", 0.0, SECONDS_MAX)


#: Frame numbers are within +-MAX_FRAME, and a run renders at most MAX_FRAMES of them
#: (a day at 30 fps is 2.6 M; bounded so that a typo cannot take the memory or the
#: time of the machine).
MAX_FRAME = 999_999_999
MAX_FRAMES = 1_000_000


def parse_frames(text: str) -> list[int]:
    """``"1001-1100"``, ``"1-10x2"`` or ``"1,5,9-12"`` -> frame numbers."""
    out: list[int] = []
    if len(text) > 100_000:
        raise ValueError("--frames: more than 100 000 characters")
    for part in text.split(","):
        part = part.strip()
        m = re.fullmatch(r"(-?\d{1,10})(?:-(-?\d{1,10})(?:x(\d{1,10}))?)?", part)
        if not m:
            raise ValueError("--frames must be A-B, A-BxSTEP or a comma list of them (got "
                             f"{part[:80]!r})")
        a = int(m.group(1))
        b = int(m.group(2)) if m.group(2) is not None else a
        step = int(m.group(3) or 1)
        if b < a:
            every = f"x{m.group(3)}" if m.group(3) else ""
            raise ValueError(f"--frames {part}: the range is reversed (the end is before the "
                             f"start); give {b}-{a}{every}")
        if step < 1:
            raise ValueError(f"--frames {part}: the step must be 1 or more (A-BxSTEP)")
        if max(abs(a), abs(b)) > MAX_FRAME:
            raise ValueError(f"--frames {part}: frame numbers are within +-{MAX_FRAME}")
        if len(out) + (b - a) // step + 1 > MAX_FRAMES:
            raise ValueError(f"--frames {text[:80]}: more than {MAX_FRAMES} frames in one run; "
                             "split the shot")
        out.extend(range(a, b + 1, step))
    return out


def _frames(v):
    """``--frames``: ``A-B``, ``A-BxSTEP`` or a list (``parse_frames``: its errors name
    the flag and the range at fault), or the API's list of numbers."""
    if isinstance(v, str):
        return parse_frames(v)
    out = list(v)
    if not (out and len(out) <= MAX_FRAMES and all(
            isinstance(f, int) and not isinstance(f, bool) and abs(f) <= MAX_FRAME
            for f in out)):
        raise ValueError(f"must be 1 to {MAX_FRAMES} whole frame numbers within "
                         f"+-{MAX_FRAME} (got {str(v)[:60]})")
    return out


#: Named log-average scene luminances, cd/m^2 (``--luminance-scale auto:LEVEL``): an
#: 18% grey surface under the typical illuminance E (lux), L = 0.18 E / pi, rounded:
#: full moon 0.2 lx; deep civil twilight ~20 lx; a lit interior 500 lx (EN 12464
#: offices); an overcast day 10 000 lx; direct sun + sky ~90 000 lx.
NAMED_LEVELS = {"night": 0.01, "dusk": 1.0, "interior": 30.0, "overcast": 500.0,
                "daylight": 5000.0}
#: cd/m^2 of a pixel value 1.0 (``--luminance-scale S``).
SCALE_CD = Quantity("luminance of pixel value 1.0", "cd/m^2", 0.0, 1e30, above=True)
#: The first frame's log-average an ``auto`` scale puts it at.
AUTO_LEVEL = Quantity("log-average of the first frame", "cd/m^2", _LO, _HI)


def luminance_scale(v) -> tuple:
    """``--luminance-scale``: ``S`` or ``auto:LEVEL`` (cd/m^2 or a named level) ->
    (scale, auto level, its name); ValueError saying what is wrong."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return SCALE_CD.check(v, "--luminance-scale"), None, None
    t = str(v).strip()
    if t.lower().startswith("auto"):
        lvl = t.partition(":")[2].strip().lower()
        if lvl in NAMED_LEVELS:
            return None, NAMED_LEVELS[lvl], lvl
        x, why = AUTO_LEVEL._parse(lvl) if lvl else (None, "is missing")
        if why:
            raise ValueError(f"--luminance-scale auto:LEVEL: LEVEL {why}; or one of "
                             f"{', '.join(NAMED_LEVELS)}")
        return None, x, None
    return SCALE_CD.check(t, "--luminance-scale"), None, None


def _luminance_scale(v):
    luminance_scale(v)
    return v if isinstance(v, str) else float(v)


#: name -> declaration of every number and syntax the run takes (``cli/options.py``
#: makes the flags from them, ``JobOptions`` checks the API's values with them).
RUN = {
    "fps": Quantity("frame rate", "frames/s", 0.0, 1e6, above=True),
    "exposure": Quantity("exposure", "EV", -100.0, 100.0),
    "luminance_scale": Text(
        "luminance scale", "S (cd/m^2 of 1.0: > 0 and below 1e+30) or auto:LEVEL (LEVEL "
        "1e-06..1e+08 cd/m^2, or night, dusk, interior, overcast, daylight)", _luminance_scale),
    "preadapt": Text("pre-adaptation", "CD_M2 (0 or 1e-06..1e+08 cd/m^2; fully adapted) or "
                     "CD_M2:SECONDS (0..1e+07 s, an m suffix: minutes; exposed that long from "
                     "dark)", _preadapt),
    "display_white": Quantity("display white", "cd/m^2", 1.0, 10000.0),
    "display_peak": Quantity("HDR display peak", "cd/m^2", 1.0, 10000.0),
    "display_black": Quantity("display black", "cd/m^2", 0.0, 1000.0, above=True),
    "png_level": Quantity("PNG zlib level", "", 0, 9, integer=True),
    "plot_frames": Numbers("frames of the mapping curves", "I1,I2,...",
                           each=Quantity("frame index", "", 0, 1 << 24, integer=True),
                           count=(1, 64)),
    "ocio_export_size": Text("LUT lattice", "auto, 17, 25, 33, 49 or 65", _export_size),
    "checkpoint_every": Quantity("checkpoint interval", "frames", 1, 1 << 24, integer=True),
    "max_memory": Quantity("host memory budget", "MiB", 8.0, 1e9),
    "threads": Quantity("I/O threads", "", 1, MAX_THREADS, integer=True),
    "max_band_pixels": Quantity("band size", "pixels", 1, float(1 << 40), integer=True),
    "workers": Quantity("local Dask workers", "", 1, 256, integer=True),
    "chunk_frames": Quantity("frames per task", "", 1, 1 << 24, integer=True),
    "keyframe_every": Quantity("keyframe interval", "frames", 1, 1 << 24, integer=True),
}
RUN["frames"] = Text("frames", "A-B, A-BxSTEP or a comma list of them (frame numbers "
                     "within +-999999999, at most 1000000 frames)", _frames)
RUN["at"] = Text("elapsed times", f"T1,T2,... each {ELAPSED_S.range_text()} (an m "
                 "suffix: minutes)", _times)
RUN["target"] = Numbers("target", "X,Y,SIZE", parts=(
    Quantity("column", "px", 0.0, float(MAX_EDGE)),
    Quantity("row", "px", 0.0, float(MAX_EDGE)), VISIBILITY["size"]))
RUN["target_size"] = VISIBILITY["size"]
RUN["observation_time"] = VISIBILITY["time"]


# --- the sample (``ocl-tonemap sample``, ``demo``) -------------------------------------

def _size(v):
    """``WxH``, each 1..MAX_EDGE pixels."""
    m = re.fullmatch(r"\s*(\d{1,9})\s*[xX]\s*(\d{1,9})\s*", str(v))
    if not m:
        raise ValueError(f"must be WxH, whole numbers of pixels 1..{MAX_EDGE} (e.g. 320x180; "
                         f"got {v!r})")
    w, h = int(m.group(1)), int(m.group(2))
    if not (1 <= w <= MAX_EDGE and 1 <= h <= MAX_EDGE):
        raise ValueError(f"must be WxH, each 1..{MAX_EDGE} pixels (got {v!r})")
    return w, h


SAMPLE = {
    "size": Text("frame size", f"WxH pixels, each 1..{MAX_EDGE}", _size),
    "seconds": Quantity("length of the drive", "s", 0.0, 3600.0, above=True),
    "fps": Quantity("frame rate", "frames/s", 0.0, 1000.0, above=True),
}
