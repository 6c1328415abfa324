"""Real OIIO files and real OCIO processors."""

import os

import numpy as np
import OpenImageIO as oiio
import PyOpenColorIO as ocio
import pytest

from ocl_tonemap import colour
from ocl_tonemap.io import imageio
from ocl_tonemap.io.imageio import FrameError, FramePool, read_frame
from ocl_tonemap.io.patterns import find_frames, frame_path
from ocl_tonemap.io.imagewrite import write_frame


def _write(path, pix, **attrs):
    h, w, c = pix.shape
    spec = oiio.ImageSpec(w, h, c, oiio.FLOAT)
    for k, v in attrs.items():
        spec.attribute(k, v)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, c), pix)
    assert buf.write(str(path)), buf.geterror()


def test_exr_round_trip_keeps_windows_and_metadata(tmp_path):
    pix = np.random.default_rng(0).uniform(0, 4, (6, 8, 4)).astype(np.float32)
    spec = oiio.ImageSpec(8, 6, 4, oiio.FLOAT)
    spec.x, spec.y = 3, 2                      # data window offset
    spec.full_x, spec.full_y, spec.full_width, spec.full_height = 0, 0, 16, 12
    spec.attribute("Artist", "tester")
    spec.attribute("whiteLuminance", 250.0)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(3, 11, 2, 8, 0, 1, 0, 4), pix)
    src = tmp_path / "in.exr"
    assert buf.write(str(src))
    fr = read_frame(str(src), 7)
    assert fr.white_luminance == 250.0 and fr.pixels.shape == (6, 8, 4)
    np.testing.assert_array_equal(fr.pixels, pix)
    out = tmp_path / "out.exr"
    write_frame(str(out), fr.pixels, fr.spec, "sRGB - Display", {"ocltm:test": "x"}, "float", 7)
    back = oiio.ImageBuf(str(out))
    s = back.spec()
    assert (s.x, s.y, s.full_width, s.full_height) == (3, 2, 16, 12)
    assert s.getattribute("Artist") == "tester"
    assert s.getattribute("ocltm:test") == "x"
    # OIIO 3 stores its colour-interop ID for known spaces
    assert s.getattribute("oiio:ColorSpace") in ("sRGB - Display", "srgb_rec709_display")
    assert s.getattribute("whiteLuminance") is None          # output is display-referred
    assert s.alpha_channel == 3
    np.testing.assert_array_equal(back.get_pixels(oiio.FLOAT), pix)
    assert not [p for p in os.listdir(tmp_path) if ".tmp" in p]


@pytest.mark.parametrize("ext,bits,dtype", [(".png", "8", "uint8"), (".tif", "16", "uint16"),
                                            (".jpg", "8", "uint8"), (".exr", "half", "half")])
def test_write_formats(tmp_path, ext, bits, dtype):
    pix = np.linspace(0, 1, 5 * 7 * 3, dtype=np.float32).reshape(5, 7, 3)
    p = tmp_path / f"o{ext}"
    write_frame(str(p), pix, None, "sRGB - Display", {}, None)
    inp = oiio.ImageInput.open(str(p))
    assert str(inp.spec().format) == dtype
    inp.close()
    got = oiio.ImageBuf(str(p)).get_pixels(oiio.FLOAT)
    tol = {"8": 0.03 if ext == ".jpg" else 1 / 255, "16": 1 / 65535, "half": 1e-3}[bits]
    np.testing.assert_allclose(got, pix, atol=tol)


def test_failed_write_leaves_nothing_and_names_the_file(tmp_path):
    (tmp_path / "afile").write_text("x")             # a missing folder is made; under a file
    with pytest.raises(FrameError, match="cannot make the output folder"):   # it cannot be
        write_frame(str(tmp_path / "afile" / "o.exr"), np.zeros((2, 2, 3), np.float32), None,
                    "x", {}, None, 4)
    assert os.listdir(tmp_path) == ["afile"]


def test_read_errors_name_file_and_frame(tmp_path):
    bad = tmp_path / "broken.0005.exr"
    bad.write_bytes(b"not an exr at all")
    with pytest.raises(FrameError) as e:
        read_frame(str(bad), 5)
    assert e.value.frame == 5 and "broken.0005.exr" in e.value.path


def _windowed_exr(path, pix, x=3, y=2):
    h, w, c = pix.shape
    spec = oiio.ImageSpec(w, h, c, oiio.FLOAT)
    spec.x, spec.y = x, y                      # data window offset
    spec.full_x, spec.full_y, spec.full_width, spec.full_height = 0, 0, w + 8, h + 6
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(x, x + w, y, y + h, 0, 1, 0, c), pix)
    assert buf.write(str(path)), buf.geterror()


@pytest.mark.parametrize("ext", [".exr", ".hdr", ".png", ".tif"])
def test_read_into_a_pool_in_bands_equals_the_whole_read(tmp_path, monkeypatch, ext):
    """A frame read in row bands into a pooled array (the run's reads) has the pixels
    and the metadata of the whole read: every band in its place (bands of 3 rows here,
    the last one short), a data window that does not start at 0 included."""
    rng = np.random.default_rng(4)
    pix = rng.uniform(0, 4, (11, 9, 4 if ext == ".exr" else 3)).astype(np.float32)
    src = tmp_path / f"in{ext}"
    if ext == ".exr":
        _windowed_exr(src, pix)
    else:
        write_frame(str(src), pix if ext == ".hdr" else pix / 4, None, "lin_rec709", {},
                    None)
    whole = read_frame(str(src), 3)
    monkeypatch.setattr(imageio, "POOL_BAND_BYTES", 3 * 9 * pix.shape[2] * 4)
    pool = FramePool()
    banded = read_frame(str(src), 3, pool=pool)
    np.testing.assert_array_equal(banded.pixels, whole.pixels)
    def meta(fr):
        return (fr.colorspace, fr.channel_note, fr.unassociated_alpha, fr.chromaticities,
                fr.format_name, fr.white_luminance, fr.pixels.dtype, fr.pixels.shape)
    assert meta(banded) == meta(whole)
    assert pool.made == 1 and any(a is banded.pixels for a in pool._arrays)
    if ext == ".exr":
        np.testing.assert_array_equal(banded.pixels, pix)


def test_a_pool_gives_an_array_again_only_when_nothing_holds_it():
    S, T = (4, 5, 3), (2, 2, 3)
    pool = FramePool(keep=2)
    a = pool.take(S)
    b = pool.take(S)
    assert b is not a and pool.made == 2              # a is held: a second array
    bid, view = id(b), b[1:, :, :2]
    del b
    c = pool.take(S)
    assert id(c) not in (id(a), bid) and pool.made == 3   # a view still holds b
    assert not any(x is c for x in pool._arrays)      # over ``keep``: not kept
    del view, c
    d = pool.take(S)
    assert id(d) == bid and pool.made == 3            # b is free again: no new memory
    del d
    e = pool.take(T)                                  # another size: the free b makes room
    eid = id(e)
    assert e.shape == T and pool.made == 4 and len(pool._arrays) == 2
    del e
    assert id(pool.take(T)) == eid and pool.made == 4
    assert pool.take(S) is not a and pool.made == 5   # a is still held, b is gone


def test_sequence_patterns(tmp_path):
    for f in (1, 2, 10):
        _write(tmp_path / f"s.{f:04d}.exr", np.zeros((1, 1, 3), np.float32))
    assert find_frames(str(tmp_path / "s.#.exr")) == [1, 2, 10]
    assert find_frames(str(tmp_path / "s.@@@@.exr")) == [1, 2, 10]
    assert find_frames(str(tmp_path / "s.%04d.exr")) == [1, 2, 10]
    assert frame_path("a.#.exr", 42) == "a.0042.exr" and frame_path("a.@@.exr", 7) == "a.07.exr"


# --- OCIO ------------------------------------------------------------------------

def test_config_resolution_order(monkeypatch):
    monkeypatch.delenv("OCIO", raising=False)
    assert colour.resolve_config_source() == "ocio://default"
    monkeypatch.setenv("OCIO", "ocio://studio-config-latest")
    assert colour.resolve_config_source() == "ocio://studio-config-latest"
    assert colour.resolve_config_source("ocl-tonemap").endswith("ocl_tonemap.ocio")
    assert colour.load_config("ocl-tonemap").getName() == "ocl-tonemap"


def test_bad_config_is_an_error_not_raw():
    with pytest.raises(colour.ColourError, match="cannot load OCIO config"):
        colour.load_config("/nonexistent/config.ocio")


@pytest.mark.parametrize("cfgname", ["ocl-tonemap", "ocio://default"])
@pytest.mark.parametrize("display", ["sRGB - Display", "Rec.1886 Rec.709 - Display",
                                     "Display P3 - Display", "Rec.2100-PQ - Display"])
def test_encode_equals_ocio_cpu_processor(cfgname, display):
    cfg = colour.load_config(cfgname)
    cp = colour.ColourPipeline(cfg, display)
    assert cp.view == "Un-tone-mapped"
    lin = np.random.default_rng(2).uniform(0, 10, (4, 5, 3)).astype(np.float32)
    ours = cp.encode(lin)
    proc = cfg.getProcessor(cp.working, display, "Un-tone-mapped",
                            ocio.TRANSFORM_DIR_FORWARD).getDefaultCPUProcessor()
    for px, got in zip(lin.reshape(-1, 3), ours.reshape(-1, 3)):
        np.testing.assert_allclose(got, proc.applyRGB([float(v) for v in px]), rtol=1e-6, atol=1e-7)


def test_bundled_config_matches_ocio_builtin():
    ours, ref = colour.load_config("ocl-tonemap"), colour.load_config("ocio://default")
    v = [0.3, 0.6, 0.1]
    for cs in ("ACEScg", "ACES2065-1", "lin_p3d65", "lin_rec2020"):
        a = ours.getProcessor(cs, "lin_rec709").getDefaultCPUProcessor().applyRGB(v)
        b = ref.getProcessor(cs, "lin_rec709").getDefaultCPUProcessor().applyRGB(v)
        np.testing.assert_allclose(a, b, rtol=1e-5)
    # PQ: display-linear 1.0 = 100 cd/m^2 (PQ code 0.508)
    cp = colour.ColourPipeline(ours, "Rec.2100-PQ - Display")
    assert cp.encode(np.ones((1, 1, 3), np.float32))[0, 0, 1] == pytest.approx(0.5081, abs=1e-3)


def test_input_colorspace_precedence(tmp_path):
    cfg = colour.load_config("ocl-tonemap")
    p = str(tmp_path / "x.exr")
    assert colour.input_colorspace(cfg, p, "ACEScg", "lin_p3d65") == ("lin_p3d65", "--iscolorspace")
    assert colour.input_colorspace(cfg, p, "ACEScg", None) == ("ACEScg", "file oiio:ColorSpace")
    assert colour.input_colorspace(cfg, p, "not-a-space", None)[0] == "lin_rec709"
    with pytest.raises(colour.ColourError):
        colour.input_colorspace(cfg, p, None, "nope")


def test_to_working_converts_acescg():
    cfg = colour.load_config("ocl-tonemap")
    cp = colour.ColourPipeline(cfg)
    px = np.array([[[0.2, 0.5, 0.1]]], np.float32)
    expect = cfg.getProcessor("ACEScg", "lin_rec709").getDefaultCPUProcessor().applyRGB([0.2, 0.5, 0.1])
    np.testing.assert_allclose(cp.to_working(px.copy(), "ACEScg")[0, 0], expect, rtol=1e-6)


def _tags(path):
    from ocl_tonemap.io.imagewrite import ocltm_metadata
    inp = oiio.ImageInput.open(str(path))
    sp = inp.spec()
    out = {k: sp.getattribute(k) for k in ("oiio:ColorSpace", "colorInteropID", "CICP",
                                            "chromaticities", "FramesPerSecond")}
    out["ocltm"] = ocltm_metadata(sp)
    inp.close()
    return out


@pytest.mark.requires_opencl
@pytest.mark.parametrize("display, name, args, want", [
    ("sRGB - Display", "lin.exr", [], "lin_rec709_scene"),
    ("Display P3 - Display", "p3.exr", [], "lin_p3d65_scene"),
    ("Rec.2100-PQ - Display", "pq.exr", [], "lin_rec2020_scene"),
    ("sRGB - Display", "enc.exr", ["--encode"], "srgb_rec709_display"),
    ("Display P3 - Display", "p3enc.exr", ["--encode"], "srgb_p3d65_display"),
    ("sRGB - Display", "o.png", [], "srgb_rec709_display"),
    ("Display P3 - Display", "p3.png", [], "srgb_p3d65_display"),
    ("Rec.2100-PQ - Display", "pq.png", [], "pq_rec2020_display"),
    ("Rec.2100-PQ - Display", "pq.tif", [], "pq_rec2020_display"),
])
def test_output_tags_are_true_to_the_data(tmp_path, display, name, args, want):
    """Each output's colour tags say what its pixels hold, whatever the input's said
    (the sample is tagged lin_rec709 and its tag was copied: a P3 EXR said
    lin_rec709_scene, an --encode EXR too, a PNG beside its own sRGB tag): EXR's
    colorInteropID and oiio:ColorSpace are the output's interop ID, its chromaticities
    the display's primaries; PNG: sRGB for sRGB, cICP for P3 and PQ (OIIO reads the
    sRGB chunk back as srgb_rec709_scene: the same encoding); TIFF keeps only an sRGB
    tag in OIIO, so a PQ TIFF's is the ImageDescription record's
    (ocltm:output_interop_id), and it carries no other."""
    from ocl_tonemap.cli.table import main
    from ocl_tonemap.io.sample import write_tunnel_sequence
    pattern, frames = write_tunnel_sequence(str(tmp_path / "s"), 32, 18, 30.0, 0.1)
    src = frame_path(pattern, frames[0])
    out = tmp_path / name
    assert main(["run", src, str(out), "-q", "--display", display, *args]) == 0
    t = _tags(out)
    assert t["ocltm"]["ocltm:output_interop_id"] == want
    ext = out.suffix
    if ext == ".exr":
        assert t["oiio:ColorSpace"] == t["colorInteropID"] == want
        prim = {"rec709": (0.64, 0.33), "p3d65": (0.68, 0.32), "rec2020": (0.708, 0.292)}
        red = next(v for k, v in prim.items() if k in want)
        assert t["chromaticities"][:2] == pytest.approx(red, abs=1e-3)
    elif ext == ".png":
        if want == "srgb_rec709_display":
            assert t["oiio:ColorSpace"] == "srgb_rec709_scene" and t["CICP"] is None
        else:
            assert t["CICP"] is not None and t["oiio:ColorSpace"].split("_")[:2] == \
                want.split("_")[:2]
    else:
        assert t["oiio:ColorSpace"] is None and t["colorInteropID"] is None


@pytest.mark.requires_opencl
def test_frames_per_second_is_the_runs(tmp_path):
    """--fps 24 on a 30 fps sample: the outputs say 24 (they said the input's 30)."""
    from ocl_tonemap.cli.table import main
    from ocl_tonemap.io.sample import write_tunnel_sequence
    pattern, frames = write_tunnel_sequence(str(tmp_path / "s"), 32, 18, 30.0, 0.1)
    out = tmp_path / "o.####.exr"
    assert main(["run", pattern, str(out), "-q", "--fps", "24", "--no-checkpoint"]) == 0
    assert _tags(frame_path(str(out), frames[0]))["FramesPerSecond"] == (24, 1)
    out2 = tmp_path / "p.####.exr"
    assert main(["run", pattern, str(out2), "-q", "--no-checkpoint"]) == 0
    assert _tags(frame_path(str(out2), frames[0]))["FramesPerSecond"] == (30, 1)
