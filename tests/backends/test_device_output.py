"""The display encoding applied where the operator's output is (``Tonemapper.process_frame(..., encoding=)``):
the code values that come back from the device are the ones the host path makes from the
display-linear frame, to the byte; frames that cannot take it fall back and say so."""

import numpy as np
import pytest

from ocl_tonemap.colour import ColourPipeline, load_config
from ocl_tonemap.effects import EffectSettings
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.job.frame import encode_pixels

from conftest import hdr_image


@pytest.fixture(scope="module")
def colour_table(rt):
    cp = ColourPipeline(load_config("ocl-tonemap"), "sRGB - Display")
    cp.set_display_encode("table", "opencl")
    assert cp.device_table is not None and cp.device_table.rt.context == rt.context
    return cp


def frames(h, w):
    """Three frames of a drive into the dark: daylight, dusk, night (cd/m^2)."""
    base = hdr_image(h, w, seed=5, lo=-2.0, hi=4.0).astype(np.float32)
    return [base, base * 1e-2, base * 1e-4]


def run(op, cp, bits, pix, encode_on_device, wavelengths=None, **kw):
    tm = Tonemapper(op, "opencl", **kw)
    outs, flags = [], []
    for i, f in enumerate(pix):
        enc = cp.device_output_encoding(bits, tm.backend.device_runtime()) \
            if encode_on_device else None
        res = tm.process_frame(f, time_s=0.5 * i, wavelengths=wavelengths, encoding=enc)
        flags.append(res.encoded)
        outs.append(res.output if res.encoded else
                    encode_pixels(cp, res.output, res.alpha, False, bits))
    return outs, flags, tm


@pytest.mark.parametrize("op", ["pattanaik00", "durand00", "ledda04", "kirk11"])
@pytest.mark.parametrize("bits", [8, 16, 0])
def test_device_encoding_equals_the_host_path(colour_table, op, bits):
    """Same bytes (8-bit), the same 16-bit codes (half the download of floats) or the
    same float code values, frame after frame; 37 x 29 pixels: the 4-pixel kernel and
    its scalar tail both run."""
    pix = frames(29, 37)
    want, f0, _ = run(op, colour_table, bits, pix, False)
    got, f1, tm = run(op, colour_table, bits, pix, True)
    assert f0 == [False] * 3 and f1 == [True] * 3
    dtype = {8: np.uint8, 16: np.uint16, 0: np.float32}[bits]
    for g, w_ in zip(got, want):
        assert g.dtype == dtype and g.shape == (29, 37, 3)
        np.testing.assert_array_equal(g, w_)


@pytest.mark.parametrize("op", ["pattanaik00", "kirk11"])
def test_banded_frames_are_encoded_band_by_band(colour_table, op):
    """A frame in row bands (max_band_pixels): every band comes back encoded, in place."""
    pix = frames(40, 33)
    want, _, _ = run(op, colour_table, 8, pix, False, max_band_pixels=33 * 7)
    got, flags, tm = run(op, colour_table, 8, pix, True, max_band_pixels=33 * 7)
    assert len(tm.backend.bands(40, 33)) > 1 and flags == [True] * 3
    for g, w_ in zip(got, want):
        np.testing.assert_array_equal(g, w_)


def test_spectral_frames_are_encoded(colour_table):
    """kirk11 on spectral radiance: the same bytes either way."""
    from ocl_tonemap.io.sample import spectral_patches
    lam, spectra, _ = spectral_patches("A", 1.0)
    cube = (spectra[np.arange(24 * 9) % 24].reshape(12, 18, -1) * 50.0).astype(np.float32)
    pix = [cube, cube * 1e-2, cube * 1e-4]
    want, _, _ = run("kirk11", colour_table, True, pix, False, wavelengths=lam)
    got, flags, _ = run("kirk11", colour_table, True, pix, True, wavelengths=lam)
    assert flags == [True] * 3
    for g, w_ in zip(got, want):
        np.testing.assert_array_equal(g, w_)


@pytest.mark.parametrize("op", ["pattanaik00", "durand00", "ledda04", "kirk11"])
def test_acuity_blurs_on_the_device_before_the_encoding(colour_table, op):
    """Acuity at night (2 degrees over 37 px: a wide blur) on a frame in one band: blurred
    where the operator left it and encoded there (``encoded``), within one 8-bit code of
    the host path (display-linear back, blurred in float64, encoded: float32 rounding)
    and its acuity record the same; a frame in row bands still takes the host path."""
    pix = frames(29, 37)
    fx = {"effects": EffectSettings(acuity="on", fov_deg=2.0)}
    want, f0, ref = run(op, colour_table, True, pix, False, **fx)
    got, f1, tm = run(op, colour_table, True, pix, True, **fx)
    assert f0 == [False] * 3 and f1 == [True] * 3
    assert tm.last.effects["acuity"]["ran"] and tm.last.effects["acuity"]["blend"] > 0
    assert tm.last.effects["acuity"] == ref.last.effects["acuity"]
    for g, w_ in zip(got, want):
        d = np.abs(g.astype(int) - w_.astype(int))
        assert d.max() <= 1 and np.mean(d > 0) < 0.02, (d.max(), np.mean(d > 0))
    # the blur changed the frame: not the unblurred one
    plain, _, _ = run(op, colour_table, True, pix[2:], True)
    assert np.abs(plain[0].astype(int) - got[2].astype(int)).max() > 4
    _, fb, _ = run(op, colour_table, True, pix, True, max_band_pixels=37 * 8, **fx)
    assert fb == [True, False, False]          # daylight does not blur: encoded


def test_frames_that_cannot_fall_back_to_the_host_path(colour_table):
    """Alpha and luminance-only frames: display-linear comes back
    (``FrameResult.encoded`` False), unchanged (acuity at night is blurred on the
    device: test_acuity_blurs_on_the_device_before_the_encoding)."""
    enc = colour_table.device_output_encoding(True, None)
    assert enc is None                                   # no runtime: no device encoding
    pix = frames(16, 20)
    cases = [("pattanaik00", [np.concatenate([p, np.full_like(p[..., :1], 0.5)], 2)
                              for p in pix], {}),
             ("pattanaik00", [p[..., 1] for p in pix], {})]
    for op, px, kw in cases:
        tm = Tonemapper(op, "opencl", **kw)
        enc = colour_table.device_output_encoding(True, tm.backend.device_runtime())
        for i, f in enumerate(px):
            res = tm.process_frame(f, time_s=3600.0 * i, encoding=enc)
            out = res.output
            assert not res.encoded and out.dtype == np.float32, (op, i)
            ref = Tonemapper(op, "opencl", **kw)
            for j in range(i + 1):
                r = ref.process(px[j], time_s=3600.0 * j)
            np.testing.assert_array_equal(out, r)
