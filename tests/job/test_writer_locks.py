"""Issue 65: one lock for every writer of an output pattern, that cannot be fooled.

- a link, a FIFO, a folder, a hard link or a file of other data in the place of the
  frames lock is refused in one line naming it, and nothing is written through it;
- while a run writes a pattern, ``apply``, ``apply --chunk`` and a Dask run are
  refused; while a shot's chunk writes, a serial run, another store's ``apply`` and an
  overlapping chunk are refused, and a disjoint chunk of the same shot goes ahead;
- a lock left by a killed process is recovered;
- a pass removes the stale temporaries of its own naming at its start, never a link
  or another file's; a link in the place of a temporary is refused;
- every pass's interrupt exits 130/143 and says the command that finishes the work.
"""

import json
import os
import shlex
import signal
import subprocess
import sys
import time

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.job.locks import lock_path
from ocl_tonemap.io.sample import write_tunnel_sequence

REF = ["--backend", "reference", "-q"]

#: A command held once it has taken its locks: ``target`` (module:function) is
#: wrapped to write the readiness marker and wait for a line on stdin first.
HELD = r"""
import importlib, sys
mod, name = sys.argv[2].split(":")
m = importlib.import_module(mod)
real = getattr(m, name)
def held(*a, **k):
    open(sys.argv[1], "w").close()
    sys.stdin.readline()
    return real(*a, **k)
setattr(m, name, held)
from ocl_tonemap.cli.table import main
sys.exit(main(sys.argv[3:]))
"""


def _cli(args, env=None):
    e = {**os.environ, **(env or {})}
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, timeout=900, env=e)
    return p.returncode, p.stderr


def _one_error(rc, err, *words):
    assert rc == 2, err
    assert "Traceback" not in err, err
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("ocl-tonemap ERROR: "), err
    for w in words:
        assert w in lines[0], err
    return lines[0]


class Held:
    """A command held (``HELD``) after it took its locks, until :meth:`go`."""

    def __init__(self, tmp_path, target, args):
        self.ready = tmp_path / f"ready-{time.monotonic_ns()}"
        self.p = subprocess.Popen([sys.executable, "-c", HELD, str(self.ready), target,
                                   *args], stdin=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True)
        while not self.ready.exists():                # no deadline: until it is there
            assert self.p.poll() is None, self.p.stderr.read()
            time.sleep(0.02)

    def go(self):
        _, err = self.p.communicate("go\n", timeout=900)
        return self.p.returncode, err


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    d = tmp_path_factory.mktemp("seq")
    return write_tunnel_sequence(str(d), 48, 27, 8.0, 1.0)        # 8 frames


def _pngs(d):
    return sorted(n for n in os.listdir(d) if n.endswith(".png")) if os.path.isdir(d) else []


def _measured(seq, d, store="shot"):
    """The shot measured and integrated into ``d/store`` (the real CLI); the output
    pattern and the store."""
    pattern, _ = seq
    out, st = str(d / "o" / "o.####.png"), str(d / store)
    for cmd in ("measure", "integrate"):
        rc, err = _cli([cmd, pattern, out, "--store", st, *REF])
        assert rc == 0, err
    return out, st


@pytest.mark.parametrize("kind", ["symlink", "fifo", "folder", "foreign", "hardlink"])
def test_a_thing_in_the_place_of_the_frames_lock_is_refused(seq, tmp_path, kind):
    pattern, _ = seq
    out = tmp_path / "o" / "o.####.png"
    out.parent.mkdir()
    lock = lock_path(str(out))
    user = tmp_path / "users_file.txt"
    user.write_text("a user's words\n")
    if kind == "symlink":
        os.symlink(user, lock)
    elif kind == "fifo":
        os.mkfifo(lock)
    elif kind == "folder":
        os.mkdir(lock)
    elif kind == "foreign":
        with open(lock, "w") as f:
            f.write("not a lock: somebody's notes\n")
    else:
        os.link(user, lock)
    rc, err = _cli(["run", pattern, str(out), *REF])
    line = _one_error(rc, err, lock, "nothing was written through it")
    assert "Errno" not in line
    assert user.read_text() == "a user's words\n"                      # untouched
    assert os.path.lexists(lock)                                       # left as it was
    assert not _pngs(out.parent)


def test_a_lock_left_by_a_killed_process_is_recovered(seq, tmp_path):
    pattern, frames = seq
    out = tmp_path / "o" / "o.####.png"
    out.parent.mkdir()
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    rec = {"what": "ocl-tonemap lock", "guards": str(out), "shot": None,
           "holders": [{"pid": gone.pid, "token": "x", "command": "run", "chunk": None}]}
    with open(lock_path(str(out)), "w") as f:
        json.dump(rec, f)
    rc, err = _cli(["run", pattern, str(out), *REF])
    assert rc == 0, err
    assert len(_pngs(out.parent)) == len(frames)
    assert not os.path.exists(lock_path(str(out)))


def test_every_writer_is_refused_while_a_run_writes(seq, tmp_path):
    pattern, _ = seq
    out, st = _measured(seq, tmp_path)
    run = Held(tmp_path, "ocl_tonemap.job.run:_run_job", ["run", pattern, out, *REF])
    try:
        for args in (["apply", pattern, out, "--store", st, *REF],
                     ["apply", pattern, out, "--store", st, "--chunk", "1-2", *REF],
                     ["run", pattern, out, "--scheduler", "dask", "--workers", "1",
                      "--store", st, *REF]):
            rc, err = _cli(args)
            _one_error(rc, err, out, f"pid {run.p.pid}", "another ocl-tonemap run")
        assert not _pngs(os.path.dirname(out))
    finally:
        rc, err = run.go()
    assert rc == 0, err


def test_a_shots_chunks_share_the_lock_and_others_are_refused(seq, tmp_path):
    pattern, frames = seq
    out, st = _measured(seq, tmp_path)
    _, st2 = _measured(seq, tmp_path, "other")
    a, b = frames[0], frames[3]
    chunk = Held(tmp_path, "ocl_tonemap.shot.passes:run_job",
                 ["apply", pattern, out, "--store", st, "--chunk", f"{a}-{b}", *REF])
    try:
        rc, err = _cli(["run", pattern, out, *REF])
        _one_error(rc, err, out, f"pid {chunk.p.pid}", f"shot store {st}")
        rc, err = _cli(["apply", pattern, out, "--store", st2, *REF])
        _one_error(rc, err, out, "another shot store")
        rc, err = _cli(["apply", pattern, out, "--store", st, "--chunk",
                        f"{b}-{frames[-1]}", *REF])
        _one_error(rc, err, out, f"frames {a}-{b}", "overlap")
        # a disjoint chunk of the same shot goes ahead while the first one writes
        rc, err = _cli(["apply", pattern, out, "--store", st, "--chunk",
                        f"{frames[4]}-{frames[-1]}", *REF])
        assert rc == 0, err
        assert len(_pngs(os.path.dirname(out))) == len(frames) - 4
    finally:
        rc, err = chunk.go()
    assert rc == 0, err
    assert len(_pngs(os.path.dirname(out))) == len(frames)
    assert not [n for n in os.listdir(os.path.dirname(out)) if n.endswith(".lock")]
    # the chunks' frames are the serial run's
    serial = tmp_path / "serial" / "o.####.png"
    assert _cli(["run", pattern, str(serial), *REF])[0] == 0
    for n in _pngs(os.path.dirname(out)):
        x = oiio.ImageBuf(os.path.join(os.path.dirname(out), n)).get_pixels(oiio.UINT8)
        y = oiio.ImageBuf(str(serial.parent / n)).get_pixels(oiio.UINT8)
        assert np.array_equal(x, y), n


def _dead_pid():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_pass_removes_its_own_stale_temporaries_only(seq, tmp_path):
    pattern, frames = seq
    out, st = _measured(seq, tmp_path)
    od = os.path.dirname(out)
    os.makedirs(od, exist_ok=True)
    pid = _dead_pid()
    stale = os.path.join(od, f".o.{frames[1]:04d}.tmp{pid}.png")
    other = os.path.join(od, f".notes.tmp{pid}.png")          # not one of this shot's files
    link = os.path.join(od, f".o.{frames[2]:04d}.tmp{pid}.png")
    store_stale = os.path.join(st, "stats", f".{frames[0]:08d}.json.tmp{pid}")
    for p in (stale, other, store_stale):
        with open(p, "w") as f:
            f.write("half")
    os.symlink(tmp_path / "elsewhere", link)
    rc, err = _cli(["measure", pattern, out, "--store", st, *REF])
    assert rc == 0, err
    assert not os.path.exists(store_stale)
    rc, err = _cli(["apply", pattern, out, "--store", st, *REF])
    assert rc == 0, err
    assert not os.path.exists(stale)
    assert os.path.exists(other) and os.path.islink(link)


def test_a_link_in_the_place_of_a_temporary_is_refused(tmp_path):
    from ocl_tonemap.io.imageio import FrameError
    from ocl_tonemap.io.imagewrite import write_frame
    target = tmp_path / "precious.png"
    target.write_bytes(b"precious")
    path = tmp_path / "o.png"
    tmp = tmp_path / f".o.tmp{os.getpid()}.png"
    os.symlink(target, tmp)
    with pytest.raises(FrameError) as e:
        write_frame(str(path), np.zeros((4, 4, 3), np.float32), oiio.ImageSpec(4, 4, 3,
                    oiio.FLOAT), "sRGB", {})
    assert str(tmp) in str(e.value) and "nothing was written through it" in str(e.value)
    assert target.read_bytes() == b"precious" and os.path.islink(tmp)
    assert not path.exists()


# -- interrupts ------------------------------------------------------------------------

def _started(args, ready):
    env = {**os.environ, "OCLTM_TEST_READY": str(ready)}
    return subprocess.Popen([sys.executable, "-m", "ocl_tonemap", *args],
                            stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _interrupted_at(p, ready, mark, sig):
    """Send ``sig`` once the command noted ``mark``: (exit code, stderr, noted)."""
    noted = False
    while p.poll() is None:
        if ready.exists() and mark in ready.read_text():
            noted = True
            break
        time.sleep(0.005)
    p.send_signal(sig)
    _, err = p.communicate(timeout=900)
    return p.returncode, err, noted


@pytest.fixture(scope="module")
def long_seq(tmp_path_factory):
    d = tmp_path_factory.mktemp("long")
    return write_tunnel_sequence(str(d), 48, 27, 8.0, 5.0)        # 40 frames


@pytest.mark.parametrize("sig,code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_an_interrupted_apply_says_the_chunk_left_and_it_finishes_the_shot(long_seq, tmp_path,
                                                                          sig, code):
    pattern, frames = long_seq
    out, st = _measured(long_seq, tmp_path)
    ready = tmp_path / "ready"
    p = _started(["apply", pattern, out, "--store", st, *REF], ready)
    rc, err, noted = _interrupted_at(p, ready, f"written {frames[1]}", sig)
    assert noted, err
    assert rc == code and "Traceback" not in err and "ERROR" not in err, (rc, err)
    lines = err.strip().splitlines()
    assert len(lines) == 2 and lines[0].startswith("ocl-tonemap: interrupted after frame"), err
    again = shlex.split(lines[1])
    assert again[:2] == ["ocl-tonemap", "apply"] and again[-2] == "--chunk", err
    first, last = map(int, again[-1].split("-"))
    assert last == frames[-1] and first == len(_pngs(os.path.dirname(out))) + frames[0], err
    rc, err = _cli(again[1:])
    assert rc == 0, err
    assert len(_pngs(os.path.dirname(out))) == len(frames)


@pytest.mark.parametrize("cmd,mark", [("measure", "measured"), ("integrate", "integrated")])
def test_an_interrupted_pass_says_the_command_that_finishes_it(long_seq, tmp_path, cmd, mark):
    pattern, frames = long_seq
    out, st = str(tmp_path / "o" / "o.####.png"), str(tmp_path / "shot")
    if cmd == "integrate":
        assert _cli(["measure", pattern, out, "--store", st, *REF])[0] == 0
    ready = tmp_path / "ready"
    p = _started([cmd, pattern, out, "--store", st, *REF], ready)
    rc, err, noted = _interrupted_at(p, ready, f"{mark} {frames[1]}", signal.SIGTERM)
    assert noted, err
    assert rc == 143 and "Traceback" not in err and "ERROR" not in err, (rc, err)
    lines = err.strip().splitlines()
    assert len(lines) == 2 and "To finish, run:" in lines[0], err
    again = shlex.split(lines[1])
    assert again[:2] == ["ocl-tonemap", cmd], err
    rc, err = _cli(again[1:])
    assert rc == 0, err


def test_a_dask_runs_lock_covers_the_shot_and_lets_its_own_tasks_in(seq, tmp_path):
    """A Dask run's client holds the lock over the whole shot (``shot_lock`` with every
    frame): another ``apply --chunk`` of the same store is refused as overlapping, the
    run's own tasks (``within`` its token) go ahead."""
    from ocl_tonemap.cli.table import build_parser
    from ocl_tonemap.cli.options import job_options
    from ocl_tonemap.shot import passes
    pattern, frames = seq
    out, st = _measured(seq, tmp_path)
    a = build_parser("apply").parse_args(["apply", pattern, out, "--store", st, *REF])
    opts = job_options(a, a.input, a.output)            # (the settings the CLI's apply has)
    jobs = passes.shot_jobs(opts)
    with passes.shot_lock(opts, st, jobs, "run --scheduler dask") as lock:
        rc, err = _cli(["apply", pattern, out, "--store", st, "--chunk",
                        f"{frames[0]}-{frames[1]}", *REF])
        _one_error(rc, err, out, "run --scheduler dask", "overlap")
        res = passes.apply(opts, st, (frames[0], frames[1]), lock.token)
        assert res.frames == frames[:2]
    assert not os.path.exists(lock_path(out))
