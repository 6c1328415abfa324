"""Kirk & O'Brien 2011: receptor responses, the Purkinje shift, the non-negative
display solve, range reduction; spectral and RGB input; float64 and OpenCL."""

import json

import numpy as np
import pytest

from ocl_tonemap.models import kirk2011 as ko
from ocl_tonemap.models import lmsr
from ocl_tonemap.io.imageio import read_frame
from ocl_tonemap.io.channels import spectral_channels
from ocl_tonemap.models.numerics import nnls
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.io.sample import spectral_patches, write_spectral_image

RED, ORANGE, BLUE, GREEN, WHITE = 14, 6, 12, 13, 18     # ColorChecker patch indices


# --- LMSR ------------------------------------------------------------------------------

def test_sensitivities_from_colour_science():
    S = lmsr.sensitivities()
    # peaks as Kirk & O'Brien give them (x 683 lm/W); rods peak near 507 nm
    np.testing.assert_allclose(S[:3].max(axis=1) / 683, [0.637, 0.392, 1.606], rtol=1e-9)
    assert abs(lmsr.WL[np.argmax(S[3])] - 507) <= 1 and S[3].max() == pytest.approx(1700, rel=1e-3)
    assert abs(lmsr.WL[np.argmax(S[0])] - 570) < 5 and abs(lmsr.WL[np.argmax(S[2])] - 440) < 5


def test_spectral_integration_is_exact_for_piecewise_linear_spectra():
    lam = np.arange(400.0, 701.0, 5.0)
    rng = np.random.default_rng(0)
    s = rng.uniform(0, 1, len(lam))
    fine = np.interp(lmsr.WL, lam, s, left=0, right=0)
    direct = (lmsr.sensitivities() * np.gradient(lmsr.WL)) @ fine
    np.testing.assert_allclose(lmsr.spectral_to_lmsr(lam, s), direct, rtol=1e-12)


def test_refit_gives_the_shipped_matrix_and_held_out_errors():
    from benchmarks.lib.fit_lmsr import fit
    doc = fit()
    shipped = json.loads(lmsr.FIT_FILE.read_text())
    np.testing.assert_allclose(doc["H"], shipped["H"], rtol=1e-10, atol=1e-12)
    held = doc["held_out"]["rms_relative"]
    # cones are a near-linear function of RGB; rods are not (the paper's "high residual")
    assert held["L"] < 0.01 and held["M"] < 0.01 and held["S"] < 0.05
    assert 0.02 < held["R"] < 0.2
    H = np.asarray(doc["H"])
    assert H[0].sum() + H[1].sum() == pytest.approx(1.0, abs=0.06)   # L + M ~ luminance


def test_spectral_exr_round_trip(tmp_path):
    p = str(tmp_path / "cc.exr")
    lam = write_spectral_image(p, "D65", 10.0, patch_px=2)
    fr = read_frame(p)
    np.testing.assert_array_equal(fr.wavelengths, lam)
    assert fr.spectral.shape == (8, 12, len(lam)) and fr.rgb_from_spectrum
    _, spectra, _ = spectral_patches("D65", 10.0)
    q_file = lmsr.spectral_to_lmsr(fr.wavelengths, fr.spectral[::2, ::2].reshape(24, -1))
    np.testing.assert_allclose(q_file, lmsr.spectral_to_lmsr(lam, spectra), rtol=1e-6)
    # the same patches through 1 nm spectra: 10 nm sampling costs < 2%
    lam1, fine, _ = spectral_patches("D65", 10.0, lmsr.WL)
    q_fine = lmsr.spectral_to_lmsr(lam1, fine)
    np.testing.assert_allclose(q_file, q_fine, rtol=0.02, atol=1e-3)
    # the RGB derived from the spectrum: white patch near D65 grey at 9 cd/m^2
    w = fr.pixels[2 * 3, 2 * 0]  # row 3 patch 0 = white
    assert w @ np.array([0.2126, 0.7152, 0.0722]) == pytest.approx(10.0 * 0.9, rel=0.1)


@pytest.mark.parametrize("names, n", [
    (["S0.400nm", "S0.450nm", "S0.500nm", "S0.550nm", "S0.600nm"], 5),
    (["S0.400,000000nm", "S0.500,000000nm", "S0.600,000000nm", "S0.700,000000nm"], 4),
    (["R", "G", "B", "450nm", "500nm", "550nm", "600nm"], 4),
    (["410", "420", "430", "440"], 4),
    (["R", "G", "B", "A"], 0)])
def test_spectral_channel_names(names, n):
    ch = spectral_channels(names)
    assert len(ch) == n and [w for _, w in ch] == sorted(w for _, w in ch)


# --- the shift ------------------------------------------------------------------------

def test_opponent_matrix_and_constants():
    q = np.array([3.0, 2.0, 1.0])
    np.testing.assert_allclose(ko.A @ q, [2 - 3, 1 - 5, 5])         # Eq. 11
    np.testing.assert_allclose(ko.A_INV @ ko.A, np.eye(3), atol=1e-15)


def test_photopic_scene_is_unchanged_by_the_shift():
    _, spectra, _ = spectral_patches("D65", 1.0)
    lam = np.arange(400.0, 701.0, 10.0)
    rel_full = []
    for L in (1e3, 1e4, 1e5):
        q = lmsr.spectral_to_lmsr(lam, spectra * L)
        area = ko.model_scale()
        k1, k2, gain = ko.kappas(ko.KirkSettings(kappa="adaptive"), ko.logmean(q[:, 3]))
        qh, _ = ko.purkinje_shift(q, area, k1, k2, rod_gain=gain)
        np.testing.assert_array_equal(qh, q[:, :3])        # adaptive (default): exactly none
        qh, w = ko.purkinje_shift(q, area)                 # the paper's fixed kappa
        rel_full.append(np.median(np.abs(qh - q[:, :3]).max(axis=1) / (q[:, 0] + q[:, 1])))
    # fixed kappa: the shift decays as g ~ q^-1/2 -- measured median 5.4%, 1.7%, 0.5%
    # of L+M at 1e3, 1e4, 1e5 cd/m^2 (docs/models.md)
    assert rel_full[0] > rel_full[1] > rel_full[2] and rel_full[0] < 0.07
    assert 2.0 < rel_full[1] / rel_full[2] < 4.5               # ~ sqrt(10) per decade


def _shifted(exposure, kappa="adaptive", xyz=(1.5, 1.5, 5.0)):
    """Per ColorChecker patch: (rgb chromaticity after shift + NNLS, relative shift
    |q^ - q| / (L + M), w) -- before range reduction. ``xyz``: the gamut-limit
    calibration of the shift scales (the default is a third of it)."""
    lam, spectra, _ = spectral_patches("D65", exposure)
    q = lmsr.spectral_to_lmsr(lam, spectra)
    settings = ko.KirkSettings(kappa=kappa)
    k1, k2, gain = ko.kappas(settings, ko.logmean(q[:, 3]))
    qh, w = ko.purkinje_shift(q, ko.model_scale(), k1, k2, xyz, rod_gain=gain)
    p, _ = ko.nnls3(ko.display_matrix(np.eye(3)), qh)
    rel = np.abs(qh - q[:, :3]).max(axis=1) / (q[:, 0] + q[:, 1])
    return p / np.maximum(p.sum(axis=1, keepdims=True), 1e-300), rel, w


@pytest.mark.parametrize("kappa", ["adaptive", "full"])
def test_scotopic_scene_shifts_to_blue_green_and_loses_red(kappa):
    exposures = [1e4, 1e3, 1e2, 10.0, 1.0, 0.1, 0.01, 1e-3]
    runs = [_shifted(e, kappa) for e in exposures]
    red = np.array([c[RED, 0] for c, _, _ in runs])
    assert np.all(np.diff(red) <= 1e-12) and red[-1] < 0.4 * red[0]     # reds lose red
    grey = runs[-1][0][WHITE]
    assert grey[1] > 1.5 * grey[0] and grey[2] > 1.5 * grey[0]           # white: blue-green
    assert grey.min() > 0.15                                             # ... a pale one
    # the shift and w grow monotonically as exposure falls
    shift = [np.median(r) for _, r, _ in runs]
    ws = [w.mean() for _, _, w in runs]
    assert np.all(np.diff(shift) >= 0) and shift[-1] > shift[0] and np.all(np.diff(ws) > 0)
    # the default scales: the same direction, a third as strong
    red_d = np.array([_shifted(e, kappa, ko.SHIFT_XYZ)[0][RED, 0] for e in exposures])
    assert np.all(np.diff(red_d) <= 1e-12) and red[-1] < red_d[-1] < 0.6 * red_d[0]
    grey_d = _shifted(1e-3, kappa, ko.SHIFT_XYZ)[0][WHITE]
    assert grey_d[1] > grey_d[0] and grey_d[2] > grey_d[0]


def test_metamers_differ_only_when_scotopic(rt):
    lam = np.arange(400.0, 701.0, 10.0)
    W = lmsr.spectrum_weights(lam)
    _, spectra, _ = spectral_patches("D65", 1.0)
    s1 = spectra[GREEN]
    # a spectrum change invisible to the cones but not to the rods
    _, _, vt = np.linalg.svd(W[:3])
    null = vt[3:]
    n = null.T @ (null @ W[3])                                     # most rod-visible null direction
    s2 = s1 + n * (0.5 * s1.min() / np.abs(n).max())
    assert np.all(s2 >= 0)
    q1, q2 = W @ s1, W @ s2
    np.testing.assert_allclose(q1[:3], q2[:3], rtol=1e-9)
    assert abs(q2[3] / q1[3] - 1) > 0.02
    img = np.stack([np.tile(s1, (4, 4, 1)), np.tile(s2, (4, 4, 1))], axis=0).reshape(8, 4, -1)
    for exposure, kappa, same in ((3e3, "adaptive", True), (1e-3, "full", False)):
        for be in ("reference", "opencl"):
            tm = Tonemapper("kirk11", be, options={"kappa": kappa, "sigma_spatial": 1.0}, model="none")
            out = tm.process((img * exposure).astype(np.float32), wavelengths=lam)
            a, b = out[1, 1], out[6, 1]
            if same:
                np.testing.assert_allclose(a, b, rtol=1e-4, atol=1e-6)
            else:
                assert np.abs(a - b).max() > 0.01 * max(a.max(), b.max())


def test_nnls3_is_optimal_and_non_negative():
    M = ko.display_matrix(np.eye(3))
    rng = np.random.default_rng(3)
    q = rng.normal(size=(400, 3)) * np.array([1, 1, 2]) + np.array([1, 1, 0.5])
    p, fb = ko.nnls3(M, q)
    assert np.all(p >= 0) and fb.any() and (~fb).any()
    for i in range(len(q)):
        ref, res = nnls(M, q[i])
        assert np.linalg.norm(M @ p[i] - q[i]) <= res + 1e-9
        np.testing.assert_allclose(p[i], ref, atol=1e-7)


# --- whole operator ------------------------------------------------------------------

def _rgb_scene(h=24, w=36, seed=0):
    rng = np.random.default_rng(seed)
    img = rng.uniform(0.05, 1, (h, w, 3)) * rng.choice([0.02, 1.0, 30.0], (h, w, 1))
    img[:8, :8] = [1.0, 0.08, 0.06]
    return img.astype(np.float32)


@pytest.mark.parametrize("exposure", [100.0, 1.0, 0.01, 1e-4])
def test_opencl_matches_reference_rgb(exposure, rt):
    img = _rgb_scene() * np.float32(exposure)
    a = Tonemapper("kirk11", "reference", model="none").process(img)
    tm = Tonemapper("kirk11", "opencl", options={"bilateral": "exact"}, model="none")
    b = tm.process(img)
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-5)
    assert b.min() >= 0 and 0 <= tm.last.params["fallback_fraction"] <= 1


def test_opencl_matches_reference_spectral(rt):
    lam, spectra, _ = spectral_patches("A", 0.05)
    img = np.repeat(np.repeat(spectra.reshape(4, 6, -1), 4, 0), 4, 1).astype(np.float32)
    a = Tonemapper("kirk11", "reference", model="none").process(img, wavelengths=lam)
    b = Tonemapper("kirk11", "opencl", model="none").process(img, wavelengths=lam)
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-5)


def test_spectral_bad_values_repaired_and_counted_on_the_device(rt):
    """The one-pass device kernel (spectrum_to_lmsr): bad values in the first
    four-channel chunks and in the scalar tail (channels 28-30 of 31) are repaired by
    the policy, counted as the float64 reference counts them, and the frame maps as
    the reference maps it."""
    lam, spectra, _ = spectral_patches("A", 0.05)
    img = np.repeat(np.repeat(spectra.reshape(4, 6, -1), 3, 0), 3, 1).astype(np.float32)
    assert img.shape[2] == 31
    bad = [np.nan, np.inf, -np.inf, -2.0, 1e-42, 3e38]
    for k, v in enumerate(bad):
        img[k, 2 * k, 1 + k] = v                 # a vector chunk
        img[k + 3, 2 * k + 1, 28 + k % 3] = v    # the tail
    outs = {}
    for be in ("reference", "opencl"):
        tm = Tonemapper("kirk11", be, model="none")
        outs[be] = tm.process(img, wavelengths=lam)
        counts = tm.last.repairs
        assert np.isfinite(outs[be]).all() and outs[be].min() >= 0
        outs[be + ":counts"] = counts.summary()
        assert counts.summary() == ("nan=2, pos_inf=2, neg_inf=2, negative=2, denormal=2, "
                                    "over_max=2"), counts.summary()   # 3e38: over L_max
    assert outs["reference:counts"] == outs["opencl:counts"]
    np.testing.assert_allclose(outs["opencl"], outs["reference"], rtol=1e-4, atol=1e-5)


def test_dark_scenes_look_dim_and_single_exposure_control(rt):
    img = _rgb_scene()
    means = [Tonemapper("kirk11", "opencl", model="none").process(img * np.float32(e)).mean()
             for e in (1e3, 1.0, 1e-3)]
    # the display anchor (the scene's key) makes night dark; --night-dim only sets
    # the contrast of scotopic against photopic pixels within a frame. (0.26 with the
    # base's extremes as its range, 0.32 with its 1st-99th percentiles, the default)
    assert means[0] > means[1] > means[2] > 0 and means[2] < 0.35 * means[0]


@pytest.mark.parametrize("backend", ["reference", "opencl"])
def test_one_pixel_does_not_set_the_frame_compression(backend, rt):
    """Default mode: the base layer's range is its 1st-99th percentiles, so one black
    pixel (log10 Y at the floor, -10) or one lamp pixel leaves the rest of the frame
    as it was; with the extremes (the paper's, --base-percentiles 0,100) the one
    pixel stretches the span and flattens the whole frame."""
    img = _rgb_scene(48, 64, seed=3) * np.float32(20.0)
    opts = {"bilateral": "exact"}
    for outlier in (0.0, 1e7):
        odd = img.copy()
        odd[30, 40] = outlier
        keep = np.ones(img.shape[:2], bool)
        keep[24:37, 34:47] = False                      # the outlier's neighbourhood
        for bp, same in (((1.0, 99.0), True), ((0.0, 100.0), False)):
            o = {**opts, "base_percentiles": bp}
            a = Tonemapper("kirk11", backend, options=o, model="none").process(img)
            b = Tonemapper("kirk11", backend, options=o, model="none").process(odd)
            d = np.abs(a - b)[keep].max() / a[keep].max()
            assert (d < 0.01) == same, (outlier, bp, d)   # 0.2% (the log-average) vs 77-86%


def test_extremes(rt):
    img = np.array([[[np.nan, 1, 1], [np.inf, -np.inf, 1], [-5, 1e-42, 1e8]],
                    [[0, 0, 0], [1e-6, 1e-6, 1e-6], [3e38, 3e38, 3e38]]], np.float32)
    for be in ("reference", "opencl"):
        tm = Tonemapper("kirk11", be, model="none")
        out = tm.process(img)
        assert np.isfinite(out).all() and out.min() >= 0 and tm.last.repairs.total > 0
        one = Tonemapper("kirk11", be, model="none").process(np.zeros((1, 1, 3), np.float32))
        assert np.isfinite(one).all()


def test_spectral_input_errors():
    lam = np.arange(400.0, 701.0, 50.0)
    with pytest.raises(ValueError, match="kirk11"):
        Tonemapper("pattanaik00", "reference", model="none").process(np.ones((2, 2, 7), np.float32),
                                                        wavelengths=lam)
    with pytest.raises(ValueError, match="x 7"):
        Tonemapper("kirk11", "reference", model="none").process(np.ones((2, 2, 5), np.float32),
                                                   wavelengths=lam)
    with pytest.raises(ValueError):
        ko.KirkSettings(kappa="sometimes")


# --- the shift as an effect on other operators ------------------------------------------

def test_purkinje_effect_keeps_luminance_and_shifts_colour(rt):
    from ocl_tonemap.effects import EffectSettings
    from ocl_tonemap.effects.purkinje import apply_purkinje
    from ocl_tonemap.backends.opencl.lmsr import KirkDevice
    from ocl_tonemap.models.photometry import Y_WEIGHTS
    rgb = _rgb_scene().astype(np.float64) * 0.01                    # mesopic-scotopic
    ref, info = apply_purkinje(rgb, 0.02, 0.01)
    dev, _ = apply_purkinje(rgb, 0.02, 0.01, KirkDevice(rt))
    np.testing.assert_allclose(dev, ref, rtol=2e-4, atol=1e-9)
    np.testing.assert_allclose(ref @ Y_WEIGHTS, rgb @ Y_WEIGHTS, rtol=1e-5)   # Y kept
    assert info["rod_gain"] > 0.9
    red = rgb[2, 2] / rgb[2, 2].sum()
    assert (ref[2, 2] / ref[2, 2].sum())[0] < red[0]                 # the red patch loses red
    day, info = apply_purkinje(rgb * 1e5, 2000.0, 1000.0)
    np.testing.assert_array_equal(day, rgb * 1e5)
    assert info["rod_gain"] == 0.0
    for op in ("pattanaik00", "ledda04"):
        tm = Tonemapper(op, "opencl", effects=EffectSettings(purkinje="auto"))
        tm.process((rgb * 1.0).astype(np.float32))
        assert tm.last.effects["purkinje"]["ran"]
        tm.process((rgb * 1e5).astype(np.float32), dt=60)
        assert not tm.last.effects["purkinje"]["ran"]
    with pytest.raises(ValueError, match="itself"):
        Tonemapper("kirk11", "reference", effects=EffectSettings(purkinje="on"))


@pytest.mark.parametrize("method", ["exact", "fast"])
def test_banded_frames_match_one_band(method, rt):
    """Frames beyond the device budget go in row bands (per-pixel passes banded,
    the bilateral base banded, composition on the host) and give the same image."""
    img = _rgb_scene(40, 30) * np.float32(0.05)
    opts = {"bilateral": method, "sigma_spatial": 3.0}
    one = Tonemapper("kirk11", "opencl", options=opts, model="none").process(img)
    tm = Tonemapper("kirk11", "opencl", options=opts, max_band_pixels=30 * 7, model="none")
    banded = tm.process(img)
    np.testing.assert_allclose(banded, one, rtol=2e-5, atol=2e-6)
    lam, spectra, _ = spectral_patches("A", 0.05)
    cube = np.repeat(np.repeat(spectra.reshape(4, 6, -1), 3, 0), 3, 1).astype(np.float32)
    one = Tonemapper("kirk11", "opencl", options=opts, model="none").process(cube, wavelengths=lam)
    banded = Tonemapper("kirk11", "opencl", options=opts,
                        max_band_pixels=18 * 5, model="none").process(cube, wavelengths=lam)
    np.testing.assert_allclose(banded, one, rtol=2e-5, atol=2e-6)


@pytest.mark.parametrize("percentiles", [(1.0, 99.0), (0.0, 100.0), (5.0, 60.0)])
def test_base_range_counted_on_the_device_is_the_hosts(rt, percentiles):
    """Durand & Dorsey 2002's base range from the device (extremes and bin counts of
    kirk11.cl base_histogram, over two bands) is BaseRange's on the same float32 values
    exactly: every bin edge, its float neighbours, values beyond [-12, 12], signed zeros
    and denormals near the edge at 0, and a smooth base (long runs of one bin)."""
    import pyopencl as cl
    from ocl_tonemap.backends.opencl.lmsr import KirkDevice
    from ocl_tonemap.models.durand2002 import (BASE_HIST_BINS, BaseRange, base_hist_bins,
                                               base_hist_edges)
    num, off, den = base_hist_edges()
    e = ((np.arange(BASE_HIST_BINS + 1) * num + off) / den).astype(np.float32)
    rng = np.random.default_rng(3)
    v = np.concatenate([
        e, np.nextafter(e, np.float32(-np.inf)), np.nextafter(e, np.float32(np.inf)),
        np.float32([-0.0, 0.0, 1e-45, -1e-45, 1e-38, -1e-38, -13, 13, -1e30, 1e30]),
        np.sin(np.linspace(0, 20, 200_000)).astype(np.float32) * 3 + 1,   # smooth
        rng.normal(0, 2, 100_001).astype(np.float32)]).astype(np.float32)
    assert np.array_equal(base_hist_bins(e[:-1]), np.arange(BASE_HIST_BINS))
    dev = KirkDevice(rt)
    half = len(v) // 2
    acc = dev.base_range(percentiles)
    for part in (v[:half], v[half:]):
        buf = cl.Buffer(rt.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                        hostbuf=part)
        acc.add(buf, part.size)
    got = acc.result()
    assert got == BaseRange(percentiles).add(v).result()
    if percentiles != (0.0, 100.0):          # the counts themselves
        assert np.array_equal(acc.acc.hist, np.bincount(base_hist_bins(v),
                                                        minlength=BASE_HIST_BINS))


def test_the_purkinje_shift_in_bands_is_the_shift_whole(rt, monkeypatch):
    """KirkDevice.purkinje shifts a host frame in bands of SHIFT_BAND pixels (its buffer
    is host memory on a CPU device) and a device image in place: bands of 7 pixels
    give the whole frame's result (to float32 rounding: a driver may vectorise a
    7-pixel launch differently; Intel's CPU runtime differs in the last bits), the
    device image the same pixels, fallback share too."""
    import pyopencl as cl
    from ocl_tonemap.backends.base import settle
    from ocl_tonemap.backends.opencl.image import DeviceImage
    from ocl_tonemap.backends.opencl.lmsr import KirkDevice
    from ocl_tonemap.effects.purkinje import apply_purkinje
    rgb = (_rgb_scene().astype(np.float64) * 0.01).astype(np.float32)
    dev = KirkDevice(rt)
    whole, info = apply_purkinje(rgb, 0.02, 0.01, dev)
    buf = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR,
                    hostbuf=np.ascontiguousarray(rgb))
    img = DeviceImage(rt, buf, rgb.shape)
    on_dev, info_d = apply_purkinje(img, 0.02, 0.01, dev)
    assert on_dev.buffer is img.buffer and on_dev is not img    # in place, a new frame
    np.testing.assert_allclose(np.asarray(on_dev), whole, rtol=4e-6, atol=0)
    # (a device's fallback count comes down with the frame's next statistics)
    info, info_d = settle(info), settle(info_d)
    assert info_d["fallback_fraction"] == info["fallback_fraction"]
    monkeypatch.setattr(KirkDevice, "SHIFT_BAND", 7)
    bands, info7 = apply_purkinje(rgb, 0.02, 0.01, dev)
    np.testing.assert_allclose(bands, whole, rtol=4e-6, atol=0)
    assert settle(info7)["fallback_fraction"] == info["fallback_fraction"]
