"""SIGTERM ends the command even while it is blocked inside a library call that holds
the interpreter (issue 65): no Python thread can run then, so the command's watchdog
process (``interrupts._fork_backstop``, forked first thing by the ``ocl-tonemap``
entry) ends it with SIGKILL after one line, 1.5 s after the signal; where Python can
run, the command's own watchdog still wins (130 / 143 and its line). The watchdog
process holds nothing but its pipes and stderr and leaves with the command; the
library and ``cli.main`` in a host's process fork nothing.

The blocks are real: ``pthread_mutex_lock`` of a mutex the thread holds, through
``ctypes.PyDLL`` (which keeps the interpreter, and which no signal interrupts:
``pause()`` or a ``read`` return on the signal), and OCIO itself opening a LUT that
is a FIFO (``Config.getProcessor``, called directly, as a host would, past
``colour/lut_files.py``'s check)."""

import os
import signal
import subprocess
import sys
import tempfile
import time

import pytest

#: Only keeps a hang from holding the suite; the assertions are on what happened.
HANG = 60

BACKSTOP_LINE = "blocked in a library call for"

#: The real entry (``entry()``: handlers, the watchdog and its process), with the
#: sub-command replaced by a block, noted ``blocked`` in ``$OCLTM_TEST_READY`` first.
_ENTRY = r"""
import ctypes, os, sys
from ocl_tonemap.base import interrupts
from ocl_tonemap.cli import table as cli
from ocl_tonemap.__main__ import entry
how = os.environ["BLOCK"]

def blocked():
    if how == "ocio-fifo":
        import PyOpenColorIO as ocio
        cfg = ocio.Config.CreateFromFile(os.environ["BLOCK_CONFIG"])
        interrupts.ready("blocked")
        cfg.getProcessor("lin_rec709", "sRGB", "Raw", ocio.TRANSFORM_DIR_FORWARD)
    elif how == "mutex":
        mutex = ctypes.create_string_buffer(64)     # zeros: PTHREAD_MUTEX_INITIALIZER
        lock = ctypes.PyDLL(None).pthread_mutex_lock
        lock(mutex)
        interrupts.ready("blocked")
        lock(mutex)                                 # for ever, the interpreter held
    elif how == "read":                             # a system call, the interpreter free
        r, w = os.pipe()
        interrupts.ready("blocked")
        os.read(r, 1)
    elif how == "wait":                             # until told, then a normal exit
        interrupts.ready("blocked")
        os.read(int(os.environ["BLOCK_FD"]), 1)
    print("not blocked", file=sys.stderr)
    return 0

cli.main = blocked
sys.argv[0] = "ocl-tonemap"
raise SystemExit(entry())
"""

FIFO_CONFIG = """ocio_profile_version: 2
search_path: .
roles: {default: lin_rec709, scene_linear: lin_rec709}
displays:
  sRGB:
    - !<View> {name: Raw, colorspace: out}
colorspaces:
  - !<ColorSpace>
    name: lin_rec709
  - !<ColorSpace>
    name: out
    from_scene_reference: !<FileTransform> {src: fifo.cube}
"""


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(d, how, env=None, pass_fds=()):
    ready = os.path.join(d, "ready")
    e = {**os.environ, "OCLTM_TEST_READY": ready, "BLOCK": how, **(env or {})}
    p = subprocess.Popen([sys.executable, "-c", _ENTRY], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True, env=e, pass_fds=pass_fds,
                         preexec_fn=_default_sigint)
    deadline = time.monotonic() + HANG
    while p.poll() is None and time.monotonic() < deadline:
        if os.path.exists(ready) and "blocked" in open(ready).read():
            break
        time.sleep(0.01)
    assert p.poll() is None, p.communicate()[1]            # it waits, blocked
    time.sleep(0.1)                                         # (inside the call by now)
    return p


def _signalled(how, sig, env=None):
    """(exit status, seconds from the signal until its stderr closed, stderr)."""
    with tempfile.TemporaryDirectory() as d:
        if how == "ocio-fifo":
            os.mkfifo(os.path.join(d, "fifo.cube"))
            with open(os.path.join(d, "cfg.ocio"), "w") as f:
                f.write(FIFO_CONFIG)
            env = {**(env or {}), "BLOCK_CONFIG": os.path.join(d, "cfg.ocio")}
        p = _start(d, how, env)
        t0 = time.monotonic()
        p.send_signal(sig)
        try:
            _, err = p.communicate(timeout=HANG)    # stderr closed: the watchdog too
        except subprocess.TimeoutExpired:
            p.kill()
            _, err = p.communicate()
            pytest.fail(f"still running {HANG} s after the signal: {err}")
        return p.returncode, time.monotonic() - t0, err


@pytest.mark.parametrize("how, sig", [("mutex", signal.SIGTERM), ("ocio-fifo", signal.SIGTERM),
                                      ("mutex", signal.SIGINT)])
def test_a_signal_ends_the_command_blocked_holding_the_interpreter(how, sig):
    rc, took, err = _signalled(how, sig)
    assert rc == -signal.SIGKILL, err                      # the shell's 137
    assert took < 2.0, (took, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    word = "terminated" if sig == signal.SIGTERM else "interrupted"
    assert lines[0].startswith(f"ocl-tonemap: {word}; {BACKSTOP_LINE} 1."), err
    assert "SIGKILL" in lines[0] and "exit 137" in lines[0], err
    assert "not blocked" not in err and "Traceback" not in err


def test_where_python_can_run_the_commands_own_watchdog_wins():
    rc, took, err = _signalled("read", signal.SIGTERM)
    assert rc == 143, err
    assert took < 2.0, (took, err)
    assert BACKSTOP_LINE not in err and "terminated" in err, err


def _children(pid) -> list:
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            return [int(c) for c in f.read().split()]
    except OSError:
        pytest.skip("no /proc/PID/task/PID/children here")


def _gone(pid) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except OSError:
        return True


def test_the_watchdog_process_holds_only_its_pipes_and_leaves_with_the_command(tmp_path):
    """It holds stderr and its two pipe ends, nothing else (not stdin, stdout, or a
    descriptor the command was given); the command's normal exit ends it at once, so
    a caller reading the command's output to its end does not wait for it."""
    lock = open(tmp_path / "held.lock", "w")                # a caller's descriptor
    r, w = os.pipe()
    try:
        p = _start(str(tmp_path), "wait", {"BLOCK_FD": str(r)}, pass_fds=(r, lock.fileno()))
        kids = _children(p.pid)
        assert len(kids) == 1, kids
        kid = kids[0]
        fds = {int(n): os.readlink(f"/proc/{kid}/fd/{n}") for n in os.listdir(f"/proc/{kid}/fd")}
        assert 0 not in fds and 1 not in fds, fds
        assert 2 in fds and len(fds) == 3, fds
        assert all(t.startswith("pipe:") for t in fds.values()), fds
        os.write(w, b"x")                                   # the command goes on, exits 0
        t0 = time.monotonic()
        _, err = p.communicate(timeout=HANG)
        took = time.monotonic() - t0
        assert p.returncode == 0, err
        assert took < 2.0, took
        deadline = time.monotonic() + 5
        while not _gone(kid) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert _gone(kid)
    finally:
        os.close(r)
        os.close(w)
        lock.close()


def test_the_library_and_cli_main_in_a_host_fork_nothing():
    code = ("import os\n"
            "from ocl_tonemap.base import interrupts\n"
            "from ocl_tonemap.cli import table as cli\n"
            "interrupts.enable_watchdog()\n"
            "interrupts.install()\n"
            "try:\n    cli.main(['--version'])\nexcept SystemExit:\n    pass\n"
            "print(open(f'/proc/{os.getpid()}/task/{os.getpid()}/children').read().strip() "
            "or 'none')\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=HANG)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip().splitlines()[-1] == "none", p.stdout
