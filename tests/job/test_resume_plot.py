"""``--resume`` with ``--plot`` (issue 67): the README's driving-sim example
interrupted, then resumed. The frames written before the resume keep their record
(``ocltm:time_s`` too: a PNG keeps text only, so its numbers are written as text), so
the resumed run's plot covers the whole shot, with no warning, drawn from the same
records as one uninterrupted run's plot."""

import json
import logging
import os
import signal
import subprocess
import sys
import time

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import main
from ocl_tonemap.job import run as job_run
from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.io.sample import write_tunnel_sequence

#: The README's driving-sim example (--operator durand00 --fps 30 --flare auto).
COMMON = ["--operator", "durand00", "--fps", "30", "--flare", "auto", "--backend", "reference"]


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    """48 frames of the tunnel drive, 32x18, 30 fps."""
    return write_tunnel_sequence(str(tmp_path_factory.mktemp("drive")), 32, 18, 30.0, 1.6)


def _record(info) -> tuple:
    """What the plot is drawn from, of one frame (``plot.plot_adaptation``)."""
    return (info.frame, info.time_s, info.G_rod, info.G_cone,
            {k: np.asarray(v).tolist() for k, v in sorted(info.state.values.items())},
            json.loads(json.dumps(info.params, sort_keys=True, default=float)),
            (info.plan or {}).get("weights"), getattr(info, "visibility", None))


@pytest.fixture
def plotted(monkeypatch):
    """The records each ``--plot`` of this test is drawn from (the plot still drawn)."""
    seen = []
    real = job_run.plot_adaptation

    def spy(path, infos, tm, frames=None):
        seen.append([_record(i) for i in infos])
        return real(path, infos, tm, frames)
    monkeypatch.setattr(job_run, "plot_adaptation", spy)
    return seen


def _interrupted(args, n_done: int):
    """The command in a process of its own, SIGTERM once it has noted ``n_done`` frames
    written (``$OCLTM_TEST_READY``: its own notes, no guessed delay)."""
    ready = f"{args[2]}.ready"
    p = subprocess.Popen([sys.executable, "-m", "ocl_tonemap", *args], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True,
                         env={**os.environ, "OCLTM_TEST_READY": ready},
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    while p.poll() is None:
        if os.path.exists(ready) and open(ready).read().count("written ") >= n_done:
            p.send_signal(signal.SIGTERM)
            break
        time.sleep(0.005)
    _, err = p.communicate()
    return p.returncode, err


def test_a_resumed_runs_plot_is_one_runs_plot(drive, tmp_path, plotted, caplog):
    pattern, frames = drive
    whole, part = str(tmp_path / "w" / "tunnel.####.png"), str(tmp_path / "p" / "tunnel.####.png")
    caplog.set_level(logging.INFO, logger="ocl_tonemap")   # (a -q run before may have hushed it)
    assert main(["run", pattern, whole, *COMMON, "--plot", str(tmp_path / "w.png")]) == 0
    rc, err = _interrupted(["run", pattern, part, *COMMON, "-q"], 12)
    assert rc == 143 and "--resume" in err and "Traceback" not in err, err
    done = [f for f in frames if os.path.exists(frame_path(part, f))]
    assert 12 <= len(done) < len(frames)
    # the frames before the resume keep their time, as text (PNG keeps text only)
    assert done == frames[:len(done)], done
    t = [oiio.ImageInput.open(frame_path(p, done[-1])).spec().getattribute("ocltm:time_s")
         for p in (part, whole)]
    assert t[0] == t[1] == repr(done[-1] / 30.0), t
    caplog.clear()
    assert main(["run", pattern, part, *COMMON, "--resume", "--plot",
                 str(tmp_path / "p.png")]) == 0
    warned = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert warned == [], warned
    one, resumed = plotted
    assert [r[0] for r in resumed] == frames                # the whole shot, 0 - 1.57 s
    assert resumed == one
    for f in frames:                                        # (bit-identical, as promised)
        np.testing.assert_array_equal(oiio.ImageBuf(frame_path(part, f)).get_pixels(oiio.UINT8),
                                      oiio.ImageBuf(frame_path(whole, f)).get_pixels(oiio.UINT8))


def test_frames_without_a_record_are_left_out_in_one_warning(drive, tmp_path, caplog):
    """Outputs an older version wrote (no ``ocltm:time_s`` in a PNG): one warning for
    them all, not one per frame."""
    from ocl_tonemap.job.run import infos_from_outputs
    pattern, frames = drive
    out = tmp_path / "o.####.png"
    for f in frames[:3]:
        buf = oiio.ImageBuf(oiio.ImageSpec(4, 4, 3, oiio.UINT8))
        buf.specmod().attribute("ocltm:goal", json.dumps({"G_rod": 1.0, "G_cone": 1.0}))
        buf.write(frame_path(str(out), f))
    caplog.set_level(logging.INFO, logger="ocl_tonemap")
    jobs = [(f, frame_path(pattern, f), frame_path(str(out), f), False) for f in frames[:3]]
    assert infos_from_outputs(jobs) == []
    warned = [r.getMessage() for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warned) == 1 and "3 of the 3 frame(s)" in warned[0] and "2 more" in warned[0], \
        warned
