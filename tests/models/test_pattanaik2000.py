"""Pattanaik 2000: paper values, steady states, time constants, stability."""

import math

import numpy as np
import pytest

from ocl_tonemap.models import pattanaik2000 as P
from ocl_tonemap.models.integrators import bleaching_step, exponential_step
from ocl_tonemap.models.display import DisplaySpec


def test_paper_display_constants():
    # Sec. 4.3: A = 25 cd/m^2 gives sigma_cone = 646, B_rod = 0.0016, B_cone = 1.
    assert P.sigma_cone(25.0) == pytest.approx(646.0, rel=1e-3)
    assert P.bleach_rod_static(25.0) == pytest.approx(0.0016, abs=5e-6)   # printed to 2 digits
    assert P.bleach_cone_static(25.0) == pytest.approx(1.0, abs=2e-5)


def test_paper_display_slope_S_d():
    # The printed S_d = 0.1383 is the forward difference per log10 between the
    # CRT's REF_blk (125/32) and REF_whit (125): our reconstruction of Eq. 3's base.
    # (0.13853 from the printed, rounded constants; per ln it would be 0.060.)
    d = P.DisplayObserver.from_spec(DisplaySpec.crt_2000())
    assert d.S_d == pytest.approx(0.1383, rel=3e-3)


def test_sigma_rod_printed_722_is_hunts_form_of_eq4():
    # Eq. 4 as printed gives 144.7 at 25 cd/m^2; the paper's display value is 722,
    # which is Hunt's form (numerator 12.9223 A, as Eq. 5): the default.
    assert P.sigma_rod(25.0, printed=True) == pytest.approx(144.66, rel=1e-3)
    assert P.sigma_rod(25.0) == pytest.approx(722.0, rel=1e-3)


def test_sigma_limits_at_zero_are_finite():
    assert math.isfinite(float(P.sigma_rod(0.0))) and float(P.sigma_rod(0.0)) > 0
    assert float(P.sigma_cone(0.0)) == pytest.approx(12.9223, rel=1e-3)


@pytest.mark.parametrize("G", [0.0, 1e-6, 0.04, 1.0, 25.0, 1e3, 2e6, 1e8])
def test_kinetic_steady_state_equals_eq6(G):
    b_rod, b_cone = 0.5, 0.5
    for _ in range(3):
        b_rod = bleaching_step(b_rod, G, 1e5, P.K_ROD, P.TAU_ROD)
        b_cone = bleaching_step(b_cone, G, 1e5, P.K_CONE, P.TAU_CONE)
    assert b_rod == pytest.approx(float(P.bleach_rod_static(G)), rel=1e-12)
    assert b_cone == pytest.approx(float(P.bleach_cone_static(G)), rel=1e-12)


def test_exact_bleaching_matches_fine_euler():
    # Eq. 7's explicit step converges to our exact step when T*G/k << 1.
    G, B0, T = 500.0, 0.7, 2.0
    b = B0
    n = 200000
    for _ in range(n):
        b += T / n * ((1 - b) / P.TAU_ROD - b * G / P.K_ROD)
    assert bleaching_step(B0, G, T, P.K_ROD, P.TAU_ROD) == pytest.approx(b, rel=1e-4)


def test_explicit_eq7_diverges_where_exact_does_not():
    # The paper's step at 30 fps for rods at 5000 cd/m^2: T*G/16 = 10.4 > 2.
    G, T = 5000.0, 1 / 30
    b_euler = b_exact = 1.0
    for _ in range(30):
        b_euler += T * (1 - b_euler) / P.TAU_ROD - T * b_euler * G / P.K_ROD
        b_exact = bleaching_step(b_exact, G, T, P.K_ROD, P.TAU_ROD)
    assert abs(b_euler) > 1e10            # the explicit step blows up
    assert 0.0 <= b_exact <= 1.0
    assert b_exact == pytest.approx(float(P.bleach_rod_static(G)), rel=1e-6)


@pytest.mark.parametrize("t0", [P.T0_ROD, P.T0_CONE])
def test_neural_step_response_63_percent_at_t0(t0):
    a = exponential_step(0.0, 1.0, t0, t0)
    assert a == pytest.approx(1 - math.exp(-1), abs=1e-12)
    # Frame-rate independent: 100 small steps equal one big one.
    b = 0.0
    for _ in range(100):
        b = exponential_step(b, 1.0, t0 / 100, t0)
    assert b == pytest.approx(a, rel=1e-12)


def test_light_recovery_faster_than_dark_recovery():
    # Equal steps up and down (1 -> 1000 and 1000 -> 1 cd/m^2): how long until
    # rod pigment is 90% of the way to its new steady state.
    def time_to_90(G_from, G_to):
        b0 = float(P.bleach_rod_static(G_from))
        b_inf = float(P.bleach_rod_static(G_to))
        b, t, dt = b0, 0.0, 0.05
        while abs(b - b_inf) > 0.1 * abs(b0 - b_inf):
            b = bleaching_step(b, G_to, dt, P.K_ROD, P.TAU_ROD)
            t += dt
        return t
    light, dark = time_to_90(1.0, 1000.0), time_to_90(1000.0, 1.0)
    assert light < dark / 10


@pytest.mark.parametrize("G", [0.0, 1e-6, 1.0, 1e4, 1e8])
@pytest.mark.parametrize("dt", [1e-3, 1 / 30, 1.0, 3600.0])
def test_state_stable_for_any_goal_and_step(G, dt):
    v = P.steady_state(1e-3, 1e-3)
    for _ in range(5):
        v = P.advance(v, G, G, dt)
        assert all(math.isfinite(x) for x in v.values())
        assert 0.0 <= v["B_rod"] <= 1.0 and 0.0 <= v["B_cone"] <= 1.0
        assert v["A_rod"] >= 0 and v["A_cone"] >= 0


@pytest.mark.parametrize("spec", [DisplaySpec.crt_2000(), DisplaySpec.from_white("sdr", 100.0),
                                  DisplaySpec.from_white("pq", 1000.0, hdr=True)])
def test_inverse_display_response_round_trip(spec):
    d = P.DisplayObserver.from_spec(spec)
    L = np.logspace(-3, 4, 50)
    R = P.response(L, d.sigma_rod, d.B_rod) + P.response(L, d.sigma_cone, d.B_cone)
    np.testing.assert_allclose(d.luminance(R), L, rtol=1e-9)


def test_appearance_rules_and_continuity():
    d = P.DisplayObserver.from_spec(DisplaySpec.crt_2000())
    dw, dk = d.ref_white, d.ref_black
    span = dw - dk
    # Rule 1: inside the display's range -> identity.
    g, o, r = P.appearance_map(dw - 0.1 * span, dk + 0.1 * span, d)
    assert (g, o, r) == (1.0, 0.0, 1)
    # Rule 2: wider span -> white and black land on display white and black.
    g, o, r = P.appearance_map(dw + span, dk, d)
    assert r == 2 and g * (dw + span) + o == pytest.approx(dw) and g * dk + o == pytest.approx(dk)
    # Rule 3 / 4: offsets only, just enough.
    g, o, r = P.appearance_map(dw + 0.2 * span, dk + 0.5 * span, d)
    assert r == 3 and g == 1.0 and (dw + 0.2 * span) + o == pytest.approx(dw)
    g, o, r = P.appearance_map(dw - 0.5 * span, dk - 0.2 * span, d)
    assert r == 4 and g == 1.0 and (dk - 0.2 * span) + o == pytest.approx(dk)
    # Continuity across the rule 2/3 boundary (equal spans).
    eps = 1e-9
    a = P.appearance_map(dw + 0.3 * span + eps, dk + 0.3 * span - eps, d)
    b = P.appearance_map(dw + 0.3 * span - eps, dk + 0.3 * span + eps, d)
    assert a[2] == 2 and b[2] == 3
    x = dk + 0.5 * span
    assert a[0] * x + a[1] == pytest.approx(b[0] * x + b[1], abs=1e-6)


def test_mapping_is_monotonic_in_luminance():
    v = P.steady_state(300.0, 100.0)
    from ocl_tonemap.pipeline.state import AdaptationState
    st = AdaptationState("pattanaik00", v)
    p = P.frame_params(st, DisplaySpec.from_white("sdr", 100.0))
    L = np.logspace(-6, 8, 400)
    out = P.map_reference(np.repeat(L[:, None], 3, 1), L, L * 2.5, p)[:, 0]
    assert np.all(np.diff(out) >= -1e-12)
    assert np.all(np.isfinite(out)) and out.min() >= 0


def test_preadapt_longer_exposure_bleaches_more():
    # Cone pigment bleaches at G/2.2e8 per second: at 1e5 cd/m^2 minutes matter.
    short = P.preadapted(1e5, 10.0)
    long = P.preadapted(1e5, 600.0)
    full = P.preadapted(1e5, None)
    assert 1.0 > short["B_cone"] > long["B_cone"] > full["B_cone"]
    assert long["B_cone"] == pytest.approx(full["B_cone"], rel=0.05)
    assert full["A_cone"] == 1e5
