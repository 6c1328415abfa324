"""``run ... --ocio-export DIR``: the observer as an OCIO view (issue 32). The exported
config passes OCIO 2.1's and the wheel's ociocheck; the tunnel sample's frames
replayed through it by OCIO 2.1's ocioconvert (FRAME in the environment), the
wheel's ocioconvert, and oiiotool (--frames, {FRAME_NUMBER}) match the run's own PNG
output within the bound (p99 <= 1, max <= 3 8-bit codes); what cannot be per-pixel
is refused in one line."""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import OpenImageIO as oiio
import PyOpenColorIO as ocio
import pytest

from ocl_tonemap.colour import clf, lattice
from conftest import said

DEBIAN_BIN = "/usr/bin"
HERE_BIN = os.path.dirname(sys.executable)
FRAMES = (1, 3, 5)


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                          text=True, cwd=cwd, env={**os.environ, "PYTHONPATH": os.getcwd()})


def _png(path) -> np.ndarray:
    buf = oiio.ImageBuf(str(path))
    assert not buf.has_error, buf.geterror()
    return buf.get_pixels(oiio.UINT8)[..., :3].astype(np.int16)


def _assert_within_bound(a, b, what):
    d = np.abs(a - b)
    p99, mx = np.percentile(d, 99), d.max()
    assert p99 <= 1 and mx <= 3, f"{what}: p99 {p99}, max {mx} 8-bit codes"


@pytest.fixture(scope="module")
def tunnel(tmp_path_factory):
    d = tmp_path_factory.mktemp("tunnel")
    r = _cli("sample", str(d / "s"), "--size", "160x90", "--seconds", "8", "--fps", "0.625",
             "-q")
    assert r.returncode == 0, r.stderr
    return d


@pytest.fixture(scope="module", params=["pattanaik00", "durand00"])
def exported(request, tunnel):
    op = request.param
    out, exp = tunnel / f"out_{op}", tunnel / f"exp_{op}"
    r = _cli("run", str(tunnel / "s" / "tunnel.####.exr"), str(out / "o.####.png"),
             "--operator", op, "--flare", "off", "--acuity", "off", "--ocio-export", str(exp),
             "--backend", "reference")
    assert r.returncode == 0, r.stderr
    assert "OCIO export: 5 frame(s)" in r.stdout
    return op, tunnel, out, exp, exp / f"ocl-tonemap_{op}.ocio"


def test_the_folder_and_its_report(exported):
    op, _, _, exp, cfg_path = exported
    assert sorted(os.listdir(exp / "frames")) == [f"{n}.clf" for n in range(1, 6)]
    rep = json.loads((exp / "report.json").read_text())
    assert rep["operator"] == op and rep["lattice"] == "auto"
    assert {f["lattice"] for f in rep["frames"].values()} == {33}    # 33 was enough
    assert set(rep["frames"]) == {"1", "2", "3", "4", "5"}
    assert all(f["within_bound"] for f in rep["frames"].values()), rep["frames"]
    cfg = ocio.Config.CreateFromFile(str(cfg_path))
    assert cfg.getMajorVersion() == 2
    assert cfg.getCurrentContext().resolveStringVar("$FRAME") == "1"   # the first frame
    # the run's input colour space, as the file names it (the sample's EXRs: "Linear
    # Rec.709 (sRGB)", the working space of OCIO's default config): scene_linear
    assert rep["input_colorspace"] == "Linear Rec.709 (sRGB)"
    assert cfg.getColorSpace("scene_linear").getName() == rep["input_colorspace"]
    assert cfg.getDefaultView(cfg.getDefaultDisplay()) == f"{op} observer"


@pytest.mark.parametrize("tool", ["debian", "wheel"])
def test_ociocheck_passes(exported, tool):
    exe = os.path.join(DEBIAN_BIN if tool == "debian" else HERE_BIN, "ociocheck")
    if not os.path.exists(exe):
        if tool == "debian" and os.environ.get("CI"):
            pytest.fail("OCIO 2.1's ociocheck is missing: .ci/ocio21.sh installs it")
        pytest.skip(f"no {exe}")
    r = subprocess.run([exe, "--iconfig", str(exported[4])], capture_output=True, text=True)
    out = r.stdout + r.stderr
    assert r.returncode == 0 and "passed" in out and "ERROR" not in out, out


@pytest.mark.parametrize("tool", ["debian", "wheel"])
def test_ocioconvert_replays_each_frame(exported, tool, tmp_path):
    """FRAME from the environment selects the frame's CLF; the replay of the input EXR
    matches the run's PNG (8-bit both) within the bound."""
    op, tunnel, out, _, cfg_path = exported
    exe = os.path.join(DEBIAN_BIN if tool == "debian" else HERE_BIN, "ocioconvert")
    if not os.path.exists(exe):
        if tool == "debian" and os.environ.get("CI"):
            pytest.fail("OCIO 2.1's ocioconvert is missing: .ci/ocio21.sh installs it")
        pytest.skip(f"no {exe}")
    for n in FRAMES:
        dst = tmp_path / f"r{n}.png"
        r = subprocess.run([exe, "--view", str(tunnel / "s" / f"tunnel.{n:04d}.exr"),
                            "scene_linear", str(dst), "sRGB - Display", f"{op} observer"],
                           capture_output=True, text=True,
                           env={**os.environ, "OCIO": str(cfg_path), "FRAME": str(n)})
        assert r.returncode == 0, r.stdout + r.stderr
        _assert_within_bound(_png(dst), _png(out / f"o.{n:04d}.png"), f"{tool} frame {n}")


def test_oiiotool_replays_the_sequence(exported, tmp_path):
    """oiiotool from the OpenImageIO wheel: --frames and {FRAME_NUMBER} as the FRAME
    context value, the whole sequence in one command."""
    op, tunnel, out, _, cfg_path = exported
    exe = shutil.which("oiiotool", path=HERE_BIN)
    if exe is None:
        pytest.skip("the OpenImageIO wheel's oiiotool is not installed")
    r = subprocess.run([exe, "--frames", "1-5", "--colorconfig", str(cfg_path),
                        str(tunnel / "s" / "tunnel.#.exr"),
                        "--ociodisplay:from=scene_linear:key=FRAME:value={FRAME_NUMBER}",
                        "sRGB - Display", f"{op} observer", "-d", "uint8",
                        "-o", str(tmp_path / "r.#.png")], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    for n in range(1, 6):
        _assert_within_bound(_png(tmp_path / f"r.{n:04d}.png"), _png(out / f"o.{n:04d}.png"),
                             f"oiiotool frame {n}")
    # the frames differ: a wrong FRAME would show (frame 1 replayed as frame 5)
    a, b = _png(tmp_path / "r.0001.png"), _png(out / "o.0005.png")
    assert np.abs(a - b).max() > 10


@pytest.mark.parametrize("op, what", [("ledda04", "local adaptation"),
                                      ("kirk11", "bilateral base layer")])
def test_local_operators_are_refused_in_one_line(tunnel, op, what):
    exp = tunnel / f"refused_{op}"
    r = _cli("run", str(tunnel / "s" / "tunnel.0001.exr"), str(tunnel / f"{op}.png"),
             "--operator", op, "--flare", "off", "--acuity", "off", "--ocio-export", str(exp))
    assert r.returncode == 2
    lines = said(r.stderr)
    assert len(lines) == 1 and what in lines[0] and "per-pixel" in lines[0], r.stderr
    assert not exp.exists() and not (tunnel / f"{op}.png").exists()


def test_spatial_effects_are_refused_naming_them(tunnel):
    r = _cli("run", str(tunnel / "s" / "tunnel.0001.exr"), str(tunnel / "spatial.png"),
             "--ocio-export", str(tunnel / "refused_spatial"))
    assert r.returncode == 2
    lines = said(r.stderr)
    assert len(lines) == 1 and "--flare" in lines[0] and "--acuity" in lines[0], r.stderr


def test_clf_text_equals_the_transform(tmp_path):
    """The CLF text and the OCIO transforms made from one op list agree (the text is
    what OCIO reads; the transforms are what the export judges with)."""
    rng = np.random.default_rng(3)
    P = lattice.camera_log(0.01, 50.0)
    ops = [("range", 0.0, None), ("matrix", np.array([[1.1, 0.1, 0], [0, 0.9, 0.05],
                                                      [0.02, 0, 1.0]]), np.array([0.0, 0.01, 0])),
           ("log", P, False), ("lut1d", np.sqrt(np.linspace(0, 1, 257))[:, None].repeat(3, 1)),
           ("lut3d", rng.random((9, 9, 9, 3))), ("log", P, True), ("range", 0.0, 2.0)]
    path = tmp_path / "t.clf"
    path.write_text(clf.to_text(ops, "test"))
    cfg = ocio.Config.CreateRaw()
    x = np.ascontiguousarray(rng.uniform(0, 40, (5000, 3)).astype(np.float32))
    a, b = x.copy(), x.copy()
    cfg.getProcessor(clf.to_transform(ops)).getDefaultCPUProcessor().applyRGB(a)
    ft = ocio.FileTransform(src=str(path), interpolation=ocio.INTERP_TETRAHEDRAL)
    cfg.getProcessor(ft).getDefaultCPUProcessor().applyRGB(b)
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6)


def test_stage_b_rgb_is_exact_below_the_knee():
    """The shoulder is the identity below the knee; the RGB lattice reproduces it there
    exactly (its cells below the knee are linear in value)."""
    from ocl_tonemap.models.display import apply_shoulder
    rng = np.random.default_rng(5)
    vals = np.concatenate([rng.uniform(0, 0.6, (2000, 3)), rng.uniform(0, 5, (200, 3))])
    sh = lambda x: np.clip(apply_shoulder(np.maximum(x, 0), 1.0), 0, 100)   # noqa: E731
    cfg = ocio.Config.CreateRaw()
    low = np.ascontiguousarray(rng.uniform(0, 0.45, (3000, 3)).astype(np.float32))
    st = lattice.stage_b_rgb(1.0, 0.7, vals, sh, 17)
    y = low.copy()
    cfg.getProcessor(clf.to_transform(st.ops)).getDefaultCPUProcessor().applyRGB(y)
    np.testing.assert_allclose(y, low, atol=2e-6)


def test_a_linear_stage_is_a_matrix():
    M = np.array([[0.5, 0.2, 0.0], [0.1, 0.7, 0.1], [0.0, 0.1, 0.9]])
    st = lattice.stage_a(lambda x: x @ M.T, np.random.default_rng(0).uniform(0, 100, (500, 3)))
    assert st.kind == "matrix"
    np.testing.assert_allclose(st.ops[0][1], M, atol=1e-9)


def test_an_input_colour_space_goes_into_input_clf(tunnel, tmp_path):
    """A frame in ACEScg (named with --iscolorspace): the config's scene_linear is
    ACEScg, input.clf takes it to the working space, and OCIO's replay of the ACEScg
    file matches the run's PNG."""
    src = oiio.ImageBuf(str(tunnel / "s" / "tunnel.0003.exr"))
    aces = oiio.ImageBufAlgo.colorconvert(src, "lin_rec709", "ACEScg")
    aces.write(str(tmp_path / "aces.exr"))
    exp = tmp_path / "exp"
    r = _cli("run", str(tmp_path / "aces.exr"), str(tmp_path / "o.png"), "--iscolorspace",
             "ACEScg", "--flare", "off", "--acuity", "off", "--ocio-export", str(exp),
             "--backend", "reference")
    assert r.returncode == 0, r.stderr
    assert (exp / "input.clf").exists() or (exp / "input.ctf").exists()
    cfg = ocio.Config.CreateFromFile(str(exp / "ocl-tonemap_pattanaik00.ocio"))
    assert cfg.getColorSpace("scene_linear").getName() == "ACEScg"
    exe = os.path.join(HERE_BIN, "ocioconvert")
    if not os.path.exists(exe):
        pytest.skip("the OCIO wheel's ocioconvert is not installed")
    r = subprocess.run([exe, "--view", str(tmp_path / "aces.exr"), "ACEScg",
                        str(tmp_path / "r.png"), "sRGB - Display", "pattanaik00 observer"],
                       capture_output=True, text=True,
                       env={**os.environ, "OCIO": str(exp / "ocl-tonemap_pattanaik00.ocio")})
    assert r.returncode == 0, r.stdout + r.stderr
    _assert_within_bound(_png(tmp_path / "r.png"), _png(tmp_path / "o.png"), "ACEScg input")


def test_the_shot_export_pass_writes_what_apply_writes(tunnel, tmp_path):
    """measure -> integrate -> export (frames read, none mapped) gives the same CLF
    files as the apply pass exporting while it renders: a farm makes the view without
    rendering pixels. A chunk of the export pass writes its frames alone."""
    seq, out = str(tunnel / "s" / "tunnel.####.exr"), str(tmp_path / "o" / "o.####.png")
    common = ["--flare", "off", "--acuity", "off", "--backend", "reference"]
    for cmd in ("measure", "integrate"):
        r = _cli(cmd, seq, out, *common)
        assert r.returncode == 0, r.stderr
    r = _cli("export", seq, out, *common, "--ocio-export", str(tmp_path / "x"))
    assert r.returncode == 0, r.stderr
    assert "OCIO export: 5 frame(s)" in r.stdout and "ms exporting" in r.stdout
    r = _cli("apply", seq, out, *common, "--ocio-export", str(tmp_path / "y"))
    assert r.returncode == 0, r.stderr
    for n in range(1, 6):
        assert (tmp_path / "x" / "frames" / f"{n}.clf").read_bytes() == \
            (tmp_path / "y" / "frames" / f"{n}.clf").read_bytes(), n
    r = _cli("export", seq, out, *common, "--ocio-export", str(tmp_path / "z"), "--chunk", "3-4")
    assert r.returncode == 0, r.stderr
    assert sorted(os.listdir(tmp_path / "z" / "frames")) == ["3.clf", "4.clf"]
    assert (tmp_path / "z" / "frames" / "4.clf").read_bytes() == \
        (tmp_path / "x" / "frames" / "4.clf").read_bytes()
    cfg = ocio.Config.CreateFromFile(str(tmp_path / "z" / "ocl-tonemap_pattanaik00.ocio"))
    assert cfg.getCurrentContext().resolveStringVar("$FRAME") == "1"   # the shot's first


@pytest.mark.parametrize("backend,age", [
    ("reference", 25.0), ("reference", 70.0),
    pytest.param("opencl", 25.0, marks=pytest.mark.requires_opencl)])
def test_the_api_export_replays_the_run_on_either_backend(tmp_path, backend, age):
    """From the API: OcioExport beside Tonemapper.process; the view read back by OCIO
    against the frames the run itself returned (OpenCL: float32 kernels), within the
    bound; an older observer's view takes the light behind the media as the run
    does."""
    from ocl_tonemap import EffectSettings, OcioExport, Tonemapper
    from ocl_tonemap.colour import ColourPipeline
    from ocl_tonemap.io.sample import render_frame
    colour = ColourPipeline("ocl-tonemap")
    tm = Tonemapper("durand00", backend=backend,
                    effects=EffectSettings(chromatic_adaptation="auto", purkinje="auto",
                                           age=age))
    assert (tm.media_gain < 0.9) == (age == 70.0)
    view = OcioExport(str(tmp_path / "v"), colour, tm, first_frame=1)
    for n, t in enumerate((0.0, 3.0, 6.0), 1):
        frame = np.ascontiguousarray(render_frame(t, 96, 54, 8.0)[..., :3], np.float32)
        out = tm.process(frame, dt=None if n == 1 else 1.5, luminance_scale=2.0)
        rec = view.add_frame(n, frame, 2.0)
        assert rec["within_bound"], rec
        run = np.rint(np.clip(colour.encode(out), 0, 1).reshape(-1, 3) * 255)
        got = np.rint(np.clip(view.replay(n, frame.reshape(-1, 3)), 0, 1) * 255)
        _assert_within_bound(got, run, f"{backend} frame {n}")
