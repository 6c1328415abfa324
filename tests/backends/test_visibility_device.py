"""The visibility planes' device paths (backends/opencl/visibility.py) against their
host references, through the backend's written interface (``Backend.visibility``,
``visibility_view``): the view's paint exactly, the veil's device sum against the
host's FFT, the scene's luminance kept from the frame's colour stage against a second
colour stage, and the scalar (GPU) kernels against the vector ones."""

from __future__ import annotations

import numpy as np
import pytest

from ocl_tonemap.backends.base import VisibilityRequest, paint_view
from ocl_tonemap.job.visibility_out import view_paint
from ocl_tonemap.models.visibility_map import Geometry, recipe
from ocl_tonemap.operators import get_operator
from ocl_tonemap.effects.visibility import Viewing

pytestmark = pytest.mark.requires_opencl


def _request(pix, dt=np.float16, op="pattanaik00", age=25.0):
    h, w = pix.shape[:2]
    o = get_operator(op)({})
    obs = o.observer_preadapted(50.0, None)
    view = Viewing(10.0, age)
    return VisibilityRequest(pix, 1.0, recipe(Geometry(h, w, 50.0), 10.0, age), view, o,
                             lambda: obs, None, None, dt)


@pytest.fixture(scope="module")
def backend():
    from ocl_tonemap.backends.opencl import OpenCLBackend
    return OpenCLBackend()


def _frame(h=61, w=97, seed=0):
    rng = np.random.default_rng(seed)
    return (10 ** rng.uniform(-3, 4, (h, w, 3))).astype(np.float32)


@pytest.mark.parametrize("dt", [np.float16, np.float32])
def test_the_view_is_painted_as_the_host_paints_it(backend, dt):
    """vis_view from the planes where they are: the same codes as paint_view (8-bit,
    16-bit and float code values in; 8-bit and float out), bit for bit."""
    rng = np.random.default_rng(1)
    pix = _frame()
    h, w = pix.shape[:2]
    P = backend.visibility(_request(pix, dt))
    paint = view_paint(h, w)
    for shown, top in (((rng.random((h, w, 3)) * 255).astype(np.uint8), 255.0),
                       ((rng.random((h, w, 3)) * 65535).astype(np.uint16), 65535.0),
                       (rng.random((h, w, 3)).astype(np.float32) * 1.2, 1.0)):
        ref = paint_view(shown.astype(np.float32) / np.float32(top),
                         P.plane("VL").astype(np.float32), paint)
        for u8 in (True, False):
            got = backend.visibility_view(P, shown, paint, u8)
            want = np.round(np.clip(ref, 0, 1) * 255).astype(np.uint8) if u8 else ref
            assert got.dtype == want.dtype and np.array_equal(got, want)
    assert backend.visibility_view(P.__class__(P.data, P.veil_cells), shown, paint, True) \
        is None                                     # not the planes it made last


def test_the_device_sum_of_the_veil_is_the_hosts_fft(backend, monkeypatch):
    """A GPU's veil (vis_veil_cells, every pair of cells summed) against a CPU device's
    (the cells to the host's FFT): within 2e-5 relative."""
    pix = _frame(135, 240, 2)
    host = backend.visibility(_request(pix, np.float32))
    monkeypatch.setattr(backend._visibility, "host_veil", False)
    dev = backend.visibility(_request(pix, np.float32))
    np.testing.assert_allclose(dev.veil_cells, host.veil_cells, rtol=2e-5)
    np.testing.assert_allclose(dev.plane("Lveil"), host.plane("Lveil"), rtol=2e-5)


@pytest.mark.parametrize("age", [25.0, 70.0])
def test_the_kept_luminance_is_a_second_colour_stage(backend, age):
    """The planes read the luminance the frame's own colour stage made (at the media's
    gain) where it is kept: equal to the planes of a colour stage of their own."""
    pix = _frame(54, 96, 3)
    req = _request(pix, np.float32, age=age)
    alone = backend.visibility(req)
    g = req.view.media_gain
    backend.keep_scene_luminance(pix)
    backend.to_working(pix, 1.0 * g, count=False)            # (as the frame's would)
    assert backend.kept_scene_luminance(pix) is not None
    kept = backend.visibility(req)
    if age == 25.0:                                           # (no gain: the same bits)
        assert np.array_equal(kept.data, alone.data)
    else:      # the media's gain on and off again: float32 rounding, VL's cancellation
        np.testing.assert_allclose(kept.data[..., :4], alone.data[..., :4], rtol=2e-6)
        np.testing.assert_allclose(kept.data[..., 4], alone.data[..., 4], rtol=1e-3,
                                   atol=1e-6)
    backend.keep_scene_luminance(None)
    assert backend.kept_scene_luminance(pix) is None


def test_a_local_observer_without_a_kernel_is_made_on_the_host(backend):
    """ledda04 with its state not on the device (no schedule given): the host's planes."""
    pix = _frame(20, 30, 4)
    o = get_operator("ledda04")({})
    obs = {k: np.broadcast_to(v, (20, 30)) for k, v in
           o.observer_preadapted(50.0, None).items()}
    view = Viewing()
    req = VisibilityRequest(pix, 1.0, recipe(Geometry(20, 30, 50.0), 10.0, 25.0), view, o,
                            lambda: obs, None, None, np.float32)
    P = backend.visibility(req)
    assert P.data.shape == (20, 30, 5) and np.isfinite(P.data).all()
