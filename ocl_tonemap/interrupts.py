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


#: The signal received, if any (0: none): an interrupt that a library turned into its
#: own error (a C extension's import fails with "initialization failed") is still
#: an interrupt.
received = 0


def _terminate(signum, frame):
    global received
    received = signum
    raise Terminated(signum)


def _interrupt(signum, frame):
    global received
    received = signum
    raise KeyboardInterrupt


def _unraisable(info) -> None:
    """A finalizer's error (``Exception ignored in ...``: a library object that a
    signal cut short while it was made, then collected): logged (``-vv``), not printed
    as a traceback."""
    import logging
    logging.getLogger("ocl_tonemap").debug("ignored in %r: %r", info.object, info.exc_value)


def install() -> None:
    """SIGINT -> KeyboardInterrupt, SIGTERM -> :class:`Terminated`, each remembered in
    :data:`received`; finalizers' errors to the log (the command line only)."""
    import sys
    sys.unraisablehook = _unraisable
    try:
        signal.signal(signal.SIGTERM, _terminate)
        if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
            signal.signal(signal.SIGINT, _interrupt)
    except ValueError:               # not the main thread (an embedding): leave them be
        pass


def exit_code(exc: BaseException | None = None) -> int:
    """128 + the signal: of ``exc``, else the one :data:`received`."""
    if isinstance(exc, Terminated):
        return 128 + exc.signum
    if isinstance(exc, KeyboardInterrupt) or not received:
        return 130
    return 128 + received


def ignore_for_exit() -> None:
    """SIGINT and SIGTERM ignored from now on (a command whose work is done: a signal
    would only cut its exit short). One landing while they are set is dropped too."""
    for _ in range(3):
        try:
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, signal.SIG_IGN)
            return
        except (KeyboardInterrupt, Terminated):
            continue


#: A test hook: where the command notes how far it got (``ready``), so that a test
#: can send its signal at a known point instead of after a guessed delay.
READY_ENV = "OCLTM_TEST_READY"


def ready(what: str) -> None:
    """Append ``what`` as a line to the file named by ``$OCLTM_TEST_READY`` (nothing
    when it is not set): ``handlers`` once the signal handlers are in, ``written N``
    once frame N's output and checkpoint are on disk."""
    import os
    path = os.environ.get(READY_ENV)
    if not path:
        return
    try:
        with open(path, "a", encoding="utf-8") as f:
            f.write(what + "\n")
    except OSError:
        pass
