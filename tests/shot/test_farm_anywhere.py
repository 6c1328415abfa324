"""Farm jobs that run anywhere (issue 58, part 8): ``farm-template`` made in one folder
from relative paths writes them absolute (INPUT, OUTPUT, --store and the files run
options name), so that each step's command, run as a farm runs it from another
working directory, writes the frames where intended, equal to a serial ``run``."""

import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.shot.farm import absolute_tokens
from opencue_chunks import opencue_commands

EXE = [sys.executable, "-m", "ocl_tonemap"]


def _run(argv, cwd):
    r = subprocess.run(argv, capture_output=True, text=True, cwd=cwd, timeout=600)
    assert r.returncode == 0, r.stderr
    return r


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A folder with 6 frames of the tunnel (48x27), a metering mask and a cut list,
    all named relative to it; the serial run's frames of the same options."""
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("made")
    pattern, frames = write_tunnel_sequence(str(d / "scene"), 48, 27, 12.0, 0.5)
    mask = np.zeros((27, 48, 1), np.float32)
    mask[5:20, 10:40] = 1.0
    o = oiio.ImageOutput.create(str(d / "mask.exr"))
    assert o.open(str(d / "mask.exr"), oiio.ImageSpec(48, 27, 1, oiio.FLOAT))
    o.write_image(mask)
    o.close()
    (d / "cuts.txt").write_text(f"{frames[3]}\n")
    rel = os.path.relpath(pattern, d)
    opts = ["--metering", "mask:mask.exr", "--cuts=cuts.txt", "--out-bits", "float"]
    _run(EXE + ["run", rel, "serial/o.####.exr", "-q", *opts], d)
    return d, rel, frames, opts


def _same(a, b, frames):
    for f in frames:
        pa = oiio.ImageBuf(frame_path(str(a), f)).get_pixels(oiio.FLOAT)
        pb = oiio.ImageBuf(frame_path(str(b), f)).get_pixels(oiio.FLOAT)
        assert pa is not None and pb is not None, f
        assert np.array_equal(pa, pb), f"frame {f}: differs from the serial run"


def _template(made, fmt, job):
    d, rel, frames, opts = made
    _run(EXE + ["farm-template", "--format", fmt, rel, f"farm_{fmt}/t.####.exr",
                "--chunk-frames", "4", *opts, "-o", job, "-q"], d)
    return d / job


def test_path_options_are_made_absolute(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    here = str(tmp_path)
    toks = ["--state-in", "a.json", "--state-out=b/s.json", "--colorconfig", "ocl-tonemap",
            "--colorconfig=ocio://default", "--metering", "mask:m.exr:mean", "--cuts",
            "detect", "--plot", "p.png", "--exposure", "1", "--visibility", "v.####.exr"]
    assert absolute_tokens(toks) == [
        "--state-in", f"{here}/a.json", f"--state-out={here}/b/s.json", "--colorconfig",
        "ocl-tonemap", "--colorconfig=ocio://default", "--metering",
        f"mask:{here}/m.exr:mean", "--cuts", "detect", "--plot", f"{here}/p.png",
        "--exposure", "1", "--visibility", f"{here}/v.####.exr"]
    assert absolute_tokens(["--colorconfig", "c.ocio", "--metering", "logmean"]) == \
        ["--colorconfig", f"{here}/c.ocio", "--metering", "logmean"]


@pytest.mark.requires_opencl
def test_openjd_steps_run_from_another_folder(made, tmp_path):
    d, rel, frames, _ = made
    doc = json.loads(_template(made, "openjd", "job.json").read_text())
    assert "workingDirectory" not in json.dumps(doc)
    command = next(p["default"] for p in doc["parameterDefinitions"]
                   if p["name"] == "OclTonemapCommand")
    elsewhere = tmp_path / "worker"
    elsewhere.mkdir()
    for step in doc["steps"]:                       # in dependency order, as listed
        args = step["script"]["actions"]["onRun"]["args"]
        assert args[1] == str(d / rel) and args[2] == str(d / "farm_openjd" / "t.####.exr")
        assert args[args.index("--store") + 1] == str(d / "farm_openjd" / "t.exr.shot")
        assert f"mask:{d}/mask.exr" in args and f"--cuts={d}/cuts.txt" in args, args
        space = step.get("parameterSpace")
        chunks = space["taskParameterDefinitions"][0]["range"] if space else [None]
        for c in chunks:
            argv = [a.replace("{{Task.Param.Chunk}}", c) if c else a for a in args]
            assert step["script"]["actions"]["onRun"]["command"] == \
                "{{Param.OclTonemapCommand}}" and command == "ocl-tonemap"
            _run(EXE + argv + ["-q"], elsewhere)
    assert not os.listdir(elsewhere)                 # nothing written where it ran
    _same(d / "serial" / "o.####.exr", d / "farm_openjd" / "t.####.exr", frames)


@pytest.mark.requires_opencl
def test_opencue_layers_run_from_another_folder(made, tmp_path):
    d, rel, frames, _ = made
    root = ET.parse(_template(made, "opencue", "job.xml")).getroot()
    elsewhere = tmp_path / "worker"
    elsewhere.mkdir()
    for layer in root.findall("job/layers/layer"):
        for argv in opencue_commands(layer):
            assert argv[0] == "ocl-tonemap"
            assert os.path.isabs(argv[2]) and os.path.isabs(argv[3]), argv
            assert os.path.isabs(argv[argv.index("--store") + 1]), argv
            assert f"mask:{d}/mask.exr" in argv and f"--cuts={d}/cuts.txt" in argv, argv
            _run(EXE + argv[1:] + ["-q"], elsewhere)
    assert not os.listdir(elsewhere)
    _same(d / "serial" / "o.####.exr", d / "farm_opencue" / "t.####.exr", frames)
