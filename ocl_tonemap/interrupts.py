"""Signals of the command line: SIGINT raises KeyboardInterrupt (exit 130), SIGTERM
:class:`Terminated` (exit 143), from the first moment of ``main`` and never the
system's default (which would kill the process in the middle of a write). A run
(``job/run.py``) turns the first one into "stop after this frame"."""

from __future__ import annotations

import signal


class Terminated(BaseException):
    """SIGTERM, or a second signal during a run: stop now; exit 128 + ``signum``."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = int(signum)


def _terminate(signum, frame):
    raise Terminated(signum)


def install() -> None:
    """SIGTERM -> :class:`Terminated` (SIGINT is Python's KeyboardInterrupt already)."""
    try:
        signal.signal(signal.SIGTERM, _terminate)
        if signal.getsignal(signal.SIGINT) in (signal.SIG_DFL, signal.SIG_IGN, None):
            signal.signal(signal.SIGINT, signal.default_int_handler)
    except ValueError:               # not the main thread (an embedding): leave them be
        pass


def exit_code(exc: BaseException) -> int:
    return 128 + exc.signum if isinstance(exc, Terminated) else 130
