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


#: Seconds a signal gives the command to end on its own (the frame in flight
#: finished or discarded, its locks released) before :func:`arm`'s watchdog ends the
#: process itself: a wait the signal cannot cut short (a thread stuck in a C call
#: that the main thread waits for, a pool's shutdown joining it) ends all the same.
GRACE_S = 1.0

#: The watchdog is the command's own (``__main__``: :func:`enable_watchdog`), never
#: a host's that embeds the library or runs ``cli.main`` in its own process.
_watchdog = False
_armed = False

#: What the watchdog says after "interrupted" (a run sets it: where its state is).
checkpoint: str | None = None
#: Folders where this process writes temporary files (a run's outputs and state):
#: the watchdog removes its own (``.NAME.tmp<pid>EXT``) before it leaves.
temp_folders: set = set()


def enable_watchdog(on: bool = True) -> None:
    """Let :func:`arm` end the process (the ``ocl-tonemap`` command only), armed the
    moment a signal lands (:func:`_wake_on_signal`)."""
    global _watchdog
    _watchdog = bool(on)
    if on:
        _wake_on_signal()


def _wake_on_signal() -> None:
    """Python's own C handler writes each signal's number to a pipe
    (``signal.set_wakeup_fd``) even while the main thread is inside a long C call
    (an OpenCL wait, a NumPy loop), where no Python handler can run until it returns;
    a thread reading the pipe arms the watchdog at once. Called from the main thread
    before :func:`install`; where that cannot be (an embedding), nothing."""
    import os
    import threading
    try:
        r, w = os.pipe()
        os.set_blocking(w, False)
        signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except (ValueError, OSError):
        return

    def read() -> None:
        while True:
            try:
                got = os.read(r, 64)
            except OSError:
                return
            if not got:
                return
            for signum in got:
                if signum in (signal.SIGINT, signal.SIGTERM):
                    arm(signum)
    threading.Thread(target=read, name="ocltm-signal-wakeup", daemon=True).start()


def arm(signum: int) -> None:
    """The first signal's watchdog: unless the process has ended :data:`GRACE_S`
    seconds from now, it says so in one line and leaves with 128 + ``signum``
    (``os._exit``: no thread is waited for; the run locks are released, a
    temporary file of the frame in flight is removed by the next run). A daemon
    thread, so nothing when the command ends first; only where
    :func:`enable_watchdog` was called.

    It runs wherever the main thread waits with the interpreter free (a lock, a
    future, a pool's join, a system call); a library call that holds the
    interpreter (OIIO's or OCIO's open of a FIFO) cannot be reached from Python,
    which is why such files are refused before they are opened
    (``safeio.check_input``)."""
    global _armed
    if not _watchdog or _armed:
        return
    _armed = True
    import threading
    threading.Thread(target=_watch, args=(int(signum),), name="ocltm-signal-watchdog",
                     daemon=True).start()


def _watch(signum: int) -> None:
    import os
    import sys
    import time
    time.sleep(GRACE_S)
    try:
        ck = sys.modules.get("ocl_tonemap.job.checkpoint")
        if ck is not None:
            ck.release_held()
        _remove_own_temps()
        where = (f"; the state of the frames written is in {checkpoint} (run it again "
                 "with --resume)") if checkpoint and os.path.exists(checkpoint) else ""
        sys.stderr.write(f"ocl-tonemap: {'terminated' if signum == 15 else 'interrupted'}; "
                         f"the work in flight did not stop within {GRACE_S:g} s and was "
                         f"discarded{where}\n")
        sys.stderr.flush()
        sys.stdout.flush()
    except BaseException:  # noqa: BLE001 -- leaving is all that is left to do
        pass
    os._exit(128 + signum)


def _remove_own_temps() -> None:
    import os
    mark = f".tmp{os.getpid()}"
    for d in list(temp_folders):
        try:
            names = os.listdir(d)
        except OSError:
            continue
        for n in names:
            if n.startswith(".") and mark in n:
                try:
                    os.unlink(os.path.join(d, n))
                except OSError:
                    pass


def _terminate(signum, frame):
    global received
    received = signum
    arm(signum)
    raise Terminated(signum)


def _interrupt(signum, frame):
    global received
    received = signum
    arm(signum)
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
