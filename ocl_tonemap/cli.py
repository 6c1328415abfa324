"""Command line: ``ocl-tonemap run | simulate | devices | displays | sample | demo``."""

from __future__ import annotations

import argparse
import logging
import os
import sys

from . import __version__
from .cli_options import add_run_options, add_shot_options, operator_flags

log = logging.getLogger("ocl_tonemap")


def registry() -> dict:
    """The operators (imported here, not at module level: ``--version`` and ``devices``
    need none of them, nor NumPy)."""
    from .operators import registry as operators
    return operators()


def _options(a, input_, output, defer_backend: bool = False):
    """The run's JobOptions; ``defer_backend``: "auto", probed by ``job.run.run_job``."""
    from .backends.plan import quality_tier
    from .imageio import parse_frames
    from .job.options import JobOptions, parse_preadapt
    tier = quality_tier(a.quality)
    return JobOptions(
        input=input_, output=output,
        frames=parse_frames(a.frames) if a.frames else None, fps=a.fps, operator=a.operator,
        metering=a.metering, luminance_scale=a.luminance_scale, exposure=a.exposure,
        colorconfig=a.colorconfig, iscolorspace=a.iscolorspace, display=a.display, view=a.view,
        display_model=a.display_model, display_white=a.display_white,
        display_peak=a.display_peak, display_black=a.display_black, unpremult=a.unpremult,
        encode=a.encode,
        preadapt=parse_preadapt(a.preadapt) if a.preadapt else None,
        state_in=a.state_in, state_out=a.state_out, backend=_backend(a, tier, defer_backend),
        device=a.device, quality=tier.name,
        out_bits=a.out_bits, plot=a.plot, ocio_export=a.ocio_export, fov_given=a.fov is not None,
        stills=a.stills,
        ocio_export_size=_export_size(a.ocio_export_size),
        plot_frames=[int(x) for x in a.plot_frames.split(",")] if a.plot_frames else None,
        max_band_pixels=a.max_band_pixels, operator_options=_tier_options(a, tier),
        effects=_effects(a, tier), missing=a.missing, resume=a.resume, checkpoint=a.checkpoint,
        checkpoint_every=a.checkpoint_every,
        channels=[c.strip() for c in a.channels.split(",")] if a.channels else None,
        png_level=a.png_level, png_filter=a.png_filter, max_memory=a.max_memory,
        overlap_io=not a.serial_io,
        cuts=parse_cuts(a.cuts),
        display_encode=a.display_encode or tier.display_encode,
        progress=(not a.quiet) and (a.verbose > 0 or sys.stderr.isatty()))


def _export_size(text: str):
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"--ocio-export-size must be auto or a number (got {text!r})") from None


def _backend(a, tier, defer: bool = False) -> str:
    """The backend a run uses. ``--backend`` given: that one (a broken or missing
    OpenCL device is then an error, as is a ``--device`` naming a broken one).
    Otherwise OpenCL on the first working device, else the float64 reference with one
    warning line (``backends.resolve_backend``; ``defer``: "auto", for the job to
    resolve)."""
    from .backends import resolve_backend
    if a.backend:
        return a.backend
    name = "auto" if tier.backend == "opencl" else tier.backend
    return name if defer and name == "auto" else resolve_backend(name, a.device)


def parse_cuts(text: str | None):
    """``--cuts``: ``detect``, or a file of frame numbers (whitespace or commas; ``#``
    starts a comment)."""
    if text is None:
        return None
    if text.strip().lower() == "detect":
        return "detect"
    from .imageio import MAX_FRAME
    from .safeio import read_text
    raw = read_text(text, "--cuts", CUTS_CAP)
    body = " ".join(line.split("#", 1)[0] for line in raw.splitlines())
    try:
        cuts = sorted({int(v) for v in body.replace(",", " ").split()})
    except ValueError:
        raise ValueError(f"--cuts {text}: the file must hold frame numbers") from None
    if any(abs(c) > MAX_FRAME for c in cuts):
        raise ValueError(f"--cuts {text}: frame numbers are within +-{MAX_FRAME}")
    return cuts


#: Largest --cuts file (a list of frame numbers), bytes.
CUTS_CAP = 1 << 20


def _effects(a, tier=None):
    fx = _effect_settings(a, tier)
    _check_effect_flags(a, fx)
    return fx


def _effect_settings(a, tier=None):
    """The effects asked for, over the ``--quality`` tier's defaults."""
    from .effects import EffectSettings
    given = dict(flare=a.flare, acuity=a.acuity, chromatic_adaptation=a.chromatic_adaptation,
                 purkinje=a.purkinje, fov_deg=a.fov, illuminant=a.illuminant,
                 flare_method=a.flare_method, flare_threshold=a.flare_threshold,
                 flare_per_octave=a.flare_sampling)
    base = dict(tier.effects) if tier is not None else {}
    return EffectSettings.for_operator(
        a.operator, a.model or "auto", paper=a.mode == "paper",
        **{**base, **{k: v for k, v in given.items() if v is not None}})


def _tier_options(a, tier) -> dict | None:
    """The operator's options given on the command line over the ``--quality`` tier's
    (only those the chosen operator declares: no warning for the others)."""
    given = _operator_options(a) or {}
    declared = [o.name for o in registry()[a.operator].options]
    return {**tier.options_for(declared), **given} or None


def _ignored(flag: str, where: str, operator: str) -> None:
    log.warning("%s applies to %s: ignored for %s", flag, where, operator)


def _operator_options(a) -> dict | None:
    if a.max_band_pixels is not None and a.max_band_pixels < 1:
        raise ValueError("--max-band-pixels must be >= 1")
    opts = {"mode": a.mode} if a.mode else {}
    for o, ops in operator_flags():
        v = getattr(a, o.dest)
        if v is None or v == o.default:
            continue
        if o.check is not None:
            o.check(v)
        if a.operator not in ops:
            _ignored(o.flag, " and ".join(ops), a.operator)
            continue
        opts[o.name] = o.convert(v) if o.convert else v
    reg = registry()
    if reg[a.operator].metering == "local" and a.metering != "logmean":
        metered = ", ".join(n for n, c in reg.items() if c.metering != "local")
        _ignored("--metering", f"the global operators ({metered}); "
                 f"{a.operator} adapts locally", a.operator)
    return opts or None


def _check_effect_flags(a, fx) -> None:
    """Effect parameters given for an effect that is off: the same one rule."""
    for flag, v, on in (("--flare-method", a.flare_method, fx.flare != "off"),
                        ("--flare-threshold", a.flare_threshold, fx.flare != "off"),
                        ("--flare-sampling", a.flare_sampling, fx.flare != "off"),
                        ("--illuminant", a.illuminant, fx.chromatic_adaptation != "off"),
                        ("--fov", a.fov, fx.flare != "off" or fx.acuity != "off")):
        if v is not None and not on:
            log.warning("%s applies to an effect that is off: ignored (switch it on with "
                        "--flare/--acuity/--chromatic-adaptation on|auto)", flag)
    if a.plot_frames and not a.plot:
        log.warning("--plot-frames applies to --plot: ignored")


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


def _command_of(argv) -> str | None:
    """The sub-command an argument list names: its first token that is not a flag (the
    top-level flags -v, -q, --version and -h take no value)."""
    return next((t for t in argv if not t.startswith("-")), None)


#: build_parser's default: every sub-command with all its options.
ALL_COMMANDS = "*"


class _Parser(argparse.ArgumentParser):
    """argparse with its errors in one line (``ocl-tonemap ERROR: ...``), exit 2, and no
    abbreviated flags (``--fram`` is an error, not ``--frames``)."""

    def __init__(self, *args, **kw):
        kw.setdefault("allow_abbrev", False)
        super().__init__(*args, **kw)

    def error(self, message):
        self.exit(2, f"ocl-tonemap ERROR: {message} (see {self.prog} --help)\n")


def build_parser(command: str | None = ALL_COMMANDS) -> argparse.ArgumentParser:
    """The whole parser; with ``command``, that sub-command's options only (the others
    keep their name and help; None: no sub-command's, as for ``--version`` or the
    top-level ``--help``): the run options of seven sub-commands take ~15 ms to build,
    and the operators they list import NumPy."""
    ap = _Parser(prog="ocl-tonemap", description=(
        "Show an HDR scene or shot as a human observer would see it (time-dependent "
        "visual adaptation on OpenCL, OIIO/OCIO pipelines)."))
    ap.add_argument("--version", action="version", version=f"ocl-tonemap {__version__}")
    ap.add_argument("-v", "--verbose", action="count", default=0)
    ap.add_argument("-q", "--quiet", action="store_true")
    # -v/-q also after the sub-command (ocl-tonemap run ... -v)
    common = _Parser(add_help=False)
    common.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS)
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS)
    sub = ap.add_subparsers(dest="cmd", required=True, parser_class=_Parser)
    _sub = sub.add_parser

    def add_parser(name, **kw):
        return _sub(name, parents=[common], **kw)
    sub.add_parser = add_parser

    def run_args(p, name):
        if command in (ALL_COMMANDS, name):
            add_run_options(p, shown=name == "run")
    also = "; also every option of run (ocl-tonemap run --help)"
    p = sub.add_parser("run", help="tone map an image or a sequence",
                       usage="ocl-tonemap run [options] INPUT OUTPUT")
    p.add_argument("input", help="image or sequence pattern (shot.#.exr, shot.@@@@.exr, shot.%%04d.exr)")
    p.add_argument("output", help="output image or pattern (format by extension)")
    run_args(p, "run")
    g = p.add_argument_group("a shot on many machines (measure -> integrate -> apply)")
    g.add_argument("--scheduler", metavar="dask|tcp://HOST:PORT",
                   help="run the three passes on Dask: dask starts a local cluster of "
                   "--workers processes, an address uses a running one (default: serial)")
    g.add_argument("--workers", type=int, default=2, help="local cluster size (default 2)")
    g.add_argument("--scheduler-security", metavar="FILE",
                   help="TLS for a tls:// scheduler: a YAML or JSON file with ca, cert and key "
                   "(PEM paths, relative to the file), Dask's Security; without it, Dask's own "
                   "configuration (distributed.comm.tls.*, DASK_DISTRIBUTED__COMM__TLS__*)")
    add_shot_options(g, chunk_frames=True)
    for name, what in (("measure", "pass 1: each frame's statistics into the shot store "
                        "(parallel over chunks)"),
                       ("integrate", "pass 2: the adaptation state through the whole shot "
                        "from the statistics (serial)"),
                       ("apply", "pass 3: tone map a chunk of frames from the integrated "
                        "state (parallel over chunks)"),
                       ("export", "pass 3 without pixels: the observer as an OCIO view "
                        "(--ocio-export DIR) from the integrated state; frames are read, "
                        "none mapped or written (parallel over chunks)")):
        p = sub.add_parser(name, help=what, description=what + also,
                           usage=f"ocl-tonemap {name} [options] INPUT OUTPUT")
        p.add_argument("input", help="the shot's sequence pattern")
        p.add_argument("output", help="the output pattern (the store defaults to beside it)")
        run_args(p, name)
        g = p.add_argument_group(f"{name} pass")
        add_shot_options(g, chunk=name != "integrate", keyframes=name == "integrate")
        if name == "measure":
            g.add_argument("--redo", action="store_true",
                           help="measure frames again even when their statistics are stored")
    what = "write a render-farm job (OpenJD or OpenCue) that runs the shot as measure -> " \
        "integrate -> apply"
    p = sub.add_parser("farm-template", help=what, description=what + also,
                       usage="ocl-tonemap farm-template --format F -o JOB [options] INPUT OUTPUT")
    p.add_argument("input", help="the shot's sequence pattern")
    p.add_argument("output", help="the output pattern")
    run_args(p, "farm-template")
    g = p.add_argument_group("job")
    g.add_argument("--format", required=True, choices=["openjd", "opencue"],
                   help="openjd: an Open Job Description template (Deadline Cloud ...); "
                   "opencue: an OpenCue job spec (XML)")
    g.add_argument("-o", "--job-file", required=True, help="where to write the job")
    g.add_argument("--name", help="job name (default: from the output name)")
    g.add_argument("--command", default="ocl-tonemap",
                   help="the command the farm runs (default ocl-tonemap)")
    add_shot_options(g, chunk_frames=True)
    what = "a still image seen over time after pre-adaptation (one output per --at time)"
    p = sub.add_parser("simulate", help=what, description=what + also,
                       usage="ocl-tonemap simulate --at T1,T2,... [options] INPUT OUTPUT")
    p.add_argument("input", help="one image")
    p.add_argument("output", help="output name (a _t<T>s suffix is added) or a frame pattern "
                   "(frames 1..n in --at order)")
    p.add_argument("--at", required=True, help="elapsed times since the switch: T1,T2,... "
                   "seconds, or with an m suffix minutes (e.g. 1m,2m,4m,16m)")
    run_args(p, "simulate")
    sub.add_parser("radiance-env", help="the shell lines that put Radiance's programs from "
                   "pip install 'ocl-tonemap[radiance]' on PATH (eval \"$(ocl-tonemap "
                   "radiance-env)\")")
    p = sub.add_parser("devices", help="list OpenCL devices, each probed: ok or broken")
    p.add_argument("--check", action="store_true",
                   help="exit 1 when no device works (scripts, CI)")
    p = sub.add_parser("displays", help="list the OCIO config's displays and views")
    p.add_argument("--colorconfig")
    p = sub.add_parser("sample", help="write the built-in tunnel-drive sample (EXR, cd/m^2)")
    p.add_argument("outdir")
    p.add_argument("--spectral", action="store_true",
                   help="also write a spectral OpenEXR ColorChecker lit by tungsten at "
                   "0.05 cd/m^2 (colorchecker_spectral.exr, for kirk11)")
    p.add_argument("--size", default="320x180")
    p.add_argument("--seconds", type=float, default=8.0)
    p.add_argument("--fps", type=float, default=30.0)
    what = "write the sample and run the main job on it"
    p = sub.add_parser("demo", help=what, description=what + also,
                       usage="ocl-tonemap demo [options] OUTDIR")
    p.add_argument("outdir")
    p.add_argument("--size", default="320x180")
    p.add_argument("--seconds", type=float, default=8.0)
    run_args(p, "demo")
    return ap


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w < 1 or h < 1:
            raise ValueError
        return w, h
    except ValueError:
        raise SystemExit(f"ocl-tonemap ERROR: bad --size {text!r} (use WxH)") from None


def _shot_command(a, argv: list[str]) -> int:
    """``measure`` / ``integrate`` / ``apply`` / ``export`` / ``farm-template``."""
    from .shot import passes
    opts = _options(a, a.input, a.output)
    store = a.store or passes.default_store(opts)
    if a.cmd == "measure":
        done = passes.measure(opts, store, passes.parse_chunk(a.chunk), redo=a.redo)
        if not a.quiet:
            print(f"measured {len(done)} frame(s) into {store}")
    elif a.cmd == "integrate":
        doc = passes.integrate(opts, store, a.keyframe_every)
        if not a.quiet:
            print(f"integrated {len(doc['frames'])} frame(s) in {store}; keyframes "
                  f"{len(doc['keyframes'])}; cuts: {', '.join(map(str, doc['cuts'])) or 'none'}")
    elif a.cmd == "apply":
        res = passes.apply(opts, store, passes.parse_chunk(a.chunk))
        if not a.quiet:
            print(f"wrote {len(res.outputs)} frame(s) in {res.seconds:.2f} s")
            if res.export:
                print(res.export)
    elif a.cmd == "export":
        if not opts.ocio_export:
            raise ValueError("export: say where, --ocio-export DIR")
        ex, read_s, export_s = passes.export(opts, store, passes.parse_chunk(a.chunk))
        if not a.quiet:
            print(f"{ex.summary()}; per frame {1e3 * export_s:.0f} ms exporting, "
                  f"{1e3 * read_s:.0f} ms reading")
    else:
        from .shot.farm import write_template
        path = write_template(a.format, opts, run_option_tokens(argv, a), a.job_file,
                              store=a.store, chunk=a.chunk_frames, name=a.name,
                              command=a.command)
        if not a.quiet:
            print(f"wrote {a.format} job {path}")
    return 0


def _radiance_env() -> int:
    """``export PATH=...`` and ``export RAYPATH=...`` for Radiance's programs of the
    pyradiance wheel (``radiance.tools``), quoted for a POSIX shell."""
    import shlex
    from .radiance import tools
    found = tools()
    if found is None:
        raise ValueError("Radiance's programs are not installed: pip install "
                         "'ocl-tonemap[radiance]' (the pyradiance wheel)")
    b, env = found
    print(f"export PATH={shlex.quote(b)}:\"$PATH\"")
    print(f"export RAYPATH={shlex.quote(env['RAYPATH'])}")
    return 0


def _devices(check: bool = False) -> int:
    """``devices``: every OpenCL device with its probe verdict, and which one a run
    takes by default."""
    from .backends.opencl import probe
    from .backends.opencl.runtime import (INSTALL_HINT, OpenCLUnavailable, describe_device,
                                          device_status, list_devices)
    devs = list_devices()
    if not devs:
        if check:
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
        return 1 if check else 0
    else:
        key = next(k for k, d in devs if d == dev)
        print(f"default: {key} {dev.name.strip()}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """The command line: 0 done, 2 bad input or a failure named in one ERROR line
    (never a traceback; ``-vv`` logs it), 130 / 143 interrupted (SIGINT / SIGTERM)."""
    from .interrupts import Terminated, exit_code, install
    install()
    try:
        return _main(argv)
    except (KeyboardInterrupt, Terminated) as exc:
        ck = sys.modules.get("ocl_tonemap.job.checkpoint")
        if ck is not None:                # a lock whose release the signal cut short
            ck.release_held()
        print("ocl-tonemap: interrupted; the frame in flight was discarded", file=sys.stderr)
        return exit_code(exc)
    except Exception:                     # a signal a library made its own error (NumPy's
        from . import interrupts          # import under the parser: ImportError)
        if not interrupts.received:
            raise
        print("ocl-tonemap: interrupted", file=sys.stderr)
        return exit_code()


def _main(argv: list[str] | None = None) -> int:
    a = build_parser(_command_of(sys.argv[1:] if argv is None else argv)).parse_args(argv)
    logging.addLevelName(25, "NOTE")    # what the user should know, not a fault
    level = logging.WARNING if a.quiet else (logging.INFO if a.verbose else 25)
    level = logging.DEBUG if a.verbose > 1 else level
    logging.basicConfig(level=level, format="ocl-tonemap %(levelname)s: %(message)s")
    if a.quiet:
        logging.getLogger("ocl_tonemap").setLevel(logging.ERROR)
    from .imageio import FrameError, one_line
    try:
        if a.cmd == "devices":
            return _devices(a.check)
        if a.cmd == "displays":
            from .colour import list_displays, load_config, resolve_config_source
            cfg = load_config(a.colorconfig)
            print(f"config: {resolve_config_source(a.colorconfig)} ({cfg.getName() or 'unnamed'})")
            for d, views in list_displays(cfg):
                print(f"{d}: {', '.join(views)}")
            return 0
        if a.cmd == "radiance-env":
            return _radiance_env()
        if a.cmd == "sample":
            from .sample import write_tunnel_sequence
            w, h = _size(a.size)
            pattern, frames = write_tunnel_sequence(a.outdir, w, h, a.fps, a.seconds)
            print(f"wrote {len(frames)} frames: {pattern} (frames {frames[0]}-{frames[-1]})")
            if a.spectral:
                from .sample import write_spectral_image
                sp = os.path.join(a.outdir, "colorchecker_spectral.exr")
                write_spectral_image(sp, "A", 0.05, patch_px=24)
                print(f"wrote {sp}")
            return 0
        if a.cmd == "demo":
            from .sample import write_tunnel_sequence
            from .job.run import run_job
            w, h = _size(a.size)
            src = os.path.join(a.outdir, "scene")
            pattern, frames = write_tunnel_sequence(src, w, h, 30.0, a.seconds)
            out = os.path.join(a.outdir, "display", "tunnel.####.png")
            os.makedirs(os.path.dirname(out), exist_ok=True)
            opts = _options(a, pattern, out)
            opts.plot = opts.plot or os.path.join(a.outdir, "adaptation.png")
            opts.state_out = opts.state_out or os.path.join(a.outdir, "state.json")
            res = run_job(opts)
            print(f"demo: {len(res.outputs)} frames -> {out}; plot {opts.plot}; "
                  f"state {opts.state_out}; {res.seconds:.1f} s")
            return 0
        if a.cmd == "simulate":
            from .job.options import parse_times
            from .job.simulate import run_simulate
            res = run_simulate(_options(a, a.input, a.output), parse_times(a.at))
            if not a.quiet:                   # (rendered in time order)
                for t, o in zip(sorted(parse_times(a.at)), res.outputs):
                    print(f"t = {t:g} s -> {o}")
            return 0
        if a.cmd in ("measure", "integrate", "apply", "export", "farm-template"):
            return _shot_command(a, argv if argv is not None else sys.argv[1:])
        if a.scheduler:
            from .shot.distributed import run_distributed
            opts = _options(a, a.input, a.output)
            res = run_distributed(opts, a.scheduler, a.workers, a.chunk_frames, a.store,
                                  progress=opts.progress,
                                  pocl_threads=max(1, (os.cpu_count() or 1) // max(1, a.workers)),
                                  security=a.scheduler_security)
            if not a.quiet:
                times = ", ".join(f"{k} {v:.2f} s" for k, v in res.passes.items())
                print(f"wrote {len(res.outputs)} frame(s) in {res.seconds:.2f} s ({times})")
            return 0
        from .job.options import Interrupted
        from .job.run import run_job
        try:
            res = run_job(_options(a, a.input, a.output, defer_backend=True))
        except Interrupted as e:
            import shlex
            again = [x for x in (argv if argv is not None else sys.argv[1:]) if x != "--resume"]
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
            if res.export:
                print(res.export)
        return 0
    except Exception as e:                                    # noqa: BLE001
        from . import interrupts
        if interrupts.received:          # a signal a library turned into its own error
            print("ocl-tonemap: interrupted", file=sys.stderr)   # (an import: ImportError)
            return interrupts.exit_code()
        log.debug("traceback", exc_info=True)
        if isinstance(e, FrameError):
            where = e.path if e.frame is None else f"{e.path} frame {e.frame}"
            print(f"ocl-tonemap ERROR: {where}: {e.why}", file=sys.stderr)
        elif isinstance(e, MemoryError):
            print("ocl-tonemap ERROR: out of memory; give --max-memory MIB to process frames "
                  "in row bands", file=sys.stderr)
        else:   # ours say what and where; a library's own (OCIO's, Dask's ...) says its kind
            known = isinstance(e, (ValueError, RuntimeError, OSError))
            print(f"ocl-tonemap ERROR: {one_line(e, not known)}", file=sys.stderr)
        return 2
