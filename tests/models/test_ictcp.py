"""ICtCp and Delta E ITP against colour-science (the benchmarks' measure)."""

import warnings

import numpy as np

from ocl_tonemap.models.ictcp import delta_e_itp, rgb709_to_ictcp


def _colour():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    return colour


def test_ictcp_and_delta_e_equal_colour_science():
    col = _colour()
    rng = np.random.default_rng(0)
    a = rng.uniform(0, 1, (200, 3)) * 10.0 ** rng.uniform(-4, 4, (200, 1))
    b = a * rng.uniform(0.9, 1.1, (200, 3))
    M = col.matrix_RGB_to_RGB(col.RGB_COLOURSPACES["ITU-R BT.709"],
                              col.RGB_COLOURSPACES["ITU-R BT.2020"])
    ia, ib = (col.RGB_to_ICtCp(x @ M.T) for x in (a, b))
    np.testing.assert_allclose(rgb709_to_ictcp(a), ia, atol=1e-6)
    np.testing.assert_allclose(delta_e_itp(rgb709_to_ictcp(a), rgb709_to_ictcp(b)),
                               col.delta_E(ia, ib, method="ITP"), rtol=1e-5, atol=1e-5)


def test_negative_and_huge_light_stay_finite():
    x = np.array([[-1.0, 0.0, 1e9], [np.finfo(np.float64).tiny, 0, 0]])
    assert np.all(np.isfinite(rgb709_to_ictcp(x)))
