"""Runs that survive faults: missing frames, interruption (real signals to a real
subprocess) and resumption to the same frames, state from an output frame."""

import glob
import json
import os
import pathlib
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import main
from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.io.sample import write_tunnel_sequence

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

def _default_sigint():
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _run(args, ready_file=None):
    """The command in a process of its own, SIGINT at its default as a terminal starts
    it (a test run started with ``&`` in a script inherits SIGINT ignored); its
    readiness notes in ``ready_file`` (``$OCLTM_TEST_READY``)."""
    env = dict(os.environ)
    if ready_file is not None:
        env["OCLTM_TEST_READY"] = str(ready_file)
    return subprocess.Popen([sys.executable, "-m", "ocl_tonemap", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=_default_sigint)


def _interrupt_after(args, n_done, sig):
    """Start a run, send ``sig`` once it has noted ``n_done`` frames written (its own
    readiness notes, ``interrupts.ready``: no guessed delay, no deadline);
    (returncode, stderr)."""
    with tempfile.TemporaryDirectory() as d:
        ready = os.path.join(d, "ready")
        p = _run(args, ready)
        while p.poll() is None:
            if os.path.exists(ready) and \
                    open(ready).read().count("written ") >= n_done:
                p.send_signal(sig)
                break
            time.sleep(0.005)
        _, err = p.communicate()
    return p.returncode, err


@pytest.mark.requires_opencl
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
        rc, err = _interrupt_after(["run", pattern, part, *common], n_done, sig)
        if sig == signal.SIGTERM:
            assert rc == 143, err                   # sent with 48 of 60 frames to go
            assert "--resume" in err and "Traceback" not in err
            assert not [x for x in os.listdir(d) if ".tmp" in x]
        else:
            assert rc == -9, err
        p = _run(["run", pattern, part, *common, "--resume"])
        _, err = p.communicate()
        assert p.returncode == 0, err
        assert not [x for x in os.listdir(d) if ".tmp" in x]
        for f in frames:
            np.testing.assert_array_equal(pixels(frame_path(part, f)), pixels(frame_path(whole, f)),
                                          err_msg=f"{op} {sig!r} frame {f}")


@pytest.mark.requires_opencl
def test_sparse_checkpoints_resume_to_the_same_frames(shot, tmp_path):
    """--checkpoint-every 7: a killed run re-renders the frames after the last
    checkpoint, identically."""
    pattern, frames = shot
    common = ["--operator", "ledda04", "--out-bits", "float", "-q", "--checkpoint-every", "7"]
    whole = str(tmp_path / "w.####.exr")
    assert main(["run", pattern, whole, *common]) == 0
    part = str(tmp_path / "p.####.exr")
    _interrupt_after(["run", pattern, part, *common], 20, signal.SIGKILL)
    ck = json.loads((tmp_path / "p.exr.state.json").read_text())
    assert ck["frame"] % 7 == 0 or ck["frame"] == frames[-1]
    p = _run(["run", pattern, part, *common, "--resume"])
    _, err = p.communicate()
    assert p.returncode == 0, err
    for f in frames:
        np.testing.assert_array_equal(pixels(frame_path(part, f)), pixels(frame_path(whole, f)))


def test_ctrl_c_exits_130_with_the_checkpoint(shot, tmp_path):
    pattern, frames = shot
    out = str(tmp_path / "o.####.png")
    rc, err = _interrupt_after(["run", pattern, out], 5, signal.SIGINT)
    assert rc == 130 and "Traceback" not in err and "--resume" in err
    ckpt = json.loads((tmp_path / "o.png.state.json").read_text())
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


# --- the front door: arguments, channels, API -------------------------------------------

def _exr(path, pix, names=None, **attrs):
    h, w, c = pix.shape
    spec = oiio.ImageSpec(w, h, c, oiio.FLOAT)
    if names:
        spec.channelnames = tuple(names)
    for k, v in attrs.items():
        spec.attribute(k, v)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, c), np.ascontiguousarray(pix, np.float32))
    assert buf.write(str(path))
    return str(path)


@pytest.mark.parametrize("args, why", [
    (["--fps", "0"], "--fps must be > 0"), (["--fps", "-1"], "--fps must be > 0"),
    (["--fps", "nan"], "--fps must be > 0"), (["--fps", "inf"], "--fps must be > 0"),
    (["--exposure", "2000"], "--exposure must be"), (["--luminance-scale", "0"], "--luminance-scale"),
    (["--luminance-scale", "-5"], "--luminance-scale"), (["--sigma-spatial", "0"], "--sigma-spatial"),
    (["--display-white", "-1"], "--display-white"),
    (["--operator", "ledda04", "--local-strength", "2"], "--local-strength"),
])
def test_bad_numbers_fail_before_the_first_frame(shot, tmp_path, capsys, args, why):
    pattern, _ = shot
    try:
        rc = main(["run", pattern, str(tmp_path / "o.#.png"), *args, "-q"])
    except SystemExit as e:                                  # (the parser's check)
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2 and why in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    assert not list(tmp_path.iterdir())                      # nothing written


def test_channel_rules(tmp_path, capsys, caplog):
    import logging
    rg = _exr(tmp_path / "rg.exr", np.ones((4, 4, 2)), ("R", "G"))
    assert main(["run", rg, str(tmp_path / "o.png"), "-q"]) == 2
    assert "2 channels (R, G)" in capsys.readouterr().err
    assert main(["run", rg, str(tmp_path / "o.png"), "--channels", "R,G,G", "-q"]) == 0
    y = _exr(tmp_path / "y.exr", np.full((4, 4, 1), 5.0), ("Y",))
    with caplog.at_level(logging.WARNING, logger="ocl_tonemap"):
        assert main(["run", y, str(tmp_path / "y.exr.png").replace(".exr", ""),
                     "--luminance-scale", "1"]) == 0
    assert any("taken as luminance" in r.getMessage() for r in caplog.records)


def test_misplaced_options_warn_by_one_rule(shot, tmp_path, caplog):
    import logging
    pattern, frames = shot
    with caplog.at_level(logging.WARNING, logger="ocl_tonemap"):
        assert main(["run", pattern, str(tmp_path / "a.#.png"), "--frames", str(frames[0]),
                     "--kappa", "full"]) == 0
        assert main(["run", pattern, str(tmp_path / "b.#.png"), "--frames", str(frames[0]),
                     "--operator", "ledda04", "--metering", "spot:0.5,0.5"]) == 0
        assert main(["run", pattern, str(tmp_path / "c.#.png"), "--frames", str(frames[0]),
                     "--display", "Rec.2100-PQ - Display"]) == 0
    msgs = " | ".join(r.getMessage() for r in caplog.records)
    assert "--kappa applies to kirk11: ignored for pattanaik00" in msgs
    assert "--metering applies to" in msgs and "ignored for ledda04" in msgs
    assert "in 8 bits" in msgs


def test_help_names_every_metering_and_the_defaults(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = capsys.readouterr().out
    assert "mask:" in out and "default pattanaik00" in out and "(default 1000)" in out


def test_api_dtypes_and_shapes(rt):
    from ocl_tonemap import Tonemapper, process_imagebuf
    tm = Tonemapper("pattanaik00")
    u8 = np.full((4, 6, 3), 255, np.uint8)
    f = np.ones((4, 6, 3), np.float32)
    np.testing.assert_array_equal(Tonemapper("pattanaik00").process(u8),
                                  Tonemapper("pattanaik00").process(f))   # as OIIO normalises
    grey = tm.process(np.full((4, 6), 50.0, np.float32))
    assert grey.shape == (4, 6)
    assert Tonemapper("pattanaik00").process(np.full((4, 6, 1), 50.0)).shape == (4, 6, 1)
    with pytest.raises(ValueError, match="real numbers"):
        Tonemapper("pattanaik00").process(np.ones((2, 2, 3), bool))
    with pytest.raises(ValueError, match="H x W"):
        Tonemapper("pattanaik00").process(np.ones((2, 2, 2), np.float32))


def test_process_imagebuf_is_the_clis_front_door(tmp_path, rt):
    """The same calibration, colour and metadata as the command line."""
    from ocl_tonemap import Tonemapper, process_imagebuf
    from ocl_tonemap.io.imageio import FrameError
    pix = np.random.default_rng(1).uniform(0.1, 2.0, (6, 8, 3)).astype(np.float32)
    p = _exr(tmp_path / "in.exr", pix, None, whiteLuminance=300.0)
    cli_out = tmp_path / "o.exr"
    assert main(["run", p, str(cli_out), "--out-bits", "float", "-q"]) == 0
    res = process_imagebuf(Tonemapper("pattanaik00"), oiio.ImageBuf(p))
    cli = oiio.ImageBuf(str(cli_out))
    np.testing.assert_allclose(res.get_pixels(oiio.FLOAT), cli.get_pixels(oiio.FLOAT), rtol=1e-6)
    for k in ("ocltm:luminance_scale", "ocltm:luminance_scale_source", "ocltm:input_colorspace",
              "whiteLuminance", "ocltm:output_encoding", "ocltm:state"):
        assert res.spec().getattribute(k) == cli.spec().getattribute(k), k
    from ocl_tonemap.colour import load_config
    cfg = load_config(None)                       # (OIIO writes its interop ID into files)
    assert cfg.getColorSpace(res.spec().getattribute("oiio:ColorSpace")).getName() == \
        cfg.getColorSpace(cli.spec().getattribute("oiio:ColorSpace")).getName()
    assert res.spec().getattribute("ocltm:luminance_scale") == 300.0
    with pytest.raises(FrameError, match="cannot read"):
        process_imagebuf(Tonemapper("pattanaik00"), oiio.ImageBuf(str(tmp_path / "nope.exr")))


# --- frames larger than the memory budget: streamed in row bands -----------------------

def _big(path, w, h, alpha=False):
    rng = np.random.default_rng(4)
    lum = 10.0 ** rng.uniform(-1, 3, (h, w, 1))
    pix = lum * rng.uniform(0.2, 1.0, (h, w, 3))
    if alpha:
        a = np.clip(rng.uniform(-0.2, 1.2, (h, w, 1)), 0, 1)
        pix = np.concatenate([pix * a, a], axis=2)
    return _exr(path, pix.astype(np.float32), None, whiteLuminance=1.0)


@pytest.mark.parametrize("op, extra", [("pattanaik00", []),
                                       ("durand00", ["--chromatic-adaptation", "on", "--flare",
                                                     "off", "--acuity", "off"])])
@pytest.mark.requires_opencl
@pytest.mark.parametrize("ext, alpha", [(".exr", True), (".png", False)])
def test_streamed_frames_equal_whole_ones(tmp_path, op, extra, ext, alpha):
    """--max-memory below what the whole frame needs: read, mapped and written in
    row bands (OIIO scanlines), the same pixels as the whole-frame path (but for
    the float32 order of the metering sums) and the same metadata."""
    src = _big(tmp_path / "big.exr", 301, 203, alpha)
    whole, streamed = str(tmp_path / f"w{ext}"), str(tmp_path / f"s{ext}")
    common = ["--operator", op, *extra, "-q", "--no-checkpoint"]
    assert main(["run", src, whole, *common]) == 0
    assert main(["run", src, streamed, *common, "--max-memory", "8"]) == 0
    a, b = oiio.ImageBuf(whole), oiio.ImageBuf(streamed)
    pa, pb = a.get_pixels(oiio.FLOAT), b.get_pixels(oiio.FLOAT)
    if ext == ".exr":
        # half floats: the sums' order moves a value by ~1e-7, which can carry one in a
        # few thousand across a half rounding boundary (one half ulp, 2^-10; the
        # default effects -- flare, Purkinje -- add sums of their own, and the shared
        # pigment course's equivalent background reads the goals the sums give: 5.5e-4
        # of the values moved by one ulp where 2.3e-4 did before it)
        np.testing.assert_allclose(pb, pa, rtol=2.0 ** -10, atol=1e-5)
        assert np.mean(pb != pa) < 1e-3
    else:
        np.testing.assert_allclose(pb, pa, atol=1.0 / 255)
    assert "row bands" in b.spec().getattribute("ocltm:streamed")
    for k in ("ocltm:luminance_scale", "ocltm:input_colorspace", "ocltm:output_colorspace"):
        assert a.spec().getattribute(k) == b.spec().getattribute(k), k
    assert not [x for x in os.listdir(tmp_path) if ".tmp" in x]


#: What a streamed run may hold beyond 3 frames, above the same command's peak on a
#: 16x16 frame (the OpenCL driver's fixed cost is in that: ~140 MiB on PoCL, more on
#: NVIDIA's runtime, which maps its own memory): band buffers, OIIO's caches.
STREAM_SLACK_MB = 150


def _peak_rss_mb(args, small=None) -> float:
    """Peak RSS (MiB) of a child ocl-tonemap run (``args``: ``run SRC DST ...``); with
    ``small`` (an input like SRC at 16x16), less the peak of the same command on it:
    the part that grows with the frame.

    The same command runs once before, to a scratch output, so that PoCL's kernel
    cache is warm: a cold cache compiles each kernel (per work-group size) with LLVM
    inside the process, a fixed ~120 MiB that has nothing to do with the frame
    (seen on fresh CI machines)."""
    dst = pathlib.Path(args[2])
    warm = dst.parent / "warm"
    warm.mkdir(exist_ok=True)
    subprocess.run([sys.executable, "-m", "ocl_tonemap", args[0], args[1],
                    str(warm / dst.name), *args[3:]], capture_output=True, check=True)
    code = ("import resource, sys, subprocess; "
            "r = subprocess.run([sys.executable, '-m', 'ocl_tonemap', *sys.argv[1:]]); "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024); "
            "sys.exit(r.returncode)")
    p = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    peak = float(p.stdout.strip().splitlines()[-1])
    if small is None:
        return peak
    return peak - _peak_rss_mb([args[0], str(small), str(warm / ("small_" + dst.name)),
                                *args[3:]])


@pytest.mark.slow
@pytest.mark.requires_opencl
def test_streaming_bounds_memory(tmp_path):
    """A 2400x1600 frame (44 MiB as float32 RGB): whole, the run peaks at many times
    that; streamed it grows by under 3x the frame plus STREAM_SLACK_MB."""
    w, h = 2400, 1600
    src, small = _big(tmp_path / "big.exr", w, h), _big(tmp_path / "small.exr", 16, 16)
    frame_mb = w * h * 12 / 2**20
    whole = _peak_rss_mb(["run", src, str(tmp_path / "w.png"), "-q", "--no-checkpoint"], small)
    streamed = _peak_rss_mb(["run", src, str(tmp_path / "s.png"), "-q", "--no-checkpoint",
                             "--max-memory", "64"], small)
    assert streamed <= 3 * frame_mb + STREAM_SLACK_MB, (streamed, whole)
    assert streamed < whole


def test_operators_that_cannot_stream_say_so(tmp_path, caplog):
    import logging
    src = _big(tmp_path / "big.exr", 400, 300)
    with caplog.at_level(logging.WARNING, logger="ocl_tonemap"):
        assert main(["run", src, str(tmp_path / "o.png"), "--operator", "ledda04",
                     "--backend", "reference", "--max-memory", "8", "--no-checkpoint"]) == 0
    assert any("cannot be streamed" in r.getMessage() for r in caplog.records)


@pytest.mark.requires_opencl
def test_durand00_defaults_stream_unless_a_frame_needs_flare(tmp_path, caplog):
    """flare and acuity on auto: every frame streams now, one with a light source too
    (the flare in row bands: tests/effects/test_stream_effects.py), and both equal the
    whole-frame renders; nothing is read whole."""
    import logging
    rng = np.random.default_rng(7)                             # an even, daylit field
    pix = (500.0 * rng.uniform(0.5, 2.0, (203, 301, 3))).astype(np.float32)
    plain = _exr(tmp_path / "plain.exr", pix, None, whiteLuminance=1.0)
    pix[100:104, 150:154] = 1e6                                  # a lamp
    lamp = _exr(tmp_path / "lamp.exr", pix, None, whiteLuminance=1.0)
    for src, flared in ((plain, False), (lamp, True)):
        w, s = str(tmp_path / "w.exr"), str(tmp_path / "s.exr")
        assert main(["run", src, w, "--operator", "durand00", "-q", "--no-checkpoint",
                     "--out-bits", "float"]) == 0
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="ocl_tonemap"):
            assert main(["run", src, s, "--operator", "durand00", "--no-checkpoint",
                         "--max-memory", "8", "--out-bits", "float"]) == 0
        b = oiio.ImageBuf(s)
        assert b.spec().getattribute("ocltm:streamed") is not None
        assert not any("not streamed" in r.getMessage() for r in caplog.records)
        ran = b.spec().getattribute("ocltm:effects_ran").split(",")
        assert ("flare" in ran) == flared
        np.testing.assert_allclose(b.get_pixels(oiio.FLOAT),
                                   oiio.ImageBuf(w).get_pixels(oiio.FLOAT), atol=1e-4, rtol=1e-4)


# --- regressions found in review ----------------------------------------------------------

def test_encoded_outputs_of_premultiplied_input_keep_the_colour(tmp_path):
    """The same straight colour at alpha 1, 0.5 and 0.25: a display encoding must
    encode the straight colour (it stored encode(c a)/a, brighter at low alpha)."""
    c = np.array([40.0, 20.0, 10.0], np.float32)
    a = np.repeat(np.array([1.0, 0.5, 0.25], np.float32), 8)[None, :, None].repeat(4, axis=0)
    pix = np.concatenate([c * a, a], axis=2)
    src = _exr(tmp_path / "in.exr", pix, None, whiteLuminance=1.0)
    hint = oiio.ImageSpec()
    hint.attribute("oiio:UnassociatedAlpha", 1)
    for ext in (".png", ".tif"):
        out = str(tmp_path / f"o{ext}")
        assert main(["run", src, out, "--metering", "mean", "-q", "--no-checkpoint"]) == 0
        got = oiio.ImageBuf(out, 0, 0, hint).get_pixels(oiio.FLOAT)
        if ext == ".tif":                   # TIFF stores associated alpha: code values x a
            got[..., :3] /= np.maximum(got[..., 3:4], 1e-6)
        for k in (8, 16):                                   # alpha 0.5 and 0.25 vs 1
            np.testing.assert_allclose(got[1, k, :3], got[1, 0, :3], atol=2 / 255, err_msg=ext)


def test_state_files_never_overwrite_frames(shot, tmp_path, capsys):
    pattern, frames = shot
    victim = tmp_path / "victim.exr"
    shutil.copy(frame_path(pattern, frames[0]), victim)
    before = victim.read_bytes()
    assert main(["run", str(victim), str(tmp_path / "o.png"), "--state-out", str(victim),
                 "-q"]) == 2
    assert "state file would overwrite" in capsys.readouterr().err
    assert victim.read_bytes() == before
    assert main(["run", str(victim), str(tmp_path / "o2.png"), "--state-out",
                 str(tmp_path / "new" / "s.json"), "-q"]) == 0     # its folder is made
    assert (tmp_path / "new" / "s.json").exists() and (tmp_path / "o2.png").exists()
    (tmp_path / "afile").write_text("x")                            # ... where it can be
    assert main(["run", str(victim), str(tmp_path / "o3.png"), "--state-out",
                 str(tmp_path / "afile" / "s.json"), "-q"]) == 2
    assert "cannot make the state's folder" in capsys.readouterr().err
    assert not (tmp_path / "o3.png").exists()


def test_resume_refuses_other_settings_and_outputs_keep_their_own_checkpoints(shot, tmp_path,
                                                                           capsys):
    pattern, frames = shot
    part = str(tmp_path / "p.####.png")
    _interrupt_after(["run", pattern, part], 5, signal.SIGKILL)
    assert main(["run", pattern, str(tmp_path / "p.####.exr"), "--frames",
                 f"{frames[0]}-{frames[2]}", "-q"]) == 0          # another output: its own
    assert (tmp_path / "p.png.state.json").exists() and (tmp_path / "p.exr.state.json").exists()
    assert main(["run", pattern, part, "--resume", "--fps", "10", "-q"]) == 2
    assert "other settings" in capsys.readouterr().err
    assert main(["run", pattern, part, "--resume", "-q"]) == 0
    assert all(os.path.exists(frame_path(part, f)) for f in frames)


def test_stale_temporaries_of_other_outputs_are_left_alone(shot, tmp_path):
    pattern, frames = shot
    other = tmp_path / ".someone_else.tmp999999.png"
    mine = [tmp_path / ".o.tmp999999.png",                  # a frame, the state JSON and
            tmp_path / ".o.png.state.json.tmp999999",       # its planes, killed mid-write
            tmp_path / ".o.png.state.pixels.2.tmp999999.exr"]
    for p in (other, *mine):
        p.write_bytes(b"x")
    assert main(["run", frame_path(pattern, frames[0]), str(tmp_path / "o.png"), "-q"]) == 0
    assert other.exists() and not any(p.exists() for p in mine)


def test_streaming_keeps_the_files_frame_rate(shot, tmp_path):
    pattern, frames = shot
    a, b = str(tmp_path / "a.####.exr"), str(tmp_path / "b.####.exr")
    rng = f"{frames[0]}-{frames[3]}"
    assert main(["run", pattern, a, "--frames", rng, "-q", "--no-checkpoint"]) == 0
    assert main(["run", pattern, b, "--frames", rng, "-q", "--no-checkpoint",
                 "--max-memory", "8"]) == 0
    for f in range(frames[0], frames[3] + 1):
        ta = json.loads(oiio.ImageBuf(frame_path(a, f)).spec().getattribute("ocltm:state"))
        tb = json.loads(oiio.ImageBuf(frame_path(b, f)).spec().getattribute("ocltm:state"))
        assert ta["time_s"] == tb["time_s"]


@pytest.mark.parametrize("kind", ["tiled", "offset-jpg", "rgba-hdr"])
def test_streaming_and_formats(tmp_path, kind):
    rng = np.random.default_rng(9)
    w, h = 301, 203
    pix = (100.0 * rng.uniform(0.5, 2.0, (h, w, 4))).astype(np.float32)
    pix[..., 3] = 1.0
    spec = oiio.ImageSpec(w, h, 4, oiio.FLOAT)
    spec.attribute("whiteLuminance", 1.0)
    if kind == "tiled":
        spec.tile_width = spec.tile_height = 64
    if kind == "offset-jpg":
        spec.x, spec.y = 7, 5
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(spec.x, spec.x + w, spec.y, spec.y + h, 0, 1, 0, 4), pix)
    src = str(tmp_path / "in.exr")
    assert buf.write(src)
    ext = {"tiled": ".exr", "offset-jpg": ".jpg", "rgba-hdr": ".hdr"}[kind]
    whole, streamed = str(tmp_path / f"w{ext}"), str(tmp_path / f"s{ext}")
    assert main(["run", src, whole, "-q", "--no-checkpoint"]) == 0
    assert main(["run", src, streamed, "-q", "--no-checkpoint", "--max-memory", "8"]) == 0
    tol = 3 / 255 if ext == ".jpg" else 2e-3
    np.testing.assert_allclose(oiio.ImageBuf(streamed).get_pixels(oiio.FLOAT),
                               oiio.ImageBuf(whole).get_pixels(oiio.FLOAT), atol=tol, rtol=tol)


def test_spectral_files_are_not_streamed_and_auto_calibrate_right(tmp_path):
    from ocl_tonemap.io.sample import write_spectral_image
    sp = str(tmp_path / "sp.exr")
    write_spectral_image(sp, "A", 50.0, patch_px=12)
    a, b = str(tmp_path / "a.exr"), str(tmp_path / "b.exr")
    assert main(["run", sp, a, "-q", "--no-checkpoint"]) == 0
    assert main(["run", sp, b, "-q", "--no-checkpoint", "--max-memory", "8"]) == 0
    np.testing.assert_array_equal(oiio.ImageBuf(a).get_pixels(oiio.FLOAT),
                                  oiio.ImageBuf(b).get_pixels(oiio.FLOAT))
    k = str(tmp_path / "k.exr")
    assert main(["run", sp, k, "--operator", "kirk11", "--luminance-scale", "auto:30", "-q",
                 "--no-checkpoint"]) == 0
    p = str(tmp_path / "p.exr")
    assert main(["run", sp, p, "--luminance-scale", "auto:30", "-q", "--no-checkpoint"]) == 0
    sk = oiio.ImageBuf(k).spec().getattribute("ocltm:luminance_scale")
    spp = oiio.ImageBuf(p).spec().getattribute("ocltm:luminance_scale")
    assert sk == pytest.approx(spp, rel=1e-3)        # the same frame, the same calibration
