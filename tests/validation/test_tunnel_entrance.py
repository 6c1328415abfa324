"""The tunnel entrance and light adaptation (issue 66, item 4;
``benchmarks/lib/human/tunnel.py``): CIE 88's curves as the experiment reads them,
and the numbers each operator's observer gives now. The model misses two things the
data show (docs/validation.md, "The tunnel entrance and light adaptation (issue
66)"): pattanaik00's and kirk11's VL is below 1 for well under a second after a
sudden step, and no operator but ledda04 (its paper's 1 s hold) has a threshold above
its steady value after a field goes on before a dark-adapted eye; the tests hold the
model's own values (so that a change shows)."""

import math

import numpy as np
import pytest

from benchmarks.lib.human import tunnel as T

REL = 1e-2


def test_the_transition_curve_as_cie88_writes_it():
    # L_tr = L_th (1.9 + t)^-1.4, t from the transition zone's start: 0.407 L_th there,
    # where the threshold zone (linear to 0.4 L_th over its second half) ends
    assert T.transition(1.0, 0.0) == pytest.approx(1.9 ** -1.4)
    assert float(T.transition(T.L_TH, 0.0)) == pytest.approx(0.4074 * T.L_TH, rel=1e-3)
    assert float(T.transition(250.0, 10.0)) == pytest.approx(250.0 * 11.9 ** -1.4)
    t_end = T.transition_end_s()
    assert float(T.transition(T.L_TH, t_end)) == pytest.approx(T.L_INTERIOR)


def test_the_road_and_the_target():
    D = T.threshold_zone_s()
    assert D == pytest.approx(100.0 / (80.0 / 3.6))
    assert T.L_TH == pytest.approx(0.06 * 5000.0)
    r = T.road([-1.0, 0.0, 0.49 * D, 0.75 * D, D, D + 1.0, 100.0])
    assert r[0] == T.L20 and r[1] == r[2] == T.L_TH
    assert r[3] == pytest.approx(0.7 * T.L_TH)
    assert r[4] == pytest.approx(T.L_TH * 1.9 ** -1.4)
    assert r[5] == pytest.approx(T.L_TH * 2.9 ** -1.4)
    assert r[6] == T.L_INTERIOR
    # falling throughout but at the join: 0.4 L_th at the threshold zone's end, the
    # curve's 1.9^-1.4 = 0.407 L_th at its start
    up = np.diff(T.road(np.arange(0.0, 40.0, 0.02)))
    assert np.sum(up > 1e-9) == 1 and up.max() < 0.008 * T.L_TH
    assert T.target_arcmin() == pytest.approx(math.degrees(0.002) * 60.0, rel=1e-6)


@pytest.fixture(scope="module")
def runs():
    drives, onsets, failed = T.run_all(("pattanaik00", "durand00", "ledda04"), (1000.0,))
    assert not failed
    return drives, onsets


# (VL at the entrance, least VL on the curve + interior, s VL < 1 after the step)
HELD_DRIVE = {"pattanaik00": (1.680, 3.100, 0.35),
              "durand00": (0.316, 3.079, 1.89),
              "ledda04": (3.312, 3.713, 0.0)}


@pytest.mark.parametrize("op", sorted(HELD_DRIVE))
def test_the_drive_and_the_step(runs, op):
    d = runs[0][op]
    vl0, vl_curve, below = HELD_DRIVE[op]
    assert d.VL_threshold_zone == pytest.approx(vl0, rel=REL)
    assert d.vl_min_curve == pytest.approx(vl_curve, rel=REL)
    assert d.step_below1_s == pytest.approx(below, abs=0.05)
    # the shape: the curve keeps the target seen (within 0.8 x its entrance value or
    # above), the step hides it at first; adapted to L_th it would be seen best
    assert d.vl_min_curve >= 0.8 * d.VL_threshold_zone and d.vl_min_curve >= 1.0
    assert (d.step_VL[0] < 1.0) == (below > 0.0)
    assert d.VL_adapted_th >= d.VL_threshold_zone


# (dL_th / steady at 0, 0.1 and 2 s after 1000 cd/m^2 goes on before a dark eye)
# ledda04: the cones' onset lag (bleaching Eq. 7, Baker's fast phase) on its
# Naka-Rushton cone; the others' thresholds do not rise on a lowered level
HELD_ONSET = {"pattanaik00": (3.93, 1.0, 1.0), "durand00": (1.0, 1.0, 1.0),
              "ledda04": (1.44, 1.51, 1.07)}


@pytest.mark.parametrize("op", sorted(HELD_ONSET))
def test_light_adaptation_on_a_dark_eye(runs, op):
    o = runs[1][op][1000.0]
    for t, v in zip((0.0, 0.1, 2.0), HELD_ONSET[op]):
        assert o.over_steady_at(t) == pytest.approx(v, rel=REL)
    assert o.over_steady_at(60.0) == pytest.approx(1.0, abs=0.01)


def test_the_onset_jump_falls_within_seconds(runs):
    """Baker 1949's fast phase, as Ledda et al. Sec. 5 describe it: highest just after
    the onset, falling fast over the first seconds (ledda04 with the defaults)."""
    o = runs[1]["ledda04"][1000.0]
    after = [o.over_steady_at(t) for t in (0.01, 0.1, 0.5, 1.0, 2.0, 5.0, 10.0)]
    assert after[0] > 1.4 and all(a >= b for a, b in zip(after, after[1:]))
    assert after[-2] < 1.02 and o.above_steady_until <= 5.0
