"""Acuity against luminance (issue 34, experiment 2): sine gratings through the command
line with ``--acuity on`` and ``off`` (``benchmarks/lib/human/acuity.py``); the measured
cut-off (transfer 10^-0.395) against Shlaer 1937's table."""

import numpy as np
import pytest

from benchmarks.lib.human import acuity


@pytest.mark.parametrize("La", [1e-3, 1e-2, 1e-1, 1.0, 10.0])
def test_cutoff_within_a_quarter_of_shlaer(La):
    m = acuity.cutoff(acuity.transfer(La))
    assert m is not None
    assert 1 / 1.25 <= m / float(acuity.shlaer(La)) <= 1.25


def test_the_transfer_falls_with_frequency():
    tr = acuity.transfer(0.1)
    ok = np.isfinite(tr)
    assert tr[ok][0] > 0.95 and tr[ok][-1] < 0.05
    assert np.all(np.diff(tr[ok]) < 0.02)


def test_no_blur_where_the_display_sampling_limits():
    """60 degrees over 256 px (4.3 px a degree, Nyquist 2.1 cycles/degree): the eye
    resolves more than the image holds even at 1e-3 cd/m^2 (3.6 cycles/degree), so the
    output is the same with the effect on as off."""
    for La in (1e-3, 100.0):
        tr = acuity.transfer(La, fov=60.0, width=256)
        ok = np.isfinite(tr)
        assert ok.any()
        np.testing.assert_allclose(tr[ok], 1.0, atol=1e-6)
