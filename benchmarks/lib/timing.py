"""Shared by the benchmark scripts: the timing rule."""

from __future__ import annotations

import statistics
import time


def timeit(fn, reps: int) -> float:
    """Median wall time of ``reps`` calls after one warm-up call, seconds."""
    fn()
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def table(head, rows) -> str:
    """A Markdown table."""
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(out + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])
