"""Nothing blocks past a signal, and the errors are in our words (issue 58, parts 3
and 4): what the command opens that is not a regular file (a FIFO) is refused before
it is opened, in one line; a run blocked anywhere ends within 2 s of SIGTERM with
exit 143; OIIO's and OCIO's errors are read and reworded, nothing printed at exit."""

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import OpenImageIO as oiio
import pytest

from conftest import said
from ocl_tonemap.io.patterns import frame_path

#: Only keeps a hang from holding the suite; nothing here should come near it.
HANG = 60

FIFO_LINE = "is a named pipe (FIFO), not a file"
PENDING = "pending error"


def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _cli(args, env=None, cwd=None):
    e = dict(os.environ)
    e.update(env or {})
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, env=e, cwd=cwd, timeout=HANG)
    return p.returncode, p.stdout, p.stderr


def _only_error(rc, err, *words):
    """Exit 2 and stderr of exactly one line, the ERROR line, holding ``words``."""
    assert rc == 2, err
    lines = said(err)
    assert len(lines) == 1, err
    assert lines[0].startswith("ocl-tonemap ERROR: "), err
    for w in words:
        assert w in lines[0], err
    assert PENDING not in err and "Traceback" not in err
    return lines[0]


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    """A short sequence of 6 frames (EXR, cd/m^2), 32x18."""
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("seq")
    pattern, frames = write_tunnel_sequence(str(d), 32, 18, 10.0, 0.6)
    return pattern, frames


def _fifo(path):
    os.mkfifo(path)
    return str(path)


# --- A FIFO where a file is expected: refused before it is opened -----------------------

def test_a_fifo_input_still_is_refused(tmp_path):
    fifo = _fifo(tmp_path / "in.exr")
    t0 = time.monotonic()
    rc, _, err = _cli(["run", fifo, str(tmp_path / "o.png")])
    line = _only_error(rc, err, FIFO_LINE)
    assert line == f"ocl-tonemap ERROR: {fifo}: {FIFO_LINE}"
    assert time.monotonic() - t0 < HANG / 2
    assert sorted(os.listdir(tmp_path)) == ["in.exr"]          # nothing made


def test_a_fifo_in_the_middle_of_a_sequence_is_refused_before_any_frame(seq, tmp_path):
    pattern, frames = seq
    d = tmp_path / "in"
    d.mkdir()
    for f in frames:
        shutil.copy(frame_path(pattern, f), d)
    mid = frames[len(frames) // 2]
    mid_path = d / os.path.basename(frame_path(pattern, mid))
    mid_path.unlink()
    _fifo(mid_path)
    out = tmp_path / "out"
    rc, _, err = _cli(["run", str(d / os.path.basename(pattern)), str(out / "o.####.png")])
    _only_error(rc, err, str(mid_path), f"frame {mid}", FIFO_LINE)
    assert not out.exists() or not os.listdir(out)              # no frame made before it


@pytest.mark.parametrize("where", ["mask", "colorconfig", "OCIO", "state-in", "resume",
                                   "cuts"])
def test_a_fifo_mask_config_or_state_is_refused(seq, tmp_path, where):
    pattern, frames = seq
    out = str(tmp_path / "o.####.png")
    args, env = ["run", pattern, out], {}
    if where == "resume":
        fifo = _fifo(tmp_path / "o.png.state.json")             # the checkpoint's name
        args.append("--resume")
    else:
        fifo = _fifo(tmp_path / {"mask": "mask.exr", "colorconfig": "fifo.ocio",
                                 "OCIO": "env.ocio", "state-in": "s.json",
                                 "cuts": "cuts.txt"}[where])
        if where == "mask":
            args += ["--metering", f"mask:{fifo}"]
        elif where == "OCIO":
            env["OCIO"] = fifo
        else:
            args += [f"--{where}", fifo]
    rc, _, err = _cli(args, env)
    _only_error(rc, err, fifo, FIFO_LINE)
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".png")]


def test_a_folder_where_a_file_is_expected_is_refused(tmp_path):
    d = tmp_path / "notafile.exr"
    d.mkdir()
    rc, _, err = _cli(["run", str(d), str(tmp_path / "o.png")])
    _only_error(rc, err, str(d), "is a folder, not a file")


# --- SIGTERM ends a run blocked anywhere within 2 s -----------------------------------

#: The command with its frame reader made to block in a system call (``os.read`` of a
#: pipe no one writes: the interpreter is free, the call never returns) from the frame
#: ``BLOCK_AT`` on, after noting ``blocked`` in ``$OCLTM_TEST_READY``: a reader thread
#: (or, with --serial-io, the main thread) stuck where no signal handler can end it.
BLOCKED = r"""
import os, sys
import ocl_tonemap.job.run as run
from ocl_tonemap import interrupts
real, at = run.read_frame, int(os.environ["BLOCK_AT"])
r, w = os.pipe()
def read_frame(path, frame=None, *a, **k):
    if frame is not None and frame >= at:
        interrupts.ready("blocked")
        os.read(r, 1)
    return real(path, frame, *a, **k)
run.read_frame = read_frame
from ocl_tonemap.__main__ import entry
sys.argv[0] = "ocl-tonemap"
raise SystemExit(entry())
"""


def _blocked_run(args, block_at, sig):
    """(exit code, seconds from the signal to the exit, stderr) of a run blocked at
    frame ``block_at``, signalled once it has said it is blocked."""
    with tempfile.TemporaryDirectory() as d:
        ready = os.path.join(d, "ready")
        env = {**os.environ, "OCLTM_TEST_READY": ready, "BLOCK_AT": str(block_at)}
        p = subprocess.Popen([sys.executable, "-c", BLOCKED, *args], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=env,
                             preexec_fn=_default_sigint)
        deadline = time.monotonic() + HANG
        while p.poll() is None and time.monotonic() < deadline:
            if os.path.exists(ready) and "blocked" in open(ready).read():
                break
            time.sleep(0.01)
        assert p.poll() is None, p.communicate()[1]             # it waits, blocked
        t0 = time.monotonic()
        p.send_signal(sig)
        try:
            _, err = p.communicate(timeout=HANG)
        except subprocess.TimeoutExpired:
            p.kill()
            _, err = p.communicate()
            pytest.fail(f"still running {HANG} s after the signal: {err}")
        return p.returncode, time.monotonic() - t0, err


@pytest.mark.parametrize("io, sig, code", [
    ([], signal.SIGTERM, 143),                   # a reader thread stuck, the main one waits
    (["--serial-io"], signal.SIGTERM, 143),      # the main thread itself stuck
    (["--serial-io"], signal.SIGINT, 130),
])
def test_a_run_blocked_elsewhere_ends_within_two_seconds(seq, tmp_path, io, sig, code):
    pattern, frames = seq
    out = tmp_path / "o.####.png"
    rc, took, err = _blocked_run(["run", pattern, str(out), *io], frames[2], sig)
    assert rc == code, err
    assert took < 2.0, (took, err)
    assert "Traceback" not in err and PENDING not in err
    assert "interrupted" in err or "terminated" in err, err
    left = [n for n in os.listdir(tmp_path) if ".tmp" in n or n.endswith(".lock")]
    assert not left, left


def test_a_run_blocked_before_its_first_frame_ends_within_two_seconds(seq, tmp_path):
    pattern, frames = seq
    rc, took, err = _blocked_run(["run", pattern, str(tmp_path / "o.####.png")], frames[0],
                                 signal.SIGTERM)
    assert rc == 143, err
    assert took < 2.0, (took, err)
    assert "Traceback" not in err


# --- Our words, not the libraries' -----------------------------------------------------

def test_a_folder_as_output_is_one_line_and_nothing_at_exit(seq, tmp_path):
    pattern, frames = seq
    adir = tmp_path / "adir"
    adir.mkdir()
    rc, out, err = _cli(["run", frame_path(pattern, frames[0]), str(adir)])
    _only_error(rc, err, f"{adir}: is a folder")
    assert os.listdir(adir) == []


def test_an_unknown_output_extension_is_one_line_and_nothing_at_exit(seq, tmp_path):
    pattern, frames = seq
    rc, out, err = _cli(["run", frame_path(pattern, frames[0]), str(tmp_path / "o.xyz")])
    _only_error(rc, err, "o.xyz: no image format writes the extension .xyz")
    assert os.listdir(tmp_path) == []


def _read_only_folder_run(args, folder):
    """``args`` run with ``folder`` a read-only file system (a tmpfs mounted read-only
    in a mount namespace of the run's own: nothing outside it changes), or None where
    this machine cannot make one."""
    unshare = shutil.which("unshare")
    if unshare is None:
        return None
    userns = [] if os.geteuid() == 0 else ["-r"]
    script = 'mount -t tmpfs -o ro,size=1m tmpfs "$1" || exit 99; shift; exec "$@"'
    p = subprocess.run([unshare, *userns, "-m", "sh", "-c", script, "sh", str(folder),
                        sys.executable, "-m", "ocl_tonemap", *args],
                       capture_output=True, text=True, timeout=HANG)
    if p.returncode == 99 or "unshare:" in p.stderr:
        return None
    return p


def test_a_read_only_output_folder_is_named_and_a_still_makes_no_lock(seq, tmp_path):
    pattern, frames = seq
    ro = tmp_path / "rofs"
    ro.mkdir()
    args = ["run", frame_path(pattern, frames[0]), str(ro / "o.png")]
    os.chmod(ro, 0o555)
    try:
        if not os.access(ro, os.W_OK):       # not root: the permissions hold
            rc, _, err = _cli(args)
        else:
            p = _read_only_folder_run(args, ro)
            if p is None:
                pytest.skip("running as root, which chmod does not stop, and no read-only "
                            "tmpfs can be mounted here (unshare -m)")
            rc, err = p.returncode, p.stderr
    finally:
        os.chmod(ro, 0o755)
    line = _only_error(rc, err, f"{ro}: the folder is not writable (", "cannot write o.png")
    assert ".lock" not in line and "Errno" not in line
    assert os.listdir(ro) == []


def test_a_still_leaves_no_lock_or_state_beside_it(seq, tmp_path):
    pattern, frames = seq
    rc, _, err = _cli(["run", frame_path(pattern, frames[0]), str(tmp_path / "o.png")])
    assert rc == 0, err
    assert os.listdir(tmp_path) == ["o.png"]


def _raw_config(path):
    import PyOpenColorIO as ocio
    path.write_text(ocio.Config.CreateRaw().serialize())
    return str(path)


def test_a_missing_display_or_view_names_itself_and_lists_the_configs(seq, tmp_path):
    pattern, frames = seq
    cfg = _raw_config(tmp_path / "raw.ocio")
    inp, out = frame_path(pattern, frames[0]), str(tmp_path / "o.png")
    rc, _, err = _cli(["run", inp, out, "--colorconfig", cfg, "--display", "sRGB - Display"])
    _only_error(rc, err, "'sRGB - Display'", "its displays: 'sRGB'")
    rc, _, err = _cli(["run", inp, out, "--colorconfig", cfg, "--display", "sRGB",
                       "--view", "Film"])
    _only_error(rc, err, "'Film'", "'sRGB'", "its views: 'Raw'")


def test_the_colour_pipeline_checks_display_and_view_first(tmp_path):
    import PyOpenColorIO as ocio
    from ocl_tonemap.colour import ColourError, ColourPipeline
    cfg = ocio.Config.CreateRaw()
    with pytest.raises(ColourError, match=r"--display 'Nope' is not in .*its displays: 'sRGB'"):
        ColourPipeline(cfg, "Nope")
    with pytest.raises(ColourError, match=r"--view 'Nope' .*its views: 'Raw'"):
        ColourPipeline(cfg, "sRGB", "Nope")


def _deep_exr(path):
    spec = oiio.ImageSpec(8, 6, 4, oiio.FLOAT)
    spec.channelnames = ("R", "G", "B", "A")
    spec.alpha_channel = 3
    spec.deep = True
    buf = oiio.ImageBuf(spec)
    for y in range(6):
        for x in range(8):
            buf.set_deep_samples(x, y, 0, 1)
            for c in range(4):
                buf.set_deep_value(x, y, 0, c, 0, 1.0)
    assert buf.write(str(path)), buf.geterror()
    inp = oiio.ImageInput.open(str(path))
    assert inp.spec().deep
    inp.close()
    return str(path)


@pytest.mark.parametrize("out", ["o.exr", "o.png"])
def test_a_deep_exr_is_refused_on_read(tmp_path, out):
    deep = _deep_exr(tmp_path / "deep.exr")
    rc, _, err = _cli(["run", deep, str(tmp_path / out)])
    _only_error(rc, err, f"{deep}: a deep image (per-pixel samples); flatten it first "
                "(oiiotool --flatten)")
    assert sorted(os.listdir(tmp_path)) == ["deep.exr"]


def test_read_frame_and_band_reader_refuse_deep_and_fifos(tmp_path):
    from ocl_tonemap.io.imageio import BandReader, FrameError, read_frame
    deep = _deep_exr(tmp_path / "deep.exr")
    fifo = _fifo(tmp_path / "f.exr")
    for reader in (read_frame, BandReader):
        with pytest.raises(FrameError, match="a deep image"):
            reader(deep)
        with pytest.raises(FrameError, match=r"named pipe \(FIFO\)"):
            reader(fifo)
    assert oiio.geterror() == ""                 # nothing left pending for OIIO's exit


def test_check_input_names_each_kind():
    from ocl_tonemap.base import safeio
    with pytest.raises(safeio.NotAFile, match="^/dev/null: is a character device, not a file$"):
        safeio.check_input("/dev/null")
    with pytest.raises(safeio.NotAFile, match="is a folder, not a file"):
        safeio.check_input("/")
    safeio.check_input("/no/such/file")          # the caller's to say


_IN_A_C_CALL = """
from ocl_tonemap import interrupts
interrupts.enable_watchdog()             # as the command's entry point does
interrupts.install()
import numpy as np
a = np.random.default_rng(0).random((7000, 7000))
try:
    print("ready", flush=True)
    b = a @ a                            # one C call of ~1e12 flops: minutes here
    print("done", flush=True)
except interrupts.Terminated:            # (a signal just before the call: the entry
    import sys                           # point's own handling and line, as the command's)
    print("ocl-tonemap: terminated", file=sys.stderr)
    raise SystemExit(143)
"""


def test_a_signal_ends_a_long_c_call():
    """A signal that lands while the main thread is inside one long C call (an OpenCL
    wait, a NumPy loop) has no Python handler run until the call returns; the wakeup
    pipe arms the watchdog at once, so the process still ends with 143, not after
    the call (here: one matrix product of minutes)."""
    p = subprocess.Popen([sys.executable, "-c", _IN_A_C_CALL], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "ready"
        p.send_signal(signal.SIGTERM)
        out, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
    assert p.returncode == 143, err
    assert "done" not in out
    assert "terminated" in err and "Traceback" not in err
