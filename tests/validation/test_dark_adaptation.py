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


def test_the_criterion_meets_the_data_at_full_dark_adaptation(curves):
    """c is fixed once per operator: the dark-adapted observer's threshold is the
    data's; every curve ends near it (pattanaik00) or above it (ledda04's rods are
    still adapting at 45 min after bright fields)."""
    res, crit = curves
    goal = math.log10(dark.data_dark_threshold() / CD_PER_UUL)
    for op in ("pattanaik00", "ledda04"):
        S = dark.scotopic_photopic_ratio(dark.TEST_NM)
        thr, who = dark.threshold(op, dark.dark_state(op), crit[op], S)
        assert math.log10(thr / CD_PER_UUL) == pytest.approx(goal, abs=1e-6)
        assert who == "rod"
    assert res["pattanaik00"][400000.0][0].log_uuL[-1] == pytest.approx(goal, abs=0.05)


def test_rod_cone_break(curves):
    """Data: the break comes later after brighter fields (12-14 min after 400 000 td,
    5-7 after 19 500). The models miss it (docs/validation.md); their own values:
    pattanaik00's rods take over after about a minute whatever the field (Hunt's
    static rod bleaching leaves ~0 pigment above ~1 cd/m^2 and it regrows alike);
    ledda04's only within 45 min after the dimmest fields; durand00 has no dark time
    course (its thresholds follow the field in ~1 s)."""
    res, _ = curves
    br = {op: {td: res[op][td][0].break_min() for td in HECHT_TD.values()} for op in res}
    for td in HECHT_TD.values():
        assert br["pattanaik00"][td] == pytest.approx(1.0, abs=0.5)
        assert br["durand00"][td] == 0.0
    assert br["ledda04"][263.0] == pytest.approx(11.0, abs=1.0)
    assert br["ledda04"][19500.0] is None and br["ledda04"][400000.0] is None
    # where there is a break, brighter is never earlier
    for op in res:
        seq = [br[op][td] for td in sorted(HECHT_TD.values())]
        seq = [45.0 + 1 if b is None else b for b in seq]
        assert all(b >= a for a, b in zip(seq, seq[1:])), op


def test_total_drop_after_the_brightest_field(curves):
    """Data 4.95 log units (4-5.5); pattanaik00 5.5, ledda04 6.3 (its 45-minute value),
    durand00 0 (no dark time course)."""
    res, _ = curves
    drop = {op: res[op][400000.0][1].drop for op in res}
    assert res["pattanaik00"][400000.0][1].data_drop == pytest.approx(4.95, abs=0.01)
    assert drop["pattanaik00"] == pytest.approx(5.54, abs=0.1)
    assert drop["ledda04"] == pytest.approx(6.27, abs=0.1)
    assert drop["durand00"] == pytest.approx(0.0, abs=0.05)
