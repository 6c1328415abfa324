"""State files checked like options (issue 58, part 7): the fields of an adaptation
state are declared (``state.VALUES``, ``state.FIELDS``) and checked on every load (a
checkpoint on --resume, --state-in, an output frame's ``ocltm:state``, the shot
store's states); a bad one is refused in one line naming the file and the field,
exit 2; every state the tool writes loads back; a resume point outside the shot is
refused."""

import json
import math
import os
import subprocess
import sys

import OpenImageIO as oiio
import pytest

from ocl_tonemap.job.options import JobOptions
from ocl_tonemap.job.run import run_job
from ocl_tonemap.operators import registry
from ocl_tonemap.base.quantities import Quantity
from ocl_tonemap.pipeline.state import FIELDS, VALUES, AdaptationState
from ocl_tonemap.io.state_files import load_state, save_state

OPERATORS = sorted(registry())


def _cli(args, cwd=None):
    p = subprocess.run([sys.executable, "-m", "ocl_tonemap", *args], capture_output=True,
                       text=True, cwd=cwd, timeout=600)
    return p.returncode, p.stderr


def _one_error(rc, err, *words):
    assert rc == 2, err
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "ERROR" in lines[0], err
    for w in words:
        assert w in lines[0], err
    return lines[0]


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    """8 frames of the tunnel sample at 48x27 (EXR, cd/m^2)."""
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("seq")
    pattern, frames = write_tunnel_sequence(str(d), 48, 27, 8.0, 1.0)
    assert frames == list(range(1, 9))
    return pattern


def test_every_operators_state_fields_are_declared():
    """Each built-in operator's ``StateSpec.scalars`` is declared with its range."""
    for name, cls in registry().items():
        for k in cls.state.scalars:
            assert isinstance(VALUES.get(k), Quantity), f"{name}: {k} is not declared"
    for k, q in VALUES.items():
        assert q.lo >= 0.0 and math.isfinite(q.hi), k
    assert isinstance(FIELDS["time_s"], Quantity) and isinstance(FIELDS["frame"], Quantity)


@pytest.mark.requires_opencl
def test_the_states_the_tool_writes_load_back(seq, tmp_path):
    """Every operator with the default effects (the plan, the Purkinje levels, the
    illuminant, ledda04's per-pixel state): the --state-out JSON and the last output
    frame's ocltm:state load back with the same values."""
    seen_extra = set()
    for op in OPERATORS:
        out, st_path = tmp_path / op / "o.####.exr", tmp_path / f"{op}.json"
        run_job(JobOptions(seq, str(out), operator=op, state_out=str(st_path),
                           frames=[1, 2, 3, 4]))
        doc = json.loads(st_path.read_text())
        seen_extra |= set(doc["extra"])
        st = load_state(st_path)
        assert st.operator == op and st.frame == 4 and st.values == doc["values"]
        assert (st.pixels is not None) == bool(cls_planes(op))
        head = load_state(tmp_path / op / "o.0004.exr")
        assert head.values == pytest.approx(st.values) and head.frame == 4
        # the store's way (a shot's states): written and read back
        save_state(st, tmp_path / f"{op}.again.json", checkpoint=True)
        again = load_state(tmp_path / f"{op}.again.json")
        assert again.values == st.values
    assert {"plan", "purkinje_levels", "pixel_state", "illuminant_rgb"} <= seen_extra


def cls_planes(op):
    return registry()[op].state.planes


def _good_doc():
    return AdaptationState("pattanaik00", {"A_rod": 1.0, "A_cone": 2.0, "B_rod": 0.5,
                                           "B_cone": 0.9}, 0.1, 3, {}).to_json()


@pytest.mark.parametrize("change, words", [
    (lambda d: d["values"].__setitem__("A_cone", -5), ("values.A_cone", "got -5")),
    (lambda d: d["values"].__setitem__("A_cone", float("nan")), ("values.A_cone", "nan")),
    (lambda d: d["values"].__setitem__("A_cone", "5"), ("values.A_cone", "a number")),
    (lambda d: d["values"].__setitem__("B_rod", 2.0), ("values.B_rod", "0..1")),
    (lambda d: d["values"].pop("A_cone"), ("values.A_cone", "missing")),
    (lambda d: d["values"].__setitem__("L_wa", 1.0), ("values.L_wa", "not a field")),
    (lambda d: d.pop("values"), ("values is missing",)),
    (lambda d: d.__setitem__("frame", 1.5), ("frame", "whole number")),
    (lambda d: d.__setitem__("time_s", float("inf")), ("time_s",)),
    (lambda d: d.__setitem__("operator", "nope"), ("operator", "nope")),
    (lambda d: d["extra"].__setitem__("purkinje_levels", {"A_rod": -1}),
     ("extra.purkinje_levels",)),
])
def test_a_bad_state_is_refused_naming_the_file_and_the_field(tmp_path, change, words):
    doc = _good_doc()
    change(doc)
    p = tmp_path / "s.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as e:
        load_state(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg, msg
    for w in words:
        assert w in msg, msg


@pytest.fixture(scope="module")
def checkpoint(seq, tmp_path_factory):
    """A run of frames 1-4 of the 8: its checkpoint (frame 4), as a resume finds it."""
    d = tmp_path_factory.mktemp("ck")
    rc, err = _cli(["run", seq, str(d / "o.####.png"), "--frames", "1-4", "-q"])
    assert rc == 0, err
    doc = json.loads((d / "o.png.state.json").read_text())
    assert doc["frame"] == 4
    return doc


def _bad(doc, key, value, out=None):
    """The checkpoint with one field changed, written for a run on ``out`` (the
    settings of the run it names)."""
    doc = json.loads(json.dumps(doc))
    if out is not None:
        doc["extra"]["run"]["output"] = str(out)
    if value is _MISSING:
        doc["values"].pop(key)
    elif key == "frame":
        doc["frame"] = value
    else:
        doc["values"][key] = value
    return json.dumps(doc).replace('"__nan__"', "NaN")


_MISSING = object()


@pytest.mark.requires_opencl
@pytest.mark.parametrize("value, why", [(-5, "got -5"), ("__nan__", "got nan"),
                                        ("5", "must be a number"), (_MISSING, "missing")])
def test_resume_refuses_a_bad_checkpoint_in_one_line(seq, checkpoint, tmp_path, value, why):
    """A checkpoint with A_cone -5 (or NaN, a string, missing), then --resume: one line
    naming the checkpoint and the field, exit 2, no frame written; --state-in alike."""
    out = tmp_path / "o.####.png"
    ck = tmp_path / "o.png.state.json"
    ck.write_text(_bad(checkpoint, "A_cone", value, out))
    rc, err = _cli(["run", seq, str(out), "--resume", "-q"])
    _one_error(rc, err, str(ck), "values.A_cone", why)
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".png")]
    rc, err = _cli(["run", seq, str(tmp_path / "in" / "o.####.png"), "--state-in", str(ck),
                    "-q"])
    _one_error(rc, err, str(ck), "values.A_cone", why)
    assert not (tmp_path / "in").exists()          # (no folder left behind either)


@pytest.mark.requires_opencl
def test_resume_refuses_a_point_outside_the_shot(seq, checkpoint, tmp_path):
    """A checkpoint at frame 99 of a shot of 8: refused in one line naming the
    checkpoint, its frame and the shot's frames (it used to write 0 frames, exit 0)."""
    ck = tmp_path / "o.png.state.json"
    out = tmp_path / "o.####.png"
    ck.write_text(_bad(checkpoint, "frame", 99, out))
    rc, err = _cli(["run", seq, str(out), "--resume", "-q"])
    _one_error(rc, err, str(ck), "frame 99", "1-8")
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".png")]
    # the checkpoint as written resumes after frame 4: frames 5-8
    ck.write_text(_bad(checkpoint, "frame", 4, out))
    rc, err = _cli(["run", seq, str(out), "--resume", "-q"])
    assert rc == 0, err
    assert sorted(n for n in os.listdir(tmp_path) if n.endswith(".png")) == \
        [f"o.{f:04d}.png" for f in range(5, 9)]


@pytest.mark.requires_opencl
def test_an_output_frames_state_is_checked(seq, tmp_path):
    """``--state-in`` an output frame whose ocltm:state says A_cone = -5: refused
    naming the frame and the field."""
    run_job(JobOptions(seq, str(tmp_path / "o.####.exr"), frames=[1, 2], checkpoint=False))
    src = tmp_path / "o.0002.exr"
    buf = oiio.ImageBuf(str(src))
    doc = json.loads(buf.spec().getattribute("ocltm:state"))
    doc["values"]["A_cone"] = -5
    buf.specmod().attribute("ocltm:state", json.dumps(doc))
    bad = tmp_path / "bad.exr"
    assert buf.write(str(bad))
    with pytest.raises(ValueError) as e:
        load_state(bad)
    assert str(bad) in str(e.value) and "values.A_cone" in str(e.value)
    rc, err = _cli(["run", seq, str(tmp_path / "p.####.png"), "--state-in", str(bad), "-q"])
    _one_error(rc, err, str(bad), "values.A_cone")


def test_the_shot_stores_states_are_checked(tmp_path):
    """A shot store's state file with a level out of range, or holding another
    frame's state: refused naming the file."""
    from ocl_tonemap.shot.store import ShotStore
    store = ShotStore(str(tmp_path / "o.png.shot"))
    os.makedirs(store.states_dir, exist_ok=True)
    st = AdaptationState.from_json(_good_doc())
    store.write_state(3, st)
    assert store.read_state(3).values == st.values
    p = store.state_path(3)
    doc = json.loads(p.read_text())
    doc["values"]["A_rod"] = -1.0
    p.write_text(json.dumps(doc))
    with pytest.raises(ValueError) as e:
        store.read_state(3)
    assert str(p) in str(e.value) and "values.A_rod" in str(e.value)
    store.write_state(5, st)                 # frame 3's state under frame 5's name
    with pytest.raises(ValueError) as e:
        store.read_state(5)
    assert str(store.state_path(5)) in str(e.value) and "frame 3" in str(e.value)
