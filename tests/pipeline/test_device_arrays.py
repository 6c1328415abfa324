"""Frames that stay on the device (issue 47): ``Tonemapper.process`` takes a
``pyopencl.array.Array`` and gives one back, the same pixels as a host frame's, with
neither the frame nor its output crossing to the host."""

from __future__ import annotations

import numpy as np
import pytest

from ocl_tonemap import Tonemapper
from ocl_tonemap.io.sample import render_frame

pytestmark = pytest.mark.requires_opencl


@pytest.fixture(scope="module")
def frames():
    return [render_frame(t, 960, 540, 8.0).astype(np.float32) for t in (3.0, 3.04, 3.08)]


@pytest.mark.parametrize("op,night", [("pattanaik00", False), ("durand00", False),
                                      ("ledda04", False), ("kirk11", False),
                                      ("pattanaik00", True)])
def test_device_frames_in_and_out_equal_host_frames(frames, op, night):
    import pyopencl.array as cla
    scale = 1e-4 if night else 1.0                 # night: the acuity blur at work
    host, dev = Tonemapper(op, "opencl"), Tonemapper(op, "opencl")
    q = dev.backend.device_runtime().queue
    for k, f in enumerate(frames):
        dt = None if k == 0 else 0.04
        a = host.process(f, dt=dt, luminance_scale=scale)
        d_in = cla.to_device(q, f)
        d = dev.process(d_in, dt=dt, luminance_scale=scale)
        assert isinstance(d, cla.Array) and d.shape == f.shape and d.dtype == np.float32
        np.testing.assert_array_equal(d.get(), a)
        np.testing.assert_array_equal(d_in.get(), f)           # the input is not written
    t = dev.last.transfers
    # what crosses is statistics, the flare's ring level and the plan's patch rows
    assert t["up_bytes"] < f.nbytes / 10 and t["down_bytes"] < f.nbytes / 2, t
    if night:
        assert dev.last.effects["acuity"]["ran"]


def test_device_arrays_are_checked():
    import pyopencl.array as cla
    tm = Tonemapper("pattanaik00", "opencl")
    q = tm.backend.device_runtime().queue
    with pytest.raises(ValueError, match="H x W x 3 float32"):
        tm.process(cla.to_device(q, np.ones((4, 4, 4), np.float32)))
    with pytest.raises(ValueError, match="OpenCL backend"):
        Tonemapper("pattanaik00", "reference").process(
            cla.to_device(q, np.ones((4, 4, 3), np.float32)))
