"""Durand & Dorsey 2000 model: scale factors, mesopic factor, blue shift, light adaptation time constants, illuminants and the Planckian locus."""

import math

import numpy as np
import pytest

from ocl_tonemap.models import durand2000 as dd
from ocl_tonemap.models import ferwerda1996 as fw
from ocl_tonemap.models import durand2000 as fx
from ocl_tonemap.effects import EffectSettings
from ocl_tonemap.models.photometry import RGB709_TO_XYZ
from ocl_tonemap.pipeline import Tonemapper


NO_FX = EffectSettings()  # all effects off

def _xy(rgb):
    X = RGB709_TO_XYZ @ np.asarray(rgb, np.float64)
    return X[:2] / X.sum()


def test_scale_factors_and_mesopic_factor_ranges():
    L = 10.0 ** np.linspace(-6, 8, 300)
    mC, mR = fw.scale_factors(L, L, 50.0)
    assert np.all(mC > 0) and np.all(mR > 0) and np.all(np.diff(mC) <= 0)
    assert np.all(np.diff(mC[L > 10 ** -2.5]) < 0)      # constant below the cone floor
    # photopic: threshold mapping is Ward-like, m_C proportional to 1 / L_wa
    assert fw.scale_factors(1e5, 1e5, 50.0)[0] / fw.scale_factors(1e4, 1e4, 50.0)[0] == \
        pytest.approx(0.1, rel=1e-12)
    k = dd.mesopic_factor_walraven_valeton(L)
    assert k.min() == 0.0 and k.max() <= 1.0 and np.all(np.diff(k) <= 0)
    assert dd.mesopic_factor_walraven_valeton(0.0) == 1.0 and dd.mesopic_factor_walraven_valeton(400.0) == 0.0
    assert dd.mesopic_factor_walraven_valeton(100.0) == pytest.approx(0.375)

def test_blue_shift_makes_scotopic_white_bluish():
    white = np.full((8, 8, 3), 1e-3, np.float32)     # a white at starlight levels
    out = Tonemapper("durand00", "reference", effects=NO_FX,
                     options={"mode": "paper"}).process(white)
    assert tuple(_xy(out[0, 0])) == pytest.approx((0.30, 0.30), abs=0.002)   # Hunt's white
    # default: the same purity toward 480 nm (blue, not violet)
    out = Tonemapper("durand00", "reference", effects=NO_FX).process(white)
    assert tuple(_xy(out[0, 0])) == pytest.approx(dd.BLUE_SHIFT_DEFAULT_XY, abs=0.002)
    plain = Tonemapper("durand00", "reference", effects=NO_FX,
                       options={"tint": (1, 1, 1)}).process(white)
    assert tuple(_xy(plain[0, 0])) == pytest.approx((0.3127, 0.3290), abs=0.002)  # D65
    # photopic: no rods, no shift
    day = Tonemapper("durand00", "reference", effects=NO_FX).process(
        np.full((4, 4, 3), 1e3, np.float32))
    assert tuple(_xy(day[0, 0])) == pytest.approx((0.3127, 0.3290), abs=1e-4)

@pytest.mark.parametrize("key, tau, L0, L1", [("m_cone", dd.TAU_CONE, 1e3, 10.0),
                                              ("m_rod", dd.TAU_ROD, 1e-3, 1e-1)])
def test_light_adaptation_reaches_63_percent_at_tau(key, tau, L0, L1):
    # the paper's m (the default mode's display level follows the adapted level
    # too, so its m is not one exponential; its state is: test below)
    tm = Tonemapper("durand00", "reference", effects=NO_FX, options={"mode": "paper"})
    tm.process(np.full((4, 4, 3), L0, np.float32), time_s=0.0)
    m0 = tm.last.params[key]
    tm.process(np.full((4, 4, 3), L1, np.float32), time_s=tau)
    m_tau = tm.last.params[key]
    tm.process(np.full((4, 4, 3), L1, np.float32), time_s=tau * 40)
    m_inf = tm.last.params[key]
    assert (m_tau - m0) / (m_inf - m0) == pytest.approx(1 - math.exp(-1), abs=1e-9)
    # the same in one step or a thousand (exact integration)
    tm2 = Tonemapper("durand00", "reference", effects=NO_FX, options={"mode": "paper"})
    tm2.process(np.full((4, 4, 3), L0, np.float32), time_s=0.0)
    for k in range(1, 1001):
        tm2.process(np.full((4, 4, 3), L1, np.float32), time_s=tau * k / 1000)
    assert tm2.last.params[key] == pytest.approx(m_tau, rel=1e-9)

@pytest.mark.parametrize("key, tau, L0, L1", [("inv_eps_cone", dd.TAU_CONE, 1e3, 10.0),
                                              ("inv_eps_rod", dd.TAU_ROD, 1e-3, 1e-1)])
def test_sec33_state_reaches_63_percent_at_tau(key, tau, L0, L1):
    """Sec. 3.3's filter alone (``--mode paper``): the default mode's goals move with
    the shared pigment course's equivalent background (``models/bleaching.py``)."""
    tm = Tonemapper("durand00", "reference", options={"mode": "paper"}, effects=NO_FX)
    vals = []
    for t, L in ((0.0, L0), (tau, L1), (40 * tau, L1)):
        tm.process(np.full((4, 4, 3), L, np.float32), time_s=t)
        vals.append(tm.last.state.values[key])
    assert (vals[1] - vals[0]) / (vals[2] - vals[0]) == pytest.approx(1 - math.exp(-1), abs=1e-9)

def test_illuminant_parsing_and_normalisation():
    d65 = fx.parse_illuminant("D65")
    np.testing.assert_allclose(d65, 1.0, atol=2e-4)   # the working white
    a = fx.parse_illuminant("A")
    assert a[0] > 1 > a[2] and float(a @ RGB709_TO_XYZ[1]) == pytest.approx(1.0)
    np.testing.assert_allclose(fx.parse_illuminant("0.44757,0.40745"), a)
    with pytest.raises(ValueError):
        fx.parse_illuminant("bogus")

def test_planckian_locus_table_is_colour_sciences():
    """The vendored locus (data/planckian_locus.json) is colour-science's blackbody
    (u, v) at its temperatures, and CCT/Duv found on it agree with colour-science's
    Ohno 2013 over 1500-25000 K and |Duv| <= 0.02 (both ways)."""
    import warnings
    from ocl_tonemap.models import planckian as P
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
        mired, L, _ = P._locus()
        assert len(mired) == len(P.table_mireds()) and mired[0] == 10.0 and mired[-1] == 1000.0
        pick = np.r_[0:len(mired):97, len(mired) - 1]
        np.testing.assert_allclose(L[pick],
                                   colour.temperature.CCT_to_uv_Planck1900(1e6 / mired[pick]),
                                   rtol=1e-12)
        for T in np.geomspace(1500.0, 25000.0, 23):
            for duv in (-0.02, -0.006, -1e-4, 0.0, 0.003, 0.02):
                uv = colour.temperature.CCT_to_uv_Ohno2013(np.array([T, duv]))
                np.testing.assert_allclose(P.CCT_Duv_to_uv(T, duv), uv, atol=2e-7)
                cct, d = P.uv_to_CCT_Duv(uv)
                assert abs(cct - T) <= 2e-5 * T and abs(d - duv) <= 2e-7, (T, duv, cct, d)
                ref = colour.temperature.uv_to_CCT_Ohno2013(uv)
                assert abs(cct - ref[0]) <= 2e-5 * T and abs(d - ref[1]) <= 2e-6

def test_estimated_illuminant_needs_no_colour_science_import():
    """plausible_illuminant runs in every frame that estimates the illuminant: it must
    not import colour-science (0.5 s), checked in a fresh interpreter."""
    import subprocess
    import sys
    code = ("import sys; from ocl_tonemap.models.durand2000 import plausible_illuminant; "
            "v = plausible_illuminant([1.2, 0.8, 1.3]); "
            "assert 'colour' not in sys.modules, 'colour imported'; print(v)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-1500:]

def test_estimated_illuminant_stays_on_the_planckian_band():
    """Real light sources lie near the Planckian locus: an estimate is held there
    (|Duv| <= 0.006), so coloured lamps or a lawn cannot make a magenta or green
    'illuminant'; daylight and tungsten estimates are kept."""
    import warnings
    from ocl_tonemap.models.durand2000 import ILLUMINANTS_XY, plausible_illuminant, xy_to_rgb
    from ocl_tonemap.models.photometry import RGB709_TO_XYZ
    for name in ("D65", "A", "D50"):
        rgb = xy_to_rgb(*ILLUMINANTS_XY[name])
        np.testing.assert_allclose(plausible_illuminant(rgb), rgb, atol=2e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
        for bad in ([1.2, 0.8, 1.3], [0.8, 1.3, 0.8]):         # magenta, green
            v = plausible_illuminant(bad)
            XYZ = RGB709_TO_XYZ @ v
            uv = colour.xy_to_UCS_uv(XYZ[:2] / XYZ.sum())
            assert abs(colour.temperature.uv_to_CCT_Ohno2013(uv)[1]) <= 0.0061
