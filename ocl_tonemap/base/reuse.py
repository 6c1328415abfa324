"""Arrays used again once nothing else refers to them: the rule of the run's frame
pool (``imageio.FramePool``) and of a GPU's page-locked host arrays
(``backends/opencl/pinned.py``), kept in one place.

An array is free when the pool's own list is its only holder (CPython's reference
count, which views and buffer exports raise through their ``base``); at most ``keep``
arrays are kept, and a free one of another size makes room for a new one.
"""

from __future__ import annotations

import sys
import threading

import numpy as np


def _free(arrs: list, i: int) -> bool:
    """Whether the list's own reference is the only one (getrefcount adds its argument's)."""
    return sys.getrefcount(arrs[i]) <= 2


class Reused:
    """The pool of one kind of array: :meth:`_take` gives a kept array that ``fits`` and
    nothing holds, else a new one from ``make()`` (kept while there is room)."""

    def __init__(self, keep: int = 4):
        self.keep = int(keep)
        self._arrays: list[np.ndarray] = []
        self._lock = threading.Lock()
        self.made = 0                          # arrays allocated (fresh memory)

    def _take(self, fits, make) -> np.ndarray:
        with self._lock:
            arrs = self._arrays                # (by index: a name bound to an array
            for i in range(len(arrs)):         # would count as a reference to it)
                if fits(arrs[i]) and _free(arrs, i):
                    return arrs[i]
            if len(arrs) >= self.keep:         # free arrays of another size make room
                self._arrays = arrs = [arrs[i] for i in range(len(arrs))
                                       if fits(arrs[i]) or not _free(arrs, i)]
            out = make()
            self.made += 1
            if len(arrs) < self.keep:
                arrs.append(out)
            return out

    def clear(self) -> None:
        with self._lock:
            self._arrays.clear()
