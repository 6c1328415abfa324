"""Every file OCIO will open is checked before OCIO opens it (issue 65): a LUT of a
config (a ``FileTransform``'s ``src``) that is a FIFO, ``/dev/zero``, a link to a
FIFO or a folder is refused in one line naming the LUT and the config, wherever the
processors of a run would read it (the view's colourspace, a group, a colourspace
named through another, a look, a view transform, a named transform, a context
variable, the input colourspace); a LUT OCIO cannot parse is one line naming it."""

import json
import os
import subprocess
import sys
import time

import numpy as np
import OpenImageIO as oiio
import pytest

from conftest import said

#: Only keeps a hang from holding the suite (a FIFO that OCIO opened would wait for
#: ever, holding the interpreter); nothing here comes near it.
HANG = 60

FIFO = "is a named pipe (FIFO), not a file"
PLACES = ("view", "group", "indirect", "look", "view_transform", "named", "context", "input")
GOOD_CUBE = "LUT_1D_SIZE 2\n0 0 0\n1 1 1\n"


def config_text(where: str, src: str) -> str:
    """A config whose processors for display 'sRGB', view 'Raw' (and, for ``input``, the
    colourspace ``in_cs`` to the working space) read LUT ``src`` at ``where``; its
    search path is ``luts`` beside it."""
    ft = f"!<FileTransform> {{src: {json.dumps(src)}}}"
    view, extra, env = "colorspace: out", "", ""
    out = f"from_scene_reference: {ft}"
    if where == "group":
        out = ("from_scene_reference: !<GroupTransform>\n      children:\n"
               "        - !<MatrixTransform> {}\n        - !<GroupTransform>\n"
               f"          children: [{ft}]")
    elif where == "indirect":
        out = "from_scene_reference: !<ColorSpaceTransform> {src: lin_rec709, dst: inner}"
    elif where == "context":
        env = f"environment:\n  LUTNAME: {json.dumps(src)}\n"
        out = 'from_scene_reference: !<FileTransform> {src: "${LUTNAME}"}'
    elif where in ("look", "view_transform", "named", "input"):
        out = "from_scene_reference: !<MatrixTransform> {}"
    if where == "look":
        view = "colorspace: out, looks: +grade"
        extra = ("looks:\n  - !<Look>\n    name: grade\n    process_space: lin_rec709\n"
                 f"    transform: {ft}\n")
    elif where == "view_transform":
        view = "view_transform: film, display_colorspace: disp"
        extra = (f"view_transforms:\n  - !<ViewTransform>\n    name: film\n"
                 f"    from_scene_reference: {ft}\n"
                 "display_colorspaces:\n  - !<ColorSpace>\n    name: disp\n"
                 "    from_display_reference: !<MatrixTransform> {}\n")
    elif where == "named":
        view = "colorspace: nt"
        extra = f"named_transforms:\n  - !<NamedTransform>\n    name: nt\n    transform: {ft}\n"
    return ("ocio_profile_version: 2.1\n" + env + "search_path: luts\nroles:\n"
            "  default: lin_rec709\n  scene_linear: lin_rec709\n"
            "displays:\n  sRGB:\n    - !<View> {name: Raw, " + view + "}\n" + extra +
            "colorspaces:\n  - !<ColorSpace>\n    name: lin_rec709\n"
            f"  - !<ColorSpace>\n    name: out\n    {out}\n"
            f"  - !<ColorSpace>\n    name: inner\n    from_scene_reference: {ft}\n"
            "  - !<ColorSpace>\n    name: in_cs\n"
            + ("    to_scene_reference: " + ft if where == "input" else "    isdata: false")
            + "\n")


def _lut(folder, kind: str) -> str:
    """A LUT named ``lut.cube`` in ``folder/luts`` of ``kind``; returns its path."""
    d = folder / "luts"
    d.mkdir(exist_ok=True)
    p = d / "lut.cube"
    if kind == "fifo":
        os.mkfifo(p)
    elif kind == "link to a fifo":
        os.mkfifo(d / "real.fifo")
        os.symlink("real.fifo", p)
    elif kind == "dev zero":
        os.symlink("/dev/zero", p)
    elif kind == "folder":
        p.mkdir()
    elif kind == "garbage":
        p.write_bytes(np.random.default_rng(65).integers(0, 256, 4096, np.uint8).tobytes())
    elif kind == "good":
        p.write_text(GOOD_CUBE)
    return str(p)


#: Builds the colour pipeline of each config named on the command line (with its
#: input conversion from ``in_cs``) and prints, per config, its error or ``ok``; run
#: in a process of its own, under a memory cap, so that a LUT let through (a FIFO
#: waits for ever, /dev/zero fills the memory) fails the test instead of the suite.
_BUILD = r"""
import json, resource, sys
import numpy as np
resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
from ocl_tonemap.colour import ColourPipeline
out = {}
for cfg in sys.argv[1:]:
    try:
        cp = ColourPipeline(cfg, "sRGB", "Raw")
        cp.to_working(np.zeros((1, 1, 3), np.float32), "in_cs")
        out[cfg] = "ok"
    except Exception as exc:
        out[cfg] = f"{type(exc).__name__}: {exc}"
print(json.dumps(out))
"""


def _build(configs) -> dict:
    t0 = time.monotonic()
    p = subprocess.run([sys.executable, "-c", _BUILD, *configs], capture_output=True,
                       text=True, timeout=HANG)
    assert p.returncode == 0, p.stderr
    assert time.monotonic() - t0 < HANG / 2
    return json.loads(p.stdout)


@pytest.mark.parametrize("kind, why", [
    ("fifo", FIFO),
    ("link to a fifo", "a link to {real}, which is a named pipe (FIFO), not a file"),
    ("dev zero", "a link to /dev/zero, which is a character device, not a file"),
    ("folder", "is a folder, not a file"),
])
def test_a_lut_that_is_not_a_file_is_refused_wherever_a_processor_reads_it(tmp_path, kind,
                                                                          why):
    lut = _lut(tmp_path, kind)
    why = why.format(real=tmp_path / "luts" / "real.fifo")
    configs = {}
    for where in PLACES:
        cfg = tmp_path / f"{where}.ocio"
        cfg.write_text(config_text(where, "lut.cube"))
        configs[str(cfg)] = where
    got = _build(configs)
    for cfg, where in configs.items():
        msg = got[cfg]
        assert msg.startswith("LutFileError: "), (where, msg)
        assert msg.startswith(f"LutFileError: {cfg}: its "), (where, msg)
        assert msg.endswith(f"reads LUT {lut}: {why}"), (where, msg)
        assert "\n" not in msg
    assert "view 'Raw' of display 'sRGB'" in got[str(tmp_path / "view.ocio")]
    assert "look 'grade'" in got[str(tmp_path / "look.ocio")]
    assert "view transform 'film'" in got[str(tmp_path / "view_transform.ocio")]
    assert "named transform 'nt'" in got[str(tmp_path / "named.ocio")]
    assert "colourspace 'inner'" in got[str(tmp_path / "indirect.ocio")]
    assert f"{tmp_path / 'input.ocio'}: its colourspace 'in_cs' reads" in \
        got[str(tmp_path / "input.ocio")]


def test_the_same_configs_with_a_real_lut_build_and_read_it_there(tmp_path):
    """The control: each place is one where OCIO reads the LUT (a good one builds, one of
    random bytes fails there, named in one line, not ``'utf-8' codec can't decode``)."""
    from ocl_tonemap.colour import ColourPipeline, LutFileError
    import PyOpenColorIO as ocio
    lut = _lut(tmp_path, "good")
    for where in PLACES:
        cfg = tmp_path / f"{where}.ocio"
        cfg.write_text(config_text(where, "lut.cube"))
        ocio.ClearAllCaches()
        cp = ColourPipeline(str(cfg), "sRGB", "Raw")
        cp.to_working(np.zeros((1, 1, 3), np.float32), "in_cs")
    os.unlink(lut)
    _lut(tmp_path, "garbage")
    for where in PLACES:
        cfg = str(tmp_path / f"{where}.ocio")
        ocio.ClearAllCaches()
        with pytest.raises(LutFileError) as e:
            cp = ColourPipeline(cfg, "sRGB", "Raw")
            cp.to_working(np.zeros((1, 1, 3), np.float32), "in_cs")
        msg = str(e.value)
        assert msg.startswith(f"{cfg}: its "), msg
        assert f"reads LUT {lut}: OCIO cannot read it: " in msg, msg
        assert "codec" not in msg and "\n" not in msg and "\ufffd" not in msg, msg
        assert msg.isprintable() and len(msg) < 600, msg


def test_a_lut_over_the_cap_is_refused(tmp_path):
    from ocl_tonemap.colour import LUT_CAP, ColourPipeline, LutFileError
    cfg = tmp_path / "view.ocio"
    cfg.write_text(config_text("view", "lut.cube"))
    lut = _lut(tmp_path, "good")
    os.truncate(lut, LUT_CAP + 1)                  # sparse: no disk used
    with pytest.raises(LutFileError, match=rf"reads LUT {lut}: is {LUT_CAP + 1} bytes, "
                       "more than the 256 MiB a LUT can be$"):
        ColourPipeline(str(cfg), "sRGB", "Raw")


def test_an_unreadable_lut_is_refused(tmp_path):
    from ocl_tonemap.colour import ColourPipeline, LutFileError
    cfg = tmp_path / "view.ocio"
    cfg.write_text(config_text("view", "lut.cube"))
    lut = _lut(tmp_path, "good")
    os.chmod(lut, 0)
    try:
        if os.access(lut, os.R_OK):
            pytest.skip("running as root: permissions do not stop a read")
        with pytest.raises(LutFileError, match="cannot be read"):
            ColourPipeline(str(cfg), "sRGB", "Raw")
    finally:
        os.chmod(lut, 0o644)


def test_built_in_configs_have_no_files_and_still_build():
    from ocl_tonemap.colour import ColourPipeline, builtin_config, check_lut_files
    cfg = builtin_config()
    cp = ColourPipeline("ocio://default")
    assert check_lut_files(cp.cfg, cp.working, cp.display, cp.view,
                           __import__("PyOpenColorIO").TRANSFORM_DIR_FORWARD) == []
    assert check_lut_files(cfg, "ACEScg", "ACES2065-1") == []
    ColourPipeline("ocl-tonemap")


# --- through the command ------------------------------------------------------------

def _cli(args):
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, timeout=HANG)
    return p.returncode, p.stderr


def _still(path) -> str:
    buf = oiio.ImageBuf(oiio.ImageSpec(8, 6, 3, oiio.HALF))
    oiio.ImageBufAlgo.fill(buf, (0.18, 0.18, 0.18))
    assert buf.write(str(path)), buf.geterror()
    return str(path)


@pytest.mark.parametrize("kind, why", [("fifo", FIFO),
                                       ("garbage", "OCIO cannot read it: ")])
def test_the_command_refuses_a_fifo_lut_at_once_and_names_a_garbage_one(tmp_path, kind, why):
    inp = _still(tmp_path / "in.exr")
    lut = _lut(tmp_path, kind)
    cfg = tmp_path / "cfg.ocio"
    cfg.write_text(config_text("view", "lut.cube"))
    t0 = time.monotonic()
    rc, err = _cli(["run", inp, str(tmp_path / "o.png"), "--colorconfig", str(cfg),
                    "--display", "sRGB", "--view", "Raw"])
    assert time.monotonic() - t0 < HANG / 2
    assert rc == 2, err
    lines = said(err)
    assert len(lines) == 1, err
    assert lines[0].startswith(f"ocl-tonemap ERROR: {cfg}: its view 'Raw' of display 'sRGB' "
                               f"(through colourspace 'out') reads LUT {lut}: {why}"), err
    assert "Traceback" not in err and "codec" not in err
    assert not (tmp_path / "o.png").exists()
