"""Dark adaptation after a bright field (issue 34, experiment 1): the data as read,
and the shape of each time-course operator's simulated curves
(``benchmarks/lib/human/dark.py``, through the public API). Where a model misses the
data, the test holds the model's own value (so that a change shows) and
docs/validation.md says why."""

import math

import numpy as np
import pytest

from benchmarks.lib.human import dark
from benchmarks.lib.human.data import (CD_PER_UUL, HECHT_TD, load_hecht1937, log_uuL_to_cd,
                                       pupil_area_mm2, trolands_to_cd)


@pytest.fixture(scope="module")
def curves():
    res, crit = dark.run_all()
    return res, crit


def test_the_data_as_read():
    pts = load_hecht1937()
    assert len(pts) == 359
    assert {p.observer for p in pts} == {"S.H.", "C.H.", "A.M.C."}
    assert {p.td for p in pts} == set(HECHT_TD.values())
    # the misfiled row is S.H.'s, and continues his 263-td curve
    row = [p for p in pts if p.td == 263.0 and p.minutes == 29.6]
    assert [p.observer for p in row] == ["S.H."]
    # after the brightest field the threshold falls 4-5.5 log units (the reading)
    bright = [p for p in pts if p.td == 400000.0]
    first = np.mean([p.log_uuL for p in bright if p.minutes < 0.5])
    last = np.mean([p.log_uuL for p in bright if p.minutes >= 30])
    assert 4.0 <= first - last <= 5.5


def test_units():
    assert log_uuL_to_cd(12.0) == pytest.approx(1e4 / math.pi)      # 1 L
    assert CD_PER_UUL == pytest.approx(3.1831e-9, rel=1e-4)
    for td in HECHT_TD.values():
        L = trolands_to_cd(td)
        assert L * pupil_area_mm2(L) == pytest.approx(td, rel=1e-9)


def test_thresholds_fall_monotonically_in_the_dark(curves):
    res, _ = curves
    for op, d in res.items():
        for td, (cv, _) in d.items():
            assert np.all(np.diff(cv.log_uuL) <= 1e-9), (op, td)
            assert np.all(np.isfinite(cv.log_uuL)), (op, td)


#: The operators whose default time course is the shared pigment model (issue 66).
PIGMENT_OPS = ("pattanaik00", "durand00", "kirk11")


def test_the_criterion_meets_the_data_at_full_dark_adaptation(curves):
    """The criterion is fixed once per operator: the dark-adapted observer's threshold
    is the data's, seen by the rods; every pigment operator's curve ends near it."""
    res, crit = curves
    goal = math.log10(dark.data_dark_threshold() / CD_PER_UUL)
    S = dark.scotopic_photopic_ratio(dark.TEST_NM)
    for op in ("pattanaik00", "ledda04", "durand00", "kirk11"):
        thr, who = dark.threshold(op, dark.dark_state(op), crit[op], S)
        assert math.log10(thr / CD_PER_UUL) == pytest.approx(goal, abs=1e-6), op
        assert who == "rod"
    for op in PIGMENT_OPS:
        assert res[op][400000.0][0].log_uuL[-1] == pytest.approx(goal, abs=0.1), op


def test_within_half_a_log_unit_of_the_observers_median(curves):
    """Issue 66's target: at every intensity, fitted or held out, the pigment operators'
    curves are within 0.5 log RMS of the median of Hecht's three observers (who differ
    from one another by 0.3-0.5); ledda04 included, its frame factor read on its own
    curve (Eq. 5's power law from the metering's floor: ``pigment_matching = "local"``).
    Measured 0.08-0.35 (docs/validation.md)."""
    res, _ = curves
    for op in PIGMENT_OPS:
        for td in HECHT_TD.values():
            assert res[op][td][1].rms_median <= 0.5, (op, td, res[op][td][1].rms_median)
    # the held-out intensities as well as the fitted ones: none is the worst by far
    worst = max(res[op][td][1].rms_median for op in PIGMENT_OPS for td in HECHT_TD.values())
    assert worst <= 0.4, worst


def test_rod_cone_break(curves):
    """Data: the break comes later after brighter fields (12-14 min after 400 000 td,
    5-7 after 19 500). Every pigment operator's break is within 2 minutes of the data's
    (rhodopsin's rate-limited regeneration down to the bleached fraction whose
    equivalent background, Dowling-Rushton's term for large bleaches, meets the cone
    plateau), and it comes later after the brighter field."""
    res, _ = curves
    br = {op: {td: res[op][td][0].break_min() for td in HECHT_TD.values()} for op in res}
    for op in PIGMENT_OPS:
        assert 10.0 <= br[op][400000.0] <= 16.0, (op, br[op])
        assert 3.0 <= br[op][19500.0] <= 9.0, (op, br[op])
        assert br[op][19500.0] < br[op][38900.0] < br[op][400000.0], (op, br[op])


def test_no_late_step_after_a_dim_field(curves):
    """After 263 td people's threshold falls smoothly from the first minute: no fall of
    more than 0.3 log units within any half minute after the first minute."""
    res, _ = curves
    for op in PIGMENT_OPS:
        cv = res[op][263.0][0]
        k = cv.minutes >= 1.0
        t, y = cv.minutes[k], cv.log_uuL[k]
        for a in range(len(t)):
            b = np.searchsorted(t, t[a] + 0.5, side="right") - 1
            assert y[a] - y[b] <= 0.3, (op, t[a], y[a] - y[b])


def test_duration_counts():
    """The same field for 10 s and for 120 s: the rods recover measurably earlier after
    the shorter (bleaching is intensity x time)."""
    S = dark.scotopic_photopic_ratio(dark.TEST_NM)
    goal = math.log10(dark.data_dark_threshold() / CD_PER_UUL)
    for op in PIGMENT_OPS:
        c = dark.criterion(op)
        when = {}
        for secs in (10.0, 120.0):
            cv = dark.simulate(op, 19500.0, c, S=S, preadapt_s=secs)
            near = np.nonzero(cv.log_uuL <= goal + 1.0)[0]
            when[secs] = float(cv.minutes[near[0]])
        assert when[10.0] + 2.0 <= when[120.0], (op, when)


def test_total_drop_after_the_brightest_field(curves):
    """Data 4.95 log units (4-5.5); every operator within 0.5 of it (ledda04 4.82)."""
    res, _ = curves
    drop = {op: res[op][400000.0][1].drop for op in res}
    assert res["pattanaik00"][400000.0][1].data_drop == pytest.approx(4.95, abs=0.01)
    for op in PIGMENT_OPS:
        assert drop[op] == pytest.approx(4.95, abs=0.5), (op, drop[op])
    assert drop["ledda04"] == pytest.approx(4.95, abs=0.5)
