"""Chromatic adaptation (Durand & Dorsey 2000 Eq. 6): tau 5 s, the illuminant priority, rods left alone."""

import math

import numpy as np
import pytest

from ocl_tonemap.models import durand2000 as fx
from ocl_tonemap.effects import EffectSettings
from ocl_tonemap.pipeline import Tonemapper


NO_FX = EffectSettings()  # all effects off


@pytest.mark.parametrize("backend", ["reference", "opencl"])
def test_chromatic_adaptation_tungsten_to_daylight_tau_5s(backend, rt):
    grey = np.full((6, 6, 3), 500.0, np.float32)        # photopic: k = 0, no rod term
    A, D65 = fx.parse_illuminant("A"), fx.parse_illuminant("D65")
    tm = Tonemapper("durand00", backend,
                    effects=EffectSettings(chromatic_adaptation="on"))
    tm.process(grey * A.astype(np.float32), time_s=0.0, illuminant=A)
    g0 = np.array(tm.last.effects["chromatic_adaptation"]["illuminant"])
    np.testing.assert_allclose(g0, A)
    # a tungsten-lit grey is shown grey once adapted (Eq. 6)
    out = tm.last_output[0, 0]
    assert out[0] == pytest.approx(out[1], rel=1e-3) and out[2] == pytest.approx(out[1], rel=1e-3)
    tm.process(grey, time_s=5.0, illuminant=D65)
    g5 = np.array(tm.last.effects["chromatic_adaptation"]["illuminant"])
    frac = (g5 - A) / (D65 - A)
    np.testing.assert_allclose(frac, 1 - math.exp(-1), atol=0.02)
    tm.process(grey, time_s=40.0, illuminant=D65)
    g40 = np.array(tm.last.effects["chromatic_adaptation"]["illuminant"])
    np.testing.assert_allclose(g40, D65, atol=2e-3)

def test_illuminant_priority_and_device_estimate(rt):
    rng = np.random.default_rng(2)
    img = (rng.uniform(0.1, 1, (21, 31, 3)) * 20).astype(np.float32)
    img[5:8, 5:8] = np.array([800, 500, 200], np.float32)      # a warm lamp
    est_ref = fx.illuminant_estimate_reference(img.astype(np.float64))
    for be in ("reference", "opencl"):
        tm = Tonemapper("durand00", be, effects=EffectSettings(chromatic_adaptation="on"))
        tm.process(img)
        info = tm.last.effects["chromatic_adaptation"]
        assert info["source"] == "estimate"
        np.testing.assert_allclose(info["goal"], est_ref, rtol=1e-4)
        assert info["goal"][0] > info["goal"][2]                 # warm
        tm = Tonemapper("durand00", be, effects=EffectSettings(chromatic_adaptation="on"))
        tm.process(img, illuminant=fx.parse_illuminant("F11"))
        assert tm.last.effects["chromatic_adaptation"]["source"] == "adoptedNeutral"
        tm = Tonemapper("durand00", be, effects=EffectSettings(chromatic_adaptation="on",
                                                               illuminant="D50"))
        tm.process(img, illuminant=fx.parse_illuminant("F11"))
        assert tm.last.effects["chromatic_adaptation"]["source"] == "user"

def test_chromatic_adaptation_leaves_rods_alone():
    """Eq. 6 scales the cone signals only: in a scotopic scene the rod term (99%
    of the output) is unchanged although the blue gain for illuminant A is 2.6."""
    img = np.full((4, 4, 3), 1e-4, np.float32)
    a = Tonemapper("durand00", "reference", effects=NO_FX).process(img)
    tm = Tonemapper("durand00", "reference", effects=EffectSettings(
        chromatic_adaptation="on", illuminant="A"))
    b = tm.process(img)
    assert tm.last.effects["chromatic_adaptation"]["gains"][2] > 2.5
    np.testing.assert_allclose(a, b, rtol=0.01)
