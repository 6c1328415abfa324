"""Loss of acuity (Shaler 1937): the blur widens as light falls, none above the cut-off; the device blur equals the reference."""

import numpy as np
import pytest

from ocl_tonemap.models import ferwerda1996 as fw
from ocl_tonemap.models import shaler1937 as acu
from ocl_tonemap.backends.opencl.convolution import DeviceBlur
from ocl_tonemap.models.convolution import EDGE_CLAMP, EDGE_ZERO, blur_reference, gaussian_taps


def test_acuity_blur_widens_monotonically_as_light_falls():
    L = 10.0 ** np.linspace(-6, 4, 400)
    # paper mode: Table 1 at L_waR, strictly monotone between the table's ends
    sig = acu.acuity_sigma_px(acu.acuity_a_px(L, 50.0, 1920, mode="paper"))
    assert np.all(np.diff(sig) <= 0)                                  # never less blur in the dark
    inside = (np.log10(L) > -3.5) & (np.log10(L) < 3.0)
    assert np.all(np.diff(sig[inside]) < 0)
    # default: the table in Shlaer's photopic units, its ends at 10^-3.5 x 1.29 and
    # 10^3 x 2.57 scotopic cd/m^2, flat at the rod-cone break (4.8 c/deg) between the
    # rods' branch and the cones' (tests/models/test_shaler1937.py)
    sig = acu.acuity_sigma_px(acu.acuity_a_px(L, 50.0, 1920))
    assert np.all(np.diff(sig) <= 0)
    lo, hi = 10.0 ** -3.5 * acu.source_scotopic_ratio(), 1e3 * acu.neutral_scotopic_ratio()
    br = acu.acuity_cutoff(L) == acu.SHLAER_ROD_CONE_BREAK_CPD
    inside = (L > lo) & (L < hi) & ~br
    assert np.all(np.diff(sig)[inside[1:] & inside[:-1]] < 0)
    # Ferwerda's criterion G(omega) = eps_R(L)/L (Eq. 9) gives a blur that
    # narrows again as light falls below the rods' absolute threshold
    Lf = 10.0 ** np.linspace(-3.5, -1.0, 200)
    g = fw.threshold_rod(Lf) / Lf
    ok = g < 1
    a_f = acu.acuity_cutoff(Lf[ok], mode="paper") * np.sqrt(np.pi / -np.log(g[ok]))
    sig_f = 1.0 / (a_f * np.sqrt(2 * np.pi))
    assert np.any(np.diff(sig_f) > 0) and np.any(np.diff(sig_f) < 0)
    assert acu.ACUITY_A_PER_OMEGA == pytest.approx(1.86, abs=0.005)   # Eq. 10

def test_no_blur_above_cutoff_and_smooth_transition(rt):
    rng = np.random.default_rng(0)
    img = rng.random((30, 40, 3)).astype(np.float32)
    out, info = acu.apply_acuity(img, 100.0, 50.0)                  # daylight: no blur
    assert info["blend"] == 0.0 and out is img
    # width such that a_px crosses 1.1 .. 1.0: the blend is continuous and monotone
    a = np.linspace(1.2, 0.9, 61)
    b = acu.acuity_blend(a)
    assert b[0] == 0 and b[-1] == 1 and np.all(np.diff(b) >= 0) and np.max(np.diff(b)) < 0.06
    dark, info = acu.apply_acuity(img, 1e-4, 5.0)                  # 40 px over 5 degrees
    assert info["blend"] == 1.0 and info["sigma_px"] > 0.4
    assert dark.std() < img.std()

@pytest.mark.parametrize("edge", [EDGE_ZERO, EDGE_CLAMP])
def test_device_blur_matches_reference_and_bands(edge, rt):
    rng = np.random.default_rng(4)
    img = rng.random((41, 29, 3)).astype(np.float32)
    taps = gaussian_taps(3.3)
    ref = blur_reference(img, taps, edge)
    dev = DeviceBlur(rt).blur(img, taps, edge)
    banded = DeviceBlur(rt, max_pixels=29 * 30).blur(img, taps, edge)
    np.testing.assert_allclose(dev, ref, atol=2e-6)
    assert np.array_equal(dev, banded)


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (13, 37), (24, 64), (7, 203)])
@pytest.mark.parametrize("sigma", [0.45, 1.1, 1.6, 3.3, 9.0])
def test_device_acuity_in_place_matches_the_reference(rt, shape, sigma):
    """The acuity blur where the operator left the frame (interleaved RGB on the device,
    four pixels a work-item on CPUs: a vector body where the window is inside one row,
    tap by tap at the frame's edges) against float64 (clamped edges, then the blend):
    every shape, from one pixel and rows narrower than the window to a width that is
    not a multiple of four, and radii of 2 to 36 pixels."""
    import pyopencl as cl
    h, w = shape
    rng = np.random.default_rng(7)
    img = rng.random((h, w, 3)).astype(np.float32) * 50.0
    taps = gaussian_taps(sigma)
    t = 0.8
    want = (blur_reference(img, taps, EDGE_CLAMP) * t + img.astype(np.float64) * (1 - t))
    mf = cl.mem_flags
    buf = cl.Buffer(rt.context, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=img)
    tmp = cl.Buffer(rt.context, mf.READ_WRITE, img.nbytes)
    DeviceBlur(rt).acuity_in_place(buf, h, w, taps, t, tmp)
    got = np.empty_like(img)
    cl.enqueue_copy(rt.queue, got, buf)
    np.testing.assert_allclose(got, want, rtol=2e-6, atol=2e-6 * 50.0)
