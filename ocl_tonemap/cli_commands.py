"""The sub-commands of the command line, each a thin function ``(args, argv) -> exit
code`` over the job's API; ``cli.py`` holds the table that names them and their
arguments."""

from __future__ import annotations

import json
import logging
import math
import os
import shlex
import sys

from .cli_options import job_options

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


def size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise SystemExit(f"ocl-tonemap ERROR: bad --size {text!r} (use WxH)") from None


def run(a, argv) -> int:
    """``run``: the main job, serially or as a shot on Dask (``--scheduler``)."""
    if a.scheduler:
        from .job.visibility_out import refuse_visibility  # lazy: a command loads its own layers
        from .shot.distributed import run_distributed  # lazy: a command loads its own layers
        opts = job_options(a, a.input, a.output)
        refuse_visibility(opts, "--scheduler")
        res = run_distributed(opts, a.scheduler, a.workers, a.chunk_frames, a.store,
                              progress=opts.progress,
                              pocl_threads=max(1, (os.cpu_count() or 1) // max(1, a.workers)),
                              security=a.scheduler_security)
        if not a.quiet:
            times = ", ".join(f"{k} {v:.2f} s" for k, v in res.passes.items())
            print(f"wrote {len(res.outputs)} frame(s) in {res.seconds:.2f} s ({times})")
        return 0
    from .job.options import Interrupted  # lazy: a command loads its own layers
    from .job.run import run_job  # lazy: a command loads its own layers
    try:
        res = run_job(job_options(a, a.input, a.output, defer_backend=True))
    except Interrupted as e:
        again = [x for x in argv if x != "--resume"]
        if e.checkpoint:
            print(f"ocl-tonemap: interrupted after frame {e.last_frame} ({e.done} of "
                  f"{e.total} written; state in {e.checkpoint}). Resume with:\n  ocl-tonemap "
                  + " ".join(shlex.quote(x) for x in again) + " --resume", file=sys.stderr)
        else:
            print(f"ocl-tonemap: interrupted after frame {e.last_frame} ({e.done} of "
                  f"{e.total} written). No checkpoint was kept (--no-checkpoint): run it "
                  "again from the start to get the same frames", file=sys.stderr)
        return e.exit_code
    if not a.quiet:
        rep = f"; repaired values: {res.repairs.summary()}" if res.repairs.total else ""
        print(f"wrote {len(res.outputs)} frame(s) in {res.seconds:.2f} s{rep}")
        moved = res.transfers()
        if moved:
            print(f"host <-> device per frame: {moved}")
        _target_report(res)
        if res.export:
            print(res.export)
    return 0


def _target_report(res) -> None:
    """The tracked target's visibility, frame by frame (``run --target``)."""
    rows = [(f, i.time_s, i.visibility) for f, i in zip(res.frames, res.infos)
            if getattr(i, "visibility", None)]
    if not rows:
        return
    v0 = rows[0][2]
    print(f"target at ({v0['x']:g}, {v0['y']:g}), {v0['size_arcmin']:g} arcmin:")
    print(f"{'frame':>6} {'t (s)':>8} {'L_t':>10} {'L_b':>10} {'La':>10} {'TAF':>8} "
          f"{'dL_th':>10} {'VL':>8}")
    for f, t, v in rows:
        flag = "  below threshold" if v["VL"] < 1 else ""
        print(f"{'' if f is None else f:>6} {t:8.3f} {v['L_target']:10.4g} {v['Lb']:10.4g} "
              f"{v['La']:10.4g} {v['TAF']:8.3f} {v['dLth']:10.4g} {v['VL']:8.3f}{flag}")


def shot_pass(a, argv) -> int:
    """``measure`` / ``integrate`` / ``apply`` / ``export``: one pass of a split shot."""
    from .job.visibility_out import refuse_visibility  # lazy: a command loads its own layers
    from .shot import passes  # lazy: a command loads its own layers
    opts = job_options(a, a.input, a.output)
    refuse_visibility(opts, f"the {a.cmd} pass")
    store = a.store or passes.default_store(opts)
    if a.cmd == "measure":
        done = passes.measure(opts, store, passes.parse_chunk(a.chunk), redo=a.redo)
        said = f"measured {len(done)} frame(s) into {store}"
    elif a.cmd == "integrate":
        doc = passes.integrate(opts, store, a.keyframe_every)
        said = (f"integrated {len(doc['frames'])} frame(s) in {store}; keyframes "
                f"{len(doc['keyframes'])}; cuts: {', '.join(map(str, doc['cuts'])) or 'none'}")
    elif a.cmd == "apply":
        res = passes.apply(opts, store, passes.parse_chunk(a.chunk))
        said = f"wrote {len(res.outputs)} frame(s) in {res.seconds:.2f} s" + \
            (f"\n{res.export}" if res.export else "")
    else:
        if not opts.ocio_export:
            raise ValueError("export: say where, --ocio-export DIR")
        ex, read_s, export_s = passes.export(opts, store, passes.parse_chunk(a.chunk))
        said = (f"{ex.summary()}; per frame {1e3 * export_s:.0f} ms exporting, "
                f"{1e3 * read_s:.0f} ms reading")
    if not a.quiet:
        print(said)
    return 0


def farm_template(a, argv) -> int:
    from .shot.farm import write_template  # lazy: a command loads its own layers
    path = write_template(a.format, job_options(a, a.input, a.output),
                          run_option_tokens(argv, a), a.job_file, store=a.store,
                          chunk=a.chunk_frames, name=a.name, command=a.command)
    if not a.quiet:
        print(f"wrote {a.format} job {path}")
    return 0


def simulate(a, argv) -> int:
    from .job.options import parse_times  # lazy: a command loads its own layers
    from .job.simulate import run_simulate  # lazy: a command loads its own layers
    from .job.visibility_out import refuse_visibility  # lazy: a command loads its own layers
    opts = job_options(a, a.input, a.output)
    refuse_visibility(opts, "simulate")
    res = run_simulate(opts, parse_times(a.at))
    if not a.quiet:                   # (rendered in time order)
        for t, o in zip(sorted(parse_times(a.at)), res.outputs):
            print(f"t = {t:g} s -> {o}")
    return 0


def visibility(a, argv) -> int:
    from .models import adrian1989 as ad  # lazy: a command loads its own layers
    if not 1.0 <= a.age <= 100.0:
        raise ValueError(f"--age must be 1..100 years (got {a.age:g})")
    if not a.size > 0:
        raise ValueError(f"--size must be > 0 arcmin (got {a.size:g})")
    if not a.time > 0:
        raise ValueError(f"--time must be > 0 s (got {a.time:g})")
    if a.target is not None and not (a.target >= 0 and math.isfinite(a.target)):
        raise ValueError(f"--target must be a luminance >= 0 cd/m^2 (got {a.target:g})")
    polarity = "negative" if a.negative else "positive"
    if a.target is not None:          # the target says its polarity
        polarity = "negative" if a.target < a.background else "positive"
    from .models import cie203  # lazy: a command loads its own layers
    th = ad.threshold(a.background, a.size, a.age, a.time, polarity, a.k)
    out = th.as_dict()
    media = cie203.media_factors(a.age)
    out["media"] = {"photopic": media[0], "scotopic": media[1], "ref_age": cie203.AGE_REF}
    if a.target is not None:
        out["L_target"] = a.target
        out["VL"] = ad.visibility_level(a.target - a.background, th)
    step = _visibility_step(a, polarity)
    if step is not None:
        out["step"] = step
    if a.json:
        print(json.dumps(out, indent=1))
        return 0
    rows = [("background L_b", f"{th.L_b:.6g} cd/m^2"),
            ("target size", f"{th.alpha_arcmin:g} arcmin"),
            ("observer age", f"{th.age:g} years"),
            ("observation time", f"{th.time_s:g} s"), ("contrast polarity", th.polarity),
            ("sqrt(Phi) (Ricco)", f"{th.sqrt_phi:.5g}"),
            ("sqrt(L) (Weber)", f"{th.sqrt_weber:.5g}"),
            ("(sqrt(Phi)/alpha + sqrt(L))^2", f"{th.basic:.5g} cd/m^2"),
            ("field factor k", f"{th.k:g}"), ("polarity factor F_cp", f"{th.F_cp:.4f}"),
            ("time factor (a+t)/t", f"{th.time_factor:.4f}"),
            ("age factor AF", f"{th.age_factor:.4f}"),
            ("ocular media (CIE 203)", f"{media[0]:.3f} photopic, {media[1]:.3f} scotopic of "
             f"a {cie203.AGE_REF:g}-year-old's (the step's light; AF holds the threshold's)"),
            ("threshold dL_th", f"{th.dL_th:.5g} cd/m^2"),
            ("threshold contrast dL_th/L_b", f"{th.contrast:.4g}")]
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


def _visibility_step(a, polarity: str) -> dict | None:
    """The calculator's step: the observer of ``--operator`` adapted to ``--adapted-to``
    (``--for``), the background stepping to L_b; None without a step."""
    if a.adapted_to is None:
        if a.adapted_for is not None or a.plot:
            raise ValueError("--for and --plot need --adapted-to L0 (the step's start)")
        return None
    from . import visibility as vis  # lazy: a command loads its own layers
    from .operators import get_operator  # lazy: a command loads its own layers
    if not (a.adapted_to >= 0 and math.isfinite(a.adapted_to)):
        raise ValueError(f"--adapted-to must be a luminance >= 0 cd/m^2 (got {a.adapted_to:g})")
    if a.adapted_for is not None and not (a.adapted_for > 0 and math.isfinite(a.adapted_for)):
        raise ValueError(f"--for must be > 0 s (got {a.adapted_for:g})")
    try:
        after = [float(x) for x in a.after.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--after must be seconds, comma-separated (got {a.after!r})") from None
    if not after or not all(t >= 0 and math.isfinite(t) for t in after):
        raise ValueError(f"--after must be seconds >= 0, comma-separated (got {a.after!r})")
    op = get_operator(a.operator)({})
    view = vis.Viewing(a.size, a.age, a.time, a.k).check()
    pts = vis.trace(op, a.adapted_to, a.adapted_for, a.background, after, view, polarity,
                    a.target)
    if a.plot:
        from .plot import plot_visibility_step  # lazy: matplotlib only for --plot
        plot_visibility_step(a.plot, op, a.adapted_to, a.adapted_for, a.background, view,
                             polarity, max(after + [30.0]))
    return {"operator": op.name, "adapted_to": a.adapted_to, "for_s": a.adapted_for,
            "steady_dL_th": float(view.steady(a.background, polarity)),
            "points": [p.as_dict() for p in pts]}


def demo(a, argv) -> int:
    from .job.run import run_job  # lazy: a command loads its own layers
    from .sample import write_tunnel_sequence  # lazy: a command loads its own layers
    w, h = size(a.size)
    pattern, _ = write_tunnel_sequence(os.path.join(a.outdir, "scene"), w, h, 30.0, a.seconds)
    out = os.path.join(a.outdir, "display", "tunnel.####.png")
    os.makedirs(os.path.dirname(out), exist_ok=True)
    opts = job_options(a, pattern, out)
    opts.plot = opts.plot or os.path.join(a.outdir, "adaptation.png")
    opts.state_out = opts.state_out or os.path.join(a.outdir, "state.json")
    res = run_job(opts)
    print(f"demo: {len(res.outputs)} frames -> {out}; plot {opts.plot}; "
          f"state {opts.state_out}; {res.seconds:.1f} s")
    return 0


def sample(a, argv) -> int:
    # lazy: a command loads its own layers
    from .sample import write_spectral_image, write_tunnel_sequence
    w, h = size(a.size)
    pattern, frames = write_tunnel_sequence(a.outdir, w, h, a.fps, a.seconds)
    print(f"wrote {len(frames)} frames: {pattern} (frames {frames[0]}-{frames[-1]})")
    if a.spectral:
        sp = os.path.join(a.outdir, "colorchecker_spectral.exr")
        write_spectral_image(sp, "A", 0.05, patch_px=24)
        print(f"wrote {sp}")
    return 0


def displays(a, argv) -> int:
    # lazy: a command loads its own layers
    from .colour import list_displays, load_config, resolve_config_source
    cfg = load_config(a.colorconfig)
    print(f"config: {resolve_config_source(a.colorconfig)} ({cfg.getName() or 'unnamed'})")
    for d, views in list_displays(cfg):
        print(f"{d}: {', '.join(views)}")
    return 0


def radiance_env(a, argv) -> int:
    """``export PATH=...`` and ``export RAYPATH=...`` for Radiance's programs of the
    pyradiance wheel (``radiance.tools``), quoted for a POSIX shell."""
    from .radiance import tools  # lazy: a command loads its own layers
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
    from .backends.opencl import probe  # lazy: a command loads its own layers
    # lazy: a command loads its own layers
    from .backends.opencl.runtime import (INSTALL_HINT, OpenCLUnavailable, describe_device,
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
