"""A frame crosses between host and device once each way (issue 47): with each
operator's defaults at 1920x1080 (flare, Purkinje shift, chromatic adaptation on by
the plan), the input's bytes go up once and the output's come down once; what else
crosses is statistics and small tables. The backend counts every transfer
(``backends/opencl/transfers.py``) and each frame's record carries them."""

from __future__ import annotations

import numpy as np
import pytest

from ocl_tonemap import Tonemapper
from ocl_tonemap.backends.opencl.stats import TAIL
from ocl_tonemap.backends.opencl.transfers import (ConstantBuffers, Transfers, counted,
                                                   host_buffer, transfer)
from ocl_tonemap.io.sample import render_frame

pytestmark = pytest.mark.requires_opencl

#: Per frame: the input up once, the output down once (with the frame's last counts in
#: the same read: ``stats.TAIL``), statistics read at the frame's sync points in
#: buffers of at most 64 KiB each, at most 6 calls in all.
MAX_CALLS = 6
STATS_BYTES = 64 * 1024


@pytest.fixture(scope="module")
def frames():
    return {L: [render_frame(t, 1920, 1080, L).astype(np.float32) for t in (3.0, 3.04, 3.08)]
            for L in (8.0, 3000.0)}


@pytest.mark.parametrize("level", [8.0, 3000.0])
@pytest.mark.parametrize("op", ["pattanaik00", "durand00", "ledda04", "kirk11"])
def test_a_frame_crosses_once_each_way_with_the_defaults(frames, op, level, monkeypatch):
    """At dusk (the flare, the Purkinje shift and chromatic adaptation at work) and in
    daylight, with each operator's defaults."""
    from ocl_tonemap.backends.opencl import transfers as T
    seen = []
    count = T._count
    monkeypatch.setattr(T, "_count", lambda up, n: (seen.append((up, n)), count(up, n)))
    tm = Tonemapper(op, "opencl")
    fr = frames[level]
    tm.process(fr[0])
    tm.process(fr[1], dt=0.04)
    seen.clear()
    out = tm.process(fr[2], dt=0.04)
    t = tm.last.transfers
    if level < 100:
        w = tm.last.plan["weights"]
        assert w.get("flare") and w.get("chromatic-adaptation")      # the effects at work
    assert [n for up, n in seen if up] == [fr[2].nbytes], seen       # the frame up, once
    down = sorted(n for up, n in seen if not up)
    assert out.nbytes <= down[-1] <= out.nbytes + TAIL, seen          # the output, once
    assert all(n <= STATS_BYTES for n in down[:-1]), seen             # statistics
    assert t["up_calls"] + t["down_calls"] == len(seen) <= MAX_CALLS, (t, seen)


def test_the_counter_counts_host_memory_only(rt):
    import pyopencl as cl
    before = counted()
    a = np.arange(1000, dtype=np.float32)
    buf = host_buffer(rt.context, a)                                # up: 4000 bytes
    other = cl.Buffer(rt.context, cl.mem_flags.READ_WRITE, a.nbytes)
    transfer(rt.queue, other, buf)                                  # device to device: none
    back = np.empty(500, np.float32)
    transfer(rt.queue, back, other)                                 # down: 2000 bytes
    rt.queue.finish()
    assert counted() - before == Transfers(1, 4000, 1, 2000)
    np.testing.assert_array_equal(back[:500], a[:500])
    consts, before = ConstantBuffers(rt.context, keep=2), counted()
    one = consts.get(np.ones(3, np.float32))
    assert consts.get(np.ones(3, np.float32)) is one                 # held: no upload
    consts.get(np.zeros(3, np.float32))
    consts.get(np.full(3, 2.0, np.float32))                          # the oldest given up
    consts.get(np.ones(3, np.float32))
    assert (counted() - before).up_calls == 4


def test_the_reference_backend_moves_nothing():
    tm = Tonemapper("pattanaik00", "reference")
    tm.process(np.full((4, 4, 3), 10.0, np.float32))
    assert tm.last.transfers is None


@pytest.mark.parametrize("op", ["ledda04", "kirk11"])
def test_chromatic_gains_on_the_device_equal_the_hosts(frames, op):
    """ledda04 and kirk11 take the chromatic gains on the scene (the seen slot): on a
    frame the flare left on the device they run there (colour.cl:scale_rgb), bit for
    bit what the host's float32 products give, and the operator's colour stage runs
    again on the scaled frame (not the stale resident one)."""
    small = [f[::4, ::4].copy() for f in frames[8.0]]
    warm = np.array([1.0, 0.8, 0.55], np.float32)          # a tungsten cast: gains != 1
    outs = []
    for on_device in (True, False):
        tm = Tonemapper(op, "opencl", chromatic_adaptation="on", flare="on")
        if not on_device:
            tm.backend.scale_image = lambda img, gains: None   # the host's products
        for k, f in enumerate(small):
            tm.process(f * warm, dt=None if k == 0 else 0.04)
        g = tm.last.effects["chromatic_adaptation"]["gains"]
        outs.append(tm.last_output)
    assert max(abs(float(v) - 1.0) for v in g) > 0.05
    np.testing.assert_array_equal(outs[0], outs[1])
