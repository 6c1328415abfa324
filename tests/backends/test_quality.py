"""--quality tiers: each sets the defaults of every speed/accuracy knob, knobs given
explicitly win, and the tiers order by error against ``reference``."""

import logging

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.backends.quality import QUALITY_NAMES, QUALITY_TIERS, quality_tier
from ocl_tonemap.cli.table import main
from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.job.options import JobOptions

from conftest import hdr_image


def test_tier_names_and_default():
    assert QUALITY_NAMES == ("draft", "balanced", "reference")
    assert quality_tier(None).name == "balanced"
    with pytest.raises(ValueError, match="--quality must be one of draft, balanced, reference"):
        quality_tier("best")


@pytest.mark.requires_opencl
@pytest.mark.parametrize("op", ["pattanaik00", "durand00", "ledda04", "kirk11"])
def test_tier_options_apply_only_where_declared(op, caplog):
    """Every operator takes every tier without a misplaced-option warning, and gets the
    tier's values of the knobs it declares."""
    declared = None
    for name in QUALITY_NAMES:
        with caplog.at_level(logging.WARNING, logger="ocl_tonemap"):
            caplog.clear()
            tm = Tonemapper(op, quality=name, backend="opencl" if name == "reference" else None)
        assert not [r for r in caplog.records if "ignored" in r.getMessage()], caplog.text
        declared = {o.name for o in type(tm.op).options}
        for k, v in QUALITY_TIERS[name].operator_options:
            if k in declared:
                assert tm.options[k] == v, (op, name, k)
        assert tm.quality == name
    assert declared


@pytest.mark.requires_opencl
def test_tier_backend_and_effects():
    assert Tonemapper("pattanaik00", quality="reference").backend.name == "reference"
    assert Tonemapper("pattanaik00", quality="draft").backend.name == "opencl"
    tm = Tonemapper("durand00", quality="reference", backend="opencl")   # explicit wins
    assert tm.backend.name == "opencl" and tm.options["lut"] == 0
    assert "lut" not in Tonemapper("durand00", quality="draft").options   # measured: no gain
    assert Tonemapper("durand00", quality="draft", options={"lut": 1024}).options["lut"] == 1024
    assert Tonemapper("ledda04", quality="draft").effects.s.flare_per_octave == 1
    assert Tonemapper("ledda04", quality="reference").effects.s.flare_method == "exact"
    led = Tonemapper("ledda04", quality="draft", options={"bilateral_sampling": "2"})
    assert led.options["bilateral_sampling"] == (2.0,) and led.options["bilateral"] == "fast"


def test_job_options_resolve_the_tier():
    o = JobOptions(input="a.exr", output="b.png", quality="reference")
    assert (o.backend, o.display_encode, o.quality) == ("reference", "ocio", "reference")
    o = JobOptions(input="a.exr", output="b.png", quality="draft", display_encode="ocio")
    assert (o.backend, o.display_encode) == ("opencl", "ocio")
    o = JobOptions(input="a.exr", output="b.png")
    assert (o.backend, o.display_encode, o.quality) == ("opencl", "auto", "balanced")


def test_tiers_order_by_error_against_reference():
    """ledda04 on one frame: draft's error against reference is at least balanced's,
    and both are small in display code values."""
    img = hdr_image(48, 64, seed=3)
    img[20:28, 30:40] *= 300.0                   # a hard edge the bilateral must keep
    out = {q: Tonemapper("ledda04", quality=q).process(img, 0.0)
           for q in ("draft", "balanced", "reference")}
    err = {q: float(np.abs(out[q] - out["reference"]).max()) for q in ("draft", "balanced")}
    assert all(np.isfinite(o).all() for o in out.values())
    assert err["balanced"] <= err["draft"] + 1e-6
    assert err["balanced"] < 0.02 and err["draft"] < 0.1


@pytest.mark.requires_opencl
def test_cli_quality_end_to_end(sample_dir, tmp_path):
    pattern, frames = sample_dir
    outs = {}
    for q in ("draft", "reference"):
        out = str(tmp_path / f"{q}.####.png")
        assert main(["run", pattern, out, "--operator", "ledda04", "--quality", q, "-q"]) == 0
        b = oiio.ImageBuf(frame_path(out, frames[-1]))
        assert b.spec().getattribute("ocltm:quality") == q
        assert b.spec().getattribute("ocltm:backend") == ("reference" if q == "reference"
                                                          else "opencl")
        outs[q] = b.get_pixels(oiio.FLOAT)
    # the same picture within a few 8-bit codes
    assert np.abs(outs["draft"] - outs["reference"]).mean() < 3 / 255


def test_cli_bad_quality_is_a_usage_error(sample_dir, tmp_path, capsys):
    pattern, _ = sample_dir
    with pytest.raises(SystemExit) as e:
        main(["run", pattern, str(tmp_path / "o.####.png"), "--quality", "best"])
    assert e.value.code == 2
    assert "--quality" in capsys.readouterr().err
