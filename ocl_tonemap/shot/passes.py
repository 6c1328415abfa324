"""A shot in three passes: measure (parallel) -> integrate (serial, cheap) -> apply
(parallel).

Adaptation is a recurrence over time: frame k's state needs every frame before
it. Only the *statistics* the recurrence reads (the metering goals, the
illuminant, for local operators the per-pixel adaptation inputs) need the
pixels, and those do not depend on the state. So:

1. **measure** any frames, on any machine: each frame's statistics, exactly as a
   serial run would measure them (the same code: ``Tonemapper.process(...,
   measure_only=True)``), into the shot's store (``store.py``);
2. **integrate** once, in frame order: the state advanced over the stored
   statistics (the serial run's own ``Tonemapper.integrate``), the state kept
   every ``keyframe_every`` frames and after the last (local operators: with
   their per-pixel planes): one file a keyframe, not a file and two fsyncs a frame;
3. **apply** any chunk of frames: the serial run itself (``run_job``) over the
   chunk, started from the state before the chunk's first frame (the nearest
   keyframe, advanced over the stored statistics to it: chunks of the keyframe
   interval, as Dask's and the farm's are, start at one).

The frames are those of one serial run, bit for bit: the same kernels see the
same inputs (float64 scalars round-trip exactly through JSON, float32 planes
through uncompressed EXR, the reference backend's float64 planes through .npz;
the reference backend's per-pixel *state* keyframes are float32, so ledda04 on
that backend is within 1e-6 instead).

Every effect splits: a frame is metered as it is, before the effects
(``Tonemapper.measure``), so its statistics never depend on the state; the
effects' own time courses (the Purkinje shift's receptor levels, chromatic
adaptation's illuminant, the mechanism plan's weights) are part of the state the
integrate pass advances, from the scene goals and predictions each frame's
statistics carry.

The mechanism plan (``mechanisms/``) is split as the state is: the measure pass
stores each frame's predictions, the integrate pass advances the weights over
them (``Tonemapper.advance_plan``) into the state, and apply starts from it.

Scene cuts (``--cuts FILE`` or ``--cuts detect``): the observer starts afresh at
each cut frame (``Tonemapper.reset_adaptation``), in the serial run as here.
``detect`` finds them from the statistics: a frame whose cone adaptation goal
G_cone differs from the last frame's by more than :data:`CUT_LOG10_JUMP` log10
units (a factor 10 between two frames: no camera move in one frame time, but a
cut from a street to an interior, or day to night). Default: no cuts.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os

from ..backends.planes import band_readable
from ..io.imageio import BandReader, FrameError, read_frame

from ..colour.export import OcioExport
from ..job.banded_io import stream_frame, stream_rows
from ..base.interrupts import ready
from ..job.checkpoint import load_state_in, remove_stale_temps
from ..job.locks import export_lock
from ..job.frame import frame_input, map_frame
from ..job.options import DEFAULT_FPS, run_fingerprint
from ..job.overlap import FrameIO
from ..job.run import run_job, setup_run
from ..job.sequence import frame_jobs, frame_time
from ..operators import registry
from ..io.patterns import is_sequence, without_frame_token
from ..pipeline.state import AUTO_SCALE_KEY
from .frame_stats import (decode_value, encode_value, stats_ahead,  # noqa: F401
                          stats_document, stats_from_document, stored_stats)
from .chunks import chunk_jobs, chunks, frames_after, parse_chunk, shot_lock  # noqa: F401
from .store import ShotStore, input_identity

log = logging.getLogger("ocl_tonemap")

#: ``--cuts detect``: a cut where log10 G_cone jumps by more than this between frames.
CUT_LOG10_JUMP = 1.0
#: The integrate pass keeps the state every this many frames (the farm's chunk; local
#: operators: with their per-pixel planes). A global operator's state is a few KiB,
#: but a file a frame is two fsyncs a frame in the one serial pass (issue 59).
DEFAULT_KEYFRAME_EVERY = 50


# -- the shot and its chunks --------------------------------------------------------------
def keeps_planes(opts) -> bool:
    """Whether the run's operator keeps per-pixel state (a local operator: keyframes)."""
    return bool(registry()[opts.operator].state.planes)


def shot_jobs(opts):
    """Every frame of the shot: ``job.sequence.frame_jobs`` over ``--frames`` (inputs checked)."""
    if not is_sequence(opts.input):
        raise FrameError(opts.input, None, "measure/integrate/apply split a shot: the input "
                         "must be a frame sequence pattern (shot.####.exr)")
    return frame_jobs(opts)


def default_store(opts) -> str:
    """``--store`` default: beside the output, its name without the frame number
    + ``.shot`` (``out/tunnel.####.png`` -> ``out/tunnel.png.shot``)."""
    d, b = os.path.split(opts.output)
    b = without_frame_token(b).strip("._-") or "ocl-tonemap"
    return os.path.join(d, b + ".shot")


def _settings(opts) -> dict:
    """The settings a store belongs to (the serial run's fingerprint)."""
    return run_fingerprint(opts)


# -- 1. measure -----------------------------------------------------------------------------
def _shot_constants(opts, jobs, run, tm, store: ShotStore):
    """(fps, auto calibration constant) of the whole shot, as the serial run fixes
    them on its first frame: from the store when a worker already did."""
    if store.manifest_path.exists():
        man = store.manifest()
        return man["fps"], man.get("luminance_scale_auto")
    f0, inp0, _, held0 = jobs[0]
    reader = BandReader(inp0, f0, opts.channels)
    try:
        fps = opts.fps or reader.header.fps
    finally:
        reader.close()
    fps = fps or DEFAULT_FPS
    auto = run.calibrator.auto_scale
    if auto is None and run.request.auto_level is not None:
        try:
            frame_input(run, tm, read_frame(inp0, f0, opts.channels), inp0)
        except Exception as exc:                                 # noqa: BLE001
            raise FrameError(inp0, f0, exc) from exc
        auto = run.calibrator.auto_scale
    return fps, auto


def measure(opts, store_path: str, chunk=None, redo: bool = False,
            timing: dict | None = None) -> list[int]:
    """The measure pass over the frames of ``chunk`` (all: None): each frame's
    statistics into the store; frames already there are skipped unless ``redo``
    (a retried task does not measure them again) unless ``redo`` or the input file
    changed since (size, modification time); new statistics invalidate an earlier
    integrate. Returns the frames measured; ``timing["setup"]``: the seconds before
    the first frame (the task's overhead: checks, set-up, the store)."""
    import time
    t0 = time.perf_counter()
    jobs = shot_jobs(opts)
    todo = chunk_jobs(jobs, chunk)
    state = load_state_in(opts)
    run, tm = setup_run(opts, state)
    store = ShotStore(store_path)
    fps, auto = _shot_constants(opts, jobs, run, tm, store)
    store.open(_settings(opts), [j[0] for j in jobs], fps, auto)
    remove_stale_temps([], folders=store.folders())    # (a killed pass's, of our naming)
    if auto is not None:
        run.calibrator.auto_scale = auto
    todo = [j for j in todo if redo or not store.stats_current(j[0], _input_stat(j[1], False))]
    todo = [(*j, _input_stat(j[1])) for j in todo]      # (hashed before it is read)
    # the serial run's reads (half as stored, a frame or more ahead on threads) and
    # the store's writes behind (a local operator's planes compress there)
    io = FrameIO(opts.overlap_io, opts.threads)
    if timing is not None:
        timing["setup"] = time.perf_counter() - t0
    with io:
        for k, (f, inp, outp, held, input_stat) in enumerate(todo):
            for j in range(k + 1, min(len(todo), k + 1 + io.ahead)):
                if stream_rows(opts, tm, todo[j][1], todo[j][0]):
                    break                             # (a streamed frame reads itself)
                io.prefetch(j, lambda inp1=todo[j][1], f1=todo[j][0]:
                            read_frame(inp1, f1, opts.channels, io.pool, keep_half=True))

            def read(k=k, inp=inp, f=f):
                return io.read(k, lambda: read_frame(inp, f, opts.channels, io.pool,
                                                     keep_half=True))
            try:
                write = measure_frame(opts, run, tm, store, f, inp, outp, held, fps,
                                      input_stat, read=read, later=True)
            except BaseException:
                io.drain()
                raise
            io.write(write, lambda f=f: ready(f"measured {f}"))
        io.drain()
    return [j[0] for j in todo]


def _input_stat(inp: str, digest: bool = True):
    """The input frame's identity (``store.input_identity``: size, modification time,
    with ``digest`` the BLAKE2b of the file); None where it cannot be stat'ed."""
    return input_identity(inp, digest)


def measure_frame(opts, run, tm, store: ShotStore, f, inp, outp, held, fps, input_stat,
                  weights: dict | None = None, plan: dict | None = None, read=None,
                  later: bool = False):
    """One frame's statistics into the store: as the serial run measures it (read,
    whole or streamed, its optical effects -- the flare -- with the plan's weights of
    the frame itself, or ``weights``; ``plan``: the stored plan record to keep, where
    the frame is measured again by the integrate pass). ``read()``: the frame (read
    ahead), else read here; ``later``: the store's write returned as a function (for
    a writer thread), not done."""
    try:
        rows = stream_rows(opts, tm, inp, f)
        streamed = stream_frame(run, tm, inp, outp, f, held, rows, fps, None,
                                measure_only=True, weights=weights) if rows else None
        if streamed is not None:
            t, stats, _, hint = streamed
        else:
            fr = read() if read is not None else read_frame(inp, f, opts.channels)
            t, _ = frame_time(fr, f, held, fps, None)
            fin = frame_input(run, tm, fr, inp)
            hint = fin.illuminant
            stats = map_frame(tm, fin, t, f, measure_only=True, weights=weights)
            fr = fin = None
        want_illum = tm.effects.settings.chromatic_adaptation != "off"
        illum = stats.illuminant() if (want_illum and stats.illuminant) else None
        doc = stats_document(stats, illum, hint, t, held, inp)
        doc["input_stat"] = input_stat
        rec = tm.frame_plan
        doc["flare_metered"] = rec.get("flare_metered")
        if plan is not None:
            doc["plan"] = plan
        elif rec.get("predicted_dE_p99") is not None:
            doc["plan"] = {"predicted": rec["predicted_dE_p99"],
                           "G_cone": rec["analysis"]["G_cone"], "sig": rec.get("sig"),
                           "analysis": encode_value(rec["analysis"])}
        planes = tm.schedule.stats_planes(stats)     # (host copies: the device moves on)
    except FrameError:
        raise
    except Exception as exc:
        raise FrameError(inp, f, exc) from exc

    def write():
        try:
            store.write_stats(f, doc, planes)
        except Exception as exc:
            raise FrameError(inp, f, exc) from exc
    if later and not band_readable(planes):       # (a streamed frame's band store: now)
        return write
    write()
    return None


# -- 2. integrate ---------------------------------------------------------------------------
def detect_cuts(docs: list[dict], frames: list[int]) -> list[int]:
    """Frames whose G_cone differs from the previous frame's by more than
    :data:`CUT_LOG10_JUMP` log10 units."""
    out = []
    for k in range(1, len(docs)):
        a, b = docs[k - 1]["G_cone"], docs[k]["G_cone"]
        if a > 0 and b > 0 and abs(math.log10(b / a)) > CUT_LOG10_JUMP:
            out.append(frames[k])
    return out


def _flare_weight(tm) -> float:
    """The flare's weight in the frame the serial run meters, from the plan's weights
    just advanced (``pipeline.metered_weight``'s)."""
    fx = tm.effects
    return float(fx.weight("flare")) if fx.s.flare != "off" else 0.0


#: States the integrate pass writes behind its step, at most (memory: a 1080p
#: ledda04 keyframe is ~83 MB).
WRITES_BEHIND = 2


def _advance(tm, store: ShotStore, jobs, cuts, auto, after=None, remeasure=None) -> None:
    """The serial run's state step over stored statistics, frame by frame, in the
    serial run's order (the plan's weights, then the observer and the effects);
    ``after(k, frame, effects)`` once each frame's state is final (its mapping frozen
    in ``tm``: ``Tonemapper.last_mapping``; ``effects``: the frame's effect records).

    A frame's statistics were measured with its flare at the weight of the frame's
    own plan (the measure pass knows no state); where the serial run's plan weighs
    it otherwise (a ramp, hysteresis: a few frames where the flare comes and goes),
    ``remeasure(k, frame, weights)`` measures it again with the serial weights
    (the integrate pass); without it such a frame is an error."""
    cuts = set(cuts or ())
    ahead = stats_ahead(store, [j[0] for j in jobs])
    for k, (f, _inp, _outp, _held) in enumerate(jobs):
        doc, planes = ahead(k)
        if f in cuts and tm.adapted:
            tm.reset_adaptation()
        if auto is not None:
            tm.remember(AUTO_SCALE_KEY, float(auto))
        time_s, dt, fresh = tm.frame_clock(None, float(doc["time_s"]))
        tm.effects.begin_frame(None)
        weights = None
        if doc.get("plan"):
            weights = tm.advance_plan(doc["plan"]["predicted"], doc["plan"]["G_cone"], dt,
                                      fresh, doc["plan"].get("sig"))
        metered = doc.get("flare_metered")
        if metered is not None and metered != _flare_weight(tm):
            if remeasure is None:
                raise ValueError(f"frame {f}'s statistics were measured with another flare "
                                 f"weight than the integrated plan's: run the integrate "
                                 f"pass again")
            remeasure(k, f, weights)
            doc, planes = store.read_stats(f)
            tm.effects.begin_frame(weights)
        stats, hint = stats_from_document(doc, planes, tm.schedule)
        eff: dict = {}
        tm.freeze_mapping(stats, *tm.integrate(stats, time_s, f, dt, fresh, hint, eff))
        if after is not None:
            after(k, f, eff)


def integrate(opts, store_path: str, keyframe_every: int | None = None) -> dict:
    """The integrate pass: the state advanced over every frame of the shot, kept in
    the store at keyframes every ``keyframe_every`` frames and at the last (local
    operators: with their per-pixel planes). Needs every frame measured. Returns
    the integrate record."""
    jobs = shot_jobs(opts)
    frames = [j[0] for j in jobs]
    store = ShotStore(store_path)
    man = store.manifest()
    store.check(man, _settings(opts), frames)
    remove_stale_temps([], folders=store.folders())    # (a killed pass's, of our naming)
    missing = store.missing_stats(frames)
    if missing:
        more = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
        raise ValueError(f"frame {missing[0]}{more} of the shot have no statistics in "
                         f"{store.path}: run the measure pass over them first")
    inputs = store.check_inputs(jobs, None, (opts.input, opts.output))   # (as measured)
    cuts = opts.cuts
    if cuts == "detect":
        docs = [store.read_stats(f)[0] for f in frames]
        cuts = detect_cuts(docs, frames)
        log.info("cuts detected (|d log10 G_cone| > %g): %s", CUT_LOG10_JUMP,
                 ", ".join(map(str, cuts)) or "none")
    cuts = sorted(set(cuts or ()))
    state = load_state_in(opts)
    o = dataclasses.replace(opts, cuts=cuts)
    run, tm = setup_run(o, state)
    if man.get("luminance_scale_auto") is not None:
        run.calibrator.auto_scale = man["luminance_scale_auto"]
    local = bool(tm.op.state.planes)
    every = max(1, int(keyframe_every or DEFAULT_KEYFRAME_EVERY))
    keyframes = []
    again = []

    def remeasure(k, f, weights):
        _, inp, outp, held = jobs[k]
        doc, _ = store.read_stats(f)
        measure_frame(opts, run, tm, store, f, inp, outp, held, man["fps"],
                      doc.get("input_stat"), weights or {}, doc.get("plan"))
        again.append(f)
    n = len(jobs)

    # the states are written behind the step (a 1080p keyframe is ten planes, ~0.3 s
    # to compress and write): at most WRITES_BEHIND in flight, the first failure raised
    from collections import deque
    from concurrent.futures import ThreadPoolExecutor
    writer = ThreadPoolExecutor(1, thread_name_prefix="ocltm-states")
    pending: deque = deque()

    def after(k, f, _eff):
        ready(f"integrated {f}")
        if not ((k + 1) % every == 0 or k + 1 == n):
            return
        snap = tm.state if local else tm.scalar_state()     # (copies)
        while len(pending) >= WRITES_BEHIND:
            pending.popleft().result()
        pending.append(writer.submit(store.write_state, f, snap))
        keyframes.append(f)
    try:
        _advance(tm, store, jobs, cuts, man.get("luminance_scale_auto"), after, remeasure)
        while pending:
            pending.popleft().result()
    finally:
        writer.shutdown(wait=True)              # (a write in flight completes, renamed whole)
    if again:
        log.info("integrate: %d frame(s) measured again with the plan's flare weight "
                 "(its ramps): %s", len(again), ", ".join(map(str, again[:20])))
    doc = {"frames": frames, "keyframes": keyframes, "cuts": cuts, "measured_again": again,
           "inputs": inputs,
           "cut_rule": f"|log10 G_cone jump| > {CUT_LOG10_JUMP}" if opts.cuts == "detect"
           else ("given" if cuts else "none"), "per_pixel": local}
    store.write_integrated(doc)
    return doc


# -- 3. apply -------------------------------------------------------------------------------
def start_state(opts, store: ShotStore, jobs, k0: int, integ: dict):
    """The state before ``jobs[k0]``: the stored one after the frame before it (a
    local operator's nearest keyframe, advanced over the stored statistics)."""
    if k0 == 0:
        return load_state_in(opts)
    prev = jobs[k0 - 1][0]
    keys = [f for f in integ["keyframes"] if f <= prev]
    if not keys:                                   # before the first keyframe
        base, k_from = load_state_in(opts), 0
    else:
        base = store.read_state(keys[-1])
        k_from = [j[0] for j in jobs].index(keys[-1]) + 1
    if k_from == k0:
        return base
    o = dataclasses.replace(opts, cuts=integ["cuts"])
    _, tm = setup_run(o, base)
    _advance(tm, store, jobs[k_from:k0], integ["cuts"],
             store.manifest().get("luminance_scale_auto"))
    return tm.state


def _integrated(opts, store_path: str):
    """(options, jobs, store, manifest, integrate record) of a shot whose integrate
    pass is done over the same frames."""
    jobs = shot_jobs(opts)
    frames = [j[0] for j in jobs]
    store = ShotStore(store_path)
    man = store.manifest()
    store.check(man, _settings(opts), frames)
    integ = store.integrated()
    if integ.get("frames") != frames:
        raise ValueError(f"the shot store {store.path} was integrated over other frames: "
                         "run the integrate pass again")
    store.check_inputs(jobs, integ.get("inputs"), (opts.input, opts.output))
    return opts, jobs, store, man, integ


def export(opts, store_path: str, chunk=None) -> tuple:
    """The export pass (``--ocio-export DIR``): the observer as an OCIO view from the
    integrated store, no frame mapped or written. Each frame of ``chunk`` is read (for
    its lattices' nodes and the check of its CLF), its mapping frozen from the stored
    state and statistics, and exported. Returns (OcioExport, seconds per frame spent
    reading, seconds per frame exporting)."""
    import time
    opts, jobs, store, man, integ = _integrated(opts, store_path)
    todo = chunk_jobs(jobs, chunk)
    k0 = jobs.index(todo[0])
    o = dataclasses.replace(opts, fps=man["fps"], cuts=integ["cuts"])
    run, tm = setup_run(o, start_state(opts, store, jobs, k0, integ))
    remove_stale_temps([], folders=[opts.ocio_export])
    ex = OcioExport(opts.ocio_export, run.colour, tm, jobs[0][0], opts.ocio_export_size)
    spent = {"read": 0.0, "export": 0.0}

    def after(k, f, eff):
        _, inp, _, _ = todo[k]
        t0 = time.perf_counter()
        fr = read_frame(inp, f, opts.channels)
        fin = frame_input(run, tm, fr, inp)
        t1 = time.perf_counter()
        ic = None if fr.rgb_from_spectrum else run.input_colour(fr, inp)
        ex.add_frame(f, fin.pixels, fin.scale, eff, ic,
                     file_pixels=None if ic is None else fr.pixels)   # (as a replay reads it)
        spent["read"] += t1 - t0
        spent["export"] += time.perf_counter() - t1
    with export_lock(opts.ocio_export, "export", (store_path, _settings(opts)),
                     (todo[0][0], todo[-1][0])):
        _advance(tm, store, todo, integ["cuts"], man.get("luminance_scale_auto"), after)
    n = max(len(todo), 1)
    return ex, spent["read"] / n, spent["export"] / n


def apply(opts, store_path: str, chunk=None, within: str | None = None):
    """The apply pass over ``chunk`` (all: None): the serial run over its frames
    from the integrated state. Returns the run's JobResult (``setup_s``: the
    seconds before its first frame, the state before the chunk included)."""
    import time
    t0 = time.perf_counter()
    opts, jobs, store, man, integ = _integrated(opts, store_path)
    todo = chunk_jobs(jobs, chunk)
    k0 = jobs.index(todo[0])
    state = start_state(opts, store, jobs, k0, integ)
    o = dataclasses.replace(opts, fps=man["fps"], cuts=integ["cuts"], checkpoint=False,
                            resume=False, state_in=None, state_out=None, plot=None)
    docs = {f: store.stats_document(f) for f, *_ in todo}
    known = {f: {**d["plan"], "analysis": decode_value(d["plan"].get("analysis"))}
             for f, d in docs.items() if d.get("plan")}
    before = time.perf_counter() - t0
    with shot_lock(opts, store_path, todo, "apply", within):
        res = run_job(o, jobs=todo, state=state, plans=known,
                      stored_stats=stored_stats(store, [f for f, *_ in todo], docs))
    res.setup_s += before
    return res
