"""``Tonemapper.map_like_last``: the last frame's per-pixel mapping, frozen (what an
OCIO export of a global operator samples, issue 32): its own pixels come back as the
frame's output, bit for bit, on both backends; other pixels do not move the state."""

import numpy as np
import pytest

from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.sample import render_frame


@pytest.mark.parametrize("backend", ["reference", pytest.param("opencl", marks=pytest.mark.requires_opencl)])
@pytest.mark.parametrize("op", ["pattanaik00", "durand00"])
def test_the_frozen_map_reproduces_the_frame(op, backend):
    tm = Tonemapper(op, model="none", backend=backend)
    for k, t in enumerate((0.0, 4.0, 7.0)):
        img = np.ascontiguousarray(render_frame(t, 64, 36, 8.0)[..., :3], np.float32)
        r = tm.process_frame(img, dt=None if k == 0 else 0.5)
        state = tm.state.to_json()
        again = tm.map_like_last(img.reshape(-1, 3), 1.0).reshape(r.output.shape)
        np.testing.assert_array_equal(again, r.output)
        tm.map_like_last(np.full((5, 3), 1e6, np.float32), 1.0)
        assert tm.state.to_json() == state
