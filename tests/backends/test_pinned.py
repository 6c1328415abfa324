"""Page-locked host arrays (backends/opencl/pinned.py, issue 47): on a GPU the frames a
run reads and the outputs that come back live in memory the driver can DMA from,
mapped once and used again once nothing refers to them. A CPU device gets plain
arrays; here the page-locked path is forced on the CPU device (ALLOC_HOST_PTR works
there too), so that what a GPU runs is what these tests run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from ocl_tonemap import Tonemapper
from ocl_tonemap.backends.opencl import pinned
from ocl_tonemap.backends.opencl.pinned import HostArrays
from ocl_tonemap.io.imageio import FramePool

pytestmark = pytest.mark.requires_opencl


def test_an_array_is_used_again_only_when_nothing_refers_to_it(rt):
    h = HostArrays(rt, keep=2, pinned=True)
    a = h.empty((4, 5, 3), np.float32)
    a[:] = 1.0
    part = a[1:, :, :2]                          # a view keeps the memory in use
    del a
    b = h.empty((4, 5, 3), np.float32)
    assert not np.shares_memory(b, part) and h.made == 2
    del part, b
    c = h.empty((4, 5, 3), np.float32)           # both free: one of them again
    assert h.made == 2 and c.shape == (4, 5, 3) and c.dtype == np.float32
    d = h.empty((2, 2), np.float16, tail=16)     # another size beyond keep: a new one,
    assert d.base.nbytes == d.nbytes + 16 and h.made == 3    # a free one given up


def test_a_cpu_device_gets_plain_arrays(rt):
    h = HostArrays(rt, keep=2)
    assert not h.pinned                          # (this machine's device is a CPU)
    a = h.empty((3, 3), np.float32, tail=8)
    assert a.base.nbytes == a.nbytes + 8 and h.made == 0


def test_frames_and_outputs_in_page_locked_memory_are_the_same_frames(rt, monkeypatch):
    """A run's frame pool and the backend's outputs page-locked: the same pixels, the
    frame's last statistics still riding the output's read."""
    from ocl_tonemap.io.sample import render_frame
    frames = [render_frame(t, 160, 90, 8.0).astype(np.float32) for t in (3.0, 3.04)]
    ref = Tonemapper("pattanaik00", "opencl")
    want = [ref.process(f, dt=None if k == 0 else 0.04) for k, f in enumerate(frames)]
    monkeypatch.setattr(pinned, "_outputs", {})
    real = HostArrays.__init__
    monkeypatch.setattr(HostArrays, "__init__",
                        lambda self, rt, keep=4, pinned=None: real(self, rt, keep, True))
    tm = Tonemapper("pattanaik00", "opencl")
    pool = FramePool(keep=3)
    pool.use(tm.backend)
    got = []
    for k, f in enumerate(frames):
        fr = pool.take(f.shape)
        fr[:] = f
        got.append(tm.process(fr, dt=None if k == 0 else 0.04))
        assert isinstance(got[-1].base, np.ndarray) and got[-1].base.base is not None
    assert pool._host.made >= 1 and pinned.outputs(tm.backend.rt).made >= 1
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
    json.dumps({"effects": tm.last.effects, "params": tm.last.params})   # all settled
