"""The appearance benchmark's measures (benchmarks/lib/appearance_metrics.py) on
tiny synthetic images: each counts what its definition says and nothing else.
NumPy and colour-science only (no OpenCL)."""

import numpy as np
import pytest

from benchmarks.lib import appearance_metrics as am


def field(rgb, h=4, w=4):
    return np.broadcast_to(np.asarray(rgb, np.float64), (h, w, 3)).copy()


def half(a, b, h=4, w=4):
    """Left half ``a``, right half ``b``."""
    img = field(a, h, w)
    img[:, w // 2:] = b
    return img


MAGENTA = (0.6, 0.1, 0.6)          # CIELAB hue ~328 degrees, C* ~ 70
GREY = (0.18, 0.18, 0.18)


def test_lab_of_display_image_is_not_renormalised():
    lab = am.to_lab(field((1.0, 1.0, 1.0)), norm=None)
    assert lab[0, 0, 0] == pytest.approx(100.0, abs=0.1)
    lab = am.to_lab(field((0.18, 0.18, 0.18)), norm=None)
    assert lab[0, 0, 0] == pytest.approx(49.5, abs=0.5)


# --- brightness order ------------------------------------------------------------------

def test_brightness_means_leave_the_masked_pixels_out():
    keep = np.ones((4, 4), bool)
    keep[0, 0] = False
    dim = field(0.1)
    dim[0, 0] = 5.0                              # a lamp, brighter in the dim output
    bright = field(0.2)
    means, ok = am.brightness_means([dim, bright])
    assert not ok
    means, ok = am.brightness_means([dim, bright], mask=keep)
    assert ok and means == pytest.approx([0.1, 0.2])


# --- clipping --------------------------------------------------------------------------

def test_clipping_counts_pixels_white_in_all_three_8bit_channels():
    out = field(0.5, 2, 5)
    out[0, 0] = 1.0                 # white
    out[0, 1] = 0.997               # 8-bit code 255 in all three channels: white
    out[0, 2] = (1.0, 0.2, 0.2)     # one channel clipped: a saturated red, not white
    out[0, 3] = 0.99                # code 254: not white
    Y = np.full((2, 5), 10.0)
    assert am.clip_fraction(out, Y, 10.0) == pytest.approx(2 / 10)
    assert am.clip_fraction(out, Y, 10.0, channels="any") == pytest.approx(3 / 10)
    assert am.clip_fraction(out, Y, 10.0, eight_bit=False) == pytest.approx(1 / 10)


def test_clipping_leaves_light_sources_out():
    out = field(1.0, 2, 2)
    out[1] = 0.5
    Y = np.array([[400.0, 400.0], [1.0, 1.0]])    # top row > 30 x log-average 10
    assert am.clip_fraction(out, Y, 10.0) == 0.0
    Y[0, 0] = 10.0
    assert am.clip_fraction(out, Y, 10.0) == pytest.approx(1 / 3)


# --- magenta --------------------------------------------------------------------------

def test_a_magenta_patch_counts():
    out = half(MAGENTA, GREY)
    assert am.magenta_share(out) == pytest.approx(0.5)
    assert am.magenta_share(field(GREY)) == 0.0
    assert am.magenta_share(field((0.6, 0.1, 0.1))) == 0.0              # red: hue ~ 40
    assert am.magenta_share(field((0.3, 0.5, 0.9))) == 0.0              # sky blue: ~ 271
    assert am.magenta_share(field((0.05, 0.07, 0.2))) == 0.0            # night blue: ~ 288
    e = am.magenta_excess(out, field(GREY))
    assert e["excess"] == pytest.approx(0.5) and e["ref_share"] == 0.0


def test_the_hue_preserving_rendering_has_no_magenta_excess():
    scene = half((60.0, 10.0, 60.0), (30.0, 30.0, 30.0)) * 3.0          # magenta in the scene
    ref = am.hue_preserving_render(scene)
    assert am.magenta_share(ref) == pytest.approx(0.5)                  # the photograph's own
    e = am.magenta_excess(ref, scene)
    assert e["excess"] == 0.0 and e["share"] == pytest.approx(0.5)


def test_hue_preserving_render_keeps_rgb_ratios_and_maps_the_log_average_to_0_18_over_1_18():
    scene = field((2.0, 1.0, 0.5))
    ref = am.hue_preserving_render(scene)
    assert ref[0, 0] / ref[0, 0, 1] == pytest.approx([2.0, 1.0, 0.5])
    assert am.luminance(ref)[0, 0] == pytest.approx(0.18 / 1.18)


def test_magenta_leaves_light_sources_out():
    out = half(MAGENTA, GREY)
    keep = np.ones((4, 4), bool)
    keep[:, :2] = False
    assert am.magenta_share(out, keep) == 0.0


def test_magenta_hue_range_is_290_to_350_with_chroma_over_15():
    for rgb in [(0.5, 0.1, 0.5), (0.4, 0.1, 0.6), (0.6, 0.1, 0.45)]:
        C, h = am.chroma_hue(am.to_lab(field(rgb, 1, 1), norm=None))
        assert (290 <= h[0, 0] <= 350 and C[0, 0] > 15) == (am.magenta_share(field(rgb)) == 1.0)
    pale = (0.21, 0.18, 0.21)                                             # hue in range, C* < 15
    C, h = am.chroma_hue(am.to_lab(field(pale, 1, 1), norm=None))
    assert 290 <= h[0, 0] <= 350 and C[0, 0] < 15
    assert am.magenta_share(field(pale)) == 0.0


# --- warm turned cool --------------------------------------------------------------------

def test_a_warm_patch_rendered_blue_counts_as_warm_to_cool():
    scene = half((1.0, 0.7, 0.4), GREY)                 # warm: R > 1.3 B
    out = half((0.2, 0.3, 0.5), GREY)                   # shown blue: B > 1.15 R
    w = am.warm_to_cool(out, scene)
    assert w["share"] == pytest.approx(0.5) and w["of_warm"] == 1.0 and w["warm"] == 0.5
    kept_warm = half((0.5, 0.4, 0.3), GREY)
    assert am.warm_to_cool(kept_warm, scene)["share"] == 0.0


def test_warm_to_cool_needs_a_warm_scene_and_leaves_sources_out():
    out = field((0.2, 0.3, 0.5))
    assert am.warm_to_cool(out, field((1.0, 1.0, 1.0)))["share"] == 0.0   # neutral scene
    assert am.warm_to_cool(out, field((1.0, 0.7, 0.8)))["share"] == 0.0   # R < 1.3 B
    keep = np.zeros((4, 4), bool)
    keep[0, 0] = True
    scene = field((1.0, 1.0, 1.0))
    scene[0, 0] = (1.0, 0.7, 0.4)
    assert am.warm_to_cool(out, scene, keep)["share"] == 1.0


def test_warm_to_cool_judges_the_output_as_shown():
    scene = field((1.0, 0.7, 0.4))
    # unclipped B 3 > 1.15 R; shown (0.9, 0.9, 1.0): B < 1.15 R
    assert am.warm_to_cool(field((0.9, 2.0, 3.0)), scene)["share"] == 0.0


# --- hue against the input -------------------------------------------------------------

def test_hue_shift_is_zero_when_the_output_keeps_the_input_colours():
    scene = half((800.0, 400.0, 100.0), (100.0, 300.0, 600.0))
    out = scene / 1000.0
    assert am.hue_shift_deg(out, scene) == pytest.approx(0.0, abs=1e-6)


def test_hue_shift_measures_a_rotated_output():
    scene = field((800.0, 400.0, 100.0))                                 # orange
    out = field((0.8, 0.1, 0.6))                                         # shown magenta
    C, h_in = am.chroma_hue(am.to_lab(field((0.8, 0.4, 0.1)), norm=None))
    _, h_out = am.chroma_hue(am.to_lab(out, norm=None))
    assert am.hue_shift_deg(out, scene) == pytest.approx(float(am.hue_delta(h_out, h_in)[0, 0]))
    assert am.hue_shift_deg(out, scene) > 15.0


def test_hue_shift_skips_pale_pixels_and_light_sources():
    scene = half((800.0, 400.0, 100.0), (500.0, 500.0, 500.0))           # grey: no hue
    out = half((0.8, 0.1, 0.6), (0.5, 0.3, 0.8))
    keep = np.ones((4, 4), bool)
    assert am.hue_shift_deg(out, scene, keep) > 15.0
    keep[:, :2] = False
    assert np.isnan(am.hue_shift_deg(out, scene, keep))
    grey_out = half((0.5, 0.5, 0.5), (0.5, 0.3, 0.8))                    # output chroma < 4
    assert np.isnan(am.hue_shift_deg(grey_out, scene))


def test_hue_shift_scales_the_input_by_its_99th_percentile():
    scene = field((800.0, 400.0, 100.0))
    out = field((0.8, 0.4, 0.1))
    # any exposure of the input gives the same (its 99th percentile becomes 1)
    assert am.hue_shift_deg(out, scene * 1e-3) == pytest.approx(am.hue_shift_deg(out, scene))


# --- saturation ratio (issue 67) ---------------------------------------------------------

def _coloured_scene():
    """Mid-tone coloured patches (log-average ~ 100 cd/m^2), a grey and a lamp."""
    img = field((120.0, 90.0, 40.0), 4, 8)             # warm
    img[:, 2:4] = (40.0, 110.0, 160.0)                 # blue-green
    img[:, 4:6] = (100.0, 100.0, 100.0)                # grey: not measured (s = 0)
    img[0, 7] = (1e5, 8e4, 5e4)                        # a lamp: not measured
    return img


def test_saturation_ratio_is_one_for_a_hue_preserving_scaling():
    scene = _coloured_scene()
    la = float(np.exp(np.mean(np.log(am.luminance(scene)))))
    out = scene / (1.0 + am.luminance(scene)[..., None] / la) / (4 * la)   # curve on Y, ratios kept
    r = am.saturation_ratio(out, scene, la)
    assert r["ratio"] == pytest.approx(1.0, abs=1e-9)
    assert 0 < r["n"] < 1                                 # the grey and the lamp left out


def test_saturation_ratio_is_below_one_for_a_desaturating_map():
    scene = _coloured_scene()
    la = float(np.exp(np.mean(np.log(am.luminance(scene)))))
    lin = scene / (4 * la)
    grey = am.luminance(lin)[..., None]
    out = 0.5 * lin + 0.5 * grey                          # halfway to grey
    assert am.saturation_ratio(out, scene, la)["ratio"] < 0.9
    boosted = np.maximum(grey + 1.5 * (lin - grey), 0.0)
    assert am.saturation_ratio(boosted, scene, la)["ratio"] > 1.0


def test_saturation_ratio_leaves_clipped_output_out():
    scene = _coloured_scene()
    la = float(np.exp(np.mean(np.log(am.luminance(scene)))))
    out = np.full_like(scene, 1.0)                        # all clipped to white
    assert np.isnan(am.saturation_ratio(out, scene, la)["ratio"])
