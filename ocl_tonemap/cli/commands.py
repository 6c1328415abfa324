"""The sub-commands of the command line, each a thin function ``(args, argv) -> exit
code`` over the job's API; ``cli/table.py`` holds the table that names them and their
arguments."""

from __future__ import annotations

import json
import logging
import math
import os
import shlex
import shutil
import sys

from ..base import interrupts
from .options import job_options

log = logging.getLogger("ocl_tonemap")

#: Options of the shot commands that are not run options (farm-template drops them
#: from the command lines it writes): flag -> takes a value.
SHOT_ONLY_FLAGS = {"--format": True, "-o": True, "--job-file": True, "--name": True,
                   "--command": True, "--chunk-frames": True, "--store": True,
                   "--scheduler": True, "--workers": True, "--scheduler-security": True}


def run_option_tokens(argv: list[str], a) -> list[str]:
    """The run options of a command line (its sub-command, INPUT, OUTPUT and the
    shot-only flags dropped), to be given again to each pass."""
    toks = list(argv)
    if a.cmd in toks:
        toks.remove(a.cmd)
    out, skip = [], False
    positional = [a.input, a.output]
    for t in toks:
        if skip:
            skip = False
            continue
        flag = t.split("=", 1)[0]
        if flag in SHOT_ONLY_FLAGS:
            skip = SHOT_ONLY_FLAGS[flag] and "=" not in t
            continue
        if positional and t == positional[0]:
            positional.pop(0)
            continue
        out.append(t)
    return out


def run(a, argv) -> int:
    """``run``: the main job, serially or as a shot on Dask (``--scheduler``)."""
    if a.scheduler:
        from ..job.visibility_out import refuse_visibility  # lazy: a command loads its own layers
        from ..shot.distributed import run_distributed  # lazy: a command loads its own layers
        opts = job_options(a, a.input, a.output)
        refuse_visibility(opts, "--scheduler")
        from ..shot.chunks import command_line  # lazy: a command loads its own layers
        interrupts.again = command_line(argv)      # (each pass keeps what it finished)
        res = run_distributed(opts, a.scheduler, a.workers, a.chunk_frames, a.store,
                              progress=opts.progress,
                              pocl_threads=max(1, (os.cpu_count() or 1) // max(1, a.workers)),
                              security=a.scheduler_security)
        if not a.quiet:
            from ..shot.distributed import overhead_line  # lazy: with --scheduler only
            times = ", ".join(f"{k} {v:.2f} s" for k, v in res.passes.items())
            print(f"wrote {len(res.outputs)} frame(s) in {res.seconds:.2f} s ({times}; "
                  f"{overhead_line(res.tasks)})")
        return 0
    from ..job.options import Interrupted  # lazy: a command loads its own layers
    from ..job.run import run_job  # lazy: a command loads its own layers
    for flag, given in (("--workers", a.workers != 2), ("--chunk-frames", a.chunk_frames),
                        ("--store", a.store), ("--scheduler-security", a.scheduler_security)):
        if given:
            log.warning("%s applies to --scheduler (a shot on Dask): ignored", flag)
    try:
        res = run_job(job_options(a, a.input, a.output, defer_backend=True))
    except Interrupted as e:
        return _interrupted(e, argv, "--stills" if a.stills else "--no-checkpoint")
    if not a.quiet:
        rep = f"; repaired values: {res.repairs.summary()}" if res.repairs.total else ""
        print(f"wrote {len(res.outputs)} frame(s) in {res.seconds:.2f} s{rep}")
        moved = res.transfers() if a.verbose else None     # a developer's figure: -v
        if moved:
            print(f"host <-> device per frame: {moved}")
        _target_report(res)
        if res.export:
            print(res.export)
    return 0


def _interrupted(e, argv, why: str | None) -> int:
    """The line an interrupted run leaves: where its state is and the command that
    resumes it, or (no checkpoint: ``why``) that it runs again from the start."""
    if e.checkpoint:
        again = [x for x in argv if x != "--resume"]
        print(f"ocl-tonemap: interrupted after frame {e.last_frame} ({e.done} of "
              f"{e.total} written; state in {e.checkpoint}). Resume with:\n  ocl-tonemap "
              + " ".join(shlex.quote(x) for x in again) + " --resume", file=sys.stderr)
    else:
        print(f"ocl-tonemap: interrupted after frame {e.last_frame} ({e.done} of "
              f"{e.total} written). No checkpoint was kept ({why}): run it again from the "
              "start to get the same frames", file=sys.stderr)
    return e.exit_code


def _target_report(res) -> None:
    """The tracked target's visibility, frame by frame (``run --target``)."""
    rows = [(f, i.time_s, i.visibility) for f, i in zip(res.frames, res.infos)
            if getattr(i, "visibility", None)]
    if not rows:
        return
    v0 = rows[0][2]
    print(f"target at ({v0['x']:g}, {v0['y']:g}), {v0['size_arcmin']:g} arcmin "
          f"(a {v0['observation_s']:g} s look, Adrian {v0['adrian']}; L_b = L_s + Lveil; "
          "Lseq88: CIE 88's L_seq):")
    print(f"{'frame':>6} {'t (s)':>8} {'L_t':>10} {'L_s':>10} {'Lveil':>10} {'Lseq88':>10} "
          f"{'L_b':>10} {'La':>10} {'TAF':>8} {'dL_th':>10} {'VL':>8}")
    for f, t, v in rows:
        flag = "  below threshold" if v["VL"] < 1 else ""
        print(f"{'' if f is None else f:>6} {t:8.3f} {v['L_target']:10.4g} "
              f"{v['L_surround']:10.4g} {v['Lveil']:10.4g} {v['Lseq_cie88']:10.4g} "
              f"{v['Lb']:10.4g} {v['La']:10.4g} {v['TAF']:8.3f} {v['dLth']:10.4g} "
              f"{v['VL']:8.3f}{flag}")


def shot_pass(a, argv) -> int:
    """``measure`` / ``integrate`` / ``apply`` / ``export``: one pass of a split shot."""
    from ..job.visibility_out import refuse_visibility  # lazy: a command loads its own layers
    from ..shot import chunks, passes  # lazy: a command loads its own layers
    from ..job.options import Interrupted  # lazy: a command loads its own layers
    opts = job_options(a, a.input, a.output)
    refuse_visibility(opts, f"the {a.cmd} pass")
    store = a.store or passes.default_store(opts)
    # interrupted: each pass keeps what it finished (measure: the frames stored;
    # apply: the frames written), so the same command finishes it
    interrupts.again = chunks.command_line(argv)
    if a.cmd == "apply":
        try:
            res = passes.apply(opts, store, passes.parse_chunk(a.chunk))
        except Interrupted as e:
            return _apply_interrupted(e, a, argv)
        said = f"wrote {len(res.outputs)} frame(s) in {res.seconds:.2f} s" + \
            (f"\n{res.export}" if res.export else "")
    elif a.cmd == "measure":
        done = passes.measure(opts, store, passes.parse_chunk(a.chunk), redo=a.redo)
        said = f"measured {len(done)} frame(s) into {store}"
    elif a.cmd == "integrate":
        doc = passes.integrate(opts, store, a.keyframe_every)
        said = (f"integrated {len(doc['frames'])} frame(s) in {store}; keyframes "
                f"{len(doc['keyframes'])}; cuts: {', '.join(map(str, doc['cuts'])) or 'none'}")
    else:
        if not opts.ocio_export:
            raise ValueError("export: say where, --ocio-export DIR")
        ex, read_s, export_s = passes.export(opts, store, passes.parse_chunk(a.chunk))
        said = (f"{ex.summary()}; per frame {1e3 * export_s:.0f} ms exporting, "
                f"{1e3 * read_s:.0f} ms reading")
    if not a.quiet:
        print(said)
    return 0


def _apply_interrupted(e, a, argv) -> int:
    """The line an interrupted ``apply`` leaves: what it wrote, and the command that
    writes the frames left (``shot.chunks.finish_apply``)."""
    from ..shot import chunks, passes  # lazy: a command loads its own layers
    again = chunks.finish_apply(argv, passes.shot_jobs(job_options(a, a.input, a.output)),
                                e.last_frame, passes.parse_chunk(a.chunk))
    print(f"ocl-tonemap: interrupted after frame {e.last_frame} ({e.done} of {e.total} "
          + (f"written). To write the frames left:\n  {again}" if again else
             "written: the chunk's last)"), file=sys.stderr)
    return e.exit_code


def farm_template(a, argv) -> int:
    from ..shot.farm import write_template  # lazy: a command loads its own layers
    path = write_template(a.format, job_options(a, a.input, a.output),
                          run_option_tokens(argv, a), a.job_file, store=a.store,
                          chunk=a.chunk_frames, name=a.name, command=a.command)
    if not a.quiet:
        print(f"wrote {a.format} job {path}")
    return 0


def simulate(a, argv) -> int:
    from ..job.simulate import run_simulate  # lazy: a command loads its own layers
    from ..job.visibility_out import refuse_visibility  # lazy: a command loads its own layers
    opts = job_options(a, a.input, a.output)
    refuse_visibility(opts, "simulate")
    res = run_simulate(opts, a.at)
    if not a.quiet:                   # (rendered in time order)
        for t, o in zip(sorted(a.at), res.outputs):
            print(f"t = {t:g} s -> {o}")
    return 0


def visibility(a, argv) -> int:
    """The calculator: Adrian's threshold of a target (``visibility.Viewing``: the run's
    observer) with each term; with ``--state`` under the eye a run left, with
    ``--adapted-to`` over the seconds after a step."""
    from ..effects import visibility as vis  # lazy: a command loads its own layers
    from ..models import adrian1989 as ad  # lazy: a command loads its own layers
    from ..models import cie203  # lazy: a command loads its own layers
    from ..models.spencer1995 import DEFAULT_AGE  # lazy: a command loads its own layers
    st = _run_state(a)
    age = a.age if a.age is not None else DEFAULT_AGE
    view = vis.Viewing(a.size, age, a.time, a.k, a.adrian).check()
    polarity = _polarity(a)
    # the run's symbols (run --target's table): the surround L_s given, the veil Lveil
    # over it, L_b = L_s + Lveil (CIE 88: the veil adds to the background)
    L_b = a.background + a.veil
    th = ad.threshold(L_b, a.size, age, a.time, polarity, a.k, a.adrian)
    out = th.as_dict()
    out.update(L_s=a.background, Lveil=a.veil, observer=view.describe(),
               dL_th_adapted=th.dL_th)
    out.update(background=a.background, veil=a.veil)     # (the keys before L_s, Lveil)
    media = cie203.media_factors(age)
    out["media"] = {"photopic": media[0], "scotopic": media[1], "ref_age": cie203.AGE_REF}
    state = _visibility_state(a, st, view, polarity)
    if state is not None:
        out["state"] = state
        out["dL_th"] = state["dL_th"]
        out["C_th"] = state["dL_th"] / L_b
    if a.target is not None:
        out["L_target"] = a.target
        out["VL"] = abs(a.target - a.background) / out["dL_th"]
    step = _visibility_step(a, view, polarity)
    if step is not None:
        out["step"] = step
    if a.json:                       # (a long look's inf as a string: JSON has no Infinity)
        print(json.dumps(_finite_json(out), indent=1))
        return 0
    rows = [("surround L_s (the background given)", f"{a.background:.6g} cd/m^2"),
            ("veil Lveil", f"{a.veil:.6g} cd/m^2"),
            ("L_b = L_s + Lveil", f"{L_b:.6g} cd/m^2"),
            ("target size", f"{th.alpha_arcmin:g} arcmin"),
            ("observer age", f"{th.age:g} years"),
            ("observation time", f"{th.time_s:g} s"), ("contrast polarity", th.polarity),
            ("Adrian's model", f"{a.adrian} (docs/models.md, D1-D7)"),
            ("sqrt(Phi) (Ricco)", f"{th.sqrt_phi:.5g}"),
            ("sqrt(L) (Weber)", f"{th.sqrt_weber:.5g}"),
            ("(sqrt(Phi)/alpha + sqrt(L))^2", f"{th.basic:.5g} cd/m^2"),
            ("field factor k", f"{th.k:g}"), ("polarity factor F_cp", f"{th.F_cp:.4f}"),
            ("time factor (a+t)/t", f"{th.time_factor:.4f}"),
            ("age factor AF", f"{th.age_factor:.4f}"),
            ("ocular media (CIE 203)", f"{media[0]:.3f} photopic, {media[1]:.3f} scotopic of "
             f"a {cie203.AGE_REF:g}-year-old's (the step's light; AF holds the threshold's)"),
            ("threshold, adapted to L_b", f"{th.dL_th:.5g} cd/m^2")]
    if state is not None:
        rows += [("the eye of " + state["operator"], f"La {state['La']:.5g} cd/m^2, TAF "
                  f"{state['TAF']:.4f} ({state['file']})"),
                 ("threshold dL_th", f"{state['dL_th']:.5g} cd/m^2")]
    rows.append(("threshold contrast dL_th/L_b", f"{out['dL_th'] / L_b:.4g}"))
    if a.target is not None:
        rows += [("target L_t", f"{a.target:.6g} cd/m^2"),
                 ("visibility level VL", f"{out['VL']:.3f}" +
                  ("  (below threshold)" if out["VL"] < 1 else ""))]
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    if step is not None:
        pre = "fully" if step["for_s"] is None else f"for {step['for_s']:g} s"
        print(f"\nafter a step from {step['adapted_to']:g} cd/m^2 (adapted {pre}), "
              f"{step['operator']}'s time course:")
        head = ["t (s)", "La (cd/m^2)", "TAF", "dL_th (cd/m^2)"] + (["VL"] if a.target
                                                                   is not None else [])
        print("  ".join(f"{h:>14}" for h in head))
        for p in step["points"]:
            cells = [f"{p['t']:g}", f"{p['L_a']:.5g}", f"{p['TAF']:.4f}", f"{p['dL_th']:.5g}"]
            if p["VL"] is not None:
                cells.append(f"{p['VL']:.3f}")
            print("  ".join(f"{c:>14}" for c in cells))
    return 0


def _polarity(a) -> str:
    """The target's polarity: its luminance against the background's, else
    ``--negative``; a ``--negative`` the target contradicts is refused."""
    if a.target is None:
        return "negative" if a.negative else "positive"
    if a.negative and not a.target < a.background:
        raise ValueError(f"--negative: the target ({a.target:g} cd/m^2) is not darker than "
                         f"the background ({a.background:g} cd/m^2); leave --negative out "
                         "(the target's luminance says its polarity)")
    return "negative" if a.target < a.background else "positive"


def _run_state(a):
    """``--state FILE``: the state a run left (None without it), the run's observer age
    taken where ``--age`` is not given (the state holds the light behind that age's
    media: another age would read it wrongly, so a different one is refused)."""
    if a.state is None:
        if a.pixel is not None:
            raise ValueError("--pixel needs --state FILE (a local operator's state)")
        if a.operator is not None and a.adapted_to is None:
            raise ValueError("--operator needs --adapted-to L0 (whose time course after a "
                             "step); with --state the state says whose eye")
        return None
    for flag, given in (("--adapted-to", a.adapted_to), ("--for", a.adapted_for),
                        ("--after", a.after), ("--plot", a.plot)):
        if given is not None:
            raise ValueError(f"--state gives the eye as a run left it; {flag} (a step "
                             "from a uniform field) cannot go with it")
    from ..models import spencer1995 as fl  # lazy: a command loads its own layers
    from ..io.state_files import load_state  # lazy: a command loads its own layers
    st = load_state(a.state)
    if a.operator is not None and a.operator != st.operator:
        raise ValueError(f"--operator {a.operator}: the state {a.state} is {st.operator}'s")
    run = st.extra.get("run") or {}
    age = (run.get("effects") or {}).get("age")
    if age is not None:
        age = fl.DEFAULT_AGE if fl.is_literal(age) else float(age)
        if a.age is not None and a.age != age:
            raise ValueError(f"--age {a.age:g}: the state {a.state} is a {age:g}-year-old's "
                             "run (its light behind that age's lenses); give --age "
                             f"{age:g} or leave --age out")
        a.age = age
    return st


def _finite_json(v):
    """``v`` with infinite floats as the strings "inf" and "-inf" (strict JSON)."""
    if isinstance(v, dict):
        return {k: _finite_json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite_json(x) for x in v]
    if isinstance(v, float) and math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return v


def _visibility_state(a, st, view, polarity: str) -> dict | None:
    """The target seen by the observer the run left (``--state FILE [--pixel X,Y]``:
    ``visibility.seen``, the run's ``--target`` line's formula; its operator with the
    run's options); None without it."""
    if st is None:
        return None
    from ..operators import get_operator  # lazy: a command loads its own layers
    from ..effects.visibility import seen  # lazy: a command loads its own layers
    op = get_operator(st.operator)(dict((st.extra.get("run") or {}).get("options") or {}))
    obs = op.observer_of(st)
    if op.observer_per_pixel:
        if a.pixel is None:
            raise ValueError(f"--state {a.state}: {st.operator} adapts per pixel; say "
                             "which with --pixel X,Y")
        obs = _observer_at(obs, a.pixel, a.state)
    elif a.pixel is not None:
        raise ValueError(f"--pixel: {st.operator} adapts globally; its state has one "
                         "observer")
    s = seen(op, obs, view, a.background, a.veil, a.target, polarity == "negative")
    return {"operator": st.operator, "file": os.path.basename(a.state), "frame": st.frame,
            "La": s.L_a, "TAF": s.TAF, "dL_th": s.dL_th}


def _observer_at(obs: dict, pixel: tuple, path: str) -> dict:
    x, y = pixel
    h, w = next(iter(obs.values())).shape
    if not (0 <= x < w and 0 <= y < h):
        raise ValueError(f"--pixel {x},{y}: outside the state's {w} x {h} pixels ({path})")
    return {k: v[y, x] for k, v in obs.items()}


def _visibility_step(a, view, polarity: str) -> dict | None:
    """The calculator's step: the observer of ``--operator`` adapted to ``--adapted-to``
    (``--for``), the background stepping to L_b; None without a step."""
    if a.adapted_to is None:
        for flag, given in (("--for", a.adapted_for), ("--after", a.after),
                            ("--plot", a.plot)):
            if given is not None:
                raise ValueError(f"{flag} needs --adapted-to L0 (the step's start)")
        return None
    from ..effects import visibility as vis  # lazy: a command loads its own layers
    from ..operators import get_operator  # lazy: a command loads its own layers
    after = list(a.after or vis.AFTER_S)
    op = get_operator(a.operator or "pattanaik00")({})
    pts = vis.trace(op, a.adapted_to, a.adapted_for, a.background, after, view, polarity,
                    a.target, a.veil)
    if a.plot:
        from ..io.plot import plot_visibility_step  # lazy: matplotlib only for --plot
        plot_visibility_step(a.plot, op, a.adapted_to, a.adapted_for, a.background, view,
                             polarity, max(after + [30.0]), a.veil)
    return {"operator": op.name, "adapted_to": a.adapted_to, "for_s": a.adapted_for,
            "steady_dL_th": float(view.steady(a.background + a.veil, polarity)),
            "points": [p.as_dict() for p in pts]}


def demo(a, argv) -> int:
    """The sample written and the main job run on it; what it made is removed again
    where it fails (an interrupted demo keeps its frames)."""
    from ..job.options import Interrupted  # lazy: a command loads its own layers
    from ..io.sample import plan_sample  # lazy: a command loads its own layers
    w, h = a.size
    scene = os.path.join(a.outdir, "scene")
    out = os.path.join(a.outdir, "display", "tunnel.####.png")
    opts = job_options(a, os.path.join(scene, "tunnel.####.exr"), out)  # checked first
    plan_sample(a.outdir, w, h, 30.0, a.seconds, flag_fps="its 30 fps")
    opts.plot = opts.plot or os.path.join(a.outdir, "adaptation.png")
    opts.state_out = opts.state_out or os.path.join(a.outdir, "state.json")
    ours = [p for p in (a.outdir, scene, os.path.dirname(out), opts.plot, opts.state_out)
            if not os.path.lexists(p)]
    try:
        res = _demo_run(a, opts, w, h, scene)
    except Interrupted as e:
        return _interrupted(e, argv, None)
    except Exception:
        for p in ours:                    # the outermost first: what it holds goes with it
            if os.path.isdir(p) and not os.path.islink(p):
                shutil.rmtree(p, ignore_errors=True)
            elif os.path.lexists(p):
                os.unlink(p)
        raise
    print(f"demo: {len(res.outputs)} frames -> {out}; plot {opts.plot}; "
          f"state {opts.state_out}; {res.seconds:.1f} s")
    return 0


def _demo_run(a, opts, w: int, h: int, scene: str):
    from ..job.run import run_job  # lazy: a command loads its own layers
    from ..io.sample import write_tunnel_sequence  # lazy: a command loads its own layers
    opts.input, _ = write_tunnel_sequence(scene, w, h, 30.0, a.seconds)
    os.makedirs(os.path.dirname(opts.output), exist_ok=True)
    return run_job(opts)


def sample(a, argv) -> int:
    # lazy: a command loads its own layers
    from ..io.sample import plan_sample, write_spectral_image, write_tunnel_sequence
    w, h = a.size
    plan_sample(a.outdir, w, h, a.fps, a.seconds)
    pattern, frames = write_tunnel_sequence(a.outdir, w, h, a.fps, a.seconds)
    print(f"wrote {len(frames)} frames: {pattern} (frames {frames[0]}-{frames[-1]})")
    if a.spectral:
        sp = os.path.join(a.outdir, "colorchecker_spectral.exr")
        write_spectral_image(sp, "A", 0.05, patch_px=24)
        print(f"wrote {sp}")
    return 0


def displays(a, argv) -> int:
    """Each display of the config and its views, the ones a run takes without
    ``--display`` and ``--view`` marked (default), and the config's own default view
    where it is another (a run's default is the un-tone-mapped view: the operator
    does the tone mapping)."""
    # lazy: a command loads its own layers
    from ..colour import (ColourError, default_display, default_view, list_displays,
                         load_config, resolve_config_source)
    cfg = load_config(a.colorconfig)
    print(f"config: {resolve_config_source(a.colorconfig)} ({cfg.getName() or 'unnamed'})")
    print("(default): what run uses without --display and --view")
    first = default_display(cfg)
    for d, views in list_displays(cfg):
        try:
            ours = default_view(cfg, d)
        except ColourError:               # no un-tone-mapped view: --view is needed
            ours = None
        theirs = cfg.getDefaultView(d)
        names = [v + (" (default)" if v == ours else " (the config's default)"
                      if v == theirs else "") for v in views]
        print(f"{d}{' (default)' if d == first else ''}: {', '.join(names)}")
    return 0


def radiance_env(a, argv) -> int:
    """``export PATH=...`` and ``export RAYPATH=...`` for Radiance's programs of the
    pyradiance wheel (``radiance.tools``), quoted for a POSIX shell."""
    from ..io.radiance import tools  # lazy: a command loads its own layers
    found = tools()
    if found is None:
        raise ValueError("Radiance's programs are not installed: pip install "
                         "'ocl-tonemap[radiance]' (the pyradiance wheel)")
    b, env = found
    print(f"export PATH={shlex.quote(b)}:\"$PATH\"")
    print(f"export RAYPATH={shlex.quote(env['RAYPATH'])}")
    return 0


def devices(a, argv) -> int:
    """Every OpenCL device with its probe verdict, and which one a run takes."""
    from ..backends.opencl import probe  # lazy: a command loads its own layers
    # lazy: a command loads its own layers
    from ..backends.opencl.runtime import (INSTALL_HINT, OpenCLUnavailable, describe_device,
                                          device_status, list_devices)
    devs = list_devices()
    if not devs:
        if a.check:
            print(f"no OpenCL device: {INSTALL_HINT}")
            return 1
        raise OpenCLUnavailable(INSTALL_HINT)
    for k, d in devs:
        v = probe.verdict(d)
        print(f"{k}  {describe_device(d)}, driver {d.driver_version.strip()}: "
              + ("ok" if v.ok else f"broken: {v.reason}"))
    logging.getLogger("ocl_tonemap").setLevel(logging.ERROR)   # verdicts said above
    dev, _ = device_status(os.environ.get("PYOPENCL_CTX"))
    if dev is None:
        print(f"no working device: runs fall back to --backend reference; {probe.fix_hint()}")
        return 1 if a.check else 0
    key = next(k for k, d in devs if d == dev)
    print(f"default: {key} {dev.name.strip()}")
    return 0
