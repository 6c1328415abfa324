"""Read-ahead and write-behind (job/overlap.py FrameIO): the next frames are read and
the last ones encoded and written on ``--threads`` threads while the device works.
The frames, their metadata and the checkpoints are those of the serial run; a failure
is reported at its own frame, with the frames before it complete and no checkpoint
past it."""

import json
import os
import shutil
import threading

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import main
from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.io.sample import write_tunnel_sequence


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    d = tmp_path_factory.mktemp("seq")
    return write_tunnel_sequence(str(d), 48, 27, 30.0, 0.3)


def _meta(path):
    spec = oiio.ImageBuf(str(path)).spec()
    return {a.name: spec.getattribute(a.name) for a in spec.extra_attribs
            if a.name.startswith("ocltm:")}


@pytest.mark.parametrize("op, ext, threads", [("pattanaik00", ".png", "2"),
                                              ("ledda04", ".exr", "2"),
                                              ("pattanaik00", ".png", "4"),
                                              ("kirk11", ".tif", "5")])
def test_overlapped_io_equals_serial(seq, tmp_path, op, ext, threads):
    pattern, frames = seq
    runs = {}
    for mode, extra in (("serial", ["--serial-io"]), ("overlap", ["--threads", threads])):
        d = tmp_path / mode
        d.mkdir()
        out = str(d / f"o.####{ext}")
        assert main(["run", pattern, out, "--operator", op, "-q", *extra]) == 0
        runs[mode] = (d, out)
    (ds, os_), (do, oo) = runs["serial"], runs["overlap"]
    for f in frames:
        a, b = frame_path(os_, f), frame_path(oo, f)
        np.testing.assert_array_equal(oiio.ImageBuf(b).get_pixels(oiio.FLOAT),
                                      oiio.ImageBuf(a).get_pixels(oiio.FLOAT))
        assert _meta(a) == _meta(b)
    ca = json.loads((ds / f"o{ext}.state.json").read_text())
    cb = json.loads((do / f"o{ext}.state.json").read_text())
    for c in (ca, cb):                        # (the output path differs, and the side
        c["extra"].pop("pixel_state", None)    # file's name)
        c["extra"]["run"].pop("output")
    assert ca == cb and ca["frame"] == frames[-1]


def _with_a_bad_frame(seq, tmp_path, frame):
    """A copy of the sequence whose ``frame`` is garbage: (its pattern, that file)."""
    pattern, _ = seq
    d = tmp_path / "in"
    shutil.copytree(os.path.dirname(pattern), d)
    pat = str(d / os.path.basename(pattern))
    bad = frame_path(pat, frame)
    with open(bad, "wb") as fh:
        fh.write(b"garbage")
    return pat, bad


def test_bad_frame_while_the_last_one_is_written(seq, tmp_path, capsys):
    """Frame 4 cannot be read (its read ran ahead, on the reader thread): the error
    names it; frames 1-3 are written whole and the checkpoint is frame 3's."""
    _, frames = seq
    pat, bad = _with_a_bad_frame(seq, tmp_path, frames[3])
    out = str(tmp_path / "o.####.png")
    assert main(["run", pat, out, "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("ocl-tonemap ERROR") == 1 and f"{bad} frame {frames[3]}:" in err
    for f in frames[:3]:
        assert oiio.ImageBuf(frame_path(out, f)).get_pixels(oiio.FLOAT).shape == (27, 48, 3)
    assert not os.path.exists(frame_path(out, frames[3]))
    st = json.loads((tmp_path / "o.png.state.json").read_text())
    assert st["frame"] == frames[2]
    assert not [p for p in os.listdir(tmp_path) if ".tmp" in p]


@pytest.mark.parametrize("threads", ["2", "6"])
def test_write_failure_is_named_at_its_frame(seq, tmp_path, capsys, threads):
    """Frame 2's output cannot be written (a folder stands in its place): the error
    names that output and frame, frame 1 is complete and its checkpoint written (with
    several writers too: no checkpoint counts a frame past a failed one), and with
    one writer nothing after frame 2 is left; --resume then makes the rest."""
    pattern, frames = seq
    out = str(tmp_path / "o.####.png")
    os.mkdir(frame_path(out, frames[1]))
    assert main(["run", pattern, out, "-q", "--threads", threads]) == 2
    err = capsys.readouterr().err
    assert err.count("ocl-tonemap ERROR") == 1
    assert f"frame {frames[1]}" in err
    assert os.path.isfile(frame_path(out, frames[0]))
    assert json.loads((tmp_path / "o.png.state.json").read_text())["frame"] == frames[0]
    if threads == "2":
        assert not any(os.path.exists(frame_path(out, f)) for f in frames[2:])
    assert not [p for p in os.listdir(tmp_path) if ".tmp" in p]
    os.rmdir(frame_path(out, frames[1]))
    assert main(["run", pattern, out, "-q", "--threads", threads, "--resume"]) == 0
    assert all(os.path.isfile(frame_path(out, f)) for f in frames)


def test_the_first_frame_is_read_while_the_run_sets_up(seq, tmp_path, capsys, monkeypatch):
    """The first frame's read starts before the device is probed and the run is set up
    (on the reader thread), the device's kernels are made while it is still being read
    (``prepare_kernels``, stopped by its end), and it goes
    into memory the next frames use again: a sequence reads into two arrays in all
    (nothing the run keeps holds the first frame's read).
    Its failure is still reported at its turn: a run that cannot be set up says why
    (one ERROR line, not the frame's), and a bad first frame is named when the run is."""
    from ocl_tonemap.job import run as job_run
    pattern, frames = seq
    made, order = [], []
    real_read, real_setup = job_run.read_frame, job_run.setup_run
    prepared = threading.Event()

    def read(path, frame=None, channels=None, pool=None, **kw):
        order.append(("read", frame))
        fr = real_read(path, frame, channels, pool, **kw)
        made.append(pool.made)
        if frame == frames[0]:        # a large first frame: still read when the kernels
            prepared.wait(600)        # are made (the wait's limit: only against a hang)
        return fr

    def prepare(tm, key, stop):
        order.append(("prepare", stop()))
        prepared.set()
        return real_prepare(tm, key, stop)

    def setup(*a, **k):
        order.append(("setup", None))
        return real_setup(*a, **k)

    def resolve(*a, **k):
        order.append(("device", None))
        return real_resolve(*a, **k)
    def prefetch(self, key, fn):
        order.append(("prefetch", key))
        return real_prefetch(self, key, fn)
    real_resolve, real_prefetch = job_run.resolve_backend, job_run.FrameIO.prefetch
    real_prepare = job_run.prepare_kernels
    monkeypatch.setattr(job_run, "prepare_kernels", prepare)
    monkeypatch.setattr(job_run.FrameIO, "prefetch", prefetch)
    monkeypatch.setattr(job_run, "read_frame", read)
    monkeypatch.setattr(job_run, "setup_run", setup)
    monkeypatch.setattr(job_run, "resolve_backend", resolve)
    out = str(tmp_path / "o.####.png")
    assert main(["run", pattern, out, "-q"]) == 0
    # the OpenCL device is probed (cli: "auto") and the run set up behind the read
    main_thread = [o for o in order if o[0] != "read"]
    assert main_thread[:4] == [("prefetch", 0), ("device", None), ("setup", None),
                               ("prepare", False)]
    assert [o for o in order if o[0] == "read"][0] == ("read", frames[0])
    assert len(made) == len(frames) and made[-1] <= 2 < len(frames)
    monkeypatch.undo()

    pat, bad = _with_a_bad_frame(seq, tmp_path, frames[0])
    capsys.readouterr()
    assert main(["run", pat, str(tmp_path / "b.####.exr"), "--out-bits", "8", "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("ocl-tonemap ERROR") == 1 and "--out-bits 8" in err and bad not in err
    assert main(["run", pat, str(tmp_path / "b.####.png"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("ocl-tonemap ERROR") == 1 and f"{bad} frame {frames[0]}:" in err
    assert not [p for p in os.listdir(tmp_path) if p.startswith("b.")]
