"""A half-float EXR goes to the device as it is stored (issue 47): read as float16,
uploaded as half the bytes and made float32 there (every half is a float32), so the
frames are those of the same pixels stored as float32, with the defaults, with an
input colour conversion, and with an automatic calibration."""

from __future__ import annotations

import os

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.job.options import JobOptions
from ocl_tonemap.job.run import run_job
from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.io.sample import write_tunnel_sequence

pytestmark = pytest.mark.requires_opencl


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """The tunnel drive as half EXR (as the sample writes it) and the same values as
    float32 EXR."""
    d = tmp_path_factory.mktemp("half")
    pattern, frames = write_tunnel_sequence(str(d / "half"), 96, 54, 30.0, 0.2)
    os.makedirs(d / "float")
    fpat = str(d / "float" / os.path.basename(pattern))
    for f in frames:
        inp = oiio.ImageInput.open(frame_path(pattern, f))
        spec = inp.spec()                       # (its metadata: calibration, time)
        assert str(spec.format) == "half"
        pix = inp.read_image(oiio.FLOAT)
        inp.close()
        spec.set_format(oiio.FLOAT)
        out = oiio.ImageOutput.create(frame_path(fpat, f))
        out.open(frame_path(fpat, f), spec)
        out.write_image(pix)
        out.close()
    return pattern, fpat, frames


@pytest.mark.parametrize("op,extra", [("pattanaik00", {}), ("ledda04", {}),
                                      ("kirk11", {}),
                                      ("durand00", {"iscolorspace": "ACEScg"}),
                                      ("pattanaik00", {"luminance_scale": "auto:dusk"})])
def test_half_frames_equal_their_float_copies(pair, tmp_path, op, extra):
    half, flt, frames = pair
    res = {}
    for name, pat in (("half", half), ("float", flt)):
        out = str(tmp_path / name / "o.####.exr")
        os.makedirs(os.path.dirname(out))
        res[name] = run_job(JobOptions(pat, out, operator=op, checkpoint=False,
                                       out_bits="float", **extra))
        res[name + "_out"] = out
    for f in frames:
        a = oiio.ImageBuf(frame_path(res["half_out"], f)).get_pixels(oiio.FLOAT)
        b = oiio.ImageBuf(frame_path(res["float_out"], f)).get_pixels(oiio.FLOAT)
        np.testing.assert_array_equal(a, b)
    frame_bytes = 96 * 54 * 12
    if not extra:                      # no conversion on the host: up as stored
        assert res["half"].infos[-1].transfers["up_bytes"] < \
            res["float"].infos[-1].transfers["up_bytes"] - frame_bytes / 3
