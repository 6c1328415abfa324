"""The OCIO export's self-check is what a replay gives (issue 67): a sunset-like
sequence -- a bright sky and sun over a dark foreground with isolated dark saturated
reds on odd columns, 1024x512, more pixels than the lattices' node sample, which
takes every second pixel and so misses every red -- exported, then replayed as a
user replays it: PyOpenColorIO on the exported config (``Config.CreateFromFile``,
the exported display and view, FRAME set) and oiiotool's ``--ociodisplay``. The
report's maximum is what the replay gives against the run's PNG, and the reds are
within the bound (they were clamped to the lattice's edge: 35-57 codes off)."""

import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import PyOpenColorIO as ocio
import pytest

from ocl_tonemap.colour import replay_check

FRAMES = (1, 2, 3)
W, H = 1024, 512
HERE_BIN = os.path.dirname(sys.executable)


def sunset(level: float, seed: int):
    """(frame, mask of its dark saturated reds): scene-linear Rec.709, cd/m^2 at a
    luminance scale of 1 -- a sky from blue overhead to orange at the horizon (40-300
    cd/m^2), a low sun (3e4), a dark ground (1-3 cd/m^2) with one pixel in 700 a dark
    saturated red ([0.02, 0.001, 0.003] x 400 x 0.3-1.5: ~1-4 cd/m^2; half of them with
    no green at all), on odd columns only."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:H, 0:W].astype(np.float64)
    v, hor = y / H, 0.6
    t = np.clip(v / hor, 0, 1)[..., None]
    sky = ((1 - t) * np.array([0.25, 0.4, 0.9]) + t * np.array([1.6, 0.7, 0.25])) * (40 + 260 * t)
    d = np.hypot(x - 0.62 * W, y - (hor - 0.04) * H) / H
    sky = sky + (3e4 * np.exp(-(d / 0.012) ** 2) + 400 * np.exp(-(d / 0.08) ** 2))[..., None] \
        * np.array([1.0, 0.8, 0.5])
    ground = np.array([0.6, 0.35, 0.25]) * (1.0 + 4.0 * rng.random((H, W, 1)))
    img = np.where((v < hor)[..., None], sky, ground)
    red = (v > hor + 0.05) & (x % 2 == 1) & (rng.random((H, W)) < 1 / 700)
    reds = np.array([0.02, 0.001, 0.003]) * 400 * rng.uniform(0.3, 1.5, (H, W, 1))
    reds[..., 1] *= rng.random((H, W)) < 0.5
    img = np.where(red[..., None], reds, img)
    return (img * level).astype(np.float32), red


def _png(path) -> np.ndarray:
    return oiio.ImageBuf(str(path)).get_pixels(oiio.UINT8)[..., :3].astype(np.int16)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    d = tmp_path_factory.mktemp("sunset")
    reds = {}
    for n, level in zip(FRAMES, (1.0, 0.3, 0.1)):
        img, reds[n] = sunset(level, n)
        buf = oiio.ImageBuf(oiio.ImageSpec(W, H, 3, oiio.FLOAT))
        buf.set_pixels(oiio.ROI(), img)
        assert buf.write(str(d / f"sun.{n:04d}.exr")), buf.geterror()
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", str(d / "sun.####.exr"),
                        str(d / "out" / "o.####.png"), "--fps", "0.5", "--luminance-scale", "1",
                        "--flare", "off", "--acuity", "off", "--ocio-export", str(d / "view"),
                        "--ocio-export-size", "33"], capture_output=True, text=True,
                       env={**os.environ, "PYTHONPATH": os.getcwd()})
    assert r.returncode == 0, r.stderr
    rep = json.loads((d / "view" / "report.json").read_text())
    return d, rep, reds, r


def _replay(d, rep, n) -> np.ndarray:
    """Frame n replayed by PyOpenColorIO on the exported config, 8-bit codes."""
    cfg = ocio.Config.CreateFromFile(str(d / "view" / rep["config"]))
    ctx = cfg.getCurrentContext()
    ctx.setStringVar("FRAME", str(n))
    cpu = cfg.getProcessor(ctx, "scene_linear", rep["display"], rep["view"],
                           ocio.TRANSFORM_DIR_FORWARD).getDefaultCPUProcessor()
    x = np.ascontiguousarray(oiio.ImageBuf(str(d / f"sun.{n:04d}.exr")).get_pixels(oiio.FLOAT))
    cpu.applyRGB(x)
    return np.rint(np.clip(x, 0, 1) * 255).astype(np.int16)


def test_the_report_states_what_the_replay_gives(exported):
    d, rep, _, _ = exported
    for n in FRAMES:
        rec = rep["frames"][str(n)]
        assert rec["checked"] == {"pixels": W * H, "of": W * H, "against": "run's output",
                                  "from": rep["input_colorspace"]}, rec["checked"]
        diff = np.abs(_replay(d, rep, n) - _png(d / "out" / f"o.{n:04d}.png"))
        assert diff.max() == rec["files_max_8bit"], (n, diff.max(), rec)
        assert np.percentile(diff, 99) == rec["files_p99_8bit"], (n, rec)
        assert diff.max() <= math.ceil(rec["max_8bit"]), (n, rec)   # (within its float max)
        assert rec["within_bound"] == (rec["max_8bit"] <= 3 and rec["p99_8bit"] <= 1)


def test_the_dark_saturated_reds_are_within_the_bound(exported):
    d, rep, reds, _ = exported
    for n in FRAMES:
        diff = np.abs(_replay(d, rep, n) - _png(d / "out" / f"o.{n:04d}.png")).max(axis=-1)
        assert reds[n].sum() > 100
        assert diff[reds[n]].max() <= 3, (n, diff[reds[n]].max())


def test_oiiotool_replays_what_the_report_says(exported, tmp_path):
    d, rep, _, _ = exported
    exe = shutil.which("oiiotool", path=HERE_BIN) or shutil.which("oiiotool")
    if exe is None:
        pytest.skip("no oiiotool (the OpenImageIO wheel's console script)")
    r = subprocess.run([exe, "--frames", "1-3", "--colorconfig", str(d / "view" / rep["config"]),
                        str(d / "sun.#.exr"),
                        "--ociodisplay:from=scene_linear:key=FRAME:value={FRAME_NUMBER}",
                        rep["display"], rep["view"], "-d", "uint8", "-o",
                        str(tmp_path / "r.#.png")], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    for n in FRAMES:
        diff = np.abs(_png(tmp_path / f"r.{n:04d}.png") - _png(d / "out" / f"o.{n:04d}.png"))
        assert diff.max() == rep["frames"][str(n)]["files_max_8bit"], n


def test_the_lattices_are_said_once_and_truly(exported):
    """Issue 67 item 5: the summary says which frames used which lattice, once; a
    frame's warning names none (it said "at 49^3; the largest lattice" while other
    frames used 65^3)."""
    _, rep, _, r = exported
    assert {f["lattice"] for f in rep["frames"].values()} == {33}
    summary = [ln for ln in r.stdout.splitlines() if ln.startswith("OCIO export:")]
    assert len(summary) == 1 and "lattices 33^3 frames 1-3" in summary[0], r.stdout
    over = [n for n, f in rep["frames"].items() if not f["within_bound"]]
    if over:
        assert "--ocio-export-size auto or 49 or 65 may come closer" in summary[0]
    warned = [ln for ln in r.stderr.splitlines() if "exported view" in ln]
    assert len(warned) == len(over), r.stderr
    assert not any("^3" in ln or "largest" in ln for ln in warned), warned


def _summary(sizes, lattices, within):
    from ocl_tonemap.colour.export import OcioExport
    ex = object.__new__(OcioExport)          # (the summary of a report alone)
    ex.sizes, ex.folder, ex.name = tuple(sizes), "/v", "x"
    ex.report = {"frames": {str(n): {"lattice": s, "p99_8bit": 0.5 if w else 2.0,
                                     "max_8bit": 1.0 if w else 9.0, "files_max_8bit": 9.0,
                                     "bytes": 1, "within_bound": w}
                            for n, (s, w) in enumerate(zip(lattices, within), 1)}}
    return ex.summary()


def test_the_summary_names_each_frames_lattice():
    s = _summary((33, 49, 65), (65, 49, 65, 33), (False, False, True, True))
    assert "lattices 65^3 frames 1, 3, 49^3 frame 2, 33^3 frame 4" in s, s
    assert "beyond the bound (p99 1, max 3): frames 1-2" in s, s
    assert "auto: 33^3, then 49^3, then 65^3" in s and "largest" not in s, s
    assert "may come closer" in _summary((33,), (33, 33), (False, True))
    assert "the largest lattice" in _summary((65,), (65,), (False,))
    assert "beyond" not in _summary((33, 49, 65), (33,), (True,))
    assert replay_check.frames_text([5, 1, 2, 3, 9]) == "1-3, 5, 9"
