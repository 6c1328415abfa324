"""Shared by the benchmark scripts: the timing rule, Markdown tables, the device's copy
bandwidth and the peak memory of a child process."""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import time

import numpy as np


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


def copy_bandwidth(rt, nbytes) -> float:
    """Buffer-to-buffer copy bandwidth of the runtime's device, bytes/s (read + write)."""
    import pyopencl as cl
    a = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE, nbytes)
    b = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE, nbytes)
    cl.enqueue_fill_buffer(rt.queue, a, np.float32(1), 0, nbytes)

    def go():
        cl.enqueue_copy(rt.queue, b, a)
        rt.queue.finish()
    t = timeit(go, 5)
    return 2 * nbytes / t  # read + write


_PEAK_CODE = (
    "import json, resource, subprocess, sys, time; cmd = json.loads(sys.argv[1]); "
    "shell = isinstance(cmd, str); t = time.perf_counter(); "
    "r = subprocess.run(cmd, shell=shell, executable='/bin/bash' if shell else None, "
    "capture_output=True); "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024, "
    "time.perf_counter() - t, r.returncode)")


def child_peak(cmd, env=None, cwd=None) -> tuple[float | None, float | None, int | None]:
    """(peak resident set MiB, wall seconds, exit status) of one run of ``cmd`` (an argument
    list, or a shell line run by bash: then the peak of its largest process), read from a
    wrapper process's ``RUSAGE_CHILDREN`` after it exits; (None, None, None) when the
    wrapper itself fails."""
    cmd = cmd if isinstance(cmd, str) else [str(c) for c in cmd]
    p = subprocess.run([sys.executable, "-c", _PEAK_CODE, json.dumps(cmd)], env=env, cwd=cwd,
                       capture_output=True, text=True)
    try:
        rss, sec, rc = p.stdout.split()[-3:]
        return float(rss), float(sec), int(rc)
    except ValueError:
        return None, None, None
