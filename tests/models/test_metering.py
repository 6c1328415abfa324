"""Metering: the log-average over the lit pixels (models/metering.py), so that exact
zeros -- black borders, letterboxes, a black half -- do not pull the adaptation level
below the lit part of the frame; the float64 reference and the device alike."""

import numpy as np
import pytest

from ocl_tonemap.models import metering as met
from ocl_tonemap.models.photometry import Y_WEIGHTS, scotopic_luminance
from conftest import hdr_image

SPECS = ["logmean", "mean", "centre", "spot:0.5,0.5,0.2", "percentile:50"]


def _scene(h=72, w=128, seed=1):
    return np.asarray(hdr_image(h, w, seed=seed, lo=0.0, hi=3.0), np.float64)


def _goal(rgb, spec):
    return met.reference_goal(rgb @ Y_WEIGHTS, scotopic_luminance(rgb), met.MeteringSpec.parse(spec))


def _with_border(rgb, kind):
    out = np.zeros_like(rgb)
    h, w = rgb.shape[:2]
    if kind == "letterbox":                      # 2.39:1 in a 16:9 frame: bars top and bottom
        b = h // 8
        out[b:h - b] = rgb[b:h - b]
    elif kind == "pillarbox":
        b = w // 8
        out[:, b:w - b] = rgb[:, b:w - b]
    elif kind == "half":
        out[:, : w // 2] = rgb[:, : w // 2]
    return out


@pytest.mark.parametrize("kind", ["letterbox", "pillarbox", "half"])
def test_black_regions_do_not_pull_the_level_down(kind):
    """The logmean of a frame with exact zeros is that of its lit part alone, to the
    last bit (the same pixels summed): a letterboxed 100 cd/m^2 scene meters 100, not
    the ~1 that ln(1e-6) as a value gave; mean likewise, percentiles of the lit part."""
    rgb = _scene()
    framed = _with_border(rgb, kind)
    lit = framed[(framed @ Y_WEIGHTS) > 0]
    for spec in ("logmean", "mean", "percentile:40"):
        got = _goal(framed, spec)
        want = _goal(lit.reshape(1, -1, 3), spec)
        assert got == pytest.approx(want, rel=1e-12), spec
    G_rod, G_cone = _goal(framed, "logmean")
    old = np.exp(np.mean(np.log(np.maximum(framed @ Y_WEIGHTS, met.LOG_FLOOR))))
    assert G_cone > 3 * old             # what the floor as a value made of it


def test_half_white_field_meters_the_wall():
    rgb = np.zeros((8, 8, 3))
    rgb[:, :4] = 100.0
    G_rod, G_cone = _goal(rgb, "logmean")
    assert G_cone == pytest.approx(100.0, rel=1e-12)


def test_darkness_meters_the_floor_and_dim_light_counts():
    """No lit pixel: the floor (dark adaptation), as before; a pixel just above the
    floor (light the eye can sense) counts in full."""
    black = np.zeros((4, 4, 3))
    assert _goal(black, "logmean") == (met.LOG_FLOOR, met.LOG_FLOOR)
    assert _goal(black, "mean") == (0.0, 0.0)
    dim = np.full((4, 4, 3), 3e-6)
    assert _goal(dim, "logmean")[1] == pytest.approx(3e-6, rel=1e-9)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("spec", SPECS)
@pytest.mark.parametrize("kind", ["letterbox", "half"])
def test_device_meters_as_the_reference(rt, spec, kind):
    """metering.cl (float32, two-stage, the lit weights in the float4 path and the
    scalar tail; the histogram counting only lit values) against the float64 reference:
    1e-5 relative (percentiles: one histogram bin), on frames of odd widths."""
    from ocl_tonemap.backends.opencl import OpenCLBackend
    be = OpenCLBackend()
    for w in (128, 101):
        rgb = _with_border(_scene(w=w), kind).astype(np.float32)
        s = met.MeteringSpec.parse(spec)
        got = be.working(rgb, 1.0, s, illuminant=False).goal
        want = _goal(rgb.astype(np.float64), spec)
        tol = 10 ** ((met.HIST_HI - met.HIST_LO) / met.HIST_BINS) - 1 if "percentile" in spec \
            else 1e-5
        np.testing.assert_allclose(got, want, rtol=tol)
