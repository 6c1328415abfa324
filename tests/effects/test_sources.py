"""Glare only from light sources (Durand & Dorsey 2000, Sec. 6.2): a pixel is a source
where it passes the paper's test (7 x the adaptation level) and is beyond what the
display shows an observer adapted to the frame (models/spencer1995.py source_limit);
with the defaults, as a user runs them, through the command line and real files."""

import json

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.cli.table import main
from ocl_tonemap.models import spencer1995 as fl
from ocl_tonemap.models.display import display_for
from ocl_tonemap.operators import get_operator
from ocl_tonemap.operators.base import white_luminance

OPERATORS = ("pattanaik00", "ledda04", "durand00", "kirk11")


def _exr(path, pix):
    h, w = pix.shape[:2]
    spec = oiio.ImageSpec(w, h, 3, oiio.FLOAT)
    spec.attribute("whiteLuminance", 1.0)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, 3), np.ascontiguousarray(pix, np.float32))
    assert buf.write(str(path))
    return str(path)


def _run(tmp_path, src, op, name):
    out = tmp_path / f"{name}_{op}.png"
    assert main(["run", src, str(out), "--operator", op, "-q", "--no-checkpoint"]) == 0
    buf = oiio.ImageBuf(str(out))
    return buf.get_pixels(oiio.UINT8), json.loads(buf.spec().getattribute("ocltm:effects"))


@pytest.mark.requires_opencl
@pytest.mark.parametrize("op", OPERATORS)
@pytest.mark.parametrize("size", [(8, 8), (180, 320)])
def test_black_stays_black_beside_a_white_wall(tmp_path, op, size):
    """Left half 100 cd/m^2 (what an sRGB display itself shows as white), right half
    exactly 0: the black half is at most 1/255 with the defaults (it was 26/255: the
    zeros metered as 1e-6 put the eye at 0.01 cd/m^2 and made the wall a source)."""
    h, w = size
    pix = np.zeros((h, w, 3), np.float32)
    pix[:, : w // 2] = 100.0
    out, eff = _run(tmp_path, _exr(tmp_path / "wall.exr", pix), op, "wall")
    assert out[:, w // 2:].max() <= 1, (op, out[:, w // 2:].max(), eff.get("flare"))
    assert out[:, : w // 2].min() > 50                     # the wall is shown, not black
    assert not eff.get("flare", {}).get("ran", False)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("op", OPERATORS)
def test_lamps_of_a_night_street_keep_their_glare(tmp_path, op):
    """A dark street (0.05-0.5 cd/m^2) with three lamps of 2e4 cd/m^2 and a letterbox:
    the flare runs with the defaults, every lamp is a source, and the veil lifts the
    street beside each lamp above the same street without the flare."""
    rng = np.random.default_rng(0)
    h, w = 120, 200
    pix = (10.0 ** rng.uniform(-1.3, -0.3, (h, w, 1)) * [1.0, 0.95, 0.85]).astype(np.float32)
    lamps = [(40, 40), (40, 100), (40, 160)]
    for y, x in lamps:
        pix[y - 1:y + 2, x - 1:x + 2] = [2e4, 1.6e4, 0.9e4]
    pix[:12] = 0.0
    pix[-12:] = 0.0                                          # letterbox bars
    src = _exr(tmp_path / "street.exr", pix)
    out, eff = _run(tmp_path, src, op, "street")
    assert eff["flare"]["ran"] and eff["flare"]["sources"] >= 9 * len(lamps), eff["flare"]
    off = tmp_path / f"off_{op}.png"
    assert main(["run", src, str(off), "--operator", op, "-q", "--no-checkpoint",
                 "--flare", "off"]) == 0
    plain = oiio.ImageBuf(str(off)).get_pixels(oiio.UINT8).astype(int)
    for y, x in lamps:                                       # beside the lamp: the veil
        ring = (slice(y - 8, y + 9), slice(x + 5, x + 9))
        assert out[ring].astype(int).mean() > plain[ring].mean() + 3, (op, y, x)


def test_source_limit_is_the_paper_test_and_the_display():
    assert fl.source_limit(2.0) == 14.0
    assert fl.source_limit(2.0, shown=30.0) == 30.0
    assert fl.source_limit(2.0, shown=5.0) == 14.0
    assert fl.source_limit(2.0, shown=np.inf) == np.inf


def test_white_luminance_finds_where_the_map_reaches_white():
    """A linear map of slope 1/50 reaches white 1.0 at 50 cd/m^2 (log-interpolated on
    the grid: within 0.1%); a map that never reaches it: inf; one already beyond it
    at ``lo``: ``lo``."""
    lin = lambda L: np.repeat((L / 50.0)[:, None], 3, axis=1)       # noqa: E731
    assert white_luminance(lin, 1.0) == pytest.approx(50.0, rel=1e-3)
    assert white_luminance(lin, 1.0, lo=80.0) == 80.0
    assert white_luminance(lambda L: np.zeros((len(L), 3)), 1.0) == np.inf


@pytest.mark.parametrize("op", ["pattanaik00", "durand00", "ledda04"])
def test_each_operator_shows_a_uniform_field_below_white(op):
    """At steady state a uniform field at the adaptation level is shown below white
    (white_luminance_at > G) and white is reached within 1e4 x G, at every level
    from night to daylight."""
    o = get_operator(op)({}, display_for("sRGB - Display"))
    for G in (1e-3, 0.1, 10.0, 1e3, 1e5):
        W = o.white_luminance_at(0.7 * G, G)
        assert G < W < 1e4 * G, (op, G, W)
