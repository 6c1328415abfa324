"""``--stills``: the frames of a pattern as independent stills (views of a room, a
year of daylight renderings): each frame comes out as a lone still's run gives it,
no state file is left, and what needs a state is refused in one line."""

import os
import shutil
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import pytest
from conftest import said


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "ocl_tonemap", *map(str, args)],
                          capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": os.getcwd()})


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    d = tmp_path_factory.mktemp("stills")
    r = _cli("sample", d / "s", "--size", "96x54", "--seconds", "8", "--fps", "1", "-q")
    assert r.returncode == 0, r.stderr
    # three views as a pattern, in an order unlike the drive's
    for k, n in enumerate((7, 1, 4), 1):
        shutil.copy(d / "s" / f"tunnel.{n:04d}.exr", d / f"view.{k:04d}.exr")
    return d


@pytest.mark.parametrize("op", ["durand00", "ledda04"])
def test_each_still_is_what_a_lone_run_gives(views, op):
    r = _cli("run", views / "view.####.exr", views / op / "v.####.png", "--stills",
             "--operator", op, "--backend", "reference")
    assert r.returncode == 0, r.stderr
    assert sorted(os.listdir(views / op)) == ["v.0001.png", "v.0002.png", "v.0003.png"]
    for k in (1, 2, 3):
        lone = views / op / f"lone{k}.png"
        r = _cli("run", views / f"view.{k:04d}.exr", lone, "--operator", op,
                 "--backend", "reference")
        assert r.returncode == 0, r.stderr
        a = oiio.ImageBuf(str(lone)).get_pixels(oiio.UINT8)
        b = oiio.ImageBuf(str(views / op / f"v.{k:04d}.png")).get_pixels(oiio.UINT8)
        assert np.array_equal(a, b), k


def test_a_sequence_without_stills_adapts_over_time(views):
    """The contrast: as a sequence, view 2 (the tunnel's start) is seen by eyes that
    came from view 1, not as a lone still."""
    r = _cli("run", views / "view.####.exr", views / "seq" / "v.####.png",
             "--operator", "durand00", "--backend", "reference", "--fps", "4")
    assert r.returncode == 0, r.stderr
    r = _cli("run", views / "view.0002.exr", views / "seq" / "lone.png", "--operator",
             "durand00", "--backend", "reference")
    a = oiio.ImageBuf(str(views / "seq" / "lone.png")).get_pixels(oiio.UINT8).astype(int)
    b = oiio.ImageBuf(str(views / "seq" / "v.0002.png")).get_pixels(oiio.UINT8).astype(int)
    assert np.abs(a - b).max() > 10


@pytest.mark.parametrize("flag", [["--state-out", "s.json"], ["--resume"], ["--cuts", "detect"]])
def test_state_flags_are_refused_with_stills(views, flag):
    r = _cli("run", views / "view.####.exr", views / "x" / "v.####.png", "--stills", *flag)
    assert r.returncode == 2
    assert len(said(r.stderr)) == 1 and "--stills" in r.stderr, r.stderr


def _hdr_with_view(path, view: str | None, seed: int):
    """A Radiance picture (OIIO's writer) with ``VIEW= <view>`` put into its header."""
    rng = np.random.default_rng(seed)
    px = (10.0 ** rng.uniform(-1, 2, (24, 32, 1)) * np.ones((1, 1, 3))).astype(np.float32)
    spec = oiio.ImageSpec(32, 24, 3, oiio.FLOAT)
    buf = oiio.ImageBuf(spec)
    buf.set_pixels(oiio.ROI(0, 32, 0, 24, 0, 1, 0, 3), px)
    assert buf.write(str(path))
    head, _, rest = path.read_bytes().partition(b"\n\n")
    if view:
        head += b"\nrpict -vtv " + view.encode() + b"\nVIEW= -vtv " + view.encode()
    path.write_bytes(head + b"\n\n" + rest)


def test_each_still_has_its_own_views_field_of_view(tmp_path):
    """Radiance views in a --stills run: each picture's VIEW sets its own field of view
    (the first one's was given to all), a picture without one the default."""
    for k, view in ((1, "-vh 20 -vv 15"), (2, "-vh 90 -vv 70"), (3, None)):
        _hdr_with_view(tmp_path / f"v.{k:04d}.hdr", view, k)
    r = _cli("run", tmp_path / "v.####.hdr", tmp_path / "o" / "o.####.exr", "--stills",
             "--operator", "durand00")
    assert r.returncode == 0, r.stderr
    fovs = []
    for k in (1, 2, 3):
        spec = oiio.ImageBuf(str(tmp_path / "o" / f"o.{k:04d}.exr")).spec()
        fovs.append(spec.getattribute("ocltm:fov"))
    from ocl_tonemap.io import radiance
    for got, vh in zip(fovs[:2], (20, 90)):
        want = radiance.fov_for(radiance.View("v", vh, 0.75 * vh))[0]
        assert got.startswith(f"{want:.6g} degrees (Radiance VIEW: perspective -vh {vh}"), fovs
    assert fovs[2].startswith("50 degrees (default"), fovs
