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
#: The command that finishes an interrupted command's work, where a sub-command knows
#: it (a shot's pass: the same command again; ``apply``: over the frames left), said in
#: the interrupted line by ``cli.main`` and by the watchdog.
again: str | None = None
#: Folders where this process writes temporary files (a run's outputs and state):
#: the watchdog removes its own (``.NAME.tmp<pid>EXT``) before it leaves.
temp_folders: set = set()


def enable_watchdog(on: bool = True, backstop: bool = False) -> None:
    """Let :func:`arm` end the process (the ``ocl-tonemap`` command only), armed the
    moment a signal lands (:func:`_wake_on_signal`); ``backstop`` (the command's entry
    only, before anything is opened): with the watchdog process of
    :func:`_fork_backstop` too."""
    global _watchdog
    _watchdog = bool(on)
    if on:
        _wake_on_signal(backstop)


#: The wakeup pipe's write end (``signal.set_wakeup_fd``) where a watchdog process
#: reads it (:func:`_fork_backstop`), else None.
_wakeup_w: int | None = None


def _wake_on_signal(backstop: bool = False) -> None:
    """Python's own C handler writes each signal's number to a pipe
    (``signal.set_wakeup_fd``) even while the main thread is inside a long C call
    (an OpenCL wait, a NumPy loop), where no Python handler can run until it returns;
    a thread reading the pipe arms the watchdog at once. Called from the main thread
    before :func:`install`; where that cannot be (an embedding), nothing. With
    ``backstop`` the pipe is read by the watchdog process, which forwards each byte to
    the pipe the thread reads."""
    import os
    import threading
    try:
        r, w = os.pipe()
        os.set_blocking(w, False)
        signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    except (ValueError, OSError):
        return
    src = _fork_backstop(r, w) if backstop else r

    def read() -> None:
        fd, forwarded = src, src != r
        while True:
            try:
                got = os.read(fd, 64)
            except OSError:
                return
            if not got:
                if not forwarded or not _reader_takes_over(w):
                    return
                fd, forwarded = _wakeup_r, False   # the watchdog process is gone: read here
                continue
            for signum in got:
                if signum in (signal.SIGINT, signal.SIGTERM):
                    arm(signum)
    threading.Thread(target=read, name="ocltm-signal-wakeup", daemon=True).start()


# --- the watchdog process: a backstop where no thread of ours can run ---------------

#: Seconds past :data:`GRACE_S` the watchdog process waits before it ends a process
#: whose own watchdog did not (its main thread inside a library call that holds the
#: interpreter: OCIO reading a FIFO, a C loop), and past that when the process's
#: watchdog said it is armed (its interpreter ran after the signal, so it normally
#: leaves at :data:`GRACE_S` with its own line and 130 / 143).
BACKSTOP_MARGIN_S = 0.5
BACKSTOP_ARMED_MARGIN_S = 3.0
#: The byte the process's :func:`arm` writes to the wakeup pipe (no signal is 0).
_ARMED = 0
#: How often the watchdog process looks whether the command is still its parent, where
#: the pipe's end does not tell (a process the command forked without exec holds w).
_BACKSTOP_POLL_S = 2.0
_wakeup_r: int | None = None


def _fork_backstop(r: int, w: int) -> int:
    """Fork the watchdog process (:func:`_backstop`) on the wakeup pipe ``r``/``w``;
    returns the read end of the pipe it forwards the signals to (``r`` itself where no
    process could be made). Called first thing in the command (nothing of ours is
    open to be inherited; no thread yet)."""
    import os
    global _wakeup_w
    try:
        fr, fw = os.pipe()
    except OSError:
        return r
    parent = os.getpid()
    try:
        pid = os.fork()
    except OSError:
        os.close(fr)
        os.close(fw)
        return r
    if pid == 0:                         # the watchdog process
        try:
            _backstop(r, w, fw, parent)
        finally:
            os._exit(0)
    os.close(r)                          # the process reads it now
    os.close(fw)
    _wakeup_w = w
    os.register_at_fork(after_in_child=_forget_backstop)
    return fr


def _forget_backstop() -> None:
    """In a process forked from the command (not exec'd: those close the pipe): no
    wakeup byte of its signals to the command's watchdog process, and no write end of
    the pipe held, whose end tells that process the command is gone."""
    import os
    global _wakeup_w
    if _wakeup_w is None:
        return
    try:
        signal.set_wakeup_fd(-1)
        os.close(_wakeup_w)
    except (ValueError, OSError):
        pass
    _wakeup_w = None


def _reader_takes_over(w: int) -> bool:
    """The watchdog process has gone while the command runs (killed by hand): a new
    pipe in place of the wakeup pipe's write end (``dup2``: the C handler's writes
    never meet a pipe without a reader), read by the thread itself."""
    import os
    global _wakeup_r, _wakeup_w
    try:
        nr, nw = os.pipe()
        os.set_blocking(nw, False)
        os.dup2(nw, w, inheritable=False)
        os.close(nw)
    except OSError:
        return False
    _wakeup_r, _wakeup_w = nr, None
    return True


def _backstop(r: int, w: int, fw: int, parent: int) -> None:
    """The watchdog process (``os``, ``time``, ``select``, ``signal`` only; stdin and
    stdout closed, stderr kept for its one line, every other descriptor closed): reads
    the wakeup pipe, forwards each byte to the command's reading thread (``fw``) and,
    :data:`GRACE_S` + :data:`BACKSTOP_MARGIN_S` after a SIGINT / SIGTERM, ends the
    command with SIGKILL if it is still there (the command's own watchdog could not
    run). It ignores both signals itself (a terminal's Ctrl-C goes to the whole
    group) and leaves when the pipe ends: the command held its only write end."""
    import os
    import select
    import time
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    try:
        signal.set_wakeup_fd(-1)
    except ValueError:
        pass
    keep = sorted({r, fw, 2})
    try:
        fds = sorted(int(n) for n in os.listdir("/proc/self/fd"))
    except OSError:
        fds = range(max(keep) + 256)
    for fd in fds:                       # w (the command's) above all: its end is the news
        if fd not in keep:
            try:
                os.close(fd)
            except OSError:
                pass
    os.set_blocking(fw, False)
    deadline = signalled = None
    signum = 0
    while True:
        wait = _BACKSTOP_POLL_S if deadline is None else max(0.0, deadline - time.monotonic())
        if select.select([r], [], [], wait)[0]:
            try:
                got = os.read(r, 64)
            except OSError:
                return
            if not got:
                return                   # the command is gone
            sigs = bytes(b for b in got if b != _ARMED)
            if sigs:
                try:
                    os.write(fw, sigs)
                except OSError:          # (its reader gone, or full: the bytes are kept here)
                    pass
            for b in got:
                if b in (signal.SIGINT, signal.SIGTERM) and signalled is None:
                    signum, signalled = b, time.monotonic()
                    deadline = signalled + GRACE_S + BACKSTOP_MARGIN_S
                elif b == _ARMED and signalled is not None:
                    deadline = signalled + GRACE_S + BACKSTOP_ARMED_MARGIN_S
            continue
        if os.getppid() != parent:
            return                       # the command is gone (a process it forked has w)
        if deadline is None or select.select([r], [], [], 0)[0]:
            continue                     # (no signal yet; or news came at the deadline)
        took = time.monotonic() - signalled
        try:
            os.write(2, (f"ocl-tonemap: {'terminated' if signum == 15 else 'interrupted'}; "
                         f"blocked in a library call for {took:.1f} s, ended with SIGKILL "
                         "(exit 137: only the kernel can stop it now); --resume goes on "
                         "from its checkpoint, if it wrote one\n").encode())
        except OSError:
            pass
        os.kill(parent, signal.SIGKILL)
        return


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
    (``safeio.check_input``, ``colour/lut_files.py``), and why the command has a
    watchdog process as well (:func:`_fork_backstop`), told here that this one is
    armed."""
    global _armed
    if not _watchdog or _armed:
        return
    _armed = True
    import threading
    threading.Thread(target=_watch, args=(int(signum),), name="ocltm-signal-watchdog",
                     daemon=True).start()
    if _wakeup_w is not None:
        import os
        try:
            os.write(_wakeup_w, bytes([_ARMED]))
        except OSError:
            pass


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
                 "with --resume)") if checkpoint and os.path.exists(checkpoint) else \
            (f"; to finish, run: {again}" if again else "")
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
