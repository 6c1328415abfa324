"""kirk11 at night: scotopic colour is a desaturated blue-green (never magenta), the
shifted cone signal is displayable, and darker scenes are shown darker.
Fails on ab46a99 (saturated teal, 100% NNLS fallback, night as bright as day)."""

import numpy as np
import pytest

from ocl_tonemap.models import kirk2011 as ko
from ocl_tonemap.models import lmsr
from ocl_tonemap.models.photometry import RGB709_TO_XYZ, Y_WEIGHTS
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.io.sample import spectral_patches

LEAF = np.array([0.05, 0.12, 0.03])


def lab(rgb):
    """CIELAB (L*, C*, h in degrees) of linear Rec.709 relative to white (1, 1, 1)."""
    xyz = np.asarray(rgb, np.float64) @ RGB709_TO_XYZ.T
    t = xyz / (RGB709_TO_XYZ @ np.ones(3))
    f = np.where(t > (6 / 29) ** 3, np.cbrt(np.maximum(t, 0)), t / (3 * (6 / 29) ** 2) + 4 / 29)
    a, b = 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])
    return 116 * f[..., 1] - 16, np.hypot(a, b), np.degrees(np.arctan2(b, a)) % 360


def _scene(level):
    """Left half a leaf, right half a neutral grey twice as bright, textured; log-average
    luminance ``level`` cd/m^2."""
    rng = np.random.default_rng(1)
    img = np.empty((32, 48, 3))
    img[:, :24] = LEAF / (LEAF @ Y_WEIGHTS)
    img[:, 24:] = 2.0
    img *= 10 ** rng.uniform(-0.3, 0.3, (32, 48, 1))
    y = img @ Y_WEIGHTS
    return (img * level / np.exp(np.log(y).mean())).astype(np.float32)


def _out(level, backend="reference"):
    return Tonemapper("kirk11", backend, model="none").process(_scene(level)).astype(np.float64)


def test_luminance_row_of_the_shift_is_achromatic():
    """Eq. 12's luminance term (rods add light) must not change the colour of a neutral:
    the working white keeps L/(L+M) and S/(L+M) within 5% at full scotopic adaptation."""
    q = lmsr.rgb_to_lmsr(np.full(3, 1e-3))
    qh, w = ko.purkinje_shift(q, ko.model_scale(), ko.KAPPA1, ko.KAPPA2, (0.0, 0.0, 5.0))
    assert w > 1                                                  # fully scotopic
    for a, b in ((qh, q),):
        assert a[0] / (a[0] + a[1]) == pytest.approx(b[0] / (b[0] + b[1]), rel=0.05)
        assert a[2] / (a[0] + a[1]) == pytest.approx(b[2] / (b[0] + b[1]), rel=0.05)


@pytest.mark.parametrize("kappa", ["adaptive", "full"])
def test_unconstrained_solve_holds_in_most_cases(kappa):
    """Sec. 3.2: "In most cases, the result of the unconstrained problem satisfies the
    constraint" -- for the ColorChecker under D65 at every level 1e-3..1e4 cd/m^2, at
    most one patch (the cyan, outside sRGB in daylight) needs the fallback."""
    M = lmsr.fitted()["H"][:3]
    for e in (1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0, 1e4):
        lam, spectra, _ = spectral_patches("D65", e)
        q = lmsr.spectral_to_lmsr(lam, spectra)
        k1, k2, gain = ko.kappas(ko.KirkSettings(kappa=kappa), ko.logmean(q[:, 3]))
        qh, _ = ko.purkinje_shift(q, ko.model_scale(), k1, k2, rod_gain=gain)
        p = qh @ np.linalg.inv(M).T
        assert np.sum(np.any(p < 0, axis=1)) <= 1, e


def test_leaf_goes_blue_green_and_desaturates_never_magenta():
    hue, chroma = {}, {}
    for level in (1e-3, 1e-2, 0.1, 1.0, 100.0, 1e3):
        out = _out(level)
        _, C, h = lab((lambda m: m / (m @ Y_WEIGHTS))(out[:, :24].mean(axis=(0, 1))))
        hue[level], chroma[level] = float(h), float(C)
        assert not (h >= 270 or h < 60), (level, h)               # no magenta/red/orange
    assert 120 <= hue[1e-2] <= 240 and 120 <= hue[1e-3] <= 240
    assert chroma[1e-2] < 0.6 * chroma[100.0]                     # desaturated
    assert chroma[1e-3] <= chroma[1e-2] * 1.05 and chroma[1e-2] < chroma[1.0] < chroma[100.0]


def test_neutral_tint_at_night_is_a_pale_blue_green():
    for level in (1e-3, 1e-2):
        m = _out(level)[:, 24:].mean(axis=(0, 1))
        _, C, h = lab(m / (m @ Y_WEIGHTS))
        assert 150 <= h <= 260 and 3 < C < 35, (level, h, C)   # ab46a99: C* 55 at 1e-3 (R = 0)


def test_night_is_shown_darker_than_day():
    means = {lv: float((_out(lv) @ Y_WEIGHTS).mean()) for lv in (1e-2, 0.1, 1.0, 100.0)}
    assert means[1e-2] < means[0.1] < means[1.0] < means[100.0]
    assert means[0.1] < 0.5 * means[100.0] and means[1e-2] < 0.25 * means[100.0]


@pytest.mark.parametrize("level", [1e-3, 0.1, 10.0])
def test_device_matches_reference_at_night(level, rt):
    a = Tonemapper("kirk11", "reference", model="none").process(_scene(level))
    b = Tonemapper("kirk11", "opencl", options={"bilateral": "exact"}, model="none").process(_scene(level))
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-5)
