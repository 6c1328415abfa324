"""The output frames are locked, not only the state file (issue 58, part 7): a second
run on the same output pattern, even with another --state-out, is refused in one line
naming the output and the first run's pid; a still takes no lock and makes no side
file; a refused run leaves no folder behind."""

import os
import subprocess
import sys
import time

import pytest

from ocl_tonemap.job import checkpoint

#: The first run, held after it has taken its locks: it writes the readiness marker
#: (argv[1]) and waits for a line on its stdin before it renders (the real CLI).
HELD_RUN = r"""
import sys
from ocl_tonemap.job import run as R
real = R._run_job
def held(*a, **k):
    open(sys.argv[1], "w").close()          # ready: the run holds its locks
    sys.stdin.readline()                   # until the test lets it go
    return real(*a, **k)
R._run_job = held
from ocl_tonemap.cli.table import main
sys.exit(main(sys.argv[2:]))
"""


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("seq")
    pattern, frames = write_tunnel_sequence(str(d), 48, 27, 8.0, 0.5)
    return pattern, frames


def _cli(args):
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, timeout=600)
    return p.returncode, p.stderr


def _locks(d):
    return [n for n in os.listdir(d) if n.endswith(".lock")]


@pytest.mark.requires_opencl
def test_two_runs_on_the_same_outputs_with_other_state_files(seq, tmp_path):
    pattern, frames = seq
    out = tmp_path / "out" / "o.####.png"
    ready = tmp_path / "ready"
    first = subprocess.Popen([sys.executable, "-c", HELD_RUN, str(ready), "run", pattern,
                              str(out), "--state-out", str(tmp_path / "a.json"), "-q"],
                             stdin=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120          # (a bound, not what decides the test)
        while not ready.exists():
            assert first.poll() is None, first.stderr.read()
            assert time.monotonic() < deadline, "the first run never took its locks"
            time.sleep(0.05)
        rc, err = _cli(["run", pattern, str(out), "--state-out", str(tmp_path / "b.json"),
                        "-q"])
        assert rc == 2 and "Traceback" not in err, err
        lines = err.strip().splitlines()
        assert len(lines) == 1, err
        assert str(out) in lines[0] and f"pid {first.pid}" in lines[0], err
        assert "another ocl-tonemap run" in lines[0], err
        assert not (tmp_path / "b.json").exists()
        assert not [n for n in os.listdir(out.parent) if n.endswith(".png")]
    finally:
        _, err1 = first.communicate("go\n", timeout=600)
    assert first.returncode == 0, err1
    assert sorted(n for n in os.listdir(out.parent) if n.endswith(".png")) == \
        [f"o.{f:04d}.png" for f in frames]
    assert not _locks(out.parent) and not _locks(tmp_path)
    # the lock goes with the run: a second run now works
    rc, err = _cli(["run", pattern, str(out), "--state-out", str(tmp_path / "b.json"), "-q"])
    assert rc == 0, err
    assert not _locks(out.parent)


def test_the_output_lock_in_process(tmp_path):
    """The lock's files: the output pattern's beside the frames, the state's beside the
    state; another run on either is refused naming the file it guards."""
    out = str(tmp_path / "f" / "o.####.exr")
    with checkpoint.RunLock(str(tmp_path / "s.json"), output=out) as lock:
        assert sorted(_locks(tmp_path / "f")) == [".o.exr.frames.lock"]
        assert _locks(tmp_path) == [".s.json.lock"]
        with pytest.raises(Exception) as e:
            with checkpoint.RunLock(str(tmp_path / "other.json"), output=out):
                pass
        assert out in str(e.value) and f"pid {os.getpid()}" in str(e.value)
        with pytest.raises(Exception) as e:
            with checkpoint.RunLock(str(tmp_path / "s.json"),
                                    output=str(tmp_path / "g" / "o.####.exr")):
                pass
        assert "s.json" in str(e.value)
        assert not (tmp_path / "g").exists()          # (the refused run's folder: gone)
        assert lock.fd is not None
    assert not (tmp_path / "f").exists() and not _locks(tmp_path)    # (left empty: gone)
    # a still's output takes no lock of its own
    with checkpoint.RunLock(str(tmp_path / "s.json"), output=str(tmp_path / "x.png")):
        assert _locks(tmp_path) == [".s.json.lock"]


@pytest.mark.requires_opencl
def test_a_still_makes_no_side_file(seq, tmp_path):
    pattern, frames = seq
    from ocl_tonemap.io.patterns import frame_path
    d = tmp_path / "still"
    d.mkdir()
    rc, err = _cli(["run", frame_path(pattern, frames[0]), str(d / "o.png"), "-q"])
    assert rc == 0, err
    assert os.listdir(d) == ["o.png"]
