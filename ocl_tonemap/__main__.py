"""``python -m ocl_tonemap`` and the ``ocl-tonemap`` command (``entry``): the command
line with its signals handled from the first moment (``interrupts.py``): SIGINT
exits 130, SIGTERM 143, in one line, never a traceback."""

import os
import sys


def _leave(code: int) -> None:
    """End an interrupted run at once: its files are closed and its temporaries
    removed by now; the interpreter's own shutdown would run the finalizers of
    whatever the signal cut short (a cache half made prints a traceback) and may
    re-raise the signal (exit -2 instead of 130)."""
    for f in (sys.stdout, sys.stderr):
        try:
            f.flush()
        except Exception:  # noqa: BLE001
            pass
    os._exit(code)


def entry() -> int:
    try:
        from .interrupts import install
        install()
        from .cli import main
        code = main()
    except BaseException as exc:          # noqa: BLE001 - only the two signals end here
        from .interrupts import Terminated, exit_code
        if not isinstance(exc, (KeyboardInterrupt, Terminated)):
            raise
        print("ocl-tonemap: interrupted" if isinstance(exc, KeyboardInterrupt)
              else "ocl-tonemap: terminated", file=sys.stderr)
        code = exit_code(exc)
    if code in (130, 143):
        _leave(code)
    import signal                         # done: a signal now would only cut the exit short
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    return code


if __name__ == "__main__":
    raise SystemExit(entry())
