"""The observer's clock: one rule for ``dt`` and ``time_s`` on every entry (RGB,
spectral, in bands). A fresh observer's first frame needs neither; every later frame
needs one of them; time never goes backwards; the state advances by the step."""

from __future__ import annotations

import numpy as np
import pytest

from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.io.sample import spectral_patches


def _spectral():
    lam, spectra, _ = spectral_patches("D65", 50.0)
    return lam, np.repeat(np.repeat(spectra.reshape(4, 6, -1), 2, 0), 2, 1).astype(np.float32)


def test_a_spectral_frame_without_dt_is_refused_after_the_first():
    """Issue 46: a spectral frame without ``dt`` used to advance 0 s in silence."""
    lam, img = _spectral()
    tm = Tonemapper("kirk11", "reference", model="none")
    tm.process(img, wavelengths=lam)                       # fresh: needs neither
    with pytest.raises(ValueError, match="give dt"):
        tm.process(img, wavelengths=lam)
    tm.process(img * 0.001, dt=2.0, wavelengths=lam)       # a step down, 2 s later
    assert tm.last.time_s == 2.0 and tm.last.dt == 2.0
    tm.process(img * 0.001, time_s=5.0, wavelengths=lam)
    assert tm.last.time_s == 5.0 and tm.last.dt == 3.0
    with pytest.raises(ValueError, match="backwards"):
        tm.process(img, time_s=4.0, wavelengths=lam)


def test_a_spectral_step_is_the_sum_of_its_parts():
    """After a 100x step down, the rods' adaptation A_rod has moved part of the way
    in 0.5 s, further in 1 s, and two steps of 0.5 s equal one of 1 s (the clock's
    steps reach the state as they are, spectral frames included; to 1e-7: the shared
    pigment course's rods, bleached and regenerated at once, have no closed form, and
    its integrator's one step and two halves agree to ~2e-9)."""
    lam, img = _spectral()

    def after(*steps):
        tm = Tonemapper("kirk11", "reference", model="none")
        tm.process(img, wavelengths=lam)
        for dt in steps:
            tm.process(img * 0.01, dt=dt, wavelengths=lam)
        return tm.scalar_state().values["A_rod"]

    start, half, whole, split = after(), after(0.5), after(1.0), after(0.5, 0.5)
    goal = start * 0.01
    assert start > half > whole > goal
    assert split == pytest.approx(whole, rel=1e-7)
