"""The main job: tone map an image or a frame sequence file to file.

read (OIIO) -> OCIO to working space -> x luminance scale = cd/m^2 -> meter ->
advance state -> per-pixel operator -> display-linear -> OCIO display/view ->
write (OIIO, atomic). Every failure names its file and frame.
"""

from __future__ import annotations

import logging
import os
import sys
import time

from ..base import interrupts, safeio
from ..backends.select import resolve_backend
from ..colour import ColourPipeline
from ..io.imageio import FrameError, read_frame
from ..io.imagewrite import ocltm_metadata, output_bits, write_frame
from ..base.interrupts import Terminated, ready
from ..models.metering import MeteringSpec
from ..models.photometry import RepairCounts
from ..io.patterns import is_sequence
from ..pipeline import FrameInfo, Tonemapper
from ..io.plot import plot_adaptation
from .visibility_out import (check_visibility, frame_request, frame_visibility,
                             target_visibility, view_pixels, visibility_path, write_view,
                             write_visibility)
from ..pipeline.state import AdaptationState
from ..io.state_files import save_state
from .banded_io import read_whole, stream_frame, stream_rows
from .checkpoint import (RunLock, check_state_paths, checkpoint_path, checkpoint_state,
                         load_state_in, remove_stale_temps, resume_point)
from .frame import encode_pixels, export_frame, frame_input, map_frame, output_metadata
from .options import (RUN_KEY, Interrupted, JobOptions, JobResult, output_is_linear,
                      run_fingerprint, transfers_line)
from .overlap import FrameIO
from .sequence import frame_jobs, frame_time
from .setup import RunSetup, check_output_depth, check_output_tag
from .views import still_view, view_from_header

log = logging.getLogger("ocl_tonemap")


def make_tonemapper(opts: JobOptions, colour: ColourPipeline, state, disp) -> Tonemapper:
    tm = Tonemapper(opts.operator, opts.backend, opts.metering, disp, opts.preadapt, state,
                    opts.device, opts.max_band_pixels, opts.operator_options, opts.effects,
                    quality=opts.quality)
    tm.set_display_primaries(colour.display_primaries())
    log.info("quality %s; backend: %s", tm.quality, tm.backend.describe())
    log.info("OCIO: working %s, display %r view %r -> %s", colour.working, colour.display,
             colour.view, colour.output_colorspace)
    log.info("display: white %g cd/m^2, black %g cd/m^2%s", disp.white_cd, disp.black_cd,
             " (Pattanaik 2000's CRT)" if disp.paper_crt else "")
    return tm


def setup_run(opts: JobOptions, state: AdaptationState | None):
    """What a run sets up once: (RunSetup, Tonemapper from ``state``)."""
    opts = view_from_header(opts)
    run = RunSetup(opts, state.extra if state is not None else None)
    return run, make_tonemapper(opts, run.colour, state, run.disp)


def kernels_key(tm: Tonemapper) -> str:
    """What decides the kernels a run asks for, device aside (the runtime's): its
    settings as given, before any frame (the plan turns ``auto`` effects on and off)."""
    return "|".join((tm.operator_name, tm.quality, repr(tm.effects.s),
                     repr(sorted(tm.options.items()))))


def prepare_kernels(tm: Tonemapper, key: str, stop) -> None:
    """While the first frame is read (until ``stop()``): the kernels the last run of
    ``key`` asked for, loaded from the cache (``Runtime.warm_kernels``; a 4K frame's
    ~40 ms of program loads), and a module its first frame imports (NumPy's
    percentile, in the mechanism plan, brings in numpy.ma: ~15 ms)."""
    import numpy.ma  # noqa: F401
    rt = tm.backend.device_runtime()
    if rt is not None and not stop():
        rt.warm_kernels(key, stop)


def resolved_backend(opts: JobOptions) -> JobOptions:
    """``opts`` with a backend of "auto" (``cli.options.job_options(defer_backend=True)``) resolved:
    OpenCL on the first working device, else the reference with one warning."""
    if opts.backend != "auto":
        return opts
    import dataclasses

    return dataclasses.replace(opts, backend=resolve_backend("auto", opts.device))


def check_read_files(opts: JobOptions) -> None:
    """The files a run reads besides its frames (``--metering mask:``, ``--state-in``),
    each a regular file, checked before anything opens one (``safeio.check_input``: a
    FIFO is refused, never waited on); the frames are checked as each is read
    (``imageio.check_readable``), the OCIO config where it is loaded
    (``colour.config.load_config``: a name such as ``ocl-tonemap`` is no path), cut
    lists and checkpoints where they are read (``safeio.read_text``, ``load_state``)."""
    try:
        mask = MeteringSpec.parse(opts.metering).mask if isinstance(opts.metering, str) \
            else getattr(opts.metering, "mask", None)
    except ValueError:
        mask = None                      # (refused in its own words where it is used)
    for p in (mask, opts.state_in):
        if p:
            safeio.check_input(p)


def check_stills(opts: JobOptions) -> None:
    """``--stills``: independent frames keep no state; what needs one is refused."""
    for flag, given in (("--state-in", opts.state_in), ("--state-out", opts.state_out),
                        ("--resume", opts.resume), ("--cuts", opts.cuts),
                        ("--plot", opts.plot)):
        if given:
            raise ValueError(f"--stills: every frame is its own observer, with no state "
                             f"over time; {flag} has nothing to work on (run the frames "
                             "left again with --frames to finish an interrupted run)")


def run_job(opts: JobOptions, jobs=None, state: AdaptationState | None = None,
            plans: dict | None = None, stored_stats=None) -> JobResult:
    """The main job. Writes the state after every frame (``checkpoint_path``); SIGINT
    and SIGTERM end it after the frame in flight (:class:`Interrupted`).
    ``jobs`` (a slice of ``frame_jobs(opts)``) and ``state`` (to start from, over
    ``--state-in``): one chunk of a shot (``shot/passes.py`` apply), with the
    ``plans``: its frames' mechanism plans as its measure pass stored them (frame ->
    {"predicted", "sig", "analysis"}: not made again) and ``stored_stats(frame)``:
    its statistics as that
    pass measured them (None: measured here), where the operator's schedule maps
    from them (``applies_stored``)."""
    t_start = time.perf_counter()
    whole = jobs is None
    jobs = frame_jobs(opts) if jobs is None else list(jobs)
    check_read_files(opts)
    # a still keeps its state in its own metadata (ocltm:state): no side file unless
    # asked for (--state-out); a sequence checkpoints it beside its frames
    still = (not is_sequence(opts.input) and len(jobs) == 1 and not opts.resume) or opts.stills
    if opts.stills:
        check_stills(opts)
    ckpt = checkpoint_path(opts) if ((opts.checkpoint and not still) or opts.resume) else None
    if whole:
        interrupts.checkpoint = ckpt
    interrupts.temp_folders.update(os.path.dirname(os.path.abspath(p)) for p in
                                   {j[2] for j in jobs} | {ckpt, opts.state_out} if p)
    if not whole:                    # a chunk of a shot's apply pass: the chunks run together
        return _run_job(opts, jobs, state, ckpt, t_start, chunk=True, plans=plans,
                        stored_stats=stored_stats)
    single = not is_sequence(opts.input) and len(jobs) == 1
    if single and not ckpt and not opts.state_out:   # a still makes no side file, not even
        return _run_job(opts, jobs, state, ckpt, t_start)   # a lock (its write is atomic)
    with RunLock(ckpt or opts.state_out or checkpoint_path(opts), output=opts.output,
                 export=opts.ocio_export):
        return _run_job(opts, jobs, state, ckpt, t_start)


def _run_job(opts: JobOptions, jobs, state, ckpt, t_start, chunk: bool = False,
             plans: dict | None = None, stored_stats=None) -> JobResult:
    # (the default checkpoint's too: a still that writes none cleans a killed run's)
    remove_stale_temps(jobs, [p for p in {ckpt, opts.state_out, checkpoint_path(opts)} if p])
    check_state_paths(jobs, [p for p in {ckpt, opts.state_out} if p], opts.plot,
                      [opts.state_in, opts.colorconfig])
    if state is None:
        state = load_state_in(opts)
    else:
        state.extra.pop(RUN_KEY, None)
    check_visibility(opts, jobs)
    done_before: list = []
    if opts.resume:
        opts = resolved_backend(opts)              # (its fingerprint names the backend)
        all_jobs = jobs
        st, jobs = resume_point(opts, jobs, ckpt, opts.operator)
        state = st if st is not None else state
        done_before = [j for j in all_jobs if j not in jobs]
    if opts.ocio_export:                    # refused before any device work
        from ..colour.export import ExportError, operator_blocker  # lazy: only with --ocio-export
        why = operator_blocker(opts.operator)
        if why:
            raise ExportError(f"--ocio-export: {why}")
    io = FrameIO(opts.overlap_io, opts.threads)
    try:
        if jobs and read_whole(opts, jobs[0][1]):   # the first frame read while the run
            f0, inp0 = jobs[0][0], jobs[0][1]       # sets up (its errors come at its turn)
            io.prefetch(0, lambda: read_frame(inp0, f0, opts.channels, io.pool, keep_half=True))
        opts = resolved_backend(opts)              # the device probed behind the read
        run, tm = setup_run(opts, state)
        plans = plans or {}                        # (a shot's apply pass: from its store)
        tm.plan.known = {f: p["predicted"] for f, p in plans.items()}
        tm.plan.replay = {f: (p["analysis"], p.get("sig")) for f, p in plans.items()
                          if p.get("analysis")}
        tm.graph.stored = stored_stats
        io.pool.use(tm.backend)                    # page-locked frames for a GPU
        check_output_depth(opts, run.disp, jobs)
        check_output_tag(run.colour, opts, jobs)
        exporter = None
        if opts.ocio_export:
            from ..colour.export import OcioExport  # lazy: only with --ocio-export (~30 ms)
            # the shot's first frame (a chunk of a shot's apply pass: the whole shot's)
            first = (done_before or (frame_jobs(opts) if chunk else jobs) or [(None,)])[0][0]
            exporter = OcioExport(opts.ocio_export, run.colour, tm, first,
                                  opts.ocio_export_size)
        kernels = kernels_key(tm)
        read_done = io.read_done(0)
        if not read_done():                        # the device's kernels while it is read
            prepare_kernels(tm, kernels, read_done)
    except BaseException:
        io.__exit__(None, None, None)
        raise
    fingerprint = run_fingerprint(opts)
    result = JobResult([], [])
    fps = opts.fps
    t_prev = tm.state.time_s
    n = len(jobs)
    rows_of: dict = {}
    said: dict = {}                    # the last plan said (-v)
    if opts.cuts == "detect":
        raise ValueError("--cuts detect finds cuts in the shot's statistics: it needs the "
                         "measure and integrate passes (ocl-tonemap measure / integrate / "
                         "apply, or run --scheduler dask); give a file of frame numbers for "
                         "a serial run")
    cuts = set(opts.cuts or ())

    def rows(k):                       # streamed in bands? (decided once per frame)
        if k not in rows_of:
            rows_of[k] = stream_rows(opts, tm, jobs[k][1], jobs[k][0])
        return rows_of[k]

    result.setup_s = time.perf_counter() - t_start
    with _StopSignals() as stop, io:
        for k, (f, inp, outp, held) in enumerate(jobs):
            for j in range(k + 1, min(n, k + 1 + io.ahead)):    # read-ahead
                if rows(j):
                    break                             # (a streamed frame reads itself)
                io.prefetch(j, lambda inp1=jobs[j][1], f1=jobs[j][0]:
                            read_frame(inp1, f1, opts.channels, io.pool, keep_half=True))
            try:
                if opts.stills and tm.adapted:   # each still its own observer
                    tm.reset_adaptation(opts.preadapt)
                elif f in cuts and tm.adapted:   # a scene cut: the eyes start afresh
                    tm.reset_adaptation()
                    log.info("frame %s: scene cut, adaptation reset", f)
                if rows(k) and exporter is not None:
                    raise FrameError(inp, f, "--ocio-export needs whole frames; this one "
                                     "would stream in row bands (--max-memory): give more")
                if rows(k) and (opts.visibility or opts.visibility_view or opts.target):
                    raise FrameError(inp, f, "--visibility needs whole frames; this one "
                                     "would stream in row bands (--max-memory): give more")
                if rows(k):
                    io.drain()                        # a streamed frame writes in bands
                    still_view(tm, run, inp)
                    t, info, fps = stream_frame(run, tm, inp, outp, f, held, rows(k), fps,
                                                t_prev)
                    write = None
                else:
                    fr = io.read(k, lambda: read_frame(inp, f, opts.channels, io.pool,
                                                       keep_half=True))
                    still_view(tm, run, inp, fr)
                    t, info, fps, write = _whole_frame(run, tm, fr, inp, outp, f, held, fps,
                                                       t_prev, exporter)
                    fr = None          # its array free for the frame after next (FramePool)
            except BaseException:
                io.drain()                 # the frames before this one are complete
                raise
            snap = None
            if ckpt and ((k + 1) % opts.checkpoint_every == 0 or k + 1 == n
                         or stop.signum is not None):
                snap = checkpoint_state(tm, fingerprint)

            def after(snap=snap, f=f):
                if snap is not None:
                    try:
                        save_state(snap, ckpt, checkpoint=True)
                    except Exception as exc:                      # noqa: BLE001
                        raise FrameError(ckpt, f, "cannot write the checkpoint: "
                                         f"{safeio.reason(exc)}") from None
                ready(f"written {f}")
            io.write(write, after)
            if info.repairs.total:
                log.warning("%s%s: repaired bad values (%s)", inp,
                            "" if f is None else f" frame {f}", info.repairs.summary())
            _say_plan(info, f, inp, said)
            _say_transfers(info, f, inp, said)
            result.repairs += info.repairs
            result.frames.append(f)
            result.outputs.append(outp)
            result.infos.append(info)
            t_prev = t
            if opts.progress:
                _progress(k + 1, n, time.perf_counter() - t_start)
            if stop.signum is not None and k + 1 < n:
                io.drain()
                if opts.progress:
                    sys.stderr.write("\n")
                raise Interrupted(stop.signum, k + 1, n, f, ckpt)
        io.drain()
    rt = tm.backend.device_runtime()
    if rt is not None:                             # for the next run's start
        rt.remember_kernels(kernels)
    if opts.progress and n:
        sys.stderr.write("\n")
    if opts.state_out:
        # with the run's settings, as every checkpoint: --resume from it checks them
        save_state(checkpoint_state(tm, fingerprint), opts.state_out)
    if opts.plot:
        # a resumed run's plot covers the whole shot: the frames before the resume
        # from their outputs' own records (ocltm:*)
        before = infos_from_outputs(done_before) if done_before else []
        plot_adaptation(opts.plot, before + result.infos, tm, opts.plot_frames)
    if exporter is not None:
        result.export = exporter.summary()
    result.seconds = time.perf_counter() - t_start
    return result


def infos_from_outputs(jobs) -> list:
    """FrameInfo of frames already written, from their ``ocltm:*`` records (headers
    only); frames whose record cannot be read are left out (one warning for them all)."""
    import json

    import OpenImageIO as oiio

    out, missed = [], []
    for f, _, outp, _ in jobs:
        inp = oiio.ImageInput.open(outp) if os.path.isfile(outp) else None   # (no FIFO)
        if inp is None:
            oiio.geterror()
            missed.append((outp, "cannot read its record"))
            continue
        try:
            m = ocltm_metadata(inp.spec())
        finally:
            inp.close()
        try:
            goal = json.loads(m["ocltm:goal"])
            plan = {}
            if m.get("ocltm:plan"):
                plan = {"weights": json.loads(m["ocltm:plan"])}
            out.append(FrameInfo(f, float(m["ocltm:time_s"]), 0.0, float(goal["G_rod"]),
                                 float(goal["G_cone"]),
                                 RepairCounts(**json.loads(m.get("ocltm:repairs", "{}"))),
                                 AdaptationState.from_json(json.loads(m["ocltm:state"])),
                                 json.loads(m.get("ocltm:params", "{}")),
                                 json.loads(m.get("ocltm:effects", "{}")), plan))
        except (KeyError, TypeError, ValueError) as exc:
            missed.append((outp, f"its record is incomplete ({exc})"))
    if missed:
        log.warning("--plot: %d of the %d frame(s) written before left out: %s: %s%s",
                    len(missed), len(jobs), *missed[0],
                    f" (and {len(missed) - 1} more)" if len(missed) > 1 else "")
    return out


def _whole_frame(run: RunSetup, tm: Tonemapper, fr, inp, outp, f, held, fps, t_prev,
                 exporter=None):
    """One frame (read whole) mapped; returns (time, info, fps, write): ``write()``
    encodes it for the display and writes it (on the writer thread when the I/O
    overlaps), from what this frame left, whatever the next frame does. ``exporter``:
    the frame also goes to the OCIO export (``colour/export.py``)."""
    try:
        t, fps = frame_time(fr, f, held, fps, t_prev)
        fin = frame_input(run, tm, fr, inp)
        linear = output_is_linear(run.opts, outp)
        bits = {"8": 8, "16": 16}.get(output_bits(outp, run.opts.out_bits), 0)
        # encoded outputs: the display table runs where the operator's output is, and
        # only code values come back (encode_pixels, below, for frames that cannot)
        enc = None if linear else run.colour.device_output_encoding(
            bits, tm.backend.device_runtime())
        seen = run.opts.visibility or run.opts.visibility_view or run.opts.target
        view_u8 = bool(run.opts.visibility_view) and \
            not run.opts.visibility_view.lower().endswith(".exr")
        # the planes read the scene's luminance where the frame's colour stage made it
        tm.backend.keep_scene_luminance(fin.pixels if seen else None)
        res = map_frame(tm, fin, t, f, encoding=enc)
        written = None                 # (the export checks what is written: encoded once)
        if exporter is not None and fin.wavelengths is None:
            written = export_frame(exporter, run, fr, fin, res, inp, f, linear, bits)
        vis = req = view = None
        if seen:
            req = frame_request(tm, fin, res.info, run.opts, run.once)
            vis = frame_visibility(tm, req)
            if run.opts.target:
                res.info.visibility = target_visibility(tm, req, vis, run.opts)
            if run.opts.visibility_view and res.encoded:   # the codes as written are here:
                view = view_pixels(tm.backend, vis, res.output, view_u8)   # where the planes are
        extra = {"ocltm:held_from": os.path.basename(inp)} if held else None
        meta = output_metadata(run, tm, fr, fin, res.info, extra, linear,
                               res.output.shape[2] == 4, fps)
        spec = fr.spec          # write() keeps the header, not the frame: its pixels
    except FrameError:          # go back to the pool while it is written
        raise
    except Exception as exc:
        raise FrameError(inp, f, exc) from exc

    def write():
        try:
            pixels = written if written is not None else res.output if res.encoded else \
                encode_pixels(run.colour, res.output, res.alpha, linear, bits)
            _, out_cs, chroma, white, straight = meta
            write_frame(outp, pixels, spec, out_cs, meta[0], run.opts.out_bits, f,
                        chromaticities=chroma, white_luminance=white, straight_alpha=straight,
                        png_level=run.opts.png_level, png_filter=run.opts.png_filter)
            if vis is not None and run.opts.visibility:
                write_visibility(visibility_path(run.opts.visibility, f), vis, f, req.view,
                                 tm.op.name, tm.effects.settings.fov_deg, req.halo is not None)
            if vis is not None and run.opts.visibility_view:
                v = view if view is not None else view_pixels(
                    None, vis, run.colour.encode_fast(res.output[..., :3]) if linear
                    else pixels, view_u8)
                write_view(visibility_path(run.opts.visibility_view, f), v, f,
                           run.opts.png_level, run.opts.png_filter)
        except FrameError:
            raise
        except Exception as exc:
            raise FrameError(outp, f, exc) from exc
    return t, res.info, fps, write


class _StopSignals:
    """SIGINT / SIGTERM set ``signum``; the run stops after the frame in flight. A
    second signal stops at once (the frame in flight is discarded: outputs are
    written to temporary files and renamed, so nothing partial is left)."""

    def __init__(self):
        self.signum = None
        self._old = {}

    def _handler(self, signum, frame):
        interrupts.arm(signum)           # a frame that cannot end is not waited for long
        if self.signum is not None:
            raise Terminated(signum)
        self.signum = signum

    def __enter__(self):
        import signal
        import threading
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                if signal.getsignal(sig) is not signal.SIG_IGN:     # (nohup's stays ignored)
                    self._old[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc):
        import signal
        for sig, h in self._old.items():
            signal.signal(sig, h)
        return False


def _progress(done: int, total: int, elapsed: float) -> None:
    width = 30
    filled = int(width * done / total)
    rate = done / elapsed if elapsed > 0 else 0.0
    sys.stderr.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} frames "
                     f"{rate:5.1f} fps")
    sys.stderr.flush()


def _say_transfers(info, f, inp, said: dict) -> None:
    """``-v``: the frame's host <-> device transfers where their calls change."""
    t = info.transfers
    if not t or said.get("t") == (t["up_calls"], t["down_calls"]):
        return
    log.info("%s%s: host <-> device %s", inp, "" if f is None else f" frame {f}",
             transfers_line([t]))
    said["t"] = (t["up_calls"], t["down_calls"])


def _say_plan(info, f, inp, said: dict) -> None:
    """``-v``: the mechanism plan where it changes (the frame and the weights that
    changed; ``said`` keeps the last one)."""
    w = (info.plan or {}).get("weights")
    if not w or said.get("w") == w:
        return
    prev = said.get("w") or {}
    changed = {m: v for m, v in w.items() if prev.get(m) != v}
    log.info("%s%s: plan %s", inp, "" if f is None else f" frame {f}",
             ", ".join(f"{m} {v:g}" for m, v in changed.items()))
    said["w"] = dict(w)
