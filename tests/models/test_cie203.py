"""The ocular media by age (models/cie203.py; issue 48's lens): CIE 203:2012's form of
van de Kraats & van Norren 2007, held against the paper's own form and against
Pokorny, Smith & Lutze 1987's independent lens data; and what the run does with it
(the light behind an older eye's media)."""

import numpy as np
import pytest

from ocl_tonemap.models import cie203

LAM = np.arange(380.0, 781.0, 5.0)

# Pokorny, Smith & Lutze 1987, "Aging of the human lens", Applied Optics 26(8),
# 1437-1440, Table I (400-650 nm, 10 nm): the lens density's two components;
# D(A) = TL1 (1 + 0.02 (A - 32)) + TL2 for 20 < A <= 60,
#        TL1 (1.56 + 0.0667 (A - 60)) + TL2 above.
PSL_NM = np.arange(400.0, 651.0, 10.0)
PSL_TL1 = np.array([0.600, 0.510, 0.433, 0.377, 0.327, 0.295, 0.267, 0.233, 0.207, 0.187,
                    0.167, 0.147, 0.133, 0.120, 0.107, 0.093, 0.080, 0.067, 0.053, 0.040,
                    0.033, 0.027, 0.020, 0.013, 0.007, 0.0])
PSL_TL2 = np.array([1.000, 0.583, 0.300, 0.116, 0.033, 0.005] + [0.0] * 20)


def _psl(age):
    f = 1.0 + 0.02 * (age - 32.0) if age <= 60 else 1.56 + 0.0667 * (age - 60.0)
    return PSL_TL1 * f + PSL_TL2


def test_every_public_form_gives_the_same_relative_transmittance():
    """The forms differ only in their terms without age (the paper's 0.446 / 0.998 /
    0.111, CIE 203's erratum 0.15 / 1.05 / 0.06): their absolute densities differ,
    one age over another does not."""
    for form in ("paper", "paper-large-field"):
        assert not np.allclose(cie203.optical_density(LAM, 70, form),
                               cie203.optical_density(LAM, 70, "cie203"))
        for A in (1, 40, 70, 100):
            rel = 10.0 ** -(cie203.optical_density(LAM, A, form)
                            - cie203.optical_density(LAM, 25, form))
            np.testing.assert_allclose(rel, cie203.relative_transmittance(LAM, A), rtol=1e-12)


def test_the_media_darken_and_yellow_with_age():
    """Density rises with age most in the blue; beyond ~600 nm little changes; a
    child's media pass more than the reference's. At 70 the cones get 0.84 and the
    rods 0.66 of a 25-year-old's light from a white (rods lose more: V' is bluer)."""
    t70 = cie203.relative_transmittance(LAM, 70)
    assert np.all(t70 < 1.0) and t70[LAM == 420.0] < 0.35 and t70[LAM == 650.0] > 0.93
    assert np.all(np.diff(t70[(LAM >= 420) & (LAM <= 700)]) > 0)
    assert np.all(cie203.relative_transmittance(LAM, 5) > 1.0)
    prev = (2.0, 2.0)
    for A in (5, 25, 40, 55, 70, 85, 100):
        p, s = cie203.media_factors(A)
        assert p < prev[0] and s < prev[1] and (s < p if A > 25 else s >= p)
        prev = (p, s)
    assert cie203.media_factors(25) == (1.0, 1.0)
    assert cie203.media_factors(70) == pytest.approx((0.838, 0.660), abs=2e-3)


@pytest.mark.parametrize("age,tol", [(30, 0.03), (40, 0.03), (50, 0.03), (60, 0.03),
                                     (70, 0.13)])
def test_held_against_pokorny_smith_lutze_1987(age, tol):
    """An independent fit to lens data (PSL 1987, the lens alone): the light a white
    gives the cones and the rods at ``age`` over a 25-year-old's agrees with CIE 203's
    within 2.5 % from 30 to 60 years; at 70 PSL's second segment (0.0667 a year
    beyond 60) takes 10 % (cones) and 12.5 % (rods) more, and beyond that the two
    fits part further (80: 17 %, 26 %)."""
    t_psl = 10.0 ** -(_psl(age) - _psl(25))
    S, V, Vs = (np.interp(PSL_NM, cie203.WL, x) for x in cie203._spectra())
    p_psl = (S * V * t_psl).sum() / (S * V).sum()
    s_psl = (S * Vs * t_psl).sum() / (S * Vs).sum()
    p, s = cie203.media_factors(age)
    assert p == pytest.approx(p_psl, rel=tol) and s == pytest.approx(s_psl, rel=tol)


def test_the_run_gives_the_operator_the_light_behind_the_media():
    """An older observer's frame is the younger one's frame of the light the media pass
    (flare off: the flare has an age of its own), to float32 rounding, on the
    reference backend; the default observer (25) and Spencer's ageless one get the
    scene's light as it is."""
    from ocl_tonemap.pipeline import Tonemapper
    from ocl_tonemap.io.sample import render_frame
    rgb = render_frame(3.0, 64, 36, 8.0, ss=1).astype(np.float32)
    for op in ("pattanaik00", "durand00"):
        old = Tonemapper(op, backend="reference", age=70, flare="off")
        young = Tonemapper(op, backend="reference", flare="off")
        assert young.media_gain == 1.0 and old.media_gain == pytest.approx(0.838, abs=2e-3)
        assert Tonemapper(op, backend="reference", age="spencer").media_gain == 1.0
        for night in (1e-3, 1.0):
            a = old.process(rgb, luminance_scale=night, dt=1.0)
            b = young.process(rgb, luminance_scale=night * old.media_gain, dt=1.0)
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)
        # a pre-adaptation is the light behind the media too, at the start and at a cut
        old = Tonemapper(op, backend="reference", age=70, flare="off", preadapt=(100.0, None))
        g = old.media_gain
        young = Tonemapper(op, backend="reference", flare="off", preadapt=(100.0 * g, None))
        for cut in (None, (3.0, 2.0)):
            if cut:
                old.reset_adaptation(cut)
                young.reset_adaptation((cut[0] * g, cut[1]))
            a = old.process(rgb, luminance_scale=0.1, dt=0.5)
            b = young.process(rgb, luminance_scale=0.1 * g, dt=0.5)
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)
        # an older eye sees the night's frame darker than a young one
        c = Tonemapper(op, backend="reference", flare="off").process(rgb, luminance_scale=1e-3)
        d = Tonemapper(op, backend="reference", age=70, flare="off").process(
            rgb, luminance_scale=1e-3)
        assert d.mean() < c.mean()
