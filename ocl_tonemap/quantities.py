"""Numbers a user gives, each declared once: what it is, its unit and its range.

A :class:`Quantity` checks a value the same way wherever it comes in (a flag's
parser, the API, a calculator), says its range in the help and in one error line,
and warns where a value is accepted but lies beyond the data a model was fitted
to (the extrapolation named). The visibility's inputs (``visibility.INPUTS``) and
the observer's age are declared with it; the other inputs keep their own checks
for now (issue 58 brings them here).
"""

from __future__ import annotations

import argparse
import logging
import math
from dataclasses import dataclass

log = logging.getLogger("ocl_tonemap")


def _num(v: float) -> str:
    return f"{v:g}"


@dataclass(frozen=True)
class Quantity:
    """One input: ``what`` it is, its ``unit``, the accepted range ``lo``..``hi``
    (``above``: lo itself excluded), with 0 (``zero``) or +inf (``inf``) accepted
    besides, and the range of the data its model was fitted to (``data``; outside,
    a warning naming ``data_note``)."""

    what: str
    unit: str = ""
    lo: float = -math.inf
    hi: float = math.inf
    above: bool = False
    zero: bool = False
    inf: bool = False
    data: tuple[float, float] | None = None
    data_note: str = ""

    def range_text(self) -> str:
        """The accepted values as the help and the errors say them, e.g.
        ``1e-06..1e+08 cd/m^2`` or ``> 0 and at most 100``."""
        u = f" {self.unit}" if self.unit else ""
        if self.above and math.isinf(self.hi):
            text = f"> {_num(self.lo)}{u}"
        elif self.above:
            text = f"> {_num(self.lo)} and at most {_num(self.hi)}{u}"
        elif math.isinf(self.hi):
            text = f">= {_num(self.lo)}{u}"
        else:
            text = f"{_num(self.lo)}..{_num(self.hi)}{u}"
        extra = [w for w, ok in (("0", self.zero), ("inf", self.inf)) if ok]
        return text + (f" (or {' or '.join(extra)})" if extra else "")

    def accepts(self, v: float) -> bool:
        if math.isnan(v):
            return False
        if (self.zero and v == 0.0) or (self.inf and v == math.inf):
            return True
        if not math.isfinite(v) or v > self.hi:
            return False
        return v > self.lo if self.above else v >= self.lo

    def check(self, v, flag: str) -> float:
        """``v`` as a float, or ValueError in one line naming ``flag``, the quantity
        and its range (:meth:`warn_beyond_data` says where the model extrapolates)."""
        x, why = self._parse(v)
        if why:
            raise ValueError(f"{flag} {why}")
        return x

    def _parse(self, v) -> tuple[float, str]:
        """(value, "") or (nan, why it is refused: "must be ...")."""
        try:
            x = float(v)
        except (TypeError, ValueError):
            return math.nan, (f"must be a number, {self.range_text()}: the {self.what} "
                              f"(got {v!r})")
        if not self.accepts(x):
            return x, f"must be {self.range_text()}: the {self.what} (got {_num(x)})"
        return x, ""

    def warn_beyond_data(self, x: float, flag: str) -> None:
        """One warning where an accepted ``x`` lies beyond the model's data."""
        if self.data is None or (self.zero and x == 0.0):
            return
        lo, hi = self.data
        if not lo <= x <= hi:
            log.warning("%s %s%s is beyond %s (%s..%s%s): extrapolated", flag, _num(x),
                        f" {self.unit}" if self.unit else "", self.data_note, _num(lo),
                        _num(hi), f" {self.unit}" if self.unit else "")

    def arg(self, flag: str):
        """An argparse ``type`` that parses and checks the flag's text (an error is
        argparse's one line, exit 2)."""
        def parse(text: str) -> float:
            x, why = self._parse(text)
            if why:                       # (argparse names the flag: "argument --k: ...")
                raise argparse.ArgumentTypeError(why)
            return x
        parse.__name__ = self.what
        return parse


#: Luminances a user gives for a scene or an observer, cd/m^2 (``calibration``'s
#: ADAPT_LUMINANCE: starlight ~1e-4 to beyond any sunlit surface).
LUMINANCE_RANGE = (1e-6, 1e8)
#: Durations a user gives, s (115 days).
SECONDS_MAX = 1e7

#: The observer's age (the flare's pupil and glare, the lens, Adrian's AF).
AGE = Quantity("observer's age", "years", 1.0, 100.0, data=(23.0, 75.0),
               data_note="the ages of Adrian's age factor")

#: The visibility's default target, arcmin (RP-8's small target is 7.5 at 83 m).
TARGET_ARCMIN = 10.0
#: The observer's look, s, wherever none is given (the calculator's ``--time``, the
#: run's ``--observation-time``): RP-8's 0.2 s fixation of a driver.
OBSERVATION_S = 0.2

_LO, _HI = LUMINANCE_RANGE
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
