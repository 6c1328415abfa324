"""The shared pigment model (issue 66, ``models/bleaching.py``): its steady states and
time constants against the literature it cites, its stability from 1 ms to hours and
at extreme fields, and that intensity and duration both count."""

import math

import numpy as np
import pytest

from ocl_tonemap.models import bleaching as B


def test_cone_steady_state_is_rushton_and_henry():
    """Eq. 2's fixed point: Bb = I / (I + I0), half bleached at 10^4.3 td."""
    for L in (1.0, 100.0, 1e4, 1e6):
        s = B.steady(L * 2.5, L)
        I = B.trolands(L * 2.5, L)[1]
        assert s["Bb_cone"] == pytest.approx(I / (I + B.I0_CONE), rel=1e-6)


def test_cone_recovery_time_constant():
    s = B.steady(2.5e4, 1e4)
    b0 = s["Bb_cone"]
    s = B.advance(s, 0.0, 0.0, B.TAU_CONE)
    assert s["Bb_cone"] == pytest.approx(b0 / math.e, rel=1e-6)


def test_rod_regeneration_is_rate_limited():
    """From a full bleach to 20 % in the dark takes Eq. 4's integral, 13.2 min (within
    1 % by the integrator); at small bleaches the log falls at v / (K_m ln 10)."""
    s = {"Bb_rod": 1.0, "Bb_cone": 0.0, "N_rod": 0.0, "N_cone": 0.0}
    t, dt = 0.0, 1.0
    while s["Bb_rod"] > 0.2:
        s = B.advance(s, 0.0, 0.0, dt)
        t += dt
    assert t / 60.0 == pytest.approx(B.regeneration_minutes(1.0, 0.2), rel=0.01)
    assert B.regeneration_minutes(1.0, 0.2) == pytest.approx(13.2, abs=0.1)
    s = {**s, "Bb_rod": 1e-3}
    s1 = B.advance(s, 0.0, 0.0, 60.0)
    slope = math.log10(s["Bb_rod"] / s1["Bb_rod"])
    assert slope == pytest.approx(B.V_ROD_PER_MIN / (B.KM_ROD * math.log(10.0)), rel=0.02)


def test_a_step_of_any_length_is_stable_and_close_to_many_short_ones():
    s0 = B.preadapted(1e4, 60.0)
    one = B.advance(s0, 0.0, 0.0, 600.0)
    many = dict(s0)
    for _ in range(600):
        many = B.advance(many, 0.0, 0.0, 1.0)
    for k in ("Bb_rod", "Bb_cone"):
        assert one[k] == pytest.approx(many[k], abs=2e-3), k
    for dt in (1e-3, 1.0 / 24, 1.0, 3600.0, 10 * 3600.0, 1e9):
        for L in (0.0, 1e-6, 1.0, 1e8, math.inf, math.nan, -5.0):
            s = B.advance(s0, L * 2.5, L, dt)
            assert B.check(s), (dt, L, s)
            assert all(math.isfinite(v) for v in s.values())


def test_intensity_and_duration_both_count():
    """Bleaching is driven by retinal illuminance x time: a brighter field or a longer one
    bleaches more, the same energy about as much (Rushton: first-order kinetics)."""
    short, long_ = B.preadapted(5e3, 10.0), B.preadapted(5e3, 120.0)
    assert short["Bb_rod"] < 0.5 * long_["Bb_rod"]
    assert B.preadapted(500.0, 120.0)["Bb_rod"] < long_["Bb_rod"]
    dim_long = B.preadapted(500.0, 100.0)["Bb_rod"]
    bright_short = B.preadapted(5000.0, 10.0)["Bb_rod"]
    assert dim_long == pytest.approx(bright_short, rel=0.35)


def test_the_dark_and_the_equivalent_background():
    assert B.equivalent_background(B.dark()) == (0.0, 0.0)
    assert B.elevation(B.dark()) == (0.0, 0.0)
    s = B.preadapted(1.3e5, 120.0)
    er, ec = B.elevation(B.advance(s, 0.0, 0.0, 60.0))
    assert er > ec > 0.0                      # the rods stay desensitised longer
    # the cones' neural phase decays with tau_N once the field is gone
    s = B.steady(78.0, 31.0)
    a = B.advance(s, 0.0, 0.0, 1.0)["N_cone"]
    b = B.advance(s, 0.0, 0.0, 1.0 + B.TAU_N)["N_cone"]
    assert b == pytest.approx(a / math.e, rel=1e-6)


@pytest.mark.parametrize("L", [31.0, 5.2e3, 1.3e5])
def test_the_rods_neural_phase_falls_as_one_over_time_whatever_the_field(L):
    """Eq. 5, rods: second order, so after its first seconds the equivalent background
    of the field's memory is near C_N / t whatever the field was (Hecht's 263 td:
    L_eq t about constant from 15 s to 10 min) until tau_S ends it; one long step
    equals many short ones."""
    s = B.steady(L * 2.57, L)
    first = B.C_N_ROD / (B.W_N_ROD * s["N_rod"])          # its first decay time, s
    for t in (60.0, 600.0, 3600.0):
        one = B.advance(s, 0.0, 0.0, t)
        Leq_t = B.W_N_ROD * one["N_rod"] * t
        end = math.exp(-t / B.TAU_S_ROD)
        assert B.C_N_ROD * (1.0 - first / t) * end <= Leq_t <= B.C_N_ROD * end ** 0.5
        many = s
        for _ in range(1000):
            many = B.advance(many, 0.0, 0.0, t / 1000)
        assert many["N_rod"] == pytest.approx(one["N_rod"], rel=1e-9)
    # it rises to a field with tau_N: a millisecond's flash leaves next to nothing
    assert B.advance(B.dark(), 5.0, 2.0, 1e-3)["N_rod"] == pytest.approx(5.0 * 1e-3 / B.TAU_N,
                                                                           rel=1e-3)
    assert B.advance(B.dark(), 5.0, 2.0, 1e-3)["N_cone"] == 2.0      # the cones' at once
    assert B.advance(s, L * 2.57, L, 3600.0)["N_rod"] == pytest.approx(L * 2.57, rel=1e-12)


def test_steady_state_adds_little_to_a_steady_field():
    """On a field held for good, the equivalent background is small beside the field (the
    pictures of stills stay as they were): the cones' under 2 % of it from 1e-3 to 1e5
    cd/m^2, the rods' too up to 1e3; above, where more than half the rhodopsin is
    bleached and the rods' response is saturated, Dowling-Rushton's term makes it up
    to 10 % (6.3 % at 1e4 cd/m^2)."""
    for L in np.logspace(-3, 5, 9):
        s = B.steady(L * 2.5, L)
        Lr, Lc = B.equivalent_background(s, L * 2.5, L)
        assert Lc <= 0.02 * L + 1e-3, (L, Lc)
        assert Lr <= (0.02 if L <= 1e3 else 0.10) * L * 2.5 + 1e-3, (L, Lr)


# -- Eq. 7: the cones' onset lag (Baker 1949 as Pattanaik and Ledda describe it) --------
@pytest.mark.parametrize("L_dark", [0.0, 1e-6, 1e-3])
def test_a_field_on_a_dark_eye_starts_the_same_lag_whatever_the_dark(L_dark):
    s = B.steady(L_dark * 2.5, L_dark)
    s = B.advance(s, 2500.0, 1000.0, 1e-3)
    assert B.onset_lag(s, 1000.0) == pytest.approx(B.PSI_FAST, rel=2e-3)


def test_the_lag_falls_with_its_time_constant_and_is_gone_within_seconds():
    s = B.advance(B.dark(), 2500.0, 1000.0, 1e-3)
    lag0 = B.onset_lag(s, 1000.0)
    s = B.advance(s, 2500.0, 1000.0, B.TAU_FAST)
    assert B.onset_lag(s, 1000.0) == pytest.approx(lag0 * math.exp(-1.0), rel=1e-6)
    s = B.advance(s, 2500.0, 1000.0, 10.0)
    assert B.onset_lag(s, 1000.0) < 1e-3 * lag0


def test_the_lag_is_split_invariant_and_small_steps_lag_only_their_own_size():
    one = B.advance(B.steady(25.0, 10.0), 250.0, 100.0, 3.0)
    many = B.steady(25.0, 10.0)
    for _ in range(300):
        many = B.advance(many, 250.0, 100.0, 0.01)
    assert B.onset_lag(many, 100.0) == pytest.approx(B.onset_lag(one, 100.0), rel=1e-9)
    small = B.advance(B.steady(25.0, 10.0), 50.0, 20.0, 1e-9)
    assert B.onset_lag(small, 20.0) == pytest.approx(math.log10(2.0), rel=1e-6)


def test_a_dimmer_or_steady_field_has_no_lag_and_old_states_read_as_none():
    s = B.advance(B.steady(2500.0, 1000.0), 2.5, 1.0, 1e-3)
    assert B.onset_lag(s, 1.0) == 0.0
    assert B.onset_lag(B.steady(2500.0, 1000.0), 1000.0) == 0.0
    old = {k: v for k, v in B.steady(2.5, 1.0).items() if k in B.KEYS_V1}
    assert B.check(old)
    assert B.onset_lag(B.advance(old, 2500.0, 1000.0, 0.01), 1000.0) == 0.0
    assert not B.check({**old, "M_cone": -1.0})


def test_the_operators_goal_lags_a_field_that_comes_on_and_the_display_is_white_at_first():
    """pattanaik00 with the defaults: stepping from the dark into 1000 cd/m^2, its cone
    level sits below the field for the first seconds and is there by 10 s."""
    from ocl_tonemap.operators import get_operator
    op = get_operator("pattanaik00")({})
    obs = op.observer_preadapted(1e-6, None)
    obs = op.observer_advance(obs, 1000.0, 0.5)
    assert op.observer_level(obs) < 10.0 ** -0.5 * 1000.0
    obs = op.observer_advance(obs, 1000.0, 10.0)
    assert op.observer_level(obs) == pytest.approx(1000.0, rel=0.01)
