"""Shaler's Table 1 in its own units: Shlaer measured with a white (tungsten) field in
photometric units, the model's level L_waR is scotopic. The default reads the cones'
branch at L_waR / neutral_scotopic_ratio() and the rods' at L_waR /
source_scotopic_ratio(); --mode paper reads the table at L_waR (docs/models.md,
"Loss of acuity")."""

import numpy as np
import pytest

from ocl_tonemap.models import photometry
from ocl_tonemap.models import shaler1937 as acu

L = 10.0 ** np.linspace(-6, 6, 2401)
NODES = 10.0 ** acu.SHALER_LOG_L
ROD_NODES = acu.SHALER_OMEGA < acu.SHLAER_ROD_CONE_BREAK_CPD     # 2.1, 2.9, 4.1


def test_ratios_come_from_the_working_space_photometry():
    assert acu.neutral_scotopic_ratio is photometry.neutral_scotopic_ratio
    assert acu.neutral_scotopic_ratio() == pytest.approx(2.573, abs=5e-4)   # D65 white
    # Shlaer's tungsten white (illuminant A) has far fewer rod lumens per lumen
    assert acu.source_scotopic_ratio() == pytest.approx(1.292, abs=5e-4)
    assert acu.SHLAER_ROD_CONE_BREAK_CPD == pytest.approx(4.8)               # 30 x 0.16


def test_paper_mode_is_the_table_at_L_waR():
    np.testing.assert_array_equal(acu.acuity_cutoff(NODES, mode="paper"), acu.SHALER_OMEGA)
    np.testing.assert_array_equal(acu.acuity_cutoff(L, mode="paper"), acu.table_cutoff(L))


def test_cones_branch_is_the_table_at_the_neutral_photopic_luminance():
    sp = photometry.neutral_scotopic_ratio()
    # every node of the cones' branch, shifted by the S/P ratio of the working white
    cones = ~ROD_NODES
    np.testing.assert_allclose(acu.acuity_cutoff(NODES[cones] * sp), acu.SHALER_OMEGA[cones],
                               rtol=1e-12)
    above = L >= 10.0 ** -2 * sp            # cones' branch from 5.5 c/deg (Table 1 at 10^-2)
    np.testing.assert_array_equal(acu.acuity_cutoff(L[above]), acu.table_cutoff(L[above] / sp))


def test_rods_branch_is_the_table_at_the_tungsten_field_with_the_same_rod_light():
    sp = acu.source_scotopic_ratio()
    np.testing.assert_allclose(acu.acuity_cutoff(NODES[ROD_NODES] * sp),
                               acu.SHALER_OMEGA[ROD_NODES], rtol=1e-12)
    below = L <= 10.0 ** -2.5 * sp
    np.testing.assert_array_equal(acu.acuity_cutoff(L[below]), acu.table_cutoff(L[below] / sp))
    # between the two: the rods at their break, until the cones pass it
    br = acu.acuity_cutoff(L) == acu.SHLAER_ROD_CONE_BREAK_CPD
    lo, hi = L[br].min(), L[br].max()
    assert lo == pytest.approx(0.00726, rel=0.01) and hi == pytest.approx(0.01447, rel=0.01)
    assert hi / lo == pytest.approx(photometry.neutral_scotopic_ratio() / sp, rel=0.01)


def test_the_ratio_is_followed_not_hard_coded(monkeypatch):
    monkeypatch.setattr(acu, "neutral_scotopic_ratio", lambda: 2.0)
    assert float(acu.acuity_cutoff(2.0 * 10.0 ** 0.5)) == pytest.approx(38.5)
    assert float(acu.acuity_cutoff(2.0 * 10.0 ** 0.5, mode="paper")) != pytest.approx(38.5)


@pytest.mark.parametrize("mode", acu.MODES)
def test_monotone_and_the_table_ends_held(mode):
    w = acu.acuity_cutoff(L, mode=mode)
    assert np.all(np.diff(w) >= 0)
    lo, hi = (10.0 ** -3.5, 1e3) if mode == "paper" else \
        (10.0 ** -3.5 * acu.source_scotopic_ratio(), 1e3 * acu.neutral_scotopic_ratio())
    assert np.all(w[L <= lo] == 2.1) and np.all(w[L >= hi] == 50.0)
    assert np.all(w[(L > lo * 1.001) & (L < hi / 1.001)] > 2.1)
    assert np.all(w[(L > lo * 1.001) & (L < hi / 1.001)] < 50.0)
    assert float(acu.acuity_cutoff(0.0, mode=mode)) == 2.1             # black: held, no NaN


def test_default_never_sharper_than_the_paper_and_the_documented_shifts():
    d, p = acu.acuity_cutoff(L), acu.acuity_cutoff(L, mode="paper")
    assert np.all(d <= p)
    # docs/models.md: how far the cut-off moves (paper / default)
    shift = {L_: float(acu.acuity_cutoff(L_, mode="paper") / acu.acuity_cutoff(L_))
             for L_ in (0.001, 0.01, 0.03, 0.1, 1.0, 10.0)}
    assert shift[0.001] == pytest.approx(1.07, abs=0.005)
    assert shift[0.01] == pytest.approx(1.15, abs=0.005)
    assert shift[0.03] == pytest.approx(1.48, abs=0.005)
    assert shift[0.1] == pytest.approx(1.58, abs=0.005)
    assert shift[1.0] == pytest.approx(1.28, abs=0.005)
    assert shift[10.0] == pytest.approx(1.10, abs=0.005)
    assert max(p / d) == pytest.approx(1.67, abs=0.005)                # at L_waR = 0.08
    assert L[np.argmax(p / d)] == pytest.approx(0.081, rel=0.03)


def test_mode_reaches_a_px_info_and_apply():
    img = np.random.default_rng(0).random((12, 16, 3)).astype(np.float32)
    for mode in acu.MODES:
        w = float(acu.acuity_cutoff(0.05, mode=mode))
        assert float(acu.acuity_a_px(0.05, 50.0, 1920, mode=mode)) == \
            pytest.approx(acu.ACUITY_A_PER_OMEGA * w * 50.0 / 1920)
        info = acu.acuity_info(0.05, 5.0, 16, mode=mode)
        out, got = acu.apply_acuity(img, 0.05, 5.0, mode=mode)
        assert got == info and info["cutoff_cpd"] == w
    # the calls effects/acuity.py makes (positional, no mode) give the default
    assert acu.acuity_info(0.05, 5.0, 16) == acu.acuity_info(0.05, 5.0, 16, mode="default")
    assert float(acu.acuity_a_px(0.05, 50.0, 1920)) < float(acu.acuity_a_px(0.05, 50.0, 1920,
                                                                            mode="paper"))
    with pytest.raises(ValueError):
        acu.acuity_cutoff(1.0, mode="literal")


def test_where_the_blur_starts():
    """50 degrees over 1920 px: a_px = 1.1 at L_waR 0.27 (paper), 0.69 (default)."""
    for mode, start in (("paper", 0.268), ("default", 0.69)):
        assert float(acu.acuity_blend(acu.acuity_a_px(start * 1.01, 50.0, 1920, mode))) == 0
        assert float(acu.acuity_blend(acu.acuity_a_px(start / 1.01, 50.0, 1920, mode))) > 0
