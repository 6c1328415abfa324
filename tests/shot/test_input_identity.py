"""A split shot's store keeps the identity of each input frame it measured (size,
modification time, BLAKE2b of the file): integrate, apply and export refuse an input
that changed since the measure pass, in one line naming the frames and the command
that mends it; measure run again measures just those frames (issue 65). The real
command line, in-process (``ocl_tonemap.cli.table.main``), on the reference backend."""

import json
import logging
import os
import shlex
import shutil

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import main
from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.shot.store import ShotStore

REF = ["--backend", "reference", "--out-bits", "float"]


@pytest.fixture(scope="module")
def tunnel(tmp_path_factory):
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("tunnel")
    pattern, frames = write_tunnel_sequence(str(d / "scene"), 48, 27, 8.0, 0.5)
    return pattern, frames


@pytest.fixture
def shot(tunnel, tmp_path):
    """(input pattern, output pattern, store, frames): the tunnel copied, so a test may
    replace its frames."""
    pattern, frames = tunnel
    scene = tmp_path / "in"
    shutil.copytree(os.path.dirname(pattern), scene)
    (tmp_path / "out").mkdir()
    return (str(scene / os.path.basename(pattern)), str(tmp_path / "out" / "o.####.exr"),
            str(tmp_path / "out" / "o.exr.shot"), frames)


def _pass(name, inp, out, *more):
    return main([name, inp, out, *REF, "-q", *more])


def _replace(path, gain=0.5):
    """The frame re-rendered: other pixels (the left half darker), renamed into place."""
    buf = oiio.ImageBuf(path)
    spec = buf.spec()
    px = buf.get_pixels(oiio.FLOAT)
    px[:, : spec.width // 2] *= gain
    new = oiio.ImageBuf(spec)
    new.set_pixels(oiio.ROI(0, spec.width, 0, spec.height, 0, 1, 0, spec.nchannels), px)
    tmp = path + ".new.exr"
    assert new.write(tmp)
    os.replace(tmp, path)


def _written(out):
    return sorted(p for p in os.listdir(os.path.dirname(out)) if p.endswith(".exr"))


def _error_line(err):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("ocl-tonemap ERROR: ") and "Traceback" not in err
    return lines[0]


def test_apply_and_export_refuse_a_frame_replaced_after_integrate(shot, capsys, tmp_path):
    inp, out, store, frames = shot
    assert _pass("measure", inp, out) == 0
    assert _pass("integrate", inp, out) == 0
    victim = frame_path(inp, frames[2])
    _replace(victim)
    capsys.readouterr()
    assert _pass("apply", inp, out) == 2
    line = _error_line(capsys.readouterr().err)
    assert f"frame {frames[2]} ({victim}) changed since the measure pass of {store}" in line
    assert (f"run the measure pass again ("
            f"{shlex.join(['ocl-tonemap', 'measure', inp, out, '--store', store])}, with this "
            "pass's other options; it measures only the changed frames), then integrate") in line
    assert _written(out) == []                                   # nothing written
    # a chunk after the changed frame is refused too (its start state came from it)
    assert _pass("apply", inp, out, "--chunk", f"{frames[3]}-{frames[3]}") == 2
    assert f"frame {frames[2]} " in _error_line(capsys.readouterr().err)
    assert _pass("export", inp, out, "--ocio-export", str(tmp_path / "ocio")) == 2
    assert f"frame {frames[2]} ({victim}) changed" in _error_line(capsys.readouterr().err)
    assert _written(out) == []


def test_integrate_refuses_a_frame_replaced_after_measure(shot, capsys):
    inp, out, store, frames = shot
    assert _pass("measure", inp, out) == 0
    for f in frames[:3] + frames[-1:]:
        _replace(frame_path(inp, f))
    capsys.readouterr()
    assert _pass("integrate", inp, out) == 2
    line = _error_line(capsys.readouterr().err)
    assert (f"frames {frames[0]} ({frame_path(inp, frames[0])}), {frames[1]} "
            f"({frame_path(inp, frames[1])}), {frames[2]} ({frame_path(inp, frames[2])}) "
            f"and 1 more changed since the measure pass of {store}") in line
    assert not ShotStore(store).integrated_path.exists()


def test_measured_again_just_the_changed_frame_equals_a_serial_run(shot, capsys, tmp_path):
    inp, out, store, frames = shot
    assert _pass("measure", inp, out) == 0
    assert _pass("integrate", inp, out) == 0
    victim = frame_path(inp, frames[1])
    _replace(victim, gain=3.0)
    capsys.readouterr()
    assert main(["measure", inp, out, *REF]) == 0
    assert f"measured 1 frame(s) into {store}" in capsys.readouterr().out
    # the new statistics invalidate the integrated states
    assert _pass("apply", inp, out) == 2
    assert "not been integrated" in capsys.readouterr().err
    doc = ShotStore(store).stats_document(frames[1])
    st = os.stat(victim)
    assert doc["input_stat"][:2] == [st.st_size, st.st_mtime_ns]
    assert _pass("integrate", inp, out) == 0 and _pass("apply", inp, out) == 0
    serial = str(tmp_path / "serial" / "o.####.exr")
    assert main(["run", inp, serial, *REF, "-q", "--no-checkpoint"]) == 0
    for f in frames:
        a = oiio.ImageBuf(frame_path(out, f))
        b = oiio.ImageBuf(frame_path(serial, f))
        assert np.array_equal(a.get_pixels(oiio.FLOAT), b.get_pixels(oiio.FLOAT)), f
        assert a.spec().getattribute("ocltm:state") == b.spec().getattribute("ocltm:state")


def test_a_touch_alone_is_not_a_change_and_old_stores_are_checked_by_stat(shot, capsys):
    """A new modification time with the content measured (its BLAKE2b) is used as
    measured; a document written before the hash (size and time only) is checked by
    its stat alone."""
    inp, out, store, frames = shot
    assert _pass("measure", inp, out) == 0
    assert _pass("integrate", inp, out) == 0
    doc = ShotStore(store).stats_document(frames[0])
    size, mtime, digest = doc["input_stat"]
    assert digest.startswith("blake2b:") and len(digest) == len("blake2b:") + 32
    touched = frame_path(inp, frames[0])
    os.utime(touched, ns=(mtime + 10**9, mtime + 10**9))
    assert _pass("apply", inp, out) == 0
    # a store of before: no hash in its documents nor its integrate record
    st = ShotStore(store)
    for f in frames:
        p = st.stats_path(f)
        d = json.loads(p.read_text())
        d["input_stat"] = d["input_stat"][:2]
        p.write_text(json.dumps(d))
    rec = json.loads(st.integrated_path.read_text())
    rec.pop("inputs", None)
    st.integrated_path.write_text(json.dumps(rec))
    capsys.readouterr()
    assert _pass("apply", inp, out) == 2                       # the stat alone differs
    assert f"frame {frames[0]} ({touched}) changed" in _error_line(capsys.readouterr().err)
    os.utime(touched, ns=(mtime, mtime))
    assert _pass("apply", inp, out) == 0
    assert _pass("integrate", inp, out) == 0


@pytest.mark.requires_opencl
def test_a_streamed_frame_keeps_its_identity(tmp_path, caplog):
    """A frame over --max-memory is measured in row bands: its statistics keep the
    input's identity as a whole frame's do."""
    from ocl_tonemap.io.sample import write_tunnel_sequence
    inp, frames = write_tunnel_sequence(str(tmp_path / "in"), 1280, 720, 8.0, 0.25)
    out = str(tmp_path / "out" / "o.####.exr")
    os.makedirs(os.path.dirname(out))
    with caplog.at_level(logging.INFO, logger="ocl_tonemap"):
        assert main(["measure", inp, out, "--max-memory", "8"]) == 0
    assert "streamed in bands" in caplog.text
    st = ShotStore(str(tmp_path / "out" / "o.exr.shot"))
    for f in frames:
        got = st.stats_document(f)["input_stat"]
        s = os.stat(frame_path(inp, f))
        assert got[:2] == [s.st_size, s.st_mtime_ns] and got[2].startswith("blake2b:")
