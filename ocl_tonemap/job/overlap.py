"""Read-ahead and write-behind on a pool of threads (``--threads N``, oiiotool's name):
frames are decoded ahead and encoded and written behind while the device works, OIIO
and OCIO releasing Python's lock as they go.

Of the N threads, ``ahead = max(1, N // 2)`` read the next frames and the rest
(``behind``) encode and write the last ones, so at most N frames are in flight beside
the one being mapped and its output: (2 + N) frames' memory (N = 2: the next frame
read, the last one written, as before ``--threads``). Outputs may finish in any
order; what follows each write (its checkpoint) runs in frame order on one thread of
its own, and not at all after an earlier write failed, so a checkpoint never counts
a frame that was not written. A failure surfaces at the next write or at ``drain``."""

from __future__ import annotations

import os
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor

from ..io.imageio import FramePool


def default_threads() -> int:
    """The machine's cores (oiiotool's default)."""
    return max(1, os.cpu_count() or 1)


class FrameIO:
    """``enabled`` False (``--serial-io``): everything on the caller's thread."""

    def __init__(self, enabled: bool = True, threads: int | None = None):
        n = max(2, int(threads or default_threads()))
        self.ahead = max(1, n // 2) if enabled else 0
        self.behind = max(1, n - self.ahead) if enabled else 0
        self._r = ThreadPoolExecutor(self.ahead, "ocltm-read") if enabled else None
        self._w = ThreadPoolExecutor(self.behind, "ocltm-write") if enabled else None
        self._after = ThreadPoolExecutor(1, "ocltm-after") if enabled else None
        self._reads: dict = {}
        self._writes: deque = deque()
        self._failed = threading.Event()
        # frames read whole, into memory used before: those read ahead, the one
        # mapped and one more the caller may still hold
        self.pool = FramePool(keep=self.ahead + 3)

    def prefetch(self, key, fn) -> None:
        if self._r is not None and key not in self._reads:
            self._reads[key] = self._r.submit(fn)

    def read_done(self, key):
        """A function saying whether the read of ``key`` is done (or was never
        submitted). It holds no reference to the read: a frame is pooled memory that
        only the frame's own turn may keep (``FramePool``)."""
        reads = self._reads

        def done() -> bool:
            fut = reads.get(key)
            return fut is None or fut.done()
        return done

    def read(self, key, fn):
        fut = self._reads.pop(key, None)
        return fn() if fut is None else fut.result()

    def write(self, fn, after) -> None:
        """Run ``fn`` (None: nothing to write) on a writer thread and then ``after``, in
        frame order, behind the caller; at most ``behind`` writes in flight."""
        if fn is None or self._w is None:
            self.drain()
            if fn is not None:
                fn()
            after()
            return
        while len(self._writes) >= self.behind:
            self._writes.popleft().result()
        wrote = self._w.submit(fn)

        def then():
            if self._failed.is_set():
                return                        # an earlier frame failed: no checkpoint past it
            try:
                wrote.result()
            except BaseException:
                self._failed.set()
                raise
            after()
        self._writes.append(self._after.submit(then))

    def drain(self) -> None:
        """Wait for every write in flight and what follows it; the first failure raised."""
        while self._writes:
            self._writes.popleft().result()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for fut in self._reads.values():
            fut.cancel()
        self._reads.clear()
        for ex in (self._r, self._w, self._after):
            if ex is not None:
                ex.shutdown(wait=True)      # a write in flight completes (renamed whole)
        return False
