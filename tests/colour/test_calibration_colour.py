"""Colour in, colour out: input colour precedence, absolute calibration, display
black, alpha, and output tagging -- through real OIIO files, the real built-in
OCIO config (``ocio://default``) and the CLI."""

import json
import logging
import math
import shutil

import numpy as np
import OpenImageIO as oiio
import PyOpenColorIO as ocio
import pytest

from ocl_tonemap.colour import calibration as cal
from ocl_tonemap import colour
from ocl_tonemap.cli.table import main
from ocl_tonemap.io.patterns import frame_path


@pytest.fixture(autouse=True)
def _default_config(monkeypatch):
    """These tests are about the defaults: no $OCIO, so ocio://default."""
    monkeypatch.delenv("OCIO", raising=False)


def write_exr(path, pix, **attrs):
    h, w, c = pix.shape
    spec = oiio.ImageSpec(w, h, c, oiio.FLOAT)
    for k, v in attrs.items():
        if k == "chromaticities":
            spec.attribute(k, oiio.TypeDesc("float[8]"), tuple(v))
        else:
            spec.attribute(k, v)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, c), np.ascontiguousarray(pix, np.float32))
    assert buf.write(str(path)), buf.geterror()
    return str(path)


def read(path):
    b = oiio.ImageBuf(str(path))
    return b.get_pixels(oiio.FLOAT), b.spec()


def scene(h=24, w=32, seed=3):
    """A textured, coloured scene (relative radiance, log-average ~1)."""
    rng = np.random.default_rng(seed)
    lum = 10.0 ** rng.uniform(-1, 1, (h, w, 1))
    return (lum * rng.uniform(0.2, 1.0, (h, w, 3))).astype(np.float32)


# --- input colour -----------------------------------------------------------------

def test_untagged_exr_is_rec709_under_the_default_config(tmp_path, caplog):
    """ocio://default maps *.exr to ACES2065-1 by a file rule; an untagged EXR is
    still scene-linear Rec.709 (OIIO/OpenEXR), and the assumption is said once."""
    pix = np.tile(np.array([0.85, 0.92, 1.0], np.float32), (4, 6, 1))   # bluish white
    pix[0, 0] = [0.9, 0.05, 0.02]                                      # saturated red
    for f in (1, 2, 3):
        write_exr(tmp_path / f"u.{f:04d}.exr", pix * 50.0)
    out = tmp_path / "o.#.exr"
    with caplog.at_level(logging.INFO, logger="ocl_tonemap"):
        assert main(["run", str(tmp_path / "u.#.exr"), str(out), "--operator", "durand00",
                     "--chromatic-adaptation", "off", "--flare", "off", "--acuity", "off",
                     "--blue-shift", "1,1,1", "--luminance-scale", "1"]) == 0
    px, spec = read(frame_path(str(out), 2))
    assert "untagged" in spec.getattribute("ocltm:input_colorspace")
    assert json.loads(spec.getattribute("ocltm:repairs"))["negative"] == 0
    said = [r for r in caplog.records if "untagged" in r.getMessage()
            and ": plan " not in r.getMessage() and "host <-> device" not in r.getMessage()]
    assert len(said) == 1 and said[0].levelno == logging.WARNING
    # the same as saying lin_rec709; not what ACES2065-1 gives (the white turns cyan)
    for cs, same in (("lin_rec709", True), ("ACES2065-1", False)):
        o2 = tmp_path / f"{cs}.#.exr"
        assert main(["run", str(tmp_path / "u.#.exr"), str(o2), "--operator", "durand00",
                     "--chromatic-adaptation", "off", "--flare", "off", "--acuity", "off",
                     "--blue-shift", "1,1,1", "--luminance-scale", "1", "--iscolorspace", cs,
                     "-q"]) == 0
        p2, _ = read(frame_path(str(o2), 2))
        assert np.array_equal(p2, px) == same
        if not same:
            assert p2[1, 1, 0] < 0.9 * p2[1, 1, 2] * px[1, 1, 0] / px[1, 1, 2]


def test_exr_chromaticities_are_honoured(tmp_path):
    """An EXR with ACES AP0 chromaticities (no colourspace name) reads like the same
    pixels tagged ACES2065-1 through OCIO (Bradford D60->D65, as OCIO's configs)."""
    ap0 = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767)
    pix = scene() * 30.0
    a = write_exr(tmp_path / "chrom.exr", pix, chromaticities=ap0)
    b = write_exr(tmp_path / "named.exr", pix, **{"oiio:ColorSpace": "ACES2065-1"})
    oa, ob = tmp_path / "a.exr", tmp_path / "b.exr"
    for i, o in ((a, oa), (b, ob)):
        assert main(["run", i, str(o), "--luminance-scale", "1", "--out-bits", "float",
                     "-q"]) == 0
    pa, sa = read(oa)
    pb, sb = read(ob)
    assert sa.getattribute("ocltm:input_colorspace").endswith("(EXR chromaticities)")
    assert "ACES2065-1" in sb.getattribute("ocltm:input_colorspace")
    np.testing.assert_allclose(pa, pb, rtol=2e-3, atol=1e-4)


def test_chromaticity_matrix_values():
    # Rec.709 primaries/D65 -> the IEC 61966-2-1 matrix; to working -> identity
    from ocl_tonemap.models.photometry import RGB709_TO_XYZ
    np.testing.assert_allclose(colour.chromaticities_to_xyz(colour.REC709_CHROMATICITIES),
                               RGB709_TO_XYZ, atol=2e-4)
    np.testing.assert_allclose(colour.chromaticities_to_working(colour.REC709_CHROMATICITIES),
                               np.eye(3), atol=5e-4)
    # sRGB primaries adapted to D50 (ICC style; Blender's world EXRs carry these):
    # Bradford back to D65 is the identity within the chromaticities' rounding
    d50 = (0.6484, 0.3309, 0.3212, 0.5979, 0.1559, 0.0660, 0.3457, 0.3585)
    np.testing.assert_allclose(colour.chromaticities_to_working(d50), np.eye(3), atol=6e-3)
    with pytest.raises(colour.ColourError):
        colour.chromaticities_to_xyz((0.3, 0.3, 0.3, 0.3, 0.3, 0.3, 0.3127, 0.329))


def test_file_rules_of_a_user_config_apply_and_builtin_rules_do_not(tmp_path):
    src = colour.bundled_config_path().read_text()
    rule = "  - !<Rule> {name: EXR, extension: exr, pattern: \"*\", colorspace: ACEScg}\n"
    cfgfile = tmp_path / "studio.ocio"
    cfgfile.write_text(src.replace("file_rules:\n", "file_rules:\n" + rule))
    user = colour.load_config(str(cfgfile))
    p = str(tmp_path / "x.exr")
    ic = colour.resolve_input(user, p, None, None, rules_from_user_config=True)
    assert (ic.colorspace, ic.why, ic.assumed) == ("ACEScg", "config file rules", False)
    builtin = colour.load_config("ocio://default")
    ic = colour.resolve_input(builtin, p, None, None, rules_from_user_config=False)
    assert ic.kind == "working" and ic.assumed
    # file metadata beats the rules; an OIIO interop ID the config lacks goes
    # through OCIO's built-in config
    assert colour.resolve_input(user, p, "lin_p3d65", None).colorspace == "lin_p3d65"
    ic = colour.resolve_input(user, p, "g22_rec709", None)
    assert ic.builtin and ic.colorspace == "Gamma 2.2 Encoded Rec.709"
    cp = colour.ColourPipeline(user)
    px = np.full((1, 1, 3), 0.5, np.float32)
    assert cp.convert_input(px, ic)[0, 0, 0] == pytest.approx(0.5 ** 2.2, abs=1e-4)


# --- calibration ------------------------------------------------------------------

def test_meter_equation_and_named_levels():
    spec = oiio.ImageSpec(1, 1, 3, oiio.FLOAT)
    spec.attribute("ExposureTime", 0.01)
    spec.attribute("FNumber", 8.0)
    spec.attribute("Exif:ISOSpeedRatings", 100)
    s, why = cal.camera_scale(spec)
    L = 12.5 * 64 / (0.01 * 100)                    # K N^2 / (t S) = 800 cd/m^2
    assert s == pytest.approx(L / 0.18) and "ISO 100" in why
    assert cal.CalibrationRequest.parse("auto:daylight").auto_level == 5000.0
    assert cal.CalibrationRequest.parse("auto:0.2").auto_level == 0.2
    assert cal.CalibrationRequest.parse("250").scale == 250.0
    order = [cal.NAMED_LEVELS[k] for k in ("night", "dusk", "interior", "overcast", "daylight")]
    assert order == sorted(order)
    for bad in ("0", "-3", "nan", "inf", "auto", "auto:bright", "auto:0", "x"):
        with pytest.raises(ValueError, match="luminance-scale"):
            cal.CalibrationRequest.parse(bad)


def test_calibration_precedence_through_files(tmp_path):
    pix = scene()
    exif = {"ExposureTime": 0.01, "FNumber": 8.0, "Exif:ISOSpeedRatings": 100}
    cases = {
        "both": (dict(whiteLuminance=250.0, **exif), [], 250.0, "whiteLuminance"),
        "camera": (exif, [], 800 / 0.18, "camera metadata"),
        "flag": (dict(whiteLuminance=250.0), ["--luminance-scale", "7"], 7.0,
                 "--luminance-scale"),
        "auto_loses_to_camera": (exif, ["--luminance-scale", "auto:night"], 800 / 0.18,
                                 "camera"),
        "none": ({}, [], 1.0, "assumed"),
    }
    for name, (attrs, flags, scale, why) in cases.items():
        i = write_exr(tmp_path / f"{name}.exr", pix, **attrs)
        o = tmp_path / f"{name}_o.exr"
        assert main(["run", i, str(o), *flags, "-q"]) == 0, name
        _, s = read(o)
        assert s.getattribute("ocltm:luminance_scale") == pytest.approx(scale, rel=1e-6), name
        assert why in s.getattribute("ocltm:luminance_scale_source"), name


def logged(caplog, level=logging.WARNING):
    return "\n".join(r.getMessage() for r in caplog.records if r.levelno >= level)


def test_no_calibration_warns_once_naming_the_flags(tmp_path, caplog):
    for f in (1, 2):
        write_exr(tmp_path / f"n.{f:04d}.exr", scene(seed=f))
    with caplog.at_level(logging.INFO, logger="ocl_tonemap"):
        assert main(["run", str(tmp_path / "n.#.exr"), str(tmp_path / "o.#.png")]) == 0
    err = logged(caplog)
    assert err.count("calibration: 1.0 = 1 cd/m^2") == 1
    assert "--luminance-scale" in err and "auto:LEVEL" in err


def test_auto_level_is_one_constant_for_the_sequence_and_resumes(tmp_path):
    """auto:LEVEL puts the first frame's log-average at LEVEL; the later, 100x
    brighter frames keep that constant (the adaptation shows), also after a resume."""
    base = scene()
    for f, gain in ((1, 1.0), (2, 100.0), (3, 100.0)):
        write_exr(tmp_path / f"s.{f:04d}.exr", base * gain)
    la = cal.log_average(base)
    whole, part = tmp_path / "w.#.exr", tmp_path / "p.#.exr"
    st = tmp_path / "st.json"
    assert main(["run", str(tmp_path / "s.#.exr"), str(whole), "--luminance-scale",
                 "auto:dusk", "-q"]) == 0
    scales = [read(frame_path(str(whole), f))[1].getattribute("ocltm:luminance_scale")
              for f in (1, 2, 3)]
    assert scales[0] == pytest.approx(1.0 / la, rel=1e-5)
    assert scales == [scales[0]] * 3
    # the resumed chunk starts at the bright frame but keeps the first frame's constant
    assert main(["run", str(tmp_path / "s.#.exr"), str(part), "--frames", "1-1",
                 "--luminance-scale", "auto:dusk", "--state-out", str(st), "-q"]) == 0
    assert main(["run", str(tmp_path / "s.#.exr"), str(part), "--frames", "2-3",
                 "--luminance-scale", "auto:dusk", "--state-in", str(st), "-q"]) == 0
    for f in (2, 3):
        a, sa = read(frame_path(str(whole), f))
        b, sb = read(frame_path(str(part), f))
        assert sb.getattribute("ocltm:luminance_scale") == scales[0]
        np.testing.assert_array_equal(a, b)


def test_radiance_files_say_their_units_are_assumed(tmp_path, caplog):
    p = tmp_path / "x.hdr"
    buf = oiio.ImageBuf(oiio.ImageSpec(8, 4, 3, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(0, 8, 0, 4, 0, 1, 0, 3), np.full((4, 8, 3), 0.5, np.float32))
    assert buf.write(str(p))
    with caplog.at_level(logging.INFO, logger="ocl_tonemap"):
        assert main(["run", str(p), str(tmp_path / "o.exr")]) == 0
    err = logged(caplog)
    assert "179 cd/m^2" in err and "--luminance-scale" in err
    _, s = read(tmp_path / "o.exr")
    assert s.getattribute("ocltm:luminance_scale") == pytest.approx(179.0)


# --- display black ----------------------------------------------------------------

@pytest.mark.parametrize("display,black", [("sRGB - Display", 0.1),
                                           ("Rec.2100-PQ - Display", 0.005)])
def test_black_frame_is_display_black(tmp_path, display, black):
    """A black frame shows the display's own black: zero signal (was white/32, i.e.
    41/255 on sRGB and 26 cd/m^2 on a 1000-nit PQ display)."""
    i = write_exr(tmp_path / "black.exr", np.zeros((4, 4, 3), np.float32))
    o = tmp_path / "o.exr"
    assert main(["run", i, str(o), "--display", display, "--luminance-scale", "1",
                 "--out-bits", "float", "-q"]) == 0
    px, s = read(o)
    assert json.loads(s.getattribute("ocltm:display"))["black_cd"] == pytest.approx(black)
    assert px.max() * 100.0 < 1e-3                     # cd/m^2 over the display's black
    png = tmp_path / "o.png"
    assert main(["run", i, str(png), "--display", display, "--luminance-scale", "1", "-q"]) == 0
    assert oiio.ImageBuf(str(png)).get_pixels(oiio.UINT8).max() == 0


def test_display_black_option_and_paper_crt(tmp_path):
    i = write_exr(tmp_path / "black.exr", np.zeros((4, 4, 3), np.float32))
    o = tmp_path / "o.exr"
    assert main(["run", i, str(o), "--display-model", "paper-crt", "--luminance-scale", "1",
                 "--out-bits", "float", "-q"]) == 0
    # the paper's CRT, literally: scene black lands on its black (4 of 125 cd/m^2,
    # display-linear 1.0 = its white: the default's toe puts R = 0 there), nothing is
    # taken out for the display's own
    _, s = read(o)
    assert json.loads(s.getattribute("ocltm:display"))["black_cd"] == pytest.approx(125 / 32)
    assert read(o)[0].mean() == pytest.approx(1 / 32, rel=1e-5)
    # a scene: a higher display black lifts nothing (it is the display's own), but
    # compresses the rest into less signal
    j = write_exr(tmp_path / "s.exr", scene() * 20.0)
    means = []
    for b in ("0.01", "5"):
        assert main(["run", j, str(o), "--display-black", b, "--luminance-scale", "1",
                     "--out-bits", "float", "-q"]) == 0
        px, s = read(o)
        assert json.loads(s.getattribute("ocltm:display"))["black_cd"] == float(b)
        means.append(px.mean())
    assert means[0] != means[1]
    assert main(["run", j, str(o), "--display-black", "200", "-q"]) == 2     # above white


# --- alpha ----------------------------------------------------------------------------

def test_zero_alpha_zero_colour_stays_zero_and_premultiplied_is_divided(tmp_path):
    rng = np.random.default_rng(5)
    straight = (10.0 ** rng.uniform(-1, 2, (8, 8, 1)) * rng.uniform(0.2, 1, (8, 8, 3)))
    alpha = np.full((8, 8, 1), 0.5)
    alpha[:2] = 0.0
    alpha[2:4] = 1.0
    straight[:2] = 0.0                                  # transparent, empty: a comp's hole
    prem = np.concatenate([straight * alpha, alpha], axis=2).astype(np.float32)
    full = np.concatenate([straight, np.ones_like(alpha)], axis=2).astype(np.float32)
    i = write_exr(tmp_path / "prem.exr", prem)
    j = write_exr(tmp_path / "full.exr", full)
    o, oj, on = tmp_path / "o.exr", tmp_path / "oj.exr", tmp_path / "on.exr"
    common = ["--luminance-scale", "1", "--out-bits", "float", "--metering", "mean", "-q"]
    assert main(["run", i, str(o), *common]) == 0
    assert main(["run", j, str(oj), *common]) == 0
    px, s = read(o)
    ref, _ = read(oj)
    assert np.all(px[:2] == 0)                          # was 0.0058 of white
    np.testing.assert_allclose(px[..., 3], alpha[..., 0])
    # premultiplied: tone mapped straight colour x alpha (the metering differs only
    # by the empty rows, so compare where alpha = 1 and 0.5 with the opaque run's
    # mapping after matching its adaptation)
    assert "premultiplied" in s.getattribute("ocltm:alpha")
    half = px[4:, :, :3] / 0.5
    np.testing.assert_allclose(half / half.mean(), ref[4:, :, :3] / ref[4:, :, :3].mean(),
                               rtol=0.05)
    # --no-unpremult maps the stored (darker) colour: a different, darker picture
    assert main(["run", i, str(on), "--no-unpremult", *common]) == 0
    pn, sn = read(on)
    assert np.all(pn[:2] == 0) and "as stored" in sn.getattribute("ocltm:alpha")
    assert not np.allclose(pn[4:], px[4:], rtol=0.01)


def test_straight_alpha_png_round_trip(tmp_path):
    """PNG stores straight alpha: read as it is (oiio:UnassociatedAlpha), not divided,
    and written back straight."""
    spec = oiio.ImageSpec(4, 2, 4, oiio.UINT8)
    spec.attribute("oiio:ColorSpace", "lin_rec709_scene")
    buf = oiio.ImageBuf(spec)
    pix = np.array([[[1, 1, 1, 0.5]] * 4, [[0.5, 0.5, 0.5, 1.0]] * 4], np.float32)
    buf.set_pixels(oiio.ROI(0, 4, 0, 2, 0, 1, 0, 4), pix)
    p = tmp_path / "in.png"
    assert buf.write(str(p))
    o = tmp_path / "o.png"
    assert main(["run", str(p), str(o), "--luminance-scale", "100", "--operator", "durand00",
                 "--blue-shift", "1,1,1", "-q"]) == 0
    hint = oiio.ImageSpec()
    hint.attribute("oiio:UnassociatedAlpha", 1)
    got = oiio.ImageBuf(str(o), 0, 0, hint).get_pixels(oiio.FLOAT)
    # straight colour 1.0 at alpha 0.5 maps like the opaque 1.0 would: brighter than 0.5
    assert got[0, 0, 3] == pytest.approx(0.5, abs=1 / 255)
    assert got[0, 0, 0] > got[1, 0, 0]


# --- outputs tagged with what they hold ---------------------------------------------

@pytest.mark.parametrize("display,linear_cs,primaries", [
    ("sRGB - Display", "Linear Rec.709 (sRGB)", (0.64, 0.33)),
    ("Rec.2100-PQ - Display", "Linear Rec.2020", (0.708, 0.292)),
])
def test_exr_output_is_display_linear_and_tagged(tmp_path, display, linear_cs, primaries):
    i = write_exr(tmp_path / "s.exr", scene() * 100.0,
                  chromaticities=(0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767))
    lin, enc = tmp_path / "lin.exr", tmp_path / "enc.exr"
    assert main(["run", i, str(lin), "--display", display, "--luminance-scale", "1",
                 "--out-bits", "float", "-q"]) == 0
    assert main(["run", i, str(enc), "--display", display, "--luminance-scale", "1",
                 "--out-bits", "float", "--encode", "-q"]) == 0
    pl, sl = read(lin)
    pe, se = read(enc)
    cfg = ocio.Config.CreateFromFile("ocio://default")
    assert cfg.getColorSpace(sl.getattribute("oiio:ColorSpace")).getName() == linear_cs
    assert sl.getattribute("chromaticities")[:2] == pytest.approx(primaries, abs=1e-4)
    assert sl.getattribute("whiteLuminance") == pytest.approx(100.0)
    assert "display-linear" in sl.getattribute("ocltm:output_encoding")
    # the display-encoded output is OCIO's encoding of the linear one
    proc = cfg.getProcessor(linear_cs, display, "Un-tone-mapped",
                            ocio.TRANSFORM_DIR_FORWARD).getDefaultCPUProcessor()
    want = np.ascontiguousarray(pl, np.float32)
    proc.applyRGB(want)
    np.testing.assert_allclose(pe, want, rtol=1e-4, atol=1e-5)
    assert cfg.getColorSpace(se.getattribute("oiio:ColorSpace")).getName() == display
    assert se.getattribute("whiteLuminance") is None
    assert se.getattribute("chromaticities")[:2] == pytest.approx(primaries, abs=2e-3)
    # the input's chromaticities (AP0) are not carried over
    assert not math.isclose(sl.getattribute("chromaticities")[0], 0.7347, abs_tol=1e-3)


def test_bundled_config_knows_oiio_interop_names():
    cfg = colour.load_config("ocl-tonemap")
    for name in ("lin_rec709_scene", "srgb_rec709_scene"):
        assert cfg.getColorSpace(name) is not None, name


def test_demo_sample_is_tagged_and_calibrated(tmp_path, caplog):
    """The built-in sample says what it is: no assumption is reported for it."""
    from ocl_tonemap.io.sample import write_tunnel_sequence
    pattern, frames = write_tunnel_sequence(str(tmp_path), 16, 9, 30.0, 0.1)
    with caplog.at_level(logging.INFO, logger="ocl_tonemap"):
        assert main(["run", pattern, str(tmp_path / "o.#.png")]) == 0
    err = logged(caplog)
    assert "whiteLuminance" in logged(caplog, logging.INFO)
    assert "assumed" not in err and "untagged" not in err
    shutil.rmtree(tmp_path)
