"""Increment thresholds (issue 34, experiment 3): the world increment that is one just
noticeable difference on the display over Ferwerda et al. 1996's threshold
(``benchmarks/lib/human/tvi.py``, through the public API)."""

import numpy as np
import pytest

from benchmarks.lib.human import tvi


@pytest.fixture(scope="module")
def durand():
    return tvi.run_all(operators=("durand00",))["durand00"]


def test_durand00_maps_a_world_threshold_to_a_display_threshold(durand):
    """What Durand & Dorsey's operator is built to do (Sec. 3.1): with the display
    threshold as the paper takes it (Ferwerda's at the display observer's adaptation),
    one world threshold is one display threshold, within [0.5, 2], 1e-4 to 1e4 cd/m^2."""
    ratios = [r[4] for r in durand]
    assert len(ratios) == 9
    assert all(0.5 <= r <= 2.0 for r in ratios), ratios


def test_durand00_against_delta_e_itp(durand):
    """With the display's just noticeable difference as Delta E ITP = 1 (BT.2124) the
    ratio misses [0.5, 2]: Ferwerda's thresholds (Blackwell's small brief targets) are
    ~4x a BT.2124 step at photopic levels, and at night the display shows the scene
    brighter than the scene, where a step is easier to see (docs/validation.md). The
    model's own values (so that a change shows):"""
    got = np.array([r[3] for r in durand])
    want = np.array([0.009, 0.031, 0.059, 0.058, 0.049, 0.149, 0.268, 0.267, 0.266])
    np.testing.assert_allclose(got, want, rtol=0.15, atol=0.002)


def test_world_threshold_is_ferwerdas():
    from ocl_tonemap.models.ferwerda1996 import threshold_cone
    # photopic: the cone branch, log L - 1.255
    assert tvi.world_threshold(1e3) == pytest.approx(float(threshold_cone(1e3)))
    assert tvi.world_threshold(1e3) == pytest.approx(1e3 / 10 ** 1.255, rel=1e-9)
    # scotopic: the rods see less than the cones' flat branch would allow
    assert tvi.world_threshold(1e-4) < float(threshold_cone(1e-4))
