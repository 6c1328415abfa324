"""Dark adaptation as the display shows it (issue 66; Ledda et al. 2004, Sec. 6.1's method:
``benchmarks/lib/human/display_dark.py``, the full run ``benchmarks/display_dark.py``):
the chart, the criteria and the observers' course as read, and the shape of a short
run through the public API (few times, a five-target chart). Where a model misses the
observers, the test holds the model's own value (so that a change shows) and
docs/validation.md says why."""

import numpy as np
import pytest

from benchmarks.lib.human import dark
from benchmarks.lib.human import display_dark as D

TIMES = np.array([0.05, 1.0, 5.0, 15.0, 40.0])
FEW = D.TARGETS_CD[::3]                     # 1e-6, 3.2e-5, 1e-3, 3.2e-2, 1 cd/m^2


def test_the_chart():
    f, boxes = D.chart()
    assert f.dtype == np.float32 and f.shape == (110, 170, 3)
    assert len(boxes) == len(D.TARGETS_CD) == 13
    np.testing.assert_allclose(np.diff(np.log10(D.TARGETS_CD)), 0.5)
    for (y0, x0), L in zip(boxes, D.TARGETS_CD):
        sq = f[y0:y0 + D.TARGET_PX, x0:x0 + D.TARGET_PX]
        assert np.all(sq == np.float32(L))
    # black everywhere else; a target is ~3 degrees (Hecht's field) at the default 50
    assert np.count_nonzero(f[..., 1]) == 13 * D.TARGET_PX ** 2
    assert D.TARGET_PX / f.shape[1] * 50.0 == pytest.approx(3.0, abs=0.1)
    for centre, ring in D._masks(f.shape, boxes):
        assert np.all(f[ring] == 0.0) and np.all(f[centre] > 0.0)


def test_the_crossings():
    logs = np.log10(D.TARGETS_CD)
    de = np.full(13, 10.0)
    assert D.just_visible(de) == -np.inf                  # every target visible
    assert D.just_visible(np.full(13, 0.1)) == np.inf     # none
    de[:4] = 0.1                                          # visible from target 4 on
    v = D.just_visible(de)
    assert logs[3] < v < logs[4]
    # the first time a target stays visible, between the frames around the crossing
    m = np.array([0.0, 1.0, 2.0, 3.0])
    assert D.first_visible(m, np.array([0.1, 0.5, 2.0, 3.0])) == pytest.approx(
        1.0 + np.log10(2.0) / np.log10(4.0))
    assert D.first_visible(m, np.array([2.0, 0.5, 2.0, 3.0])) > 1.0   # for good
    assert D.first_visible(m, np.full(4, 2.0)) == 0.0
    assert D.first_visible(m, np.full(4, 0.5)) == np.inf


def test_the_observers_neutral_course():
    """Above the cones' plateau the violet's threshold; below it min(plateau, 11.6x)."""
    assert D.neutral_factor() == pytest.approx(29.8 / 2.57, rel=0.01)
    P = np.log10(dark.data_cone_plateau())
    for td in (263.0, 400000.0):
        t, n = D.hecht_course(td)
        tv, yv = dark.median_curve(td)
        v = np.log10(dark.log_uuL_to_cd(yv))
        np.testing.assert_array_equal(t, tv)
        assert np.all(n >= v - 1e-12) and np.all(n <= v + np.log10(D.neutral_factor()) + 1e-9)
        np.testing.assert_allclose(n[v >= P], v[v >= P])
        assert np.all(n[v < P] <= P + 1e-12)
        first = D.hecht_first_visible(td)
        finite = first[np.isfinite(first)]
        assert np.all(np.diff(finite) <= 0.0)            # brighter targets no later
    # after the brightest field a 1e-3 cd/m^2 target is seen only after the break (~20 min)
    assert D.hecht_first_visible(400000.0)[6] == pytest.approx(17.5, abs=1.5)


@pytest.fixture(scope="module")
def short_runs():
    return {op: D.simulate(op, 400000.0, TIMES, targets=FEW)
            for op in ("pattanaik00", "durand00")}


def test_targets_emerge_in_the_dark(short_runs):
    """After 400 000 td the brightest target shows at once; the dimmer ones later: on
    every frame at least as many targets are visible as on the one before."""
    for op, run in short_runs.items():
        assert run.de.shape == (len(TIMES), len(FEW))
        assert np.all(run.de[:, -1] >= D.JND), op
        vis = (run.de >= D.JND).sum(axis=1)
        assert np.all(np.diff(vis) >= 0), (op, vis)
        assert vis[-1] > vis[0], (op, vis)


def test_pattanaik00_shows_the_rods_too_early(short_runs):
    """The miss docs/validation.md reports: a person sees a 1e-3 cd/m^2 neutral target
    only after the break (~17.5 min after 400 000 td). One minute after, neither
    display shows it (the rods' Dowling-Rushton elevation); five minutes after,
    pattanaik00's display already does (the rods' signal: its display's step is a rod
    response far below the one the state-derived experiment needs), durand00's not
    until later. Own values (1.46 and 0.62 JND at 5 min):"""
    k1, k5 = (int(np.nonzero(TIMES == t)[0][0]) for t in (1.0, 5.0))
    assert short_runs["pattanaik00"].de[k1, 2] < D.JND
    assert short_runs["pattanaik00"].de[k5, 2] >= D.JND
    assert short_runs["durand00"].de[k5, 2] < D.JND
    assert short_runs["durand00"].de[-1, 1] >= D.JND       # 3.2e-5 cd/m^2 at 40 min
    assert short_runs["pattanaik00"].de[-1, 1] >= D.JND
