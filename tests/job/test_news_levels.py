"""Normal news is quiet (issue 58, part 6): a resume is an INFO line (seen at -v), not
a warning; the host <-> device transfer counts are printed at -v only; the plot of the
mechanism plan says in its title what the plan did over the shot."""

import logging
import os
import subprocess
import sys

import pytest

from ocl_tonemap.io.plot import plan_summary, plan_title
from ocl_tonemap.io.sample import write_tunnel_sequence

HANG = 300


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    d = tmp_path_factory.mktemp("seq")
    return write_tunnel_sequence(str(d), 32, 18, 10.0, 0.6)


def _cli(args):
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, timeout=HANG)
    return p.returncode, p.stdout, p.stderr


def test_a_resume_is_info_not_a_warning(seq, tmp_path, caplog):
    from ocl_tonemap.cli.table import main
    pattern, frames = seq
    out = str(tmp_path / "o.####.png")
    common = ["--backend", "reference"]
    assert main(["run", pattern, out, *common, "--frames", f"{frames[0]}-{frames[2]}",
                 "-q"]) == 0
    with caplog.at_level(logging.DEBUG, logger="ocl_tonemap"):
        assert main(["run", pattern, out, *common, "--frames", f"{frames[0]}-{frames[-1]}",
                     "--resume"]) == 0
    said = [r for r in caplog.records if "resuming after frame" in r.getMessage()]
    assert said and all(r.levelno == logging.INFO for r in said), \
        [(r.levelname, r.getMessage()) for r in said]
    # the command at its default level says nothing of it on stderr; at -v it is INFO
    rc, _, err = _cli(["run", pattern, out, *common, "--frames",
                       f"{frames[0]}-{frames[-1]}", "--resume"])
    assert rc == 0, err
    assert "resuming" not in err and "WARNING" not in err, err
    rc, _, err = _cli(["run", pattern, out, *common, "--frames",
                       f"{frames[0]}-{frames[-1]}", "--resume", "-v"])
    assert rc == 0, err
    assert "ocl-tonemap INFO: resuming after frame" in err, err


def test_transfer_counts_only_at_verbose(seq, tmp_path):
    pattern, frames = seq
    out = str(tmp_path / "o.####.png")
    rc, stdout, err = _cli(["run", pattern, out, "--frames", f"{frames[0]}-{frames[1]}"])
    assert rc == 0, err
    assert "host <-> device" not in stdout + err
    assert stdout.startswith("wrote 2 frame(s)")
    from tests.conftest import opencl_status
    if opencl_status()[0] is None:
        return                       # the reference backend moves nothing to a device
    rc, stdout, err = _cli(["run", pattern, out, "--frames", f"{frames[0]}-{frames[1]}",
                            "-v", "--backend", "opencl"])
    assert rc == 0, err
    assert "host <-> device per frame: up" in stdout, stdout


def test_plan_summary_and_title_say_what_the_plan_did():
    w = [{"rods": 1.0, "flare": 0.0, "purkinje": 0.0, "acuity": 0.5, "temporal": 0.0},
         {"rods": 1.0, "flare": 1.0, "purkinje": 0.0, "acuity": 0.5, "temporal": 0.0},
         {"rods": 1.0, "flare": 0.0, "purkinje": 1.0, "acuity": 0.5, "temporal": 0.0},
         {"rods": 1.0, "flare": 1.0, "purkinje": 1.0, "acuity": 0.5, "temporal": 0.0}]
    s = plan_summary(w)
    assert s["applied"] == ["rods"]
    assert s["skipped"] == ["temporal"]
    assert s["partial"] == ["acuity 0.5"]
    assert s["switched"] == {"purkinje": (2, 4, 1), "flare": (2, 4, 3)} or \
        s["switched"] == {"flare": (2, 4, 3), "purkinje": (2, 4, 1)}
    title = plan_title(w).replace("\n", " ")
    assert "0 skipped, 1 applied" not in title
    assert "over 4 frames" in title
    assert "applied throughout: rods" in title
    assert "skipped throughout: temporal" in title
    assert "flare (on in 2 of 4 frames, 3 changes)" in title
    assert "purkinje (on in 2 of 4 frames, 1 change)" in title
    steady = plan_title([{"rods": 1.0, "flare": 0.0}] * 3).replace("\n", " ")
    assert "switched" not in steady and "applied throughout: rods" in steady


def test_the_plot_title_is_the_runs_plan(seq, tmp_path, monkeypatch):
    """--plot: the plan's axes get the title of the run's own weights."""
    pytest.importorskip("matplotlib")
    import matplotlib.axes
    from ocl_tonemap.cli.table import main
    pattern, frames = seq
    titles = []
    real = matplotlib.axes.Axes.set_title

    def set_title(self, label, *a, **k):
        titles.append(label)
        return real(self, label, *a, **k)
    monkeypatch.setattr(matplotlib.axes.Axes, "set_title", set_title)
    plot = str(tmp_path / "p.png")
    assert main(["run", pattern, str(tmp_path / "o.####.exr"), "--operator", "durand00",
                 "--backend", "reference", "--plot", plot, "-q"]) == 0
    assert os.path.getsize(plot) > 10000
    plan = [t for t in titles if t.startswith("mechanism plan")]
    assert len(plan) == 1, titles
    import json
    import OpenImageIO as oiio
    from ocl_tonemap.io.patterns import frame_path
    weights = [json.loads(oiio.ImageBuf(frame_path(str(tmp_path / "o.####.exr"), f))
                          .spec().getattribute("ocltm:plan")) for f in frames]
    assert plan[0] == plan_title(weights)
    assert "0 skipped, 1 applied" not in plan[0]
