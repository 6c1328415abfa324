"""A Radiance header value that is ignored is said in one warning line (issue 58,
part 7): an EXPOSURE of -2, 0 or nan, a COLORCORR of 0, a garbage PRIMARIES line;
valid values are read as before, and Photoshop's all-zero PRIMARIES placeholder stays
silent."""

import logging
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.io import radiance


@pytest.mark.parametrize("line, used", [
    ("EXPOSURE=-2", "exposure"), ("EXPOSURE=0", "exposure"), ("EXPOSURE=nan", "exposure"),
    ("EXPOSURE=inf", "exposure"), ("COLORCORR= 0 0 0", "colorcorr"),
    ("COLORCORR= 1 1", "colorcorr"), ("PRIMARIES= garbage", "primaries"),
    ("PRIMARIES= 0.64 0.33 0.3 0.6 0.15 0.06 0.3127", "primaries"),
    ("PRIMARIES= 0.64 0.33 0.3 0.6 0.15 -0.06 0.3127 0.329", "primaries"),
    ("PRIMARIES= 0.1 0.1 0.2 0.2 0.3 0.3 0.3127 0.329", "primaries"),   # no triangle
])
def test_an_ignored_value_is_recorded(line, used):
    h = radiance.parse_header(["#?RADIANCE", line, "FORMAT=32-bit_rle_rgbe"])
    assert len(h.ignored) == 1 and line.split("=")[0] in h.ignored[0]
    assert h.exposure == 1.0 and h.colorcorr == (1.0, 1.0, 1.0) and h.primaries is None


def test_valid_values_are_read_as_before():
    h = radiance.parse_header(["EXPOSURE=2", "EXPOSURE= 0.5e1", "COLORCORR= 2 1 0.5",
                               "PRIMARIES= 0.64 0.33 0.3 0.6 0.15 0.06 0.3127 0.329",
                               "PRIMARIES=0 0 0 0 0 0 0 0"])
    assert h.exposure == 10.0 and h.colorcorr == (2.0, 1.0, 0.5)
    assert h.primaries == (0.64, 0.33, 0.3, 0.6, 0.15, 0.06, 0.3127, 0.329)
    assert h.ignored == []
    z = radiance.parse_header(["PRIMARIES=0 0 0 0 0 0 0 0"])       # Photoshop's placeholder
    assert z.primaries is None and z.ignored == []


def _picture(path, *lines):
    img = np.full((6, 8, 3), 0.5, np.float32)
    tmp = str(path) + ".base.hdr"
    o = oiio.ImageOutput.create(tmp)
    assert o.open(tmp, oiio.ImageSpec(8, 6, 3, oiio.FLOAT))
    o.write_image(img)
    o.close()
    first, rest = open(tmp, "rb").read().split(b"\n", 1)
    path.write_bytes(first + b"\n" + b"".join(x.encode() + b"\n" for x in lines) + rest)
    return path


def test_read_header_warns_once_per_file_in_one_line(tmp_path, caplog):
    p = _picture(tmp_path / "a.hdr", "EXPOSURE=0", "COLORCORR= 0 1 1")
    radiance._SAID.clear()
    with caplog.at_level(logging.WARNING, "ocl_tonemap"):
        radiance.read_header(str(p))
        radiance.read_header(str(p))           # (its view, then its pixels: said once)
    lines = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(lines) == 1 and str(p) in lines[0], lines
    assert "EXPOSURE=0" in lines[0] and "COLORCORR= 0 1 1" in lines[0]


@pytest.mark.requires_opencl
@pytest.mark.parametrize("line", ["EXPOSURE=-2", "EXPOSURE=0", "EXPOSURE=nan",
                                  "COLORCORR= 0 0 0", "PRIMARIES= x y z"])
def test_a_run_says_the_ignored_value_in_one_warning_line(tmp_path, line):
    """The run goes on (exit 0) and the picture is read as if the line were not there,
    with one warning naming the file and the line."""
    p = _picture(tmp_path / "bad.hdr", line)
    ref = _picture(tmp_path / "ref.hdr")
    outs = []
    for src in (p, ref):
        out = tmp_path / (src.stem + ".exr")
        r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", str(src), str(out),
                            "--luminance-scale", "100"], capture_output=True, text=True,
                           timeout=600)
        assert r.returncode == 0, r.stderr
        outs.append((r.stderr, oiio.ImageBuf(str(out)).get_pixels(oiio.FLOAT)))
    warned = [ln for ln in outs[0][0].splitlines() if "WARNING" in ln and "Radiance header" in ln]
    assert len(warned) == 1 and str(p) in warned[0] and line in warned[0], outs[0][0]
    assert "Radiance header" not in outs[1][0]
    assert np.array_equal(outs[0][1], outs[1][1])
