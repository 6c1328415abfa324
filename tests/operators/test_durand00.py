"""The durand00 operator: OpenCL against the float64 reference, its LUT, the extremes."""

import numpy as np
import pytest

from conftest import hdr_image
from ocl_tonemap.models import durand2000 as dd
from ocl_tonemap.effects import EffectSettings
from ocl_tonemap.pipeline import Tonemapper


NO_FX = EffectSettings()  # all effects off


@pytest.mark.parametrize("backend", ["reference", "opencl"])
def test_durand00_opencl_matches_reference(backend, rt):
    img = hdr_image(33, 47, seed=3, lo=-5, hi=6)
    ref = Tonemapper("durand00", "reference", effects=NO_FX).process(img)
    out = Tonemapper("durand00", backend, effects=NO_FX, max_band_pixels=47 * 10).process(img)
    np.testing.assert_allclose(out, ref, rtol=2e-6, atol=1e-7)

def test_lut_error_is_within_half_an_entry(rt):
    # the tables' own error: without the highlight shoulder, which mixes channels
    img = hdr_image(40, 60, seed=5, lo=-3, hi=3)
    direct = Tonemapper("durand00", "reference", effects=NO_FX,
                        options={"mode": "paper"}).process(img)
    for n in (500, 2000, 8000):
        half = 10 ** (0.5 * dd.LUT_DECADES / (n - 1)) - 1
        for be in ("reference", "opencl"):
            out = Tonemapper("durand00", be, effects=NO_FX,
                             options={"lut": n, "mode": "paper"}).process(img)
            ok = direct > 1e-6
            rel = np.abs(out[ok] - direct[ok]) / direct[ok]
            assert rel.max() <= half * 1.0001 + 2e-6, (n, be)

@pytest.mark.parametrize("backend", ["reference", "opencl"])
def test_extremes_never_nan(backend, rt):
    img = np.array([[[np.nan, 1, 1], [np.inf, -np.inf, 1], [-5, 1e-42, 1e8]],
                    [[0, 0, 0], [1e-6, 1e-6, 1e-6], [3e38, 3e38, 3e38]]], np.float32)
    fxs = EffectSettings.for_operator("durand00", chromatic_adaptation="on", flare="on",
                                      acuity="on")
    tm = Tonemapper("durand00", backend, effects=fxs)
    for t in (0.0, 0.001, 3600.0 * 5):
        out = tm.process(img, time_s=t)
        assert np.isfinite(out).all() and out.min() >= 0
    assert tm.last.repairs.total > 0
    one = Tonemapper("durand00", backend, effects=fxs).process(np.full((1, 1, 3), 5.0, np.float32))
    assert one.shape == (1, 1, 3) and np.isfinite(one).all()
