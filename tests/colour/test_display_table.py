"""The OCIO display transform baked into device tables (colour.bake_display_table,
kernels/display.cl): error against OCIO's CPU processor over the display-linear domain,
the kernel against its float64 NumPy reference, and its use in a run. Real OCIO
configs and the real OpenCL device (PoCL in CI); no mocks."""

import logging
import threading

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap import colour
from ocl_tonemap.backends.opencl.display import DeviceDisplayTable
from ocl_tonemap.cli.table import main
from ocl_tonemap.colour import CODE_10BIT, ColourPipeline, display_probe_set, load_config
from ocl_tonemap.models.display import DISPLAY_LINEAR_MAX

#: kernel (float32) against DisplayTable.apply (float64): |d| <= KERNEL_TOL (1 + |ref|),
#: a few float32 rounding steps (0.004 10-bit code values).
KERNEL_TOL = 4e-6

BUNDLED = [(d, v) for d, views in colour.list_displays(load_config("ocl-tonemap")) for v in views]
STUDIO = "ocio://studio-config-latest"


@pytest.fixture(scope="module")
def probe():
    """1e6 random triples over log-luminance, the grey axis and the primaries and
    secondaries (dense), saturated colours: (N, 3) float32 in [0, DISPLAY_LINEAR_MAX]."""
    p = display_probe_set(1_000_000, seed=7)
    assert len(p) > 1_100_000 and p.min() == 0.0 and p.max() == DISPLAY_LINEAR_MAX
    return p


def pipeline(src, display, view=None):
    return ColourPipeline(load_config(src), display, view)


def ocio_encode(cp, rgb):
    x = np.ascontiguousarray(rgb.reshape(1, -1, 3), np.float32)
    return cp.encode(x)[0].astype(np.float64)


def errors(got, want):
    e = np.abs(np.asarray(got, np.float64) - want).max(axis=1)
    return e.max(), np.percentile(e, 99.9)


@pytest.mark.parametrize("display,view", BUNDLED)
def test_bundled_config_tables_within_one_10bit_code(display, view, probe):
    cp = pipeline("ocl-tonemap", display, view)
    t = cp.display_table()
    if view == "Raw":
        assert t.kind == "identity"
        return
    assert t.kind == "1d", t.describe()          # matrix + per-channel curves
    mx, p999 = errors(t.apply(probe), ocio_encode(cp, probe))
    assert mx < CODE_10BIT, f"{display}: max {mx * 1023:.3f} 10-bit codes"
    assert p999 <= mx and t.within_10bit
    # the bake-time self-check saw the same order of error
    assert t.max_error < CODE_10BIT and t.max_error <= 2 * mx + 1e-6


@pytest.mark.parametrize("display", ["sRGB - Display", "Display P3 - Display",
                                     "Gamma 2.2 Rec.709 - Display",
                                     "Gamma 2.6 P3-D65 - Display",
                                     "Rec.1886 Rec.709 - Display", "Rec.2100-PQ - Display",
                                     "ST2084-P3-D65 - Display"])
def test_builtin_config_plain_views_are_separable_and_within_bound(display, probe):
    cp = pipeline("ocio://default", display, "Un-tone-mapped")
    t = cp.display_table()
    assert t.kind == "1d"
    mx, _ = errors(t.apply(probe), ocio_encode(cp, probe))
    assert mx < CODE_10BIT, f"{display}: max {mx * 1023:.3f} 10-bit codes"


def test_hlg_is_not_separable_and_its_3d_table_is_within_bound(probe):
    """HLG's OOTF scales by a power of luminance: not per channel, so a 3D table."""
    cp = pipeline(STUDIO, "Rec.2100-HLG - Display", "Un-tone-mapped")
    t = cp.display_table()
    assert t.kind == "3d" and t.shaper == "log2"
    one_d = cp.display_table(form="1d")
    assert one_d.max_error > 10 * CODE_10BIT     # the probe sees the non-separability
    mx, _ = errors(t.apply(probe), ocio_encode(cp, probe))
    assert mx < CODE_10BIT, f"max {mx * 1023:.3f} 10-bit codes"


@pytest.mark.requires_opencl
def test_aces_output_transform_falls_back_to_ocio_in_auto():
    cp = pipeline(STUDIO, "sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)")
    t = cp.display_table()
    assert t.kind == "3d" and not t.within_10bit
    note = cp.set_display_encode("auto", "opencl")
    assert cp.device_table is None and "OCIO CPU processor" in note
    cp.set_display_encode("table", "opencl")      # asked for: used, error stated
    assert isinstance(cp.device_table, DeviceDisplayTable)
    assert "10-bit code values" in cp.display_encode_note


SPECIAL = np.array([[np.nan, 0.5, 0.5], [-1.0, 0.2, 0.3], [1e3, 1e5, 0.0], [np.inf, 1.0, 0.0],
                    [1e-30, 1e-38, 0.0], [DISPLAY_LINEAR_MAX] * 3, [0.0, 0.0, 0.0],
                    [-np.inf, -1e-3, 2.0]], np.float32)


@pytest.mark.parametrize("src,display,view,kind", [
    ("ocl-tonemap", "sRGB - Display", None, "1d"),
    ("ocl-tonemap", "Display P3 - Display", None, "1d"),
    ("ocl-tonemap", "Rec.2100-PQ - Display", None, "1d"),
    (STUDIO, "Rec.2100-HLG - Display", "Un-tone-mapped", "3d"),
    (STUDIO, "sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)", "3d"),
])
def test_kernel_matches_numpy_reference(rt, src, display, view, kind, probe):
    t = pipeline(src, display, view).display_table()
    assert t.kind == kind
    dev = DeviceDisplayTable(t, runtime=rt)
    x = np.concatenate([probe[: len(probe) // 16 * 4], SPECIAL])     # 8 special: len % 4 == 0
    ref = t.apply(x.astype(np.float64))
    got = dev.encode(x.reshape(1, -1, 3))[0]
    assert got.dtype == np.float32 and np.all(np.isfinite(got))
    np.testing.assert_allclose(got, ref, rtol=KERNEL_TOL, atol=KERNEL_TOL)
    # RGBA: the same colour, alpha passed through bit for bit
    a = np.random.default_rng(1).uniform(0, 1, (len(x), 1)).astype(np.float32)
    got4 = dev.encode(np.concatenate([x, a], axis=1).reshape(4, -1, 4))
    assert got4.shape == (4, len(x) // 4, 4)
    np.testing.assert_array_equal(got4.reshape(-1, 4)[:, :3], got)
    np.testing.assert_array_equal(got4.reshape(-1, 4)[:, 3], a[:, 0])


@pytest.mark.parametrize("src,display,view", [("ocl-tonemap", "sRGB - Display", None),
                                              (STUDIO, "Rec.2100-HLG - Display",
                                               "Un-tone-mapped")])
def test_8bit_code_values_are_the_bytes_oiio_writes(rt, tmp_path, src, display, view, probe):
    """encode(bits=8) quantises on the device: the same bytes as the float code
    values written to an 8-bit PNG by OIIO's ImageOutput (which quantises them
    itself: ties to even, where an ImageBuf's write rounds them up), on the
    probe set, the special values, every half-code boundary (k + 0.5) / 255 and
    its float neighbours, RGB and RGBA (alpha quantised the same way).

    Where v * 255 is exactly k + 0.5 in float32 OIIO's own rounding depends on the
    machine (the same wheel: ties to even on this CI machine kind, half up on the
    H100 machine's Xeon): there the device's byte is the even one, as documented,
    and OIIO's either neighbour."""
    import OpenImageIO as oiio
    from ocl_tonemap.io.imagewrite import write_frame
    t = pipeline(src, display, view).display_table()
    dev = DeviceDisplayTable(t, runtime=rt)
    edges = ((np.arange(-2, 258) + 0.5) / 255.0).astype(np.float32)
    edges = np.concatenate([edges, np.nextafter(edges, np.float32(2)),
                            np.nextafter(edges, np.float32(-2))])
    # inputs whose encodings land on the half-code boundaries: the table's inverse is
    # not at hand, so the boundaries are fed as alpha (quantised by the same code)
    x = np.concatenate([probe[: len(probe) // 64 * 4], SPECIAL])
    n = len(x) // 4 * 4
    a = np.resize(edges, n)[:, None]
    for pix in (x[:n].reshape(4, -1, 3), np.concatenate([x[:n], a], 1).reshape(4, -1, 4)):
        f = dev.encode(pix)
        q = dev.encode(pix, bits=8)
        assert q.dtype == np.uint8 and q.shape == pix.shape
        paths = [str(tmp_path / "f.png"), str(tmp_path / "q.png")]
        for path, px in zip(paths, (f, q)):
            write_frame(path, px, None, "sRGB", {}, straight_alpha=True)
        raw = oiio.ImageSpec()
        raw.attribute("oiio:UnassociatedAlpha", 1)          # the file's bytes, as stored
        fb, qb = (oiio.ImageBuf(p, 0, 0, raw).get_pixels(oiio.UINT8) for p in paths)
        np.testing.assert_array_equal(qb, q)
        v = np.clip(f * np.float32(255), 0, 255)
        tie = v % 1 == 0.5
        assert tie.any() or pix.shape[-1] == 3
        np.testing.assert_array_equal(qb[~tie], fb[~tie])
        np.testing.assert_array_equal(q[tie], np.rint(v[tie]))          # ties to even
        assert np.all(np.abs(fb[tie].astype(int) - qb[tie]) <= 1)


@pytest.mark.parametrize("ext", [".png", ".tif"])
def test_16bit_code_values_are_the_values_oiio_writes(rt, tmp_path, ext, probe):
    """encode(bits=16) quantises on the device as OIIO's ImageOutput quantises float
    code values into a 16-bit file: v 65535 clamped, rounded to the nearest, ties to
    even (measured on every code and its half-code boundaries), NaN 0; RGB and RGBA,
    every half-code boundary (k + 0.5) / 65535 and its float neighbours fed as alpha."""
    import OpenImageIO as oiio
    from ocl_tonemap.io.imagewrite import write_frame
    t = pipeline("ocl-tonemap", "sRGB - Display").display_table()
    dev = DeviceDisplayTable(t, runtime=rt)
    edges = ((np.arange(-2, 65538, 7) + 0.5) / 65535.0).astype(np.float32)
    edges = np.concatenate([edges, np.nextafter(edges, np.float32(2)),
                            np.nextafter(edges, np.float32(-2)), [np.nan, np.inf, -np.inf]])
    x = np.concatenate([probe[: len(probe) // 64 * 4], SPECIAL])
    n = len(x) // 4 * 4
    a = np.resize(edges.astype(np.float32), n)[:, None]
    for pix in (x[:n].reshape(4, -1, 3), np.concatenate([x[:n], a], 1).reshape(4, -1, 4)):
        f, q = dev.encode(pix), dev.encode(pix, bits=16)
        assert q.dtype == np.uint16 and q.shape == pix.shape
        paths = [str(tmp_path / f"f{ext}"), str(tmp_path / f"q{ext}")]
        for path, px in zip(paths, (f, q)):
            write_frame(path, px, None, "sRGB", {}, bits="16", straight_alpha=True)
        raw = oiio.ImageSpec()
        raw.attribute("oiio:UnassociatedAlpha", 1)
        fb, qb = (oiio.ImageBuf(p, 0, 0, raw).get_pixels(oiio.UINT16) for p in paths)
        np.testing.assert_array_equal(qb, q)               # written as they came
        with np.errstate(over="ignore"):                    # (+Inf in the ramp: 65535)
            v = np.clip(np.nan_to_num(f, nan=0.0) * np.float32(65535), 0, 65535)
        tie = v % 1 == 0.5                                  # (OIIO's rounding of an exact
        np.testing.assert_array_equal(fb[~tie], q[~tie])    # tie is the machine's: as
        np.testing.assert_array_equal(q[tie], np.rint(v[tie]))    # for 8 bits above)
        assert np.all(np.abs(fb[tie].astype(int) - q[tie]) <= 1)


@pytest.mark.parametrize("display", ["sRGB - Display", "Rec.2100-PQ - Display"])
def test_device_encoding_against_ocio(rt, display, probe):
    cp = pipeline("ocl-tonemap", display)
    cp.set_display_encode("table", "opencl")
    got = cp.encode_fast(probe.reshape(1, -1, 3)).reshape(-1, 3)
    mx, _ = errors(got, ocio_encode(cp, probe))
    assert mx < CODE_10BIT


def test_device_table_is_safe_from_several_threads(rt):
    t = pipeline("ocl-tonemap", "sRGB - Display").display_table()
    dev = DeviceDisplayTable(t, runtime=rt)
    rng = np.random.default_rng(3)
    frames = [rng.uniform(0, 4, (96 + 8 * i, 160, 3)).astype(np.float32) for i in range(6)]
    want = [dev.encode(f) for f in frames]
    got: dict = {}

    def work(k):
        for _ in range(4):
            for i in range(k, len(frames), 3):
                got[(k, i)] = dev.encode(frames[i])
    threads = [threading.Thread(target=work, args=(k,)) for k in range(3)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for (k, i), g in got.items():
        np.testing.assert_array_equal(g, want[i])


@pytest.mark.requires_opencl
def test_display_encode_modes():
    cp = pipeline("ocl-tonemap", "sRGB - Display")
    x = np.random.default_rng(0).uniform(0, 2, (8, 9, 3)).astype(np.float32)
    assert cp.device_table is None
    np.testing.assert_array_equal(cp.encode_fast(x), cp.encode(x))      # no table: OCIO
    assert "ocio" in cp.set_display_encode("ocio", "opencl") and cp.device_table is None
    assert "backend reference" in cp.set_display_encode("auto", "reference")
    assert cp.device_table is None
    cp.set_display_encode("auto", "opencl")
    assert cp.device_table is not None and "1D table" in cp.display_encode_note
    d = np.abs(cp.encode_fast(x).astype(np.float64) - cp.encode(x)).max()
    assert 0 < d < CODE_10BIT
    with pytest.raises(colour.ColourError, match="display-encode"):
        cp.set_display_encode("fast")
    raw = pipeline("ocl-tonemap", "sRGB - Display", "Raw")
    raw.set_display_encode("table", "opencl")              # identity: nothing to do
    assert raw.device_table is None
    np.testing.assert_array_equal(raw.encode_fast(x), x)


def test_job_option_is_validated():
    from ocl_tonemap.job.options import JobOptions
    assert JobOptions("a.exr", "b.png").display_encode == "auto"
    with pytest.raises(ValueError, match="display-encode"):
        JobOptions("a.exr", "b.png", display_encode="gpu")


def read(path):
    inp = oiio.ImageInput.open(str(path))
    px = inp.read_image(format=oiio.UINT8).astype(int)
    inp.close()
    return px


@pytest.mark.requires_opencl
def test_run_through_the_table_matches_ocio_within_one_8bit_code(sample_dir, tmp_path, caplog):
    pattern, frames = sample_dir
    outs = {}
    for mode in ("table", "ocio"):
        with caplog.at_level(logging.INFO, logger="ocl_tonemap"):
            caplog.clear()
            assert main(["run", pattern, str(tmp_path / f"{mode}.#.png"), "--frames", "1-4",
                         "--display-encode", mode, "--luminance-scale", "1"]) == 0
        said = [r.getMessage() for r in caplog.records if "display encoding" in r.getMessage()]
        assert len(said) == 1 and (("1D table" in said[0]) == (mode == "table")), said
        outs[mode] = [read(tmp_path / f"{mode}.{f:04d}.png") for f in range(1, 5)]
    for a, b in zip(outs["table"], outs["ocio"]):
        assert np.abs(a - b).max() <= 1


def test_png_filter_and_device_quantisation_keep_the_pixels(sample_dir, tmp_path):
    """The whole command's 8-bit PNG: the bytes quantised on the device (the default)
    equal those OIIO quantises from the float code values of the same table (a
    float TIFF of the frame read back as 8 bits), and each --png-filter
    writes the same pixels (only the file's size changes)."""
    import os
    from ocl_tonemap.job.options import JobOptions
    pattern, frames = sample_dir
    got = {}
    for filt in ("sub", "none", "adaptive"):
        assert main(["run", pattern, str(tmp_path / f"{filt}.#.png"), "--frames", "3-3",
                     "--luminance-scale", "1", "--png-filter", filt]) == 0
        got[filt] = read(tmp_path / f"{filt}.0003.png")
    np.testing.assert_array_equal(got["sub"], got["none"])
    np.testing.assert_array_equal(got["sub"], got["adaptive"])
    sizes = {f: os.path.getsize(tmp_path / f"{f}.0003.png") for f in got}
    assert len(set(sizes.values())) == 3, sizes
    # the float code values of the same frame (a float TIFF), quantised by OIIO
    assert main(["run", pattern, str(tmp_path / "f.#.tif"), "--frames", "3-3",
                 "--luminance-scale", "1", "--out-bits", "float"]) == 0
    np.testing.assert_array_equal(got["sub"], read(tmp_path / "f.0003.tif"))
    with pytest.raises(ValueError, match="png-filter"):
        JobOptions(input=pattern, output=str(tmp_path / "x.#.png"), png_filter="best")


def test_cached_table_equals_a_fresh_bake_and_follows_the_transform(tmp_path, monkeypatch):
    """The user-cache copy of a baked table is the bake, field for field; another
    display (another processor cache ID) bakes its own; a damaged file is baked again."""
    import dataclasses
    monkeypatch.setenv("OCLTM_CACHE_DIR", str(tmp_path))
    cfg = load_config("ocl-tonemap")
    cp = ColourPipeline(cfg, "sRGB - Display")
    proc = cfg.getProcessor(cp.working, cp.display, cp.view, __import__("PyOpenColorIO").TRANSFORM_DIR_FORWARD)
    first = colour.cached_display_table(proc, description="x")
    files = list((tmp_path / "display-tables").glob("*.npz"))
    assert len(files) == 1
    again = colour.cached_display_table(proc, description="y")
    fresh = colour.bake_display_table(proc, description="y")
    for f in dataclasses.fields(colour.DisplayTable):
        a, b = getattr(again, f.name), getattr(fresh, f.name)
        assert np.array_equal(a, b) if isinstance(b, np.ndarray) else a == b, f.name
    assert first.description == "x" and again.description == "y"
    other = ColourPipeline(cfg, BUNDLED[-1][0], BUNDLED[-1][1])
    other.display_table()
    assert len(list((tmp_path / "display-tables").glob("*.npz"))) == 2
    files[0].write_bytes(b"not a table")
    assert colour.cached_display_table(proc).max_error == fresh.max_error
