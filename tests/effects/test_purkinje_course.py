"""The Purkinje shift's time course with the default settings comes from the operator's
shared pigment course (issue 66): after daylight, a dim warm room's displayed colour
moves one way, as the rods come back, never back and forth. (Its own Eq. 7 bleaching,
read against a neural level that falls faster, made the rods' share jump from 0.69 at
1 s to 0.18 at 1.5 s: the room turned cool, then warm again.)"""

from __future__ import annotations

import numpy as np
import pytest

from ocl_tonemap import Tonemapper

TIMES = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 30.0, 60.0, 300.0, 900.0)


def _warm_room(level=0.5):
    rng = np.random.default_rng(0)
    base = np.array([1.6, 1.0, 0.45], np.float32)        # tungsten-ish
    return rng.lognormal(0.0, 0.8, (32, 48, 1)).astype(np.float32) * base * level


@pytest.mark.parametrize("op", ["pattanaik00", "durand00"])
def test_after_daylight_the_colour_moves_one_way(op):
    tm = Tonemapper(op, backend="reference", preadapt=(1e4, 120.0))
    fr = _warm_room()
    rb, gain = [], []
    for t in TIMES:
        out = tm.process(fr, time_s=t)
        m = out.reshape(-1, 3).astype(np.float64).mean(0)
        rb.append(m[0] / m[2])
        gain.append(tm.last.effects["purkinje"].get("rod_gain", 0.0))
    assert all(b <= a * (1 + 1e-9) for a, b in zip(rb, rb[1:])), np.round(rb, 3)
    assert all(b >= a - 1e-12 for a, b in zip(gain, gain[1:])), np.round(gain, 3)
    # the rods take minutes: little of the shift in the first minute, most by 15 min
    assert gain[TIMES.index(60.0)] < 0.1 < 0.9 < gain[-1]


def test_a_still_gets_the_whole_shift():
    """A fresh observer on a dim still is adapted to it: the rods' sensitivity is 1, as
    before the pigment course reached the shift (stills unchanged)."""
    tm = Tonemapper("pattanaik00", backend="reference")
    tm.process(_warm_room(0.05))
    assert tm.last.effects["purkinje"]["rod_sensitivity"] == pytest.approx(1.0, abs=1e-12)
