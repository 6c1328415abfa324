"""The command line end to end on the generated sample, and the Python API."""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import main
from ocl_tonemap.io.patterns import frame_path


def pixels(path):
    return oiio.ImageBuf(str(path)).get_pixels(oiio.FLOAT)


def test_run_sequence_end_to_end(sample_dir, tmp_path, capsys):
    pattern, frames = sample_dir
    out = str(tmp_path / "o.####.exr")
    assert main(["run", pattern, out, "--out-bits", "float", "-q"]) == 0
    for f in frames:
        b = oiio.ImageBuf(frame_path(out, f))
        s = b.spec()
        assert s.getattribute("ocltm:operator") == "pattanaik00"
        st = json.loads(s.getattribute("ocltm:state"))
        assert st["frame"] == f and st["time_s"] == pytest.approx(f / 30.0)
        assert set(st["values"]) == {"A_rod", "A_cone", "B_rod", "B_cone"}
        px = b.get_pixels(oiio.FLOAT)
        assert np.isfinite(px).all() and px.min() >= 0
    # inside the tunnel the first frames are darker than later ones (adaptation)
    means = [pixels(frame_path(out, f)).mean() for f in frames]
    assert max(means) > 0.05 and min(means) < max(means)


def test_chunked_state_equals_single_run(sample_dir, tmp_path):
    pattern, frames = sample_dir
    a, b = frames[0], frames[-1]
    mid = (a + b) // 2
    one = str(tmp_path / "one.####.exr")
    two = str(tmp_path / "two.####.exr")
    st = str(tmp_path / "state.json")
    assert main(["run", pattern, one, "--frames", f"{a}-{b}", "--out-bits", "float", "-q"]) == 0
    assert main(["run", pattern, two, "--frames", f"{a}-{mid}", "--state-out", st,
                 "--out-bits", "float", "-q"]) == 0
    assert main(["run", pattern, two, "--frames", f"{mid + 1}-{b}", "--state-in", st,
                 "--out-bits", "float", "-q"]) == 0
    for f in frames:
        np.testing.assert_array_equal(pixels(frame_path(one, f)), pixels(frame_path(two, f)))


@pytest.mark.requires_opencl
def test_reference_backend_cli_matches_opencl(sample_dir, tmp_path):
    pattern, frames = sample_dir
    o1, o2 = str(tmp_path / "a.####.exr"), str(tmp_path / "b.####.exr")
    rng = f"{frames[0]}-{frames[0] + 9}"
    for o, be in ((o1, "opencl"), (o2, "reference")):
        assert main(["run", pattern, o, "--frames", rng, "--backend", be,
                     "--display", "Rec.2100-PQ - Display", "--out-bits", "float", "-q"]) == 0
    for f in range(frames[0], frames[0] + 10):
        np.testing.assert_allclose(pixels(frame_path(o1, f)), pixels(frame_path(o2, f)), atol=1e-3)


def test_bad_frame_error_names_file_and_frame(sample_dir, tmp_path, capsys):
    pattern, frames = sample_dir
    d = tmp_path / "seq"
    shutil.copytree(os.path.dirname(pattern), d)
    bad = frame_path(str(d / os.path.basename(pattern)), frames[3])
    with open(bad, "wb") as fh:
        fh.write(b"garbage")
    out = str(tmp_path / "o.####.png")
    rc = main(["run", str(d / os.path.basename(pattern)), out, "-q"])
    err = capsys.readouterr().err
    assert rc != 0
    assert f"ocl-tonemap ERROR: {bad} frame {frames[3]}:" in err
    assert os.path.getsize(bad) == 7                               # input untouched
    assert os.path.exists(frame_path(out, frames[2]))              # earlier frames written
    assert not os.path.exists(frame_path(out, frames[3]))
    assert not [p for p in os.listdir(tmp_path) if ".tmp" in p]


def test_never_overwrites_input(sample_dir, tmp_path, capsys):
    pattern, frames = sample_dir
    src = tmp_path / "in.exr"
    shutil.copy(frame_path(pattern, frames[0]), src)
    before = src.read_bytes()
    assert main(["run", str(src), str(src), "-q"]) != 0
    assert "overwrite an input" in capsys.readouterr().err
    assert src.read_bytes() == before


def test_single_image_png_and_plot(sample_dir, tmp_path):
    pattern, frames = sample_dir
    out, plot = tmp_path / "still.png", tmp_path / "plot.png"
    assert main(["run", frame_path(pattern, frames[10]), str(out), "--plot", str(plot),
                 "--metering", "spot:0.5,0.8", "--preadapt", "1000:30", "-q"]) == 0
    px = pixels(out)
    assert px.shape == (27, 48, 3) and px.max() > 0
    assert plot.stat().st_size > 10_000


@pytest.mark.parametrize("operator", ["durand00", "ledda04"])
def test_plot_for_every_operator(sample_dir, tmp_path, operator):
    pattern, frames = sample_dir
    plot = tmp_path / "plot.png"
    assert main(["run", pattern, str(tmp_path / "o.####.png"), "--frames",
                 f"{frames[0]}-{frames[5]}", "--operator", operator, "--plot", str(plot),
                 "-q"]) == 0
    assert plot.stat().st_size > 10_000


def test_bad_arguments_are_clear(sample_dir, tmp_path, capsys):
    pattern, _ = sample_dir
    assert main(["run", pattern, str(tmp_path / "o.png"), "-q"]) != 0
    assert "frame pattern" in capsys.readouterr().err
    assert main(["run", pattern, str(tmp_path / "o.#.png"), "--metering", "bogus", "-q"]) != 0
    assert "bad --metering" in capsys.readouterr().err
    assert main(["run", pattern, str(tmp_path / "o.#.png"), "--display", "Nope", "-q"]) != 0
    assert "not in the OCIO config" in capsys.readouterr().err


def test_devices_and_displays_commands():
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "devices"], capture_output=True, text=True)
    assert r.returncode == 0 and "0:0" in r.stdout
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "displays", "--colorconfig", "ocl-tonemap"],
                       capture_output=True, text=True)
    assert r.returncode == 0 and "Rec.2100-PQ - Display: Un-tone-mapped (default), Raw" in r.stdout


def test_imagebuf_api_round_trip():
    from ocl_tonemap import Tonemapper, process_imagebuf
    spec = oiio.ImageSpec(6, 4, 4, oiio.FLOAT)
    buf = oiio.ImageBuf(spec)
    px = np.full((4, 6, 4), 50.0, np.float32)
    px[..., 3] = 0.5
    buf.set_pixels(oiio.ROI(0, 6, 0, 4, 0, 1, 0, 4), px)
    tm = Tonemapper()
    out = process_imagebuf(tm, buf)
    assert out.spec().nchannels == 4
    o = out.get_pixels(oiio.FLOAT)
    assert np.allclose(o[..., 3], 0.5) and (o[..., :3] > 0).all()
    s = tm.state
    process_imagebuf(tm, buf, dt=1 / 24)
    assert tm.state.time_s == pytest.approx(1 / 24) and s.time_s == 0.0


@pytest.mark.requires_opencl
def test_ledda_sequence_chunked_with_pixel_state(sample_dir, tmp_path):
    pattern, frames = sample_dir
    whole = str(tmp_path / "w.####.exr")
    assert main(["run", pattern, whole, "--operator", "ledda04", "--out-bits", "float", "-q"]) == 0
    mid = frames[len(frames) // 2]
    a, b = str(tmp_path / "a.####.exr"), str(tmp_path / "b.####.exr")
    st = str(tmp_path / "st.json")
    assert main(["run", pattern, a, "--operator", "ledda04", "--out-bits", "float", "-q",
                 "--frames", f"{frames[0]}-{mid}", "--state-out", st]) == 0
    assert os.path.exists(str(tmp_path / "st.pixels.exr"))
    assert main(["run", pattern, b, "--operator", "ledda04", "--out-bits", "float", "-q",
                 "--frames", f"{mid + 1}-{frames[-1]}", "--state-in", st]) == 0
    for f in frames[len(frames) // 2 + 1:]:
        assert np.array_equal(pixels(frame_path(whole, f)), pixels(frame_path(b, f)))
    spec = oiio.ImageBuf(frame_path(whole, frames[-1])).spec()
    params = json.loads(spec.getattribute("ocltm:params"))
    assert params["bilateral"] == "exact"          # auto: sigma_s ~1 px is cheap exactly


def test_simulate_dark_adaptation(sample_dir, tmp_path, capsys):
    pattern, frames = sample_dir
    src = frame_path(pattern, frames[0])
    out = str(tmp_path / "sim.exr")
    # the sunlit first frame at a dusk level (x 1e-3: a log-average near 1 cd/m^2),
    # after a bright field: the eye's recovery over minutes shows
    dim = str(tmp_path / "dim.exr")
    b = oiio.ImageBuf(src)
    oiio.ImageBufAlgo.mul(b, b, 1e-3)
    assert b.write(dim)
    assert main(["simulate", dim, out, "--operator", "ledda04", "--preadapt", "5000:60",
                 "--at", "1,2m,16m", "--out-bits", "float", "-q"]) == 0
    names = [str(tmp_path / f"sim_t{t}s.exr") for t in ("0001", "0120", "0960")]
    means = []
    for n in names:
        spec = oiio.ImageBuf(n).spec()
        assert spec.getattribute("ocltm:elapsed_s") in (1.0, 120.0, 960.0)
        means.append(pixels(n).mean())
    assert means[0] < means[1] < means[2]            # visibility recovers in the dark
    # works for the global operator too, and a pattern numbers the outputs
    pat = str(tmp_path / "p.#.exr")
    assert main(["simulate", src, pat, "--preadapt", "1", "--at", "12,1,3", "-q"]) == 0
    assert all(os.path.exists(frame_path(pat, k)) for k in (1, 2, 3))
    assert main(["simulate", src, out, "--at", "1", "-q"]) == 2
    assert "needs --preadapt" in capsys.readouterr().err


def test_durand_sequence_effects_metadata_and_chunks(sample_dir, tmp_path):
    """durand00 with all effects: metadata says what ran; the chromatic and
    light-adaptation state resumes across chunks bit for bit."""
    pattern, frames = sample_dir
    a, b = frames[0], frames[-1]
    mid = (a + b) // 2
    one, two = str(tmp_path / "one.####.exr"), str(tmp_path / "two.####.exr")
    st = str(tmp_path / "state.json")
    fx = ["--operator", "durand00", "--flare", "on", "--chromatic-adaptation", "on",
          "--acuity", "on", "--fov", "8", "--out-bits", "float", "-q"]
    assert main(["run", pattern, one, *fx]) == 0
    assert main(["run", pattern, two, "--frames", f"{a}-{mid}", "--state-out", st, *fx]) == 0
    saved = json.loads(open(st).read())
    assert len(saved["extra"]["illuminant_rgb"]) == 3
    assert set(saved["values"]) == {"inv_eps_rod", "inv_eps_cone", "L_waR", "L_wa"}
    assert main(["run", pattern, two, "--frames", f"{mid + 1}-{b}", "--state-in", st, *fx]) == 0
    for f in frames:
        np.testing.assert_array_equal(pixels(frame_path(one, f)), pixels(frame_path(two, f)))
    spec = oiio.ImageBuf(frame_path(one, b)).spec()
    eff = json.loads(spec.getattribute("ocltm:effects"))
    assert set(eff) == {"flare", "acuity", "chromatic_adaptation", "purkinje", "threshold"}
    assert not eff["purkinje"]["ran"]
    assert eff["threshold"]["ran"] and eff["threshold"]["T_rod"] > 0.0   # on auto (defaults)
    assert eff["chromatic_adaptation"]["source"] == "estimate"
    assert spec.getattribute("ocltm:effects_ran") == ",".join(
        k for k, v in eff.items() if v["ran"])


def test_adopted_neutral_and_mask_metering(tmp_path):
    """An EXR's adoptedNeutral drives chromatic adaptation; a weight image meters."""
    h, w = 24, 32
    img = np.full((h, w, 3), 300.0, np.float32)
    img[:, w // 2:] = 3.0                                    # dark right half
    spec = oiio.ImageSpec(w, h, 3, oiio.FLOAT)
    spec.attribute("adoptedNeutral", oiio.TypeDesc("float[2]"), (0.44757, 0.40745))  # A
    src = oiio.ImageBuf(spec)
    src.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, 3), img)
    src.write(str(tmp_path / "in.exr"))
    mask = np.zeros((h // 2, w // 2, 1), np.float32)
    mask[:, w // 4:] = 1.0                                  # meter the right half only
    mb = oiio.ImageBuf(oiio.ImageSpec(w // 2, h // 2, 1, oiio.FLOAT))
    mb.set_pixels(oiio.ROI(0, w // 2, 0, h // 2, 0, 1, 0, 1), mask)
    mb.write(str(tmp_path / "mask.exr"))
    out_u, out_m = str(tmp_path / "u.exr"), str(tmp_path / "m.exr")
    base = [str(tmp_path / "in.exr")]
    assert main(["run", *base, out_u, "--operator", "durand00", "--out-bits", "float", "-q"]) == 0
    assert main(["run", *base, out_m, "--operator", "durand00", "--out-bits", "float", "-q",
                 "--metering", f"mask:{tmp_path / 'mask.exr'}"]) == 0
    su, sm = oiio.ImageBuf(out_u).spec(), oiio.ImageBuf(out_m).spec()
    gu, gm = (json.loads(s.getattribute("ocltm:goal"))["G_cone"] for s in (su, sm))
    assert gm < 10 < gu                                     # the mask looked at the dark half
    eff = json.loads(su.getattribute("ocltm:effects"))["chromatic_adaptation"]
    assert eff["source"] == "adoptedNeutral" and eff["ran"]
    assert eff["gains"][2] > 2 * eff["gains"][0]             # tungsten: boost blue
    assert main(["run", *base, str(tmp_path / "x.exr"), "--operator", "durand00", "-q",
                 "--metering", f"mask:{tmp_path / 'nope.exr'}"]) == 2


def test_kirk11_spectral_and_rgb_files(tmp_path):
    """kirk11 reads a spectral EXR as spectra; other operators see its RGB."""
    from ocl_tonemap.io.sample import write_spectral_image
    spec = str(tmp_path / "night.exr")
    write_spectral_image(spec, "A", 0.05, patch_px=4)
    out_k, out_p = str(tmp_path / "k.exr"), str(tmp_path / "p.exr")
    assert main(["run", spec, out_k, "--operator", "kirk11", "--out-bits", "float", "-q"]) == 0
    assert main(["run", spec, out_p, "--operator", "pattanaik00", "--out-bits", "float",
                 "-q"]) == 0
    sk, sp = oiio.ImageBuf(out_k).spec(), oiio.ImageBuf(out_p).spec()
    assert sk.getattribute("ocltm:input_colorspace").startswith("spectral, 31 channels")
    assert "from the spectrum" in sp.getattribute("ocltm:input_colorspace")
    params = json.loads(sk.getattribute("ocltm:params"))
    assert params["input"] == "spectral" and params["w_mean"] > 0.5    # low mesopic
    px = pixels(out_k)
    assert px.shape == (16, 24, 3) and np.isfinite(px).all() and px.min() >= 0
    # RGB input, on a P3 display: the non-negativity is in the display's primaries
    rgb = str(tmp_path / "rgb.exr")
    b = oiio.ImageBuf(oiio.ImageSpec(8, 6, 3, oiio.FLOAT))
    b.set_pixels(oiio.ROI(0, 8, 0, 6, 0, 1, 0, 3), np.full((6, 8, 3), 0.02, np.float32))
    b.write(rgb)
    assert main(["run", rgb, str(tmp_path / "r.png"), "--operator", "kirk11",
                 "--display", "Display P3 - Display", "--kappa", "full", "--night-dim", "0.5",
                 "-q"]) == 0


def test_sample_spectral_and_exposure_control(tmp_path):
    """`sample --spectral` writes a spectral EXR; lower exposure, dimmer and bluer."""
    assert main(["sample", str(tmp_path), "--size", "16x9", "--seconds", "0.1",
                 "--spectral"]) == 0
    sp = tmp_path / "colorchecker_spectral.exr"
    outs = {}
    # (exposures below the display's highlight shoulder, which desaturates a red that
    # passes 0.9 of white)
    for ev in ("9", "5", "0"):
        o = str(tmp_path / f"k{ev}.exr")
        assert main(["run", str(sp), o, "--operator", "kirk11", "--exposure", ev,
                     "--out-bits", "float", "-q"]) == 0
        outs[ev] = pixels(o)
    red = [outs[e][24 * 2 + 12, 24 * 2 + 12] for e in ("9", "5", "0")]    # the red patch
    r_share = [p[0] / max(p.sum(), 1e-12) for p in red]
    assert r_share[0] > 0.6 and r_share[0] > r_share[1] > r_share[2]
    assert outs["9"].mean() > outs["5"].mean() > outs["0"].mean()


def test_model_plan_in_metadata_verbose_and_plot(sample_dir, tmp_path, caplog):
    """--model auto (default): every output carries its plan (ocltm:plan, weights in
    0..1 for the operator's mechanisms), -v says where it changes, --plot draws it;
    --model none records no plan and runs no effect; --model full runs them all;
    the plan resumes with the state (chunks equal one run)."""
    import logging
    pattern, frames = sample_dir
    a, b = frames[0], frames[-1]
    mid = (a + b) // 2
    one, two = str(tmp_path / "one.####.exr"), str(tmp_path / "two.####.exr")
    st, plot = str(tmp_path / "s.json"), str(tmp_path / "p.png")
    common = ["--operator", "durand00", "--out-bits", "float", "--fov", "10"]
    with caplog.at_level(logging.INFO, logger="ocl_tonemap"):
        assert main(["run", pattern, one, *common, "--plot", plot]) == 0
    said = [r.getMessage() for r in caplog.records if ": plan " in r.getMessage()]
    assert said and f"frame {a}" in said[0]
    assert os.path.getsize(plot) > 10000
    weights = [json.loads(oiio.ImageBuf(frame_path(one, f)).spec().getattribute("ocltm:plan"))
               for f in frames]
    assert set(weights[0]) == {"rods", "purkinje", "acuity", "flare", "chromatic-adaptation",
                               "temporal", "threshold"}
    assert all(0.0 <= w <= 1.0 for ws in weights for w in ws.values())
    assert len(said) == 1 + sum(1 for x, y in zip(weights, weights[1:]) if x != y)
    assert main(["run", pattern, two, "--frames", f"{a}-{mid}", "--state-out", st, "-q",
                 *common]) == 0
    assert main(["run", pattern, two, "--frames", f"{mid + 1}-{b}", "--state-in", st, "-q",
                 *common]) == 0
    for f in frames:
        np.testing.assert_array_equal(pixels(frame_path(one, f)), pixels(frame_path(two, f)))
    none = str(tmp_path / "none.exr")
    assert main(["run", frame_path(pattern, b), none, *common, "--model", "none", "-q"]) == 0
    spec = oiio.ImageBuf(none).spec()
    assert spec.getattribute("ocltm:plan") is None
    assert spec.getattribute("ocltm:effects_ran") == "none"
    full = str(tmp_path / "full.exr")
    assert main(["run", frame_path(pattern, b), full, *common, "--model", "full", "-q"]) == 0
    spec = oiio.ImageBuf(full).spec()
    assert set(json.loads(spec.getattribute("ocltm:plan")).values()) == {1.0}


def test_no_abbreviated_flags_and_a_grouped_help(capsys):
    """``--fram 1-10`` is an error, not ``--frames`` (argparse's abbreviations are off);
    ``run --help`` lists its options in groups, and the shot passes name their own
    options and point to run's instead of repeating them."""
    from ocl_tonemap.cli.table import main
    from ocl_tonemap.cli.options import GROUPS
    with pytest.raises(SystemExit) as e:
        main(["run", "a.exr", "b.png", "--fram", "1-10"])
    assert e.value.code == 2 and "--fram" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = capsys.readouterr().out
    for g in GROUPS:
        assert f"\n{g.title}:\n" in out, g.title
    assert len(out.splitlines()) < 260     # (each declared flag says its range and unit)
    for cmd in ("measure", "integrate", "apply", "export", "farm-template", "simulate"):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        out = capsys.readouterr().out
        assert "every option of run" in out and "--luminance-scale" not in out, cmd
        assert len(out.splitlines()) < 40, cmd
