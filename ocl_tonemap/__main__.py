"""``python -m ocl_tonemap`` and the ``ocl-tonemap`` command (``entry``): the command
line with its signals handled from the first moment (``base/interrupts.py``): SIGINT
exits 130, SIGTERM 143, in one line, never a traceback."""

import os
import sys

from .base.interrupts import Terminated, enable_watchdog, exit_code, ignore_for_exit, install, ready


def _leave(code: int) -> None:
    """End an interrupted run at once: its files are closed and its temporaries
    removed by now; the interpreter's own shutdown would run the finalizers of
    whatever the signal cut short (a cache half made prints a traceback) and may
    re-raise the signal (exit -2 instead of 130)."""
    release_locks()
    for f in (sys.stdout, sys.stderr):
        try:
            f.flush()
        except Exception:  # noqa: BLE001
            pass
    os._exit(code)


def release_locks() -> None:
    """The run locks a signal kept ``RunLock.__exit__`` from releasing (none when no
    run was loaded)."""
    ck = sys.modules.get("ocl_tonemap.job.checkpoint")
    if ck is not None:
        ck.release_held()


#: The command's allocations of at least this many bytes are mapped from the system
#: on their own (glibc's M_MMAP_THRESHOLD), and go back to it when freed; smaller
#: ones come from the heap, which keeps up to M_TRIM_THRESHOLD free at its top.
MMAP_THRESHOLD = 16 << 20
TRIM_THRESHOLD = 64 << 20


def _malloc_for_frames() -> None:
    """glibc's allocator set for a run of frames, in the command's own process only
    (the library leaves its host's allocator alone).

    - Blocks of a frame's size (16 MiB and more: a 1080p float32 frame is 24 MiB) are
      mapped on their own and go back to the system when freed. glibc's default
      raises its mmap threshold to the largest block freed (up to 32 MiB), so after
      the first frame such blocks came from the heap and what was freed there stayed
      in the process: a 60-frame 1080p sequence peaked ~75 MiB higher (468 against
      393 MiB, issue 33's bound 395). Frames read whole reuse their own arrays
      (``imageio.FramePool``), so they fault their pages in once.
    - Smaller blocks (OIIO's read bands, encoded outputs, the flare's scratch on a CPU
      driver) come from the heap and stay there when freed, up to 64 MiB: with a 2 MiB
      threshold each was mapped and zeroed afresh every frame (a 60-frame sequence:
      ~1.5 s of system time against ~0.45 s, and 10-20% slower).

    A user's ``MALLOC_MMAP_THRESHOLD_`` or ``MALLOC_TRIM_THRESHOLD_`` wins; other C
    libraries (no ``mallopt``) are left as they are."""
    try:
        import ctypes
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3           # <malloc.h>
    for env, param, value in (("MALLOC_MMAP_THRESHOLD_", M_MMAP_THRESHOLD, MMAP_THRESHOLD),
                              ("MALLOC_TRIM_THRESHOLD_", M_TRIM_THRESHOLD, TRIM_THRESHOLD)):
        if not os.environ.get(env):
            mallopt(ctypes.c_int(param), ctypes.c_int(value))


def _one_blas_thread() -> None:
    """NumPy's BLAS on one thread in the command's process (a user's
    ``OPENBLAS_NUM_THREADS`` or ``OMP_NUM_THREADS`` wins): the command's BLAS calls are
    3 x 3 colour matrices on frame-sized arrays, and the cores are already busy with
    the OpenCL device and the frame reader and writer; OpenBLAS's threads spun between
    those calls (1.5% of a 1080p sequence's CPU on 2 cores, perf). Set before NumPy is
    first imported, when it is read."""
    if "numpy" in sys.modules or any(os.environ.get(v) for v in
                                     ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")):
        return
    os.environ["OPENBLAS_NUM_THREADS"] = "1"


def _entry() -> int:
    try:
        # every wait ends within a second of a signal; a library call holding the
        # interpreter within 1.5 s, by the watchdog process forked here, first thing
        enable_watchdog(backstop=True)
        install()
        ready("handlers")
        _malloc_for_frames()
        _one_blas_thread()
        from .cli.table import main             # lazy: after the handlers and the BLAS setting
        code = main()
    except BaseException as exc:          # noqa: BLE001 - only the two signals end here
        if not isinstance(exc, (KeyboardInterrupt, Terminated)):
            raise
        print("ocl-tonemap: interrupted" if isinstance(exc, KeyboardInterrupt)
              else "ocl-tonemap: terminated", file=sys.stderr)
        code = exit_code(exc)
    if code in (130, 143):
        _leave(code)
    ignore_for_exit()                     # done: a signal now would only cut the exit short
    release_locks()
    return code


def entry() -> int:
    """The command, and a signal landing between its own handlers (as it returns, or
    while an interrupted one reports): it leaves at once with 128 + the signal, no
    traceback."""
    try:
        return _entry()
    except BaseException as exc:          # noqa: BLE001
        name = type(exc).__name__
        if name not in ("KeyboardInterrupt", "Terminated"):
            raise
        _leave(getattr(exc, "signum", 2) + 128)
        raise                             # (not reached)


if __name__ == "__main__":
    raise SystemExit(entry())
