"""Faults: a full disk, hostile paths and numbers, damaged files, signals, two runs
at once. Each gives one ERROR line (exit 2) or the signal's exit code, never a
traceback, never a half-written file in place, and a resume gives the frames an
uninterrupted run gives (docs/reliability.md has the table)."""

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

from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.io.sample import write_tunnel_sequence


def _cli(args, env=None, timeout=600):
    e = dict(os.environ)
    e.update(env or {})
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, env=e, timeout=timeout)
    return p.returncode, p.stderr


def _one_error(rc, err, *words):
    assert rc == 2, err
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if "ERROR" in ln]
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], err
    return lines[0]


def _temps(d):
    return [n for n in os.listdir(d) if ".tmp" in n or n.endswith(".lock")]


def _pix(p):
    return oiio.ImageBuf(str(p)).get_pixels(oiio.FLOAT)


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    """12 frames of the tunnel sample at 160x90 (PNG outputs of ~10-20 KB)."""
    d = tmp_path_factory.mktemp("seq")
    return write_tunnel_sequence(str(d), 160, 90, 30.0, 0.4)


def _mount_tmpfs(d, size):
    """A tmpfs of ``size`` at ``d`` (root only); False where it cannot be made."""
    if os.geteuid() != 0 or not shutil.which("mount"):
        return False
    os.makedirs(d, exist_ok=True)
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)],
                       capture_output=True)
    return r.returncode == 0


# --- a full disk -------------------------------------------------------------------------

def test_full_disk_during_a_png_sequence_then_resume(seq, tmp_path):
    """A real full disk (a small tmpfs; needs root): exit 2 naming the frame, nothing
    short in place, no temporary left; after space is freed, --resume gives the frames
    of an uninterrupted run."""
    pattern, frames = seq
    ref = tmp_path / "ref"
    rc, err = _cli(["run", pattern, str(ref / "o.####.png"), "-q"])
    assert rc == 0, err
    full = tmp_path / "full"
    if not _mount_tmpfs(full, "96k"):
        pytest.skip("no tmpfs here (not root); the writer hook test covers the same path")
    try:
        rc, err = _cli(["run", pattern, str(full / "o.####.png"), "-q"])
        line = _one_error(rc, err, "frame", "no space left on device")
        bad = int(line.split(" frame ")[1].split(":")[0])
        assert frames[0] < bad <= frames[-1]
        assert not _temps(full)
        for f in frames:
            p = full / os.path.basename(frame_path(str(full / "o.####.png"), f))
            if f < bad or (f == bad and p.exists()):       # (its checkpoint may be what failed)
                np.testing.assert_array_equal(_pix(p), _pix(ref / p.name))
            else:
                assert not p.exists()
        ck = json.loads((full / "o.png.state.json").read_text())
        assert ck["frame"] < bad
        assert subprocess.run(["mount", "-o", "remount,size=16m", str(full)]).returncode == 0
        rc, err = _cli(["run", pattern, str(full / "o.####.png"), "-q", "--resume"])
        assert rc == 0, err
        for f in frames:
            name = os.path.basename(frame_path(str(full / "o.####.png"), f))
            np.testing.assert_array_equal(_pix(full / name), _pix(ref / name))
    finally:
        subprocess.run(["umount", "-l", str(full)])


def test_a_jpeg_on_a_full_disk_is_one_line_not_libjpegs_exit(seq, tmp_path):
    """libjpeg ends the process on a failed write (exit 1, its temporary left, its own
    message): a JPEG is written only where the disk has room for its pixels."""
    pattern, _ = seq
    full = tmp_path / "full"
    if not _mount_tmpfs(full, "64k"):
        pytest.skip("no tmpfs here (not root)")
    try:
        rc, err = _cli(["run", pattern, str(full / "o.####.jpg"), "-q", "--no-checkpoint"])
        _one_error(rc, err, "no space left on device", "frame")
        assert "Output file write error" not in err
        assert not _temps(full)
    finally:
        subprocess.run(["umount", "-l", str(full)])


@pytest.mark.parametrize("ext,n", [(".png", 3), (".exr", 2), (".png", 4)])
def test_a_failed_write_is_named_cleaned_up_and_resumed(seq, tmp_path, ext, n):
    """The writer hook (``OCL_TONEMAP_FAIL_WRITE=N``: the N-th commit of the process
    fails as ENOSPC) on an image or a checkpoint: exit 2, the file and frame named,
    no temporary left, the checkpoint not past what was written, and the resume equal
    to an uninterrupted run."""
    pattern, frames = seq
    out = f"o.####{ext}"
    ref, d = tmp_path / "ref", tmp_path / "run"
    assert _cli(["run", pattern, str(ref / out), "-q"])[0] == 0
    rc, err = _cli(["run", pattern, str(d / out), "-q"], {"OCL_TONEMAP_FAIL_WRITE": str(n)})
    _one_error(rc, err, "no space left on device", "frame")
    assert not _temps(d)
    written = sorted(glob.glob(str(d / f"o.*{ext}")))
    ckpt = d / f"o{ext}.state.json"
    if ckpt.exists():                                           # never past what is there
        assert json.loads(ckpt.read_text())["frame"] <= frames[len(written) - 1]
    rc, err = _cli(["run", pattern, str(d / out), "-q", "--resume"])
    assert rc == 0, err
    for f in frames:
        name = os.path.basename(frame_path(out, f))
        np.testing.assert_array_equal(_pix(d / name), _pix(ref / name))


def test_a_truncated_write_is_caught_by_reading_it_back(tmp_path):
    """verify_written: a file cut short (what libpng leaves on a full disk without an
    error) is refused and removed."""
    from ocl_tonemap.io.imageio import FrameError
    from ocl_tonemap.io.imagewrite import verify_written
    p = tmp_path / ".x.tmp1.png"
    buf = oiio.ImageBuf(oiio.ImageSpec(64, 48, 3, oiio.UINT8))
    buf.set_pixels(oiio.ROI(0, 64, 0, 48, 0, 1, 0, 3),
                   np.random.default_rng(0).random((48, 64, 3)).astype(np.float32))
    assert buf.write(str(p))
    verify_written(str(p), "x.png", 7, 64, 48, 3)             # whole: accepted
    data = p.read_bytes()
    p.write_bytes(data[:len(data) // 2])
    with pytest.raises(FrameError, match="frame 7"):
        verify_written(str(p), "x.png", 7, 64, 48, 3)
    assert not p.exists()


# --- refusals and limits -------------------------------------------------------------

def test_plot_onto_an_input_or_output_is_refused(seq, tmp_path):
    pattern, frames = seq
    first = frame_path(pattern, frames[0])
    before = open(first, "rb").read()
    rc, err = _cli(["run", pattern, str(tmp_path / "o.####.png"), "-q", "--plot", first])
    _one_error(rc, err, "--plot would overwrite")
    assert open(first, "rb").read() == before
    rc, err = _cli(["run", first, str(tmp_path / "o.png"), "-q", "--plot",
                    str(tmp_path / "o.png")])
    _one_error(rc, err, "--plot would overwrite")


@pytest.mark.parametrize("flag", ["--cuts", "--state-in"])
def test_dev_zero_and_fifos_end_at_once(seq, tmp_path, flag):
    pattern, _ = seq
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    for src, word in (("/dev/zero", "/dev/zero: is a character device, not a file"),
                      (str(fifo), f"{fifo}: is a named pipe (FIFO), not a file")):
        # refused from stat (never opened: a FIFO's open would block); the timeout of
        # _cli only keeps a hang from holding the suite
        rc, err = _cli(["run", pattern, str(tmp_path / "o.####.png"), "-q", flag, src])
        _one_error(rc, err, word)


def test_huge_frame_ranges_and_paddings_end_at_once(seq, tmp_path):
    pattern, _ = seq
    rc, err = _cli(["run", pattern, str(tmp_path / "o.####.png"), "-q", "--frames",
                    "1-100000000"])
    _one_error(rc, err, "--frames")
    rc, err = _cli(["run", pattern, str(tmp_path / "o.%99999999d.png"), "-q"])
    _one_error(rc, err, "padding")
    rc, err = _cli(["run", pattern, str(tmp_path / "o.####.png"), "-q", "--frames",
                    "1-100000"])
    _one_error(rc, err, "not on disk")
    assert not [p for p in os.listdir(tmp_path) if p.startswith("o")]   # refused before any work


@pytest.mark.parametrize("args,words", [
    (["--preadapt", "1e308"], ("--preadapt", "1e+08")),
    (["--preadapt", "10:1e99"], ("--preadapt", "SECONDS must be 0..1e+07 s")),
    (["--luminance-scale", "auto:1e12"], ("auto:LEVEL", "must be 1e-06..1e+08")),
    (["--fps", "nan"], ("--fps",)),
])
def test_numbers_outside_their_physical_range_are_refused(seq, tmp_path, args, words):
    pattern, _ = seq
    rc, err = _cli(["run", pattern, str(tmp_path / "o.####.png"), "-q", *args])
    _one_error(rc, err, *words)
    assert not os.listdir(tmp_path)


@pytest.mark.slow
def test_many_channels_are_not_read(tmp_path):
    """A 1200x1200 EXR with 400 channels (R, G, B and 397 AOVs): only R, G, B are read;
    the run stays under 2 GiB (it took 5.5 GiB reading them all)."""
    n = 400
    spec = oiio.ImageSpec(1200, 1200, n, oiio.HALF)
    spec.channelnames = ("R", "G", "B") + tuple(f"aov{i}" for i in range(n - 3))
    spec.attribute("compression", "zip")
    out = oiio.ImageOutput.create(str(tmp_path / "aov.exr"))
    assert out.open(str(tmp_path / "aov.exr"), spec)
    row = np.zeros((16, 1200, n), np.float16)
    row[..., :3] = 0.18
    for y in range(0, 1200, 16):
        assert out.write_scanlines(y, y + 16, 0, row)
    out.close()
    code = ("import resource, sys; from ocl_tonemap.__main__ import entry; rc = entry(); "
            "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr); "
            "sys.exit(rc)")
    p = subprocess.run([sys.executable, "-c", code, "run", str(tmp_path / "aov.exr"),
                        str(tmp_path / "o.png"), "-q", "--luminance-scale", "100"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    peak_mib = int(p.stderr.strip().splitlines()[-1]) / 1024
    assert peak_mib < 2048, peak_mib
    assert _pix(tmp_path / "o.png").shape == (1200, 1200, 3)


# --- damaged and hostile files ----------------------------------------------------------

def test_a_store_reads_only_files_inside_itself(seq, tmp_path):
    pattern, frames = seq
    store = tmp_path / "store"
    args = [pattern, str(tmp_path / "o.####.png"), "-q", "--operator", "ledda04",
            "--store", str(store)]
    assert _cli(["measure", *args])[0] == 0
    doc_path = store / "stats" / f"{frames[0]:08d}.json"
    doc = json.loads(doc_path.read_text())
    assert doc.get("planes")
    outside = tmp_path / "elsewhere.exr"
    shutil.copy(store / "stats" / doc["planes"], outside)
    for bad in (str(outside), "../../elsewhere.exr", "../" + doc["planes"]):
        doc["planes"] = bad
        doc_path.write_text(json.dumps(doc))
        rc, err = _cli(["integrate", *args])
        _one_error(rc, err, str(doc_path))


@pytest.mark.parametrize("edit", [
    lambda d: d.pop("G_cone"), lambda d: d.update(width="wide"),
    lambda d: d.update(repairs={"nan": "x", "bogus": 1}), lambda d: d.update(plan={"x": 1}),
    lambda d: d.update(values=[1, 2]), lambda d: d.update(time_s=None),
    lambda d: d.update(scene_max_Y="x"), lambda d: d.update(scene_max_Y=True),
    lambda d: d.update(scene_goal=[1.0]), lambda d: d.update(scene_repairs={"nan": 0.5}),
])
def test_damaged_store_documents_give_one_line(seq, tmp_path, edit):
    pattern, frames = seq
    store = tmp_path / "store"
    args = [pattern, str(tmp_path / "o.####.png"), "-q", "--store", str(store)]
    assert _cli(["measure", *args])[0] == 0
    p = store / "stats" / f"{frames[2]:08d}.json"
    doc = json.loads(p.read_text())
    edit(doc)
    p.write_text(json.dumps(doc))
    rc, err = _cli(["integrate", *args])
    _one_error(rc, err)


@pytest.mark.parametrize("extra", [{"pixel_state": 123}, {"pixel_state": "../x.exr"},
                                   {"plan": {"weights": {"flare": "on"}}},
                                   {"illuminant_rgb": [1, 2]}, {"purkinje_levels": 3}])
def test_a_mangled_state_gives_one_line(seq, tmp_path, extra):
    pattern, _ = seq
    st = {"format": "ocl-tonemap.adaptation-state/1", "operator": "pattanaik00",
          "values": {}, "time_s": 0.0, "frame": 1, "extra": extra}
    (tmp_path / "s.json").write_text(json.dumps(st))
    rc, err = _cli(["run", pattern, str(tmp_path / "o.####.png"), "-q", "--state-in",
                    str(tmp_path / "s.json")])
    _one_error(rc, err, "s.json")


def test_an_unparseable_lut_in_a_config_gives_one_line(seq, tmp_path):
    pattern, frames = seq
    (tmp_path / "bad.cube").write_text("this is not a LUT\n1 2\n")
    (tmp_path / "config.ocio").write_text(f"""ocio_profile_version: 2
search_path: {tmp_path}
roles:
  default: lin
  scene_linear: lin
displays:
  sRGB:
    - !<View> {{name: Raw, colorspace: out}}
colorspaces:
  - !<ColorSpace>
    name: lin
  - !<ColorSpace>
    name: out
    from_scene_reference: !<FileTransform> {{src: bad.cube}}
""")
    rc, err = _cli(["run", frame_path(pattern, frames[0]), str(tmp_path / "o.png"), "-q",
                    "--colorconfig", str(tmp_path / "config.ocio"), "--display", "sRGB",
                    "--view", "Raw"])
    _one_error(rc, err)
    assert not (tmp_path / "o.png").exists()


def test_resume_checks_the_settings_after_a_finished_state_out_run(seq, tmp_path):
    pattern, _ = seq
    args = [pattern, str(tmp_path / "o.####.png"), "-q", "--state-out", str(tmp_path / "s.json")]
    assert _cli(["run", *args])[0] == 0
    rc, err = _cli(["run", *args, "--resume", "--exposure", "1"])
    _one_error(rc, err, "other settings", "exposure")


# --- two runs, signals --------------------------------------------------------------------

def test_a_second_run_on_the_same_outputs_is_refused(seq, tmp_path):
    from ocl_tonemap.job.checkpoint import RunLock
    pattern, _ = seq
    with RunLock(str(tmp_path / "o.png.state.json")):
        rc, err = _cli(["run", pattern, str(tmp_path / "o.####.png"), "-q"])
    _one_error(rc, err, "another ocl-tonemap run", f"pid {os.getpid()}")
    assert not glob.glob(str(tmp_path / "o.*.png"))
    assert _cli(["run", pattern, str(tmp_path / "o.####.png"), "-q"])[0] == 0
    assert not _temps(tmp_path)


def test_a_signal_a_library_turned_into_an_import_error_while_the_parser_is_made(
        monkeypatch, capsys):
    """A SIGTERM that lands inside NumPy's first import (made while the command's parser
    is built, before the run's own error handling) comes out of NumPy as an ImportError
    ("PyCapsule_Import could not import module 'datetime'", seen on a loaded machine):
    still one line and exit 143, never a traceback. Without a signal the error is
    the library's, raised as it was."""
    from ocl_tonemap.base import interrupts
    from ocl_tonemap.cli import table as cli

    def broken(*a, **k):
        raise ImportError("PyCapsule_Import could not import module \"datetime\"")
    monkeypatch.setattr(cli, "build_parser", broken)
    monkeypatch.setattr(interrupts, "received", signal.SIGTERM)
    assert cli.main(["run", "a.exr", "b.png"]) == 143
    assert capsys.readouterr().err.strip() == "ocl-tonemap: interrupted"
    monkeypatch.setattr(interrupts, "received", 0)
    with pytest.raises(ImportError):
        cli.main(["run", "a.exr", "b.png"])


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _started(args, ready_file, sigint_ignored: bool = False):
    """The command in a process of its own, its readiness notes in ``ready_file``
    (``interrupts.ready``, ``$OCLTM_TEST_READY``), with SIGINT at its default as a
    terminal starts it: a test run itself started in the background of a script
    (``cmd &``, where the shell ignores SIGINT and its children inherit that) would
    otherwise start a command that rightly ignores Ctrl-C (``sigint_ignored``)."""
    env = {**os.environ, "OCLTM_TEST_READY": str(ready_file)}
    return subprocess.Popen([sys.executable, "-m", "ocl_tonemap", *args],
                            stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=None if sigint_ignored else _default_sigint)


def _wait_for(p, ready_file, mark: str) -> bool:
    """Until the command has noted ``mark`` (True) or has ended (False): no deadline,
    however busy the machine."""
    while p.poll() is None:
        if ready_file.exists() and mark in ready_file.read_text():
            return True
        time.sleep(0.005)
    return False


@pytest.mark.parametrize("mark", ["handlers", "written"])
def test_signals_exit_130_and_143_in_one_line(seq, tmp_path, mark):
    """A signal once the command's handlers are in (``handlers``: the first thing it
    does; ``written``: a frame is on disk, mid-run): exit 130 / 143 and one line, never
    a traceback, nothing half-written. The test waits for the command's own note of
    where it is, not for a guessed delay."""
    pattern, _ = seq
    for sig, code in ((signal.SIGINT, 130), (signal.SIGTERM, 143)):
        ready = tmp_path / f"ready-{mark}-{sig}"
        p = _started(["run", pattern, str(tmp_path / f"o{sig}.####.png"), "-q",
                      "--operator", "ledda04"], ready)
        noted = _wait_for(p, ready, mark)
        p.send_signal(sig)
        _, err = p.communicate()
        assert "Traceback" not in err, err
        if noted or p.returncode != 0:            # (0: it had finished before the note)
            assert p.returncode == code, (p.returncode, err)
            lines = err.strip().splitlines()
            assert lines[0].startswith("ocl-tonemap: "), err
            # mid-run: the line says where it stopped, the next one how to resume
            assert lines[1:] in ([], [lines[-1]]) and (len(lines) == 1 or
                                                       lines[1].strip().endswith("--resume")), err
    assert not _temps(tmp_path)


def test_a_signal_that_cuts_the_lock_release_short_leaves_no_lock_file(tmp_path, monkeypatch):
    """A SIGTERM landing as a run ends may cut ``RunLock.__exit__`` short (seen under
    load: 1 run in 10 left ``.o.png.state.json.lock``); the command's exit releases the
    locks still held (``release_held``, from ``cli.main`` and the entry point), and
    ``ignore_for_exit`` then drops signals for good."""
    from ocl_tonemap.base.interrupts import Terminated, ignore_for_exit
    from ocl_tonemap.job import checkpoint
    lock = checkpoint.RunLock(str(tmp_path / "o.png.state.json"))
    real_unlink, cut = os.unlink, []

    def unlink(p):                        # the signal's exception, before the unlink
        if not cut:
            cut.append(p)
            raise Terminated(signal.SIGTERM)
        real_unlink(p)
    with pytest.raises(Terminated):
        with lock:
            monkeypatch.setattr(os, "unlink", unlink)
    assert cut and os.path.exists(lock.path)
    checkpoint.release_held()
    assert not os.path.exists(lock.path) and not checkpoint._HELD
    # cut short after the unlink and the close, before it forgot the descriptor
    lock = checkpoint.RunLock(str(tmp_path / "o.png.state.json"))
    real_close = os.close

    def close(fd):
        real_close(fd)
        raise Terminated(signal.SIGTERM)
    with pytest.raises(Terminated):
        with lock:
            monkeypatch.setattr(os, "close", close)
    monkeypatch.setattr(os, "close", real_close)
    checkpoint.release_held()                     # nothing left to do, no EBADF
    assert not os.path.exists(lock.path) and not checkpoint._HELD
    monkeypatch.undo()
    old = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    try:
        ignore_for_exit()
        signal.raise_signal(signal.SIGTERM)       # ignored now
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, old[0])
        signal.signal(signal.SIGINT, old[1])


def test_a_command_started_with_sigint_ignored_keeps_ignoring_it(seq, tmp_path):
    """``nohup``, ``cmd &`` in a script: SIGINT ignored when the command starts stays
    ignored (as Python itself and every shell tool do); SIGTERM still stops it in one
    line, 143."""
    pattern, frames = seq
    ready = tmp_path / "ready"
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        p = _started(["run", pattern, str(tmp_path / "o.####.png"), "-q",
                      "--operator", "ledda04"], ready, sigint_ignored=True)
    finally:
        signal.signal(signal.SIGINT, old)
    noted = _wait_for(p, ready, "written")
    p.send_signal(signal.SIGINT)
    noted_after = _wait_for(p, ready, f"written {frames[-1]}") if noted else False
    if noted and p.poll() is None:
        p.send_signal(signal.SIGTERM)
    _, err = p.communicate()
    assert "Traceback" not in err, err
    if noted_after:                  # the SIGINT was ignored: every frame was written
        assert p.returncode in (0, 143), (p.returncode, err)
    assert p.returncode != 130, err
    assert not _temps(tmp_path)


def test_a_signal_before_the_command_runs_is_pythons_own(seq, tmp_path):
    """A signal sent the moment the process starts may land before any code of ours
    (the interpreter's start-up, runpy compiling ``ocl_tonemap/__main__``): then it is
    the interpreter's own reaction -- SIGTERM's default kills it (-15), SIGINT raises
    Python's KeyboardInterrupt, printed by Python and ending in that one word -- which
    no program can change. Once the handlers are in: 130 / 143 in one line. Either way
    nothing of a run is left."""
    pattern, _ = seq
    for sig, code in ((signal.SIGINT, 130), (signal.SIGTERM, 143)):
        p = _started(["run", pattern, str(tmp_path / "o.####.png"), "-q"], tmp_path / "r")
        p.send_signal(sig)
        _, err = p.communicate()
        if "Traceback" in err:                    # Python's own, before our handlers
            assert sig == signal.SIGINT and err.rstrip().endswith("KeyboardInterrupt"), err
            assert p.returncode in (1, -signal.SIGINT), p.returncode
        else:
            assert p.returncode in (code, -sig, 0), (p.returncode, err)
            assert len(err.strip().splitlines()) <= 1, err
    assert not _temps(tmp_path)


def test_a_second_sigterm_mid_run_exits_143_and_leaves_nothing_half_written(seq, tmp_path):
    pattern, frames = seq
    ready = tmp_path / "ready"
    p = _started(["run", pattern, str(tmp_path / "o.####.png"), "-q", "--operator",
                  "ledda04"], ready)
    _wait_for(p, ready, "written")
    p.send_signal(signal.SIGTERM)
    p.send_signal(signal.SIGTERM)
    _, err = p.communicate()
    assert p.returncode in (143, 0), err
    assert "Traceback" not in err
    assert not _temps(tmp_path)
    for f in glob.glob(str(tmp_path / "o.*.png")):
        assert _pix(f).shape == (90, 160, 3)


# --- newcomers' surprises -------------------------------------------------------------------

def test_output_folder_is_made_and_a_still_leaves_no_side_files(seq, tmp_path):
    pattern, frames = seq
    out = tmp_path / "new" / "deeper" / "o.png"
    rc, err = _cli(["run", frame_path(pattern, frames[0]), str(out), "-q"])
    assert rc == 0, err
    assert sorted(os.listdir(out.parent)) == ["o.png"]
    spec = oiio.ImageInput.open(str(out)).spec()
    assert json.loads(spec.getattribute("ocltm:state"))["operator"] == "pattanaik00"


def test_tiff_outputs_carry_the_record_and_serve_as_state_in(seq, tmp_path):
    from ocl_tonemap.io.imagewrite import ocltm_metadata
    pattern, frames = seq
    out = tmp_path / "o.tif"
    assert _cli(["run", frame_path(pattern, frames[0]), str(out), "-q"])[0] == 0
    inp = oiio.ImageInput.open(str(out))
    meta = ocltm_metadata(inp.spec())
    cs = inp.spec().getattribute("oiio:ColorSpace")
    inp.close()
    assert meta["ocltm:operator"] == "pattanaik00" and "ocltm:state" in meta and cs
    rc, err = _cli(["run", frame_path(pattern, frames[1]), str(tmp_path / "p.png"), "-q",
                    "--state-in", str(out)])
    assert rc == 0, err


def test_integer_bits_to_exr_are_refused(seq, tmp_path):
    pattern, frames = seq
    rc, err = _cli(["run", frame_path(pattern, frames[0]), str(tmp_path / "o.exr"), "-q",
                    "--out-bits", "8"])
    _one_error(rc, err, "--out-bits 8", "half or float")


def test_auto_level_overruled_by_the_files_calibration_is_said_once(seq, tmp_path):
    pattern, frames = seq                       # the sample carries whiteLuminance
    rc, err = _cli(["run", pattern, str(tmp_path / "o.####.png"), "--luminance-scale",
                    "auto:interior"])
    assert rc == 0, err
    assert err.count("auto:interior is not used") == 1, err


def test_simulate_plots_and_labels_its_times_in_order(seq, tmp_path):
    pattern, frames = seq
    rc = subprocess.run([sys.executable, "-m", "ocl_tonemap", "simulate",
                         frame_path(pattern, frames[-1]), str(tmp_path / "s.png"),
                         "--preadapt", "1000", "--at", "30,1,5", "--plot",
                         str(tmp_path / "plot.png")], capture_output=True, text=True)
    assert rc.returncode == 0, rc.stderr
    lines = [ln for ln in rc.stdout.splitlines() if ln.startswith("t = ")]
    assert [ln.split()[2] for ln in lines] == ["1", "5", "30"]
    for ln in lines:                                   # each time names its own file
        assert f"_t{int(ln.split()[2]):04d}s" in ln, lines
    assert (tmp_path / "plot.png").stat().st_size > 1000


def test_a_resumed_runs_plot_covers_the_whole_shot(seq, tmp_path):
    from ocl_tonemap.io.patterns import find_frames
    from ocl_tonemap.job.run import infos_from_outputs
    pattern, frames = seq
    out = str(tmp_path / "o.####.exr")
    rc, err = _cli(["run", pattern, out, "-q", "--frames", f"{frames[0]}-{frames[5]}"])
    assert rc == 0, err
    jobs = [(f, frame_path(pattern, f), frame_path(out, f), False) for f in find_frames(out)]
    infos = infos_from_outputs(jobs)
    assert [i.frame for i in infos] == frames[:6]
    assert all(i.G_cone > 0 and "A_cone" in i.state.values for i in infos)


def test_colour_pipeline_takes_what_colorconfig_takes():
    from ocl_tonemap.colour import ColourPipeline
    cp = ColourPipeline("ocio://default")
    assert cp.display and cp.view
