"""``simulate``: one still seen over time by a pre-adapted observer."""

from __future__ import annotations

import json
import logging
import time
from typing import TYPE_CHECKING

from ..io.imageio import FrameError, read_frame
from .checkpoint import check_state_paths

from ..io.imagewrite import write_frame
from ..io.patterns import is_sequence, same_file
from ..base.quantities import RUN
from ..io.plot import plot_adaptation
from ..io.state_files import load_state, save_state
from .frame import frame_input, map_frame, render_output
from .options import JobOptions, JobResult, output_is_linear
from .run import setup_run
from .sequence import simulate_outputs
from .setup import RunSetup

if TYPE_CHECKING:                                  # annotations only
    from ..pipeline import Tonemapper

log = logging.getLogger("ocl_tonemap")

def write_output(run: RunSetup, tm: Tonemapper, fr, fin, res, outp, f, extra: dict | None):
    """Encode a mapped frame for the display and write it with its metadata."""
    r = render_output(run, tm, fr, fin, res, extra, output_is_linear(run.opts, outp))
    write_frame(outp, r.pixels, fr.spec, r.colorspace, r.metadata, run.opts.out_bits, f,
                chromaticities=r.chromaticities, white_luminance=r.white_luminance,
                straight_alpha=r.straight_alpha, png_level=run.opts.png_level,
                png_filter=run.opts.png_filter)


def run_simulate(opts: JobOptions, times: list[float]) -> JobResult:
    """A still image seen over time: the observer was pre-adapted (``opts.preadapt``),
    starts looking at INPUT at t = 0, and one output is rendered per elapsed time."""
    t_start = time.perf_counter()
    if is_sequence(opts.input):
        raise FrameError(opts.input, None, "simulate takes one still image, not a sequence")
    if opts.preadapt is None:
        raise ValueError("simulate needs --preadapt CD_M2[:SECONDS] (what the observer saw before)")
    times = RUN["at"].check(times, "--at")
    outs = simulate_outputs(opts.output, times)
    for _, o in outs:
        if same_file(o, opts.input):
            raise FrameError(o, None, "output would overwrite the input file; choose another OUTPUT")
        if opts.plot and same_file(opts.plot, o):
            raise FrameError(opts.plot, None, f"--plot would overwrite {o}, a file of this run")
    if opts.plot and any(same_file(opts.plot, q) for q in (opts.input, opts.state_in,
                                                           opts.state_out) if q):
        raise FrameError(opts.plot, None, "--plot would overwrite a file of this run")
    check_state_paths([(None, opts.input, o, False) for _, o in outs],
                      [opts.state_out] if opts.state_out else [], opts.plot, [opts.state_in])
    state = load_state(opts.state_in) if opts.state_in else None
    run, tm = setup_run(opts, state)
    fr = read_frame(opts.input, None, opts.channels)
    result = JobResult([], [])
    try:
        fin = frame_input(run, tm, fr, opts.input)
        t_now = 0.0
        res = map_frame(tm, fin, 0.0)                                      # the switch
        order = sorted(range(len(times)), key=lambda k: times[k])
        for k in order:
            t = times[k]
            if t > t_now:
                res = map_frame(tm, fin, t)
                t_now = t
            f, outp = outs[k]
            write_output(run, tm, fr, fin, res, outp, f,
                         {"ocltm:elapsed_s": float(t),
                          "ocltm:preadapt": json.dumps(opts.preadapt)})
            info = res.info
            result.frames.append(f)
            result.outputs.append(outp)
            result.infos.append(info)
            result.repairs += info.repairs
            log.info("t = %g s -> %s", t, outp)
    except FrameError:
        raise
    except Exception as exc:
        raise FrameError(opts.input, None, exc) from exc
    if opts.state_out:
        save_state(tm.state, opts.state_out)
    if opts.plot:                       # the observer's course over the times asked for
        plot_adaptation(opts.plot, result.infos, tm, opts.plot_frames)
    result.seconds = time.perf_counter() - t_start
    return result
