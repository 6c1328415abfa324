"""Radiance pictures read as Radiance's tools read them (issue 33), with real pictures
rendered here by ``rpict`` and filtered by ``pfilt`` / ``ra_xyze`` from the pyradiance
wheel: EXPOSURE and COLORCORR divided out, a rendering absolute (no calibration
warning), VIEW giving the field of view, PRIMARIES and XYZE converted."""

import os
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.io import radiance
from ocl_tonemap.io.imagewrite import ocltm_metadata
from conftest import said

TOOLS = radiance.tools()
needs_radiance = pytest.mark.skipif(
    TOOLS is None, reason="Radiance's programs are not installed (pip install "
    "'ocl-tonemap[radiance]': the pyradiance wheel)")

#: A glowing wall of 100 cd/m^2 (0.5587 W/sr/m^2 x 179 lm/W) in front of the view.
WALL = """void glow wallglow
0
0
4 0.5587 0.5587 0.5587 0

wallglow polygon wall
0
0
12 -5 5 -5  5 5 -5  5 5 5  -5 5 5
"""
#: A warm lamp on the wall (saturated colour: PRIMARIES matter).
LAMP = """void glow lampglow
0
0
4 30 12 2 0

lampglow sphere lamp
0
0
4 0 4.5 0 0.4
"""


def _r(cmd, out=None, cwd=None):
    with open(out, "wb") if out else open(os.devnull, "wb") as fh:
        r = subprocess.run(cmd, stdout=fh, stderr=subprocess.PIPE, env=TOOLS[1], cwd=cwd)
    assert r.returncode == 0, r.stderr.decode()


@pytest.fixture(scope="module")
def pictures(tmp_path_factory):
    if TOOLS is None:
        pytest.skip("no Radiance programs")
    d = tmp_path_factory.mktemp("rad")
    (d / "scene.rad").write_text(WALL + LAMP)
    _r(["oconv", "scene.rad"], d / "scene.oct", cwd=d)
    view = ["-vp", "0", "0", "0", "-vd", "0", "1", "0", "-vu", "0", "0", "1"]
    _r(["rpict", "-vtv", *view, "-vh", "60", "-vv", "40", "-x", "96", "-y", "64", "scene.oct"],
       d / "room.hdr", cwd=d)
    _r(["pfilt", "-1", "-e", "2", "room.hdr"], d / "room_e2.hdr", cwd=d)
    # two EXPOSURE lines (pfilt twice) and a COLORCORR
    _r(["pfilt", "-1", "-e", "3", "room_e2.hdr"], d / "room_e6.hdr", cwd=d)
    text = (d / "room_e6.hdr").read_bytes()
    head = text.partition(b"\n\n")[0]
    (d / "room_cc.hdr").write_bytes(head + b"\nCOLORCORR= 2 1 0.5\n\n" + _scaled(d))
    _r(["ra_xyze", "room.hdr"], d / "room_xyze.hdr", cwd=d)
    _r(["rpict", "-vta", *view, "-vh", "180", "-vv", "180", "-x", "64", "-y", "64",
        "scene.oct"], d / "fisheye.hdr", cwd=d)
    return d


def _scaled(d):
    """The pixel data (resolution line onwards) of room_e6.hdr times (2, 1, 0.5): what
    a COLORCORR of 2 1 0.5 undoes."""
    buf = oiio.ImageBuf(str(d / "room_e6.hdr"))
    px = buf.get_pixels(oiio.FLOAT) * np.array([2.0, 1.0, 0.5], np.float32)
    out = oiio.ImageBuf(oiio.ImageSpec(buf.spec().width, buf.spec().height, 3, oiio.FLOAT))
    out.set_pixels(oiio.ROI(), px)
    assert out.write(str(d / "tmp_cc.hdr"))
    return (d / "tmp_cc.hdr").read_bytes().partition(b"\n\n")[2]


def _run(*args):
    return subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", *map(str, args)],
                          capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": os.getcwd()})


def _png(path):
    return oiio.ImageBuf(str(path)).get_pixels(oiio.UINT8).astype(int)


@needs_radiance
def test_the_header_as_radiance_reads_it(pictures):
    h = radiance.read_header(str(pictures / "room_e6.hdr"))
    assert h.exposure == pytest.approx(6.0) and h.renderer == "rpict" and h.absolute
    assert h.view.type == "v" and h.view.vh == 60 and h.view.vv == 40
    assert h.primaries == pytest.approx(radiance.STANDARD_PRIMARIES, abs=1e-4)
    cc = radiance.read_header(str(pictures / "room_cc.hdr"))
    assert cc.colorcorr == (2.0, 1.0, 0.5) and cc.exposure == pytest.approx(6.0)
    assert radiance.read_header(str(pictures / "room_xyze.hdr")).xyze


@needs_radiance
@pytest.mark.parametrize("name", ["room_e2", "room_e6", "room_cc", "room_xyze"])
def test_exposure_colorcorr_and_xyze_give_the_raw_pictures_output(pictures, name):
    """pfilt -e (one or two EXPOSURE lines), a COLORCORR, ra_xyze: the same frame as
    the picture rpict wrote; no calibration warning (a rendering is absolute)."""
    outs = []
    for n in ("room", name):
        r = _run(pictures / f"{n}.hdr", pictures / f"{n}.png", "--operator", "durand00")
        assert r.returncode == 0, r.stderr
        news = "\n".join(said(r.stderr))
        assert "calibration" not in news and "WARNING" not in news, r.stderr
        outs.append(_png(pictures / f"{n}.png"))
    assert np.abs(outs[0] - outs[1]).max() <= 1
    meta = ocltm_metadata(oiio.ImageBuf(str(pictures / f"{name}.png")).spec())
    assert "rpict" in meta["ocltm:luminance_scale_source"]


@needs_radiance
def test_the_wall_is_100_cd_m2_and_the_fov_is_the_views(pictures):
    r = _run(pictures / "room_e6.hdr", pictures / "m.png")
    assert r.returncode == 0, r.stderr
    meta = ocltm_metadata(oiio.ImageBuf(str(pictures / "m.png")).spec())
    assert meta["ocltm:fov"].startswith("66.1595 degrees (Radiance VIEW: perspective -vh 60")
    assert "Radiance PRIMARIES" in meta["ocltm:input_colorspace"]
    r = _run(pictures / "fisheye.hdr", pictures / "f.png")
    meta = ocltm_metadata(oiio.ImageBuf(str(pictures / "f.png")).spec())
    assert meta["ocltm:fov"].startswith("180 degrees (Radiance VIEW: angular fisheye")
    r = _run(pictures / "room.hdr", pictures / "g.png", "--fov", "30")
    meta = ocltm_metadata(oiio.ImageBuf(str(pictures / "g.png")).spec())
    assert meta["ocltm:fov"] == "30 degrees (--fov)"


@needs_radiance
def test_the_wall_meters_at_its_luminance(pictures):
    """The glowing wall (100 cd/m^2 by construction) is metered at 100 cd/m^2 from
    every form of the picture."""
    from ocl_tonemap.io.imageio import read_frame
    from ocl_tonemap.colour.calibration import CalibrationRequest, Calibrator
    for n in ("room", "room_e6", "room_xyze"):
        fr = read_frame(str(pictures / f"{n}.hdr"))
        cal = Calibrator(CalibrationRequest()).frame(fr.spec, fr.format_name, None, fr.radiance)
        from ocl_tonemap.colour.config import chromaticities_to_working
        M = chromaticities_to_working(fr.chromaticities)
        wall = fr.pixels[-2, 2, :3] @ M.T * cal.scale        # a corner: wall, no lamp
        assert wall @ np.array([0.2126, 0.7152, 0.0722]) == pytest.approx(100.0, rel=0.01), n
        assert not cal.assumed


def test_view_angles_to_fields_of_view():
    v = radiance.parse_view("-vtv -vh 60 -vv 40".split())
    assert radiance.fov_for(v)[0] == pytest.approx(2 * np.degrees(np.tan(np.radians(30))))
    assert radiance.fov_for(radiance.View("a", 180, 180))[0] == 180
    assert radiance.fov_for(radiance.View("h", 180, 180))[0] == pytest.approx(2 * np.degrees(1))
    assert radiance.fov_for(radiance.View("l", 10, 10))[0] is None


def test_a_header_without_its_end_is_one_line(tmp_path):
    p = tmp_path / "bad.hdr"
    p.write_bytes(b"#?RADIANCE\n" + b"X" * (radiance.HEADER_CAP + 10))
    r = _run(p, tmp_path / "bad.png")
    assert r.returncode == 2
    lines = said(r.stderr)
    assert len(lines) == 1 and "Radiance header" in lines[0], r.stderr


def test_photoshops_zero_primaries_are_no_primaries():
    """Photoshop writes PRIMARIES=0 0 0 0 0 0 0 0 (the photographs of the benchmarks
    have it): a placeholder; the picture stays OIIO's Rec.709, with no warning."""
    h = radiance.parse_header(["# Made with Adobe Photoshop", "GAMMA=1",
                               "PRIMARIES=0 0 0 0 0 0 0 0", "FORMAT=32-bit_rle_rgbe"])
    assert h.primaries is None and h.chromaticities is None and not h.absolute


@needs_radiance
def _docs_block(page: str, section: str, cwd):
    """The first ``sh`` block under a section of a page of the docs (``radiance.md``,
    ``visibility.md``: the README's examples moved there), pasted into bash in ``cwd``
    with only the installed package on PATH (its radiance-env puts the wheel's programs
    there); the finished process."""
    import re
    from pathlib import Path
    text = (Path(__file__).resolve().parents[2] / "docs" / page).read_text()
    block = re.search(r"```sh\n(.*?)```", text.split(section, 1)[1], re.S).group(1)
    env = {**os.environ, "PATH": os.path.dirname(sys.executable) + os.pathsep +
           "/usr/bin:/bin"}
    env.pop("RAYPATH", None)
    r = subprocess.run(["bash", "-e", "-c", block], cwd=cwd, env=env,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r


def test_the_docs_radiance_block_runs_as_written(tmp_path):
    """docs/radiance.md "From Radiance": the block pasted into bash in an empty folder,
    with only the installed package on PATH (its radiance-env puts the wheel's programs
    there): it renders and maps, and pfilt's exposure gives the same picture."""
    _docs_block("radiance.md", "## From Radiance", tmp_path)
    a, b = _png(tmp_path / "room.png"), _png(tmp_path / "room_e2.png")
    assert a.shape[1] == 640 and a.mean() > 20          # (rpict keeps the view's aspect)
    assert np.abs(a - b).max() <= 1


def test_the_docs_lighting_designers_block_runs_as_written(tmp_path):
    """docs/visibility.md "For lighting designers": the portal rendered with rpict, its
    visibility planes, view and target, and the calculator's seconds after entering, as
    written there; the numbers the page states are what the run and the calculator print
    (issue 56): the veil over the road inside the portal, within 1.5x of CIE 88's
    L_seq of the same picture, the box's VL."""
    r = _docs_block("visibility.md", "## For lighting designers", tmp_path)
    for f in ("portal.png", "portal_vis.exr", "portal_vl.png", "vl_over_time.png"):
        assert (tmp_path / f).stat().st_size > 1000, f
    head = "target at (320, 185), 6 arcmin"
    row = r.stdout.split(head, 1)[1].splitlines()[2].split()
    L_t, L_s, veil, lseq, L_b, La, TAF, dL, VL = (float(x) for x in row[1:])
    # as docs/visibility.md states them (its rounding)
    assert (round(L_t, 2), round(L_s), round(veil), round(lseq), round(L_b)) == \
        (1.96, 106, 80, 103, 186)
    assert (round(La), round(TAF, 2), round(dL, 1), round(VL, 2)) == (5000, 3.98, 33.4, 3.12)
    assert 1 / 1.5 < veil / lseq < 1.5
    steps = r.stdout.split("time course:", 1)[1].splitlines()[2:5]
    assert round(float(steps[0].split()[-1]), 1) == 11.3               # VL 0.5 s after
    b = oiio.ImageBuf(str(tmp_path / "portal_vis.exr"))
    assert set(b.spec().channelnames) == {"La", "Lveil", "Lb", "dLth", "VL"}
    assert b.spec().format == oiio.HALF
    P = b.get_pixels(oiio.FLOAT)
    veil_plane = P[..., list(b.spec().channelnames).index("Lveil")]
    assert veil_plane[190:200, 300:340].min() > 50                      # the road inside
