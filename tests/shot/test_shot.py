"""A shot split into measure -> integrate -> apply (ocl_tonemap/shot/): the frames of
one serial run whatever the chunking, on the real CLI, OIIO, OpenCL (PoCL), a
real Dask LocalCluster and real OpenJD / OpenCue job descriptions."""

import json
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import OpenImageIO as oiio
import pytest

from ocl_tonemap.io.imageio import FrameError

from ocl_tonemap.io.patterns import frame_path
from ocl_tonemap.job.options import JobOptions
from ocl_tonemap.job.run import run_job
from ocl_tonemap.shot import passes
from ocl_tonemap.shot.store import ShotStore
from opencue_chunks import opencue_commands

OPERATORS = ("pattanaik00", "durand00", "ledda04", "kirk11")


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    """The tunnel drive: 1 s at 30 fps, 48x27, entering the tunnel (EXR, cd/m^2)."""
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("shot")
    pattern, frames = write_tunnel_sequence(str(d / "scene"), 48, 27, 30.0, 1.0)
    return d, pattern, frames


def _read(path):
    buf = oiio.ImageBuf(str(path))
    return buf.get_pixels(oiio.FLOAT), buf.spec().getattribute("ocltm:state")


def _serial(d, pattern, op, name="serial", **kw):
    """One serial run with the defaults (every effect on auto: the plan's)."""
    out = d / op / name / "o.####.exr"
    if not out.parent.exists():
        out.parent.mkdir(parents=True)
        run_job(JobOptions(pattern, str(out), operator=op, checkpoint=False, out_bits="float",
                           **kw))
    return out


def _split(d, pattern, op, size, name, keyframe_every=None, **kw):
    out = d / op / name / "o.####.exr"
    out.parent.mkdir(parents=True)
    o = JobOptions(pattern, str(out), operator=op, checkpoint=False, out_bits="float", **kw)
    store = passes.default_store(o)
    frames = [j[0] for j in passes.shot_jobs(o)]
    for c in reversed(passes.chunks(frames, size)):       # any order
        passes.measure(o, store, c)
    passes.integrate(o, store, keyframe_every or size)
    for c in reversed(passes.chunks(frames, size)):
        passes.apply(o, store, c)
    return out, store


def _measured(d, pattern, op, name, keyframe_every=None):
    """(output pattern, options, store) of a shot measured and integrated whole, its
    apply pass left to the test."""
    out = d / op / name / "o.####.exr"
    out.parent.mkdir(parents=True)
    o = JobOptions(pattern, str(out), operator=op, checkpoint=False, out_bits="float")
    store = passes.default_store(o)
    passes.measure(o, store)
    passes.integrate(o, store, keyframe_every)
    return out, o, store


def _same_frames(a, b, frames, tol=0.0):
    worst = 0.0
    for f in frames:
        pa, sa = _read(frame_path(str(a), f))
        pb, sb = _read(frame_path(str(b), f))
        worst = max(worst, float(np.abs(pa - pb).max()))
        if tol == 0.0:
            assert sa == sb, f"frame {f}: the recorded state differs"
    assert worst <= tol, f"largest difference {worst:g} (tolerance {tol:g})"


@pytest.mark.requires_opencl
@pytest.mark.parametrize("op", OPERATORS)
def test_passes_give_the_serial_frames_bit_for_bit(shot, op):
    d, pattern, frames = shot
    ser = _serial(d, pattern, op)
    for size in (1, 7, len(frames)):
        out, _ = _split(d, pattern, op, size, f"c{size}")
        _same_frames(ser, out, frames)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("op", ["ledda04", "pattanaik00"])
def test_state_from_an_earlier_keyframe(shot, op):
    """Apply chunks that do not start at a keyframe (keyframes every 7, chunks of
    5): the nearest keyframe is advanced over the stored statistics. Only the
    keyframes are written, global operators' too (a file and two fsyncs a frame
    in the serial pass before, issue 59)."""
    d, pattern, frames = shot
    ser = _serial(d, pattern, op)
    out, store = _split(d, pattern, op, 5, "kf7", keyframe_every=7)
    assert ShotStore(store).integrated()["keyframes"] == [7, 14, 21, 28, 30]
    assert sorted(p.name for p in ShotStore(store).states_dir.glob("*.json")) == \
        [f"{f:08d}.json" for f in (7, 14, 21, 28, 30)]
    _same_frames(ser, out, frames)


def test_reference_backend_local_operator_within_tolerance(shot):
    """float64 ledda04: statistics exact (.npz), per-pixel keyframes float32."""
    d, pattern, frames = shot
    frames = frames[:12]
    kw = dict(backend="reference", frames=frames)
    ser = _serial(d, pattern, "ledda04", "ref-serial", **kw)
    out, store = _split(d, pattern, "ledda04", 5, "ref-c5", **kw)
    assert any(p.suffix == ".npz" for p in (ShotStore(store).stats_dir).iterdir())
    _same_frames(ser, out, frames, tol=1e-4)


def _goals(path, frames):
    return [json.loads(_read(frame_path(str(path), f))[1])["values"] for f in frames]


@pytest.mark.requires_opencl
def test_cuts_reset_adaptation_serial_and_split_alike(shot, tmp_path):
    """At a cut the observer is fully adapted to the frame, as a fresh observer
    starting there; the serial run (--cuts FILE) and the passes agree."""
    d, pattern, frames = shot
    cut = frames[20]
    cut_run = _serial(d, pattern, "pattanaik00", "cut-serial", cuts=[cut])
    fresh = _serial(d, pattern, "pattanaik00", "fresh-at-cut", frames=frames[20:])
    plain = _serial(d, pattern, "pattanaik00")
    after = _goals(cut_run, frames[20:])
    assert after == _goals(fresh, frames[20:])
    assert _goals(cut_run, frames[:20]) == _goals(plain, frames[:20])
    assert after[0] != _goals(plain, [cut])[0]           # the cut changed something
    out, _ = _split(d, pattern, "pattanaik00", 7, "cut-split", cuts=[cut])
    _same_frames(cut_run, out, frames)


@pytest.mark.requires_opencl
def test_detected_cuts(tmp_path):
    """A shot that jumps from daylight to a dim interior between two frames: one cut,
    there, and nowhere in the tunnel drive's smooth changes."""
    scene = tmp_path / "scene"
    scene.mkdir()
    rng = np.random.default_rng(1)
    base = rng.uniform(0.2, 1.0, (18, 32, 3)).astype(np.float32)
    for f in range(1, 13):
        spec = oiio.ImageSpec(32, 18, 3, oiio.HALF)
        spec.attribute("whiteLuminance", 1.0)
        buf = oiio.ImageBuf(spec)
        buf.set_pixels(oiio.ROI(0, 32, 0, 18, 0, 1, 0, 3),
                       base * (3000.0 if f <= 6 else 3.0) * (1 + 0.02 * f))
        buf.write(str(scene / f"s.{f:04d}.exr"))
    o = JobOptions(str(scene / "s.####.exr"), str(tmp_path / "out" / "s.####.exr"),
                   checkpoint=False, cuts="detect")
    (tmp_path / "out").mkdir()
    store = passes.default_store(o)
    passes.measure(o, store)
    assert passes.integrate(o, store)["cuts"] == [7]
    passes.apply(o, store, (5, 12))
    st7 = json.loads(_read(tmp_path / "out" / "s.0007.exr")[1])["values"]
    st8 = json.loads(_read(tmp_path / "out" / "s.0008.exr")[1])["values"]
    assert st7["A_cone"] == pytest.approx(st8["A_cone"], rel=0.05)   # adapted at once
    with pytest.raises(ValueError, match="detect"):
        run_job(JobOptions(o.input, str(tmp_path / "out" / "x.####.exr"), cuts="detect",
                           checkpoint=False))


@pytest.mark.requires_opencl
def test_tunnel_drive_has_no_detected_cut(shot):
    d, pattern, frames = shot
    docs = []
    o = JobOptions(pattern, str(d / "nocut" / "o.####.exr"), checkpoint=False)
    (d / "nocut").mkdir()
    store = passes.default_store(o)
    passes.measure(o, store)
    docs = [ShotStore(store).read_stats(f)[0] for f in frames]
    assert passes.detect_cuts(docs, frames) == []


@pytest.mark.requires_opencl
def test_store_refuses_other_settings_and_missing_statistics(shot, tmp_path):
    d, pattern, frames = shot
    out = str(tmp_path / "o.####.exr")
    o = JobOptions(pattern, out, operator="ledda04", checkpoint=False)
    store = passes.default_store(o)
    assert passes.measure(o, store, (frames[0], frames[5])) == frames[:6]
    assert passes.measure(o, store, (frames[0], frames[5])) == []      # a retry: nothing redone
    other = JobOptions(pattern, out, operator="ledda04", checkpoint=False,
                       operator_options={"sigma_spatial": 0.1})
    with pytest.raises(ValueError, match="other settings.*options"):
        passes.measure(other, store, (frames[6], frames[7]))
    with pytest.raises(ValueError, match=f"frame {frames[6]} and {len(frames) - 7} more"):
        passes.integrate(o, store)
    with pytest.raises(ValueError, match="integrate"):
        passes.apply(o, store, (frames[0], frames[2]))
    os.remove(ShotStore(store).stats_path(frames[3]))
    assert passes.measure(o, store, (frames[0], frames[5])) == [frames[3]]


@pytest.mark.requires_opencl
def test_a_changed_input_is_measured_again_and_integrate_must_follow(shot, tmp_path):
    d, pattern, frames = shot
    scene = tmp_path / "scene"
    shutil.copytree(os.path.dirname(pattern), scene)
    o = JobOptions(str(scene / os.path.basename(pattern)), str(tmp_path / "o.####.exr"),
                   frames=frames[:6], checkpoint=False)
    store = passes.default_store(o)
    assert passes.measure(o, store) == frames[:6]
    passes.integrate(o, store)
    victim = frame_path(o.input, frames[2])
    st = os.stat(victim)
    os.utime(victim, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))   # re-rendered
    assert passes.measure(o, store) == [frames[2]]
    with pytest.raises(ValueError, match="not been integrated"):
        passes.apply(o, store)


@pytest.fixture(scope="module")
def dusk_shot(tmp_path_factory):
    """The tunnel drive at a thousandth of its light (sunlit road 5, tunnel road 0.005
    cd/m^2): the observer crosses the mesopic range, so the plan turns the Purkinje
    shift, the acuity blur and the lamps' flare on and off within the shot."""
    from ocl_tonemap.io.sample import write_tunnel_sequence
    d = tmp_path_factory.mktemp("dusk")
    pattern, frames = write_tunnel_sequence(str(d / "scene"), 48, 27, 30.0, 2.0)
    return d, pattern, frames


def _effects(path, frames):
    return [json.loads(oiio.ImageBuf(frame_path(str(path), f)).spec().getattribute(
        "ocltm:effects") or "{}") for f in frames]


@pytest.mark.requires_opencl
@pytest.mark.parametrize("model", ["auto", "full"])
@pytest.mark.parametrize("op", OPERATORS)
def test_split_equals_serial_across_the_mesopic_range(dusk_shot, op, model):
    """With the defaults (``--model auto``) and with every effect on (``full``): the
    passes give the serial run's frames bit for bit where the Purkinje shift (its own
    receptor levels), chromatic adaptation and the plan's ramps run, which change the
    frame after its metering from their own time course."""
    from ocl_tonemap.effects import EffectSettings
    d, pattern, frames = dusk_shot
    kw = dict(luminance_scale=1e-3)
    if model == "full":
        kw["effects"] = EffectSettings.for_operator(op, "full")
    ser = _serial(d, pattern, op, f"serial-{model}", **kw)
    if op != "kirk11":      # (kirk11 models the shift itself)
        ran = [e.get("purkinje", {}).get("ran", False) for e in _effects(ser, frames)]
        assert any(ran), "the Purkinje shift never ran: the shot does not test it"
    out, _ = _split(d, pattern, op, 13, f"split-{model}", **kw)
    _same_frames(ser, out, frames)


@pytest.mark.requires_opencl
def test_dask_local_cluster_matches_serial(shot, tmp_path):
    """Two worker processes on PoCL; then a corrupt frame fails with its file and
    frame named, after the retries, and nothing half-written is left."""
    pytest.importorskip("distributed")
    from ocl_tonemap.shot.distributed import run_distributed
    d, pattern, frames = shot
    ser = _serial(d, pattern, "ledda04")
    out = tmp_path / "dask" / "o.####.exr"
    out.parent.mkdir()
    o = JobOptions(pattern, str(out), operator="ledda04", checkpoint=False, out_bits="float")
    res = run_distributed(o, "dask", workers=2, chunk=8)
    assert res.frames == frames and set(res.passes) >= {"measure", "integrate", "apply"}
    _same_frames(ser, out, frames)
    # the run's summary: each pass's tasks and their overhead (issue 59)
    n_tasks = len(passes.chunks(frames, 8))
    assert {k: v["tasks"] for k, v in res.tasks.items()} == {"measure": n_tasks,
                                                             "apply": n_tasks}
    for v in res.tasks.values():
        assert 0.0 < v["setup_s"] < res.passes["apply"] + res.passes["measure"]
        assert v["dask_s"] >= 0.0

    bad = tmp_path / "bad"
    shutil.copytree(os.path.dirname(pattern), bad)
    victim = bad / os.path.basename(frame_path(pattern, frames[9]))
    victim.write_bytes(b"not an image")
    out2 = tmp_path / "dask2" / "o.####.exr"
    out2.parent.mkdir()
    o2 = JobOptions(str(bad / os.path.basename(pattern)), str(out2), checkpoint=False)
    with pytest.raises(FrameError) as e:
        run_distributed(o2, "dask", workers=2, chunk=8, retries=1)
    assert e.value.frame == frames[9] and str(victim) in e.value.path
    assert not [p for p in os.listdir(out2.parent) if ".tmp" in p]


def test_dask_default_chunks_spare_a_local_operators_keyframes():
    """Four tasks a worker by default; a local operator's tasks (each starts at a
    per-pixel keyframe, integrate writes one a chunk) hold at least
    LOCAL_CHUNK_FRAMES frames, at most a worker's share of the shot (issue 59: ledda04,
    30 frames at 1080p on 2 workers in chunks of 4 was 2.5x the serial run)."""
    from ocl_tonemap.shot.distributed import LOCAL_CHUNK_FRAMES, default_chunk
    assert [default_chunk(n, 2, False) for n in (1, 30, 240)] == [1, 4, 30]
    assert default_chunk(30, 2, True) == 15                       # a task a worker
    assert default_chunk(100, 2, True) == LOCAL_CHUNK_FRAMES
    assert default_chunk(1000, 2, True) == 125                    # four a worker again
    assert default_chunk(3, 8, True) == 1
    assert passes.keeps_planes(JobOptions("in.exr", "out.exr", operator="ledda04"))
    assert not passes.keeps_planes(JobOptions("in.exr", "out.exr", operator="pattanaik00"))


def _cli():
    exe = shutil.which("ocl-tonemap", path=os.path.dirname(sys.executable))
    return [exe] if exe else [sys.executable, "-m", "ocl_tonemap"]


def _run(argv):
    r = subprocess.run(argv, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return r


def _farm_job(fmt, shot, tmp_path, chunk, *run_options):
    """``farm-template`` over the shot's first 12 frames: (frames, output, job file)."""
    _, pattern, frames = shot
    frames = frames[:12]
    out = tmp_path / fmt / "o.####.exr"
    out.parent.mkdir()
    job_file = tmp_path / ("job.json" if fmt == "openjd" else "job.xml")
    _run(_cli() + ["farm-template", "--format", fmt, pattern, str(out), "--frames",
                   f"{frames[0]}-{frames[-1]}", "--chunk-frames", str(chunk), "--out-bits",
                   "float", *run_options, "-o", str(job_file), "-q"])
    return frames, out, job_file


@pytest.mark.slow
@pytest.mark.requires_opencl
def test_openjd_template_validates_and_runs_as_a_farm_would(shot, tmp_path):
    pytest.importorskip("openjd.model")
    from openjd.model import (StepParameterSpaceIterator, SymbolTable, create_job,
                              decode_job_template)
    d, pattern, _ = shot
    frames, out, job_file = _farm_job("openjd", shot, tmp_path, 5, "--operator", "ledda04")
    template = decode_job_template(template=json.loads(job_file.read_text()))
    job = create_job(job_template=template, job_parameter_values={})
    assert [s.name for s in job.steps] == ["Measure", "Integrate", "Apply"]
    assert job.steps[1].dependencies[0].dependsOn == "Measure"
    assert job.steps[2].dependencies[0].dependsOn == "Integrate"
    exe = _cli()
    for step in job.steps:                     # in dependency order, tasks one by one
        tasks = list(StepParameterSpaceIterator(space=step.parameterSpace)) \
            if step.parameterSpace else [{}]
        assert len(tasks) == (1 if step.name == "Integrate" else 3)
        for params in tasks:
            st = SymbolTable()
            st["Param.OclTonemapCommand"] = job.parameters["OclTonemapCommand"].value
            for k, v in params.items():
                st[f"Task.Param.{k}"] = v.value
            on = step.script.actions.onRun
            args = [a.resolve(symtab=st) for a in on.args]
            assert on.command.resolve(symtab=st) == "ocl-tonemap"
            _run(exe + args + ["-q"])
    ser = _serial(d, pattern, "ledda04", "serial12", frames=frames)
    _same_frames(ser, out, frames)


#: cjsl-1.14.dtd (OpenCue): the children each element may have, in order.
_CUE_ORDER = {
    "spec": ["facility", "dept", "show", "shot", "user", "email", "uid", "job", "depends"],
    "job": ["paused", "priority", "maxretries", "maxcores", "maxgpus", "autoeat", "localbook",
            "os", "env", "layers"],
    "layer": ["cmd", "range", "chunk", "cores", "threadable", "memory", "gpus", "gpu",
              "gpu_memory", "timeout", "timeout_llu", "tags", "limits", "env", "services",
              "outputs"],
    "depend": ["depjob", "deplayer", "depframe", "onjob", "onlayer", "onframe"],
}


def _check_order(el):
    allowed = _CUE_ORDER.get(el.tag)
    if allowed is not None:
        idx = [allowed.index(c.tag) for c in el]          # unknown child: ValueError
        assert idx == sorted(idx), f"<{el.tag}> children out of the DTD's order"
    for c in el:
        _check_order(c)


@pytest.mark.requires_opencl
def test_opencue_spec_follows_the_dtd_and_runs(shot, tmp_path):
    d, pattern, _ = shot
    frames, out, job_file = _farm_job("opencue", shot, tmp_path, 6)
    root = ET.parse(job_file).getroot()
    _check_order(root)
    for req in ("show", "shot", "user"):
        assert root.find(req) is not None
    layers = root.findall("job/layers/layer")
    assert [(x.get("name"), x.get("type")) for x in layers] == \
        [("measure", "Render"), ("integrate", "Render"), ("apply", "Render")]
    deps = [(x.findtext("deplayer"), x.findtext("onlayer"), x.get("type"))
            for x in root.findall("depends/depend")]
    assert deps == [("integrate", "measure", "LAYER_ON_LAYER"),
                    ("apply", "integrate", "LAYER_ON_LAYER")]
    exe = _cli()
    for layer in layers:                       # OpenCue's chunking of the layer's range
        for argv in opencue_commands(layer):
            assert argv[0] == "ocl-tonemap"
            _run(exe + argv[1:] + ["-q"])
    ser = _serial(d, pattern, "pattanaik00", "serial12", frames=frames)
    _same_frames(ser, out, frames)


@pytest.fixture(scope="module")
def lamp_fade(tmp_path_factory):
    """A dim street (~0.5 cd/m^2) with a small lamp that brightens from 6 to 24 cd/m^2
    over a second, through the flare's source limit, and fades again: the plan's flare
    comes in and goes out with its ramps and hysteresis, frames where its weight is
    neither the frame's own 0 nor 1."""
    from ocl_tonemap.io.patterns import frame_path
    d = tmp_path_factory.mktemp("lampfade")
    pattern = str(d / "scene" / "lamp.####.exr")
    os.makedirs(d / "scene")
    rng = np.random.default_rng(3)
    base = (0.5 * 10.0 ** rng.uniform(-0.5, 0.5, (36, 64, 1)) * np.ones((1, 1, 3)))
    frames = list(range(1, 61))
    for f in frames:
        t = (f - 1) / 29.0
        img = base.copy()
        img[10:13, 30:33] = np.array([1.0, 0.8, 0.5]) * 6.0 * 10.0 ** (0.6 * min(t, 2.0 - t))
        spec = oiio.ImageSpec(64, 36, 3, oiio.FLOAT)
        spec.attribute("whiteLuminance", 1.0)
        spec.attribute("FramesPerSecond", oiio.TypeDesc("rational"), (30, 1))
        buf = oiio.ImageBuf(spec)
        buf.set_pixels(oiio.ROI(0, 64, 0, 36, 0, 1, 0, 3), img.astype(np.float32))
        assert buf.write(frame_path(pattern, f))
    return d, pattern, frames


@pytest.mark.requires_opencl
@pytest.mark.parametrize("op", ["pattanaik00", "durand00"])
def test_flare_ramps_split_as_the_serial_run(lamp_fade, op):
    """The flare changes the light that is metered, with the plan's weight of the frame
    (ramps, hysteresis); the measure pass knows only the frame's own: the integrate
    pass measures the frames where the serial plan weighs the flare otherwise again,
    and the frames are the serial run's bit for bit."""
    d, pattern, frames = lamp_fade
    ser = _serial(d, pattern, op)
    plans = [json.loads(oiio.ImageBuf(frame_path(str(ser), f)).spec().getattribute(
        "ocltm:plan_detail")) for f in frames]
    ramp = [f for f, p in zip(frames, plans) if 0.0 < (p.get("flare_metered") or 0.0) < 1.0]
    assert ramp, "the flare never ramped: the shot does not test the ramps"
    out, store = _split(d, pattern, op, 7, "split")
    again = ShotStore(store).integrated()["measured_again"]
    assert set(ramp) <= set(again)
    _same_frames(ser, out, frames)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("op", ["pattanaik00", "kirk11"])
def test_apply_takes_the_plans_predictions_from_the_store(lamp_fade, op, monkeypatch):
    """The mechanism plan's predictions and analysis depend on the frame alone; the
    measure pass stores them and the apply pass takes them from there instead of
    making them again (predictions ~30 ms a frame at 320x180 on this 2-core PoCL
    machine, the analysis ~6 ms). With the planner's predictions and the analysis
    made impossible during apply, the frames are still the serial run's bit for bit,
    and so are the plan's records in their metadata."""
    from ocl_tonemap.mechanisms import planner
    d, pattern, frames = lamp_fade
    ser = _serial(d, pattern, op)
    out, o, store = _measured(d, pattern, op, "known")
    assert all(ShotStore(store).stats_document(f).get("plan") for f in frames)

    def made(*a, **k):
        raise AssertionError("the apply pass made a frame's predictions or analysis again")
    import ocl_tonemap.mechanisms as mechanisms
    monkeypatch.setattr(planner, "predictions", made)
    monkeypatch.setattr(mechanisms, "analyse", made)      # (the analysis replayed too)
    monkeypatch.setattr(mechanisms, "patches_of", made)
    for c in passes.chunks(frames, 5):
        passes.apply(o, store, c)
    _same_frames(ser, out, frames)
    for f in frames:                       # the plan's record too: what -v and plots show
        a, b = (oiio.ImageBuf(frame_path(str(p), f)).spec() for p in (ser, out))
        for key in ("ocltm:plan", "ocltm:plan_detail", "ocltm:effects"):
            assert a.getattribute(key) == b.getattribute(key), (f, key)


@pytest.mark.requires_opencl
@pytest.mark.parametrize("op,scene", [("pattanaik00", "lamp_fade"), ("durand00", "lamp_fade"),
                                      ("ledda04", "shot"), ("ledda04", "lamp_fade")])
def test_apply_meters_nothing_the_measure_pass_stored(op, scene, request, monkeypatch):
    """Issue 59: the apply pass maps each frame from the statistics its measure pass
    stored (ledda04: the bilateral-filtered adaptation levels, its planes), not from
    a metering of its own. With the schedules' ``measure`` made impossible during
    apply, the frames (and their recorded states) are the serial run's bit for bit;
    the lamp's flare ramps, so the stored statistics of the frames the integrate pass
    measured again are the ones used. Nor is the scene metered before the flare: its
    goals, largest luminance and repairs come from the store too."""
    from ocl_tonemap.backends.opencl import ledda04 as ledda_cl
    from ocl_tonemap.backends import opencl as cl_backend
    d, pattern, frames = request.getfixturevalue(scene)
    ser = _serial(d, pattern, op)
    out, o, store = _measured(d, pattern, op, "stored", keyframe_every=4)

    def metered(*a, **k):
        raise AssertionError("the apply pass metered a frame again")
    monkeypatch.setattr(cl_backend.PointwiseSchedule, "measure", metered)
    monkeypatch.setattr(ledda_cl.LeddaSchedule, "measure", metered)
    # nor the scene metering before the optical effects (the goals the flare and the
    # plan take, the largest luminance, the repair counts): the colour stage only
    monkeypatch.setattr(cl_backend.OpenCLBackend, "meter_pass", metered)
    for c in reversed(passes.chunks(frames, 6)):
        passes.apply(o, store, c)
    _same_frames(ser, out, frames)


@pytest.mark.requires_opencl
def test_store_planes_are_zstd_where_openexr_writes_it(shot):
    """The store's planes (ledda04's adaptation inputs, per-pixel keyframes) are
    lossless zstd where this OpenEXR writes it (3.5+: a quarter of zip's read time
    in the serial integrate pass), else zip; read back exactly either way (the
    bit-for-bit tests above)."""
    import re
    from ocl_tonemap.shot.store import planes_compression, read_compression
    d, pattern, frames = shot
    _serial(d, pattern, "ledda04")
    store = ShotStore(passes.default_store(JobOptions(
        pattern, str(d / "ledda04" / "c7" / "o.####.exr"), operator="ledda04")))
    doc = store.stats_document(frames[0])
    assert doc.get("planes")
    comp = read_compression(store.stats_dir / doc["planes"])
    assert comp == planes_compression()
    kf = sorted(store.states_dir.glob("*.exr"))
    assert kf and all(read_compression(p) == comp for p in kf)
    v = re.search(r"OpenEXR (\d+)\.(\d+)", oiio.get_string_attribute("library_list"))
    if v and (int(v.group(1)), int(v.group(2))) >= (3, 5):
        assert comp == "zstd"
    else:
        assert comp == "zip"


@pytest.mark.requires_opencl
def test_local_cluster_workers_keep_glibcs_dynamic_mmap_threshold():
    """Dask's nanny gives its workers MALLOC_TRIM_THRESHOLD_=65536, which turns off
    glibc's dynamic mmap threshold: every frame-sized array is mapped and unmapped
    again (a measure task ran 1.5x slower in a worker than in the calling process,
    issue 59). The local cluster of ``run --scheduler dask`` starts its workers
    without it, and keeps Dask's other settings for them."""
    pytest.importorskip("distributed")
    import dask
    from ocl_tonemap.shot.distributed import _client
    client, cluster = _client("dask", 1, None)
    try:
        env = next(iter(client.run(lambda: dict(os.environ)).values()))
    finally:
        client.close()
        cluster.close()
    assert "MALLOC_TRIM_THRESHOLD_" not in env
    for k, v in (dask.config.get("distributed.nanny.pre-spawn-environ") or {}).items():
        if k != "MALLOC_TRIM_THRESHOLD_":
            assert env.get(k) == str(v)
