"""The disability veil of a whole field (issue 56): CIE 146's general equation over
every cell's light (``cie146.field_weights``, ``field_veil``), against the glare
function's own integral, a point source, finer cells, and CIE 88's L_seq
(``cie88.l_seq``, the polar diagram reconstructed)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ocl_tonemap.models import cie88, cie146

#: A 1080p frame at 50 degrees, on the planes' 16-pixel cells (0.417 degrees).
SHAPE, DEG = (68, 120), 50.0 / 120


@pytest.mark.parametrize("age", [25.0, 70.0])
def test_a_uniform_field_is_the_glare_functions_integral(age):
    """100 cd/m^2 filling a 50 x 28 degree view veils its centre by 100 x the integral
    of CIE 146 x cos theta over the view outside 1 degree: 4.95 cd/m^2 at 25 years
    (9.62 at 70), the cells within 0.2 % of a fine polar integral; a corner cell gets
    about half."""
    K = cie146.field_weights(SHAPE, DEG, age)
    V = cie146.field_veil(np.full(SHAPE, 100.0), K)
    hw, hh = SHAPE[1] * DEG / 2, SHAPE[0] * DEG / 2
    want = 100.0 * cie146.uniform_field_veil(hw, hh, age)
    assert V[34, 60] == pytest.approx(want, rel=2e-3)
    assert want == pytest.approx(4.95 if age == 25 else 9.62, rel=0.01)
    corner = 100.0 * cie146.uniform_field_veil(hw, hh, age, at=(-hw + DEG / 2, -hh + DEG / 2))
    assert V[0, 0] == pytest.approx(corner, rel=5e-3) and 0.3 < corner / want < 0.6


@pytest.mark.parametrize("age", [25.0, 70.0])
def test_a_point_source_is_cie146s(age):
    """A lamp filling one cell, theta degrees from a cell's centre, veils it by E x
    CIE 146 at theta (E = L x the cell's solid angle): within 5 % at 2-20 degrees (the
    cell's 0.4-degree breadth); nothing from within 1 degree (the fixation field)."""
    K = cie146.field_weights(SHAPE, DEG, age)
    h, w = SHAPE
    E = 1.0 * math.radians(DEG) ** 2
    for d in range(1, 50):
        theta = d * DEG
        got = K[h - 1, w - 1 + d]
        if theta < cie146.EXCLUDE_DEG - DEG / 2:
            assert got == 0.0
        elif 2.0 <= theta <= 20.0:
            want = E * cie146.veil_per_lux(theta, age) * math.cos(math.radians(theta))
            assert got == pytest.approx(want, rel=0.05), theta
    assert K[h - 1, w - 1] == 0.0


def test_finer_cells_change_the_veil_little():
    """A sunlit band across a dark field: its veil on 0.42-degree cells within 2 % of
    that on cells a quarter as wide, outside the band."""
    def veil(n):
        shape = (SHAPE[0] * n, SHAPE[1] * n)
        L = np.full(shape, 0.1)
        L[: 20 * n] = 5000.0                                     # a sky band above
        K = cie146.field_weights(shape, DEG / n, 25.0)
        V = cie146.field_veil(L, K)
        return V.reshape(SHAPE[0], n, SHAPE[1], n).mean(axis=(1, 3))
    coarse, fine = veil(1), veil(4)
    below = np.s_[26:, :]
    np.testing.assert_allclose(coarse[below], fine[below], rtol=0.02)


def test_cie88s_zones_weigh_alike():
    """The reconstructed polar diagram: 12 sectors x 9 rings from 1 degree, each ring
    1.377 x the one inside, so that every zone adds 5.1e-4 x its luminance
    (Stiles-Holladay); a uniform field over all 108 zones gives 108 x 5.1e-4 x L,
    Stiles-Holladay's integral over 1 .. 17.8 degrees."""
    assert cie88.zone_weight() == pytest.approx(5.1e-4, rel=1e-9)
    edges = cie88.ring_radii()
    assert edges[0] == 1.0 and edges[-1] == pytest.approx(17.8, abs=0.05)
    s = 0.05
    n = int(2 * 20 / s)
    L, info = cie88.l_seq(np.full((n, n), 10.0), n / 2 - 0.5, n / 2 - 0.5, s)
    assert info["covered"] == 108
    SH = 10.0 * math.radians(1.0) ** 2 * 2 * math.pi * math.log(edges[-1] / edges[0]) * 10.0
    assert L == pytest.approx(108 * 5.1e-4 * 10.0, rel=1e-9) and L == pytest.approx(SH)


def test_the_whole_field_veil_against_cie88_for_a_bright_upper_field():
    """A portal-like field (sky 8000 cd/m^2 above the horizon, road 200 below, a dark
    mouth in the middle, 40 x 22.5 degrees): the whole-field veil at the mouth
    (CIE 146 at 25 years, everything outside 1 degree) within 1.5 x of CIE 88's L_seq
    of the same picture."""
    h, w, deg = 180, 320, 40.0 / 320
    Y = np.full((h, w), 200.0)
    Y[: h // 2 - 10] = 8000.0                                     # sky
    Y[70:110, 140:180] = 5.0                                     # the mouth
    Lseq, _ = cie88.l_seq(Y, 159.5, 89.5, deg)
    s = 4
    cells = Y.reshape(h // s, s, w // s, s).mean(axis=(1, 3))
    K = cie146.field_weights(cells.shape, deg * s, 25.0)
    V = cie146.field_veil(cells, K)[h // s // 2, w // s // 2]
    assert 1 / 1.5 < V / Lseq < 1.5, (V, Lseq)


def test_nothing_behind_the_eye_and_never_a_negative_weight():
    """A fisheye's field reaches past 90 degrees from a point: light there gives no
    illuminance on the plane the eye faces (cos theta < 0 would subtract)."""
    K = cie146.field_weights((30, 30), 6.0, 25.0)              # 180 degrees across
    assert K.min() >= 0.0
    h, w = 30, 30
    far = np.hypot(*np.meshgrid(np.arange(-(h - 1), h) * 6.0, np.arange(-(w - 1), w) * 6.0,
                                indexing="ij")) > 95.0          # (a cell 6 degrees wide)
    assert np.all(K[far] == 0.0) and K[~far].max() > 0.0
