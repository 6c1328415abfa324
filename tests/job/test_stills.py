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
    assert len(r.stderr.strip().splitlines()) == 1 and "--stills" in r.stderr, r.stderr
