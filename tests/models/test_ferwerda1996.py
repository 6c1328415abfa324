"""Ferwerda et al. 1996 threshold-versus-intensity curves: the published values, continuity at the branch points."""

import numpy as np
import pytest

from ocl_tonemap.models import ferwerda1996 as fw


@pytest.mark.parametrize("logL, rod", [(-5.0, -2.86), (-3.94, -2.86),
                                       (-2.0, (0.405 * -2 + 1.6) ** 2.18 - 2.86),
                                       (-1.44, -1.835), (0.0, -0.395), (3.0, 2.605)])
def test_rod_tvi_published_values(logL, rod):
    assert fw.log_threshold_rod(10.0 ** logL) == pytest.approx(rod, abs=1e-9)

@pytest.mark.parametrize("logL, cone", [(-4.0, -0.72), (-2.6, -0.72),
                                        (0.0, 0.65 ** 2.7 - 0.72), (1.9, 0.645),
                                        (3.0, 3.0 - 1.255)])
def test_cone_tvi_published_values(logL, cone):
    # the photopic branch follows the cone adaptation level L_aC (not L_wa)
    assert fw.log_threshold_cone(10.0 ** logL) == pytest.approx(cone, abs=1e-9)

@pytest.mark.parametrize("fn, breaks", [(fw.log_threshold_rod, (-3.94, -1.44)),
                                        (fw.log_threshold_cone, (-2.6, 1.9))])
def test_tvi_continuous_at_branch_points(fn, breaks):
    """Ferwerda's rounded constants leave jumps of at most 0.0123 decades (rods at
    -1.44) and 0.003 (cones at 1.9); elsewhere the curves are smooth and rising."""
    for b in breaks:
        lo, hi = fn(10.0 ** (b - 1e-9)), fn(10.0 ** (b + 1e-9))
        assert abs(hi - lo) < 0.013
    x = np.linspace(-8, 8, 4001)
    y = fn(10.0 ** x)
    steps = np.diff(y)
    assert np.all(np.abs(steps) < 0.02)
    assert np.all(steps > -0.013)       # the only decrease is the published rod jump
