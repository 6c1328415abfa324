"""Runs that survive faults: missing frames, interruption (real signals to a real
subprocess) and resumption to the same frames, state from an output frame."""

import glob
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli import main
from ocl_tonemap.imageio import frame_path
from ocl_tonemap.sample import write_tunnel_sequence

OPERATORS = ("pattanaik00", "ledda04", "durand00", "kirk11")


def pixels(path):
    return oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    """60 frames of the tunnel sample, 32x18, 30 fps."""
    d = tmp_path_factory.mktemp("shot")
    pattern, frames = write_tunnel_sequence(str(d), 32, 18, 30.0, 2.0)
    return pattern, frames


def _copy_shot(shot, d):
    pattern, frames = shot
    os.makedirs(d, exist_ok=True)
    for f in frames:
        shutil.copy(frame_path(pattern, f), d)
    return os.path.join(d, os.path.basename(pattern)), frames


# --- missing frames ------------------------------------------------------------------

def test_missing_frame_is_an_error_before_anything_runs(shot, tmp_path, capsys):
    pattern, frames = _copy_shot(shot, tmp_path / "gap")
    os.unlink(frame_path(pattern, frames[9]))
    out = str(tmp_path / "o.#.png")
    assert main(["run", pattern, out, "-q"]) == 2
    err = capsys.readouterr().err
    assert f"frame {frames[9]}: missing frame" in err and "--missing" in err
    assert not glob.glob(str(tmp_path / "o.*.png"))          # nothing was processed


def test_missing_hold_and_skip(shot, tmp_path):
    pattern, frames = _copy_shot(shot, tmp_path / "gap")
    gone = frames[9]
    os.unlink(frame_path(pattern, gone))
    held, skipped = str(tmp_path / "h.#.exr"), str(tmp_path / "s.#.exr")
    assert main(["run", pattern, held, "--missing", "hold", "-q"]) == 0
    assert main(["run", pattern, skipped, "--missing", "skip", "-q"]) == 0
    spec = oiio.ImageBuf(frame_path(held, gone)).spec()
    assert spec.getattribute("ocltm:held_from") == os.path.basename(frame_path(pattern, gone - 1))
    st = json.loads(spec.getattribute("ocltm:state"))
    assert st["time_s"] == pytest.approx(gone / 30.0)        # at the missing frame's time
    assert not os.path.exists(frame_path(skipped, gone))
    st = json.loads(oiio.ImageBuf(frame_path(skipped, gone + 1)).spec().getattribute("ocltm:state"))
    assert st["time_s"] == pytest.approx((gone + 1) / 30.0)  # time follows the frame numbers


# --- interruption and resume ---------------------------------------------------------------

def _run(args, **kw):
    return subprocess.Popen([sys.executable, "-m", "ocl_tonemap", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def _interrupt_after(args, out_glob, n_done, sig):
    """Start a run, send ``sig`` once ``n_done`` outputs exist; (returncode, stderr)."""
    p = _run(args)
    t0 = time.time()
    while len(glob.glob(out_glob)) < n_done and p.poll() is None and time.time() - t0 < 60:
        time.sleep(0.005)
    if p.poll() is None:
        p.send_signal(sig)
    _, err = p.communicate(timeout=120)
    return p.returncode, err


@pytest.mark.parametrize("op", OPERATORS)
def test_interrupted_and_resumed_equals_one_run(op, shot, tmp_path):
    """SIGTERM stops after the frame in flight (exit 143, a resume command printed);
    SIGKILL at any moment (also during a write) loses at most the frame in flight;
    --resume then renders exactly the frames of one uninterrupted run."""
    pattern, frames = shot
    whole = str(tmp_path / "w.####.exr")
    common = ["--operator", op, "--out-bits", "float", "-q"]
    assert main(["run", pattern, whole, *common]) == 0
    for sig, n_done in ((signal.SIGTERM, 12), (signal.SIGKILL, 27)):
        d = tmp_path / f"sig{int(sig)}"
        d.mkdir()
        part = str(d / "p.####.exr")
        rc, err = _interrupt_after(["run", pattern, part, *common], str(d / "p.*.exr"), n_done, sig)
        if sig == signal.SIGTERM:
            assert rc in (143, 0), err                          # 0: it finished first
            if rc == 143:
                assert "--resume" in err and "Traceback" not in err
                assert not [x for x in os.listdir(d) if ".tmp" in x]
        else:
            assert rc in (-9, 0)
        p = _run(["run", pattern, part, *common, "--resume"])
        _, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        assert not [x for x in os.listdir(d) if ".tmp" in x]
        for f in frames:
            np.testing.assert_array_equal(pixels(frame_path(part, f)), pixels(frame_path(whole, f)),
                                          err_msg=f"{op} {sig!r} frame {f}")


def test_ctrl_c_exits_130_with_the_checkpoint(shot, tmp_path):
    pattern, frames = shot
    out = str(tmp_path / "o.####.png")
    rc, err = _interrupt_after(["run", pattern, out], str(tmp_path / "o.*.png"), 5, signal.SIGINT)
    if rc == 0:
        pytest.skip("the run finished before the signal")
    assert rc == 130 and "Traceback" not in err and "--resume" in err
    ckpt = json.loads((tmp_path / "o.state.json").read_text())
    assert ckpt["frame"] == max(int(os.path.basename(p).split(".")[1])
                                for p in glob.glob(str(tmp_path / "o.*.png")))


def test_resume_without_checkpoint_starts_at_the_beginning(shot, tmp_path):
    pattern, frames = shot
    out = str(tmp_path / "o.####.png")
    assert main(["run", pattern, out, "--frames", f"{frames[0]}-{frames[4]}", "--resume",
                 "-q"]) == 0
    assert all(os.path.exists(frame_path(out, f)) for f in frames[:5])


# --- state from an output frame -------------------------------------------------------------

def test_state_in_from_an_output_frame(shot, tmp_path, capsys):
    pattern, frames = shot
    a, b = frames[0], frames[-1]
    mid = frames[len(frames) // 2]
    one = str(tmp_path / "one.####.exr")
    two = str(tmp_path / "two.####.exr")
    assert main(["run", pattern, one, "--out-bits", "float", "-q"]) == 0
    assert main(["run", pattern, two, "--frames", f"{mid + 1}-{b}", "--state-in",
                 frame_path(one, mid), "--out-bits", "float", "-q"]) == 0
    for f in range(mid + 1, b + 1):
        np.testing.assert_array_equal(pixels(frame_path(one, f)), pixels(frame_path(two, f)))
    # a local operator's output frame has no per-pixel state: a clear error
    led = str(tmp_path / "l.####.exr")
    assert main(["run", pattern, led, "--operator", "ledda04", "--frames", f"{a}-{a + 1}",
                 "-q"]) == 0
    rc = main(["run", pattern, str(tmp_path / "l2.####.exr"), "--operator", "ledda04",
               "--frames", f"{a + 2}-{a + 3}", "--state-in", frame_path(led, a + 1), "-q"])
    err = capsys.readouterr().err
    assert rc == 2 and "per-pixel state" in err and "Traceback" not in err
