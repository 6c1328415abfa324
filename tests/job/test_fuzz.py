"""A bounded, seeded fuzz of the front door: command-line arguments and mutated
EXR / Radiance / PNG inputs. Whatever comes in: exit status 0 or 2, no traceback,
no hang, no temporary file left, and no output when it fails."""

import os
import struct

import numpy as np
import OpenImageIO as oiio
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from ocl_tonemap.cli.table import main  # noqa: E402

FUZZ = settings(max_examples=int(os.environ.get("OCLTM_FUZZ_EXAMPLES", "40")), deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    rng = np.random.default_rng(0)
    pix = (10.0 ** rng.uniform(-2, 3, (6, 8, 1)) * rng.uniform(0.2, 1, (6, 8, 3))).astype(np.float32)
    files = {}
    for ext, fmt, nch in ((".exr", oiio.HALF, 4), (".hdr", oiio.FLOAT, 3), (".png", oiio.UINT8, 4)):
        spec = oiio.ImageSpec(8, 6, nch, fmt)
        spec.attribute("whiteLuminance", 100.0)
        buf = oiio.ImageBuf(spec)
        data = np.concatenate([pix / pix.max(), np.full((6, 8, 1), 0.5, np.float32)], axis=2)
        buf.set_pixels(oiio.ROI(0, 8, 0, 6, 0, 1, 0, nch), np.ascontiguousarray(data[..., :nch]))
        p = d / f"base{ext}"
        assert buf.write(str(p))
        files[ext] = p.read_bytes()
    return d, files


def _check(rc, err, out_dir, out_name):
    assert rc in (0, 2), err
    assert "Traceback" not in err and "frame None" not in err
    left = [n for n in os.listdir(out_dir) if ".tmp" in n]
    assert not left, left
    if rc == 2:
        assert not os.path.exists(os.path.join(out_dir, out_name)), err


_SPECIAL = st.sampled_from(["0", "-1", "nan", "inf", "-inf", "1e308", "1e-320", "2000", "0.5",
                           "3", "x", "", "1,2", "auto", "auto:night", "auto:0", "1,1,1", "-0"])
_PLAIN = st.floats(min_value=-1e6, max_value=1e6).map(lambda v: f"{v:g}")
NUMBERS = st.one_of(_PLAIN, _PLAIN, _SPECIAL, st.floats(allow_nan=True, allow_infinity=True).map(repr))
FLAGS = ["--fps", "--exposure", "--luminance-scale", "--display-white", "--display-black",
         "--display-peak", "--sigma-spatial", "--local-strength", "--lut", "--fov",
         "--flare-threshold", "--night-dim", "--target-contrast", "--blue-shift", "--shift-scale",
         "--preadapt", "--metering", "--frames", "--illuminant", "--bilateral-sampling",
         "--channels", "--iscolorspace", "--display", "--view", "--colorconfig"]
CHOICES = [["--operator", "ledda04"], ["--operator", "durand00"], ["--operator", "kirk11"],
           ["--mode", "paper"], ["--flare", "on"], ["--acuity", "on"], ["--purkinje", "auto"],
           ["--chromatic-adaptation", "on"], ["--encode"], ["--no-unpremult"], ["--resume"],
           ["--missing", "skip"], ["--out-bits", "16"], ["--backend", "reference"]]


@FUZZ
@given(flags=st.lists(st.tuples(st.sampled_from(FLAGS), NUMBERS), max_size=4),
       extra=st.lists(st.sampled_from(CHOICES), max_size=3))
def test_fuzzed_arguments(inputs, tmp_path_factory, capsys, flags, extra):
    d, files = inputs
    src = d / "base.exr"
    out_dir = tmp_path_factory.mktemp("o")
    args = ["run", str(src), str(out_dir / "o.png"), "-q"]
    for f, v in flags:
        args += [f, v]
    for e in extra:
        args += e
    try:
        rc = main(args)
    except SystemExit as e:                     # argparse: exit 2 with its usage message
        rc = e.code
    _check(rc, capsys.readouterr().err, str(out_dir), "o.png")


@FUZZ
@given(ext=st.sampled_from([".exr", ".hdr", ".png"]),
       cut=st.one_of(st.none(), st.integers(0, 4000)),
       flips=st.lists(st.tuples(st.integers(0, 4000), st.integers(0, 255)), max_size=6),
       big=st.booleans())
def test_fuzzed_inputs(inputs, tmp_path_factory, capsys, ext, cut, flips, big):
    d, files = inputs
    data = bytearray(files[ext])
    if big and ext == ".exr":                   # a huge declared data window
        i = data.find(b"dataWindow")
        if i >= 0:
            j = i + len(b"dataWindow\0box2i\0") + 4
            data[j + 8:j + 16] = struct.pack("<ii", 2_000_000_000, 2_000_000_000)
    for off, val in flips:
        if off < len(data):
            data[off] ^= val
    if cut is not None:
        data = data[:cut]
    work = tmp_path_factory.mktemp("m")
    src = work / f"in{ext}"
    src.write_bytes(bytes(data))
    try:
        rc = main(["run", str(src), str(work / "o.exr"), "-q", "--luminance-scale", "1"])
    except SystemExit as e:
        rc = e.code
    _check(rc, capsys.readouterr().err, str(work), "o.exr")
    assert src.read_bytes() == bytes(data)      # the input is never touched


# --- state files and shot-store documents ------------------------------------------------

JSON_LEAF = st.one_of(st.none(), st.booleans(), st.integers(-10 ** 12, 10 ** 12),
                      st.floats(allow_nan=False, allow_infinity=False), st.text(max_size=12),
                      st.sampled_from(["../x.exr", "/etc/passwd", "nan", "1e308", ""]))
JSON = st.recursive(JSON_LEAF, lambda kids: st.one_of(
    st.lists(kids, max_size=4), st.dictionaries(st.text(max_size=8), kids, max_size=4)),
    max_leaves=12)


def _mutate(doc, edits):
    """Apply (path into the document, new value or a deletion) edits to a JSON tree."""
    import copy
    doc = copy.deepcopy(doc)
    for keys, value, delete in edits:
        node = doc
        for k in keys[:-1]:
            if isinstance(node, dict) and node:
                node = node[sorted(node)[k % len(node)]]
            elif isinstance(node, list) and node:
                node = node[k % len(node)]
        if isinstance(node, dict) and node:
            key = sorted(node)[keys[-1] % len(node)]
            if delete:
                node.pop(key)
            else:
                node[key] = value
        elif isinstance(node, list) and node:
            node[keys[-1] % len(node)] = value
    return doc


EDITS = st.lists(st.tuples(st.lists(st.integers(0, 30), min_size=1, max_size=4), JSON,
                           st.booleans()), min_size=1, max_size=4)


@pytest.fixture(scope="module")
def seq_state(tmp_path_factory):
    """A 6-frame sequence, the state after it, and a measured shot store."""
    import json

    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("fuzzstate")
    pattern, frames = write_tunnel_sequence(str(d / "scene"), 16, 9, 30.0, 0.2)
    assert main(["run", pattern, str(d / "o.####.png"), "-q", "--operator", "ledda04",
                 "--state-out", str(d / "state.json")]) == 0
    assert main(["measure", pattern, str(d / "m.####.png"), "-q", "--operator", "ledda04",
                 "--store", str(d / "store")]) == 0
    stats = json.loads((d / "store" / "stats" / f"{frames[1]:08d}.json").read_text())
    return d, pattern, json.loads((d / "state.json").read_text()), stats, frames


@FUZZ
@given(edits=EDITS)
def test_fuzzed_state_files(seq_state, tmp_path_factory, capsys, edits):
    import json
    import shutil
    from ocl_tonemap.io.patterns import frame_path
    d, pattern, state, _, frames = seq_state
    work = tmp_path_factory.mktemp("s")
    side = state["extra"].get("pixel_state")
    if side:
        shutil.copy(d / side, work / side)
    (work / "state.json").write_text(json.dumps(_mutate(state, edits)))
    try:
        rc = main(["run", pattern, str(work / "o.####.png"), "-q", "--operator", "ledda04",
                   "--state-in", str(work / "state.json")])
    except SystemExit as e:
        rc = e.code
    _check(rc, capsys.readouterr().err, str(work),
           os.path.basename(frame_path(str(work / "o.####.png"), frames[0])))


@FUZZ
@given(edits=EDITS)
def test_fuzzed_store_documents(seq_state, tmp_path_factory, capsys, edits):
    import json
    import shutil
    d, pattern, _, stats, frames = seq_state
    work = tmp_path_factory.mktemp("st")
    shutil.copytree(d / "store", work / "store")
    p = work / "store" / "stats" / f"{frames[1]:08d}.json"
    p.write_text(json.dumps(_mutate(stats, edits)))
    try:
        rc = main(["integrate", pattern, str(work / "m.####.png"), "-q", "--operator",
                   "ledda04", "--store", str(work / "store")])
    except SystemExit as e:
        rc = e.code
    err = capsys.readouterr().err
    assert rc in (0, 2), err
    assert "Traceback" not in err
    assert not [n for n in os.listdir(work / "store") if ".tmp" in n]
