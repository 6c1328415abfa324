"""Command line: ``ocl-tonemap run | simulate | devices | displays | sample | demo``."""

from __future__ import annotations

import argparse
import logging
import os
import sys

from . import __version__

log = logging.getLogger("ocl_tonemap")


def registry() -> dict:
    """The operators (imported here, not at module level: ``--version`` and ``devices``
    need none of them, nor NumPy)."""
    from .operators import registry as operators
    return operators()


def _add_run_args(p: argparse.ArgumentParser) -> None:
    from .backends.plan import QUALITY_NAMES
    p.add_argument("--frames", help="frame range for sequence patterns: A-B, A-BxSTEP, or a list")
    p.add_argument("--fps", type=float, help="frames per second, up to 1e6 (default: "
                   "FramesPerSecond metadata, else 24)")
    ops = registry()
    p.add_argument("--operator", default="pattanaik00", choices=sorted(ops),
                   help="the model (default pattanaik00): " + "; ".join(
                       f"{n}: {c.description}" for n, c in ops.items()))
    p.add_argument("--mode", choices=["default", "paper"],
                   help="default: the operator as it looks right on photographs; paper: its "
                   "paper taken literally (docs/models.md says where they differ)")
    p.add_argument("--metering", default="logmean",
                   help="logmean (default) | mean | max | centre[:mean] | spot:X,Y[,SIGMA] "
                   "(X, Y: fractions 0..1 of the width and height from the top left; SIGMA: "
                   "fraction of the width, default 0.02) | percentile:P (0..100) | "
                   "mask:WEIGHTS.exr")
    p.add_argument("--luminance-scale", metavar="S|auto:LEVEL",
                   help="cd/m^2 of pixel value 1.0, or auto:LEVEL to put the first frame's "
                   "log-average at LEVEL cd/m^2 (a number, or night 0.01, dusk 1, interior 30, "
                   "overcast 500, daylight 5000; 1e-6..1e8) for files that carry no calibration "
                   "(default: whiteLuminance, else camera EXIF exposure, else 179 for "
                   "Radiance .hdr, else 1 with a warning)")
    p.add_argument("--exposure", type=float, default=0.0, help="extra scale in stops (EV), "
                   "-100..100")
    p.add_argument("--colorconfig", help="OCIO config: file, ocio:// URI or 'ocl-tonemap' "
                   "(default: $OCIO, else ocio://default)")
    p.add_argument("--iscolorspace", help="input colourspace (default: file metadata, file "
                   "rules, scene_linear)")
    p.add_argument("--display", help="OCIO display (default: the config's default)")
    p.add_argument("--view", help="OCIO view (default: the un-tone-mapped view)")
    p.add_argument("--display-model", default="display", choices=["display", "paper-crt"],
                   help="display observer: from the chosen display (default), or Pattanaik "
                   "2000's CRT")
    p.add_argument("--display-white", type=float, help="display white, cd/m^2 (default: 100 SDR, "
                   "peak for HDR)")
    p.add_argument("--display-peak", type=float, default=1000.0, help="HDR display peak, cd/m^2 "
                   "(default 1000)")
    p.add_argument("--display-black", type=float, help="display black, cd/m^2 (default: white/1000 "
                   "for SDR, 0.005 for HDR)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--unpremult", dest="unpremult", action="store_true", default=None,
                   help="the input's colour is premultiplied by alpha: divide before tone "
                   "mapping, multiply after (default: from the file, oiio:UnassociatedAlpha)")
    g.add_argument("--no-unpremult", dest="unpremult", action="store_false",
                   help="tone map the colour as stored")
    p.add_argument("--encode", action="store_true",
                   help="EXR/HDR outputs: display-encoded code values (tagged with the display "
                   "colourspace) instead of display-linear light (the default for float outputs)")
    p.add_argument("--display-encode", choices=["auto", "table", "ocio"], default=None,
                   help="display encoding: table (the OCIO display/view baked into a table, "
                   "applied on the OpenCL device), ocio (OCIO's CPU processor, the reference) "
                   "or auto (default: the table with the OpenCL backend when it is within one "
                   "10-bit code value of OCIO, else ocio)")
    p.add_argument("--preadapt", help="initial adaptation: CD_M2 (fully adapted) or "
                   "CD_M2:SECONDS (exposed that long from dark); CD_M2 0 (darkness) or "
                   "1e-6..1e8, SECONDS 0..1e7 (an m suffix: minutes)")
    p.add_argument("--state-in", help="start from this adaptation state: a state JSON, or an "
                   "output frame of ocl-tonemap (its ocltm:state; global operators)")
    p.add_argument("--state-out", help="write the adaptation state here, after every frame and "
                   "at the end (default checkpoint: OUTPUT without frame number + .state.json)")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run from its checkpoint: frames up to the "
                   "checkpoint's are kept, the rest rendered as one run would")
    p.add_argument("--no-checkpoint", dest="checkpoint", action="store_false",
                   help="do not write the state after every frame")
    p.add_argument("--checkpoint-every", type=int, default=1, metavar="N",
                   help="write the state every N frames (default 1; ledda04 at 1080p spends "
                   "~0.3 s per checkpoint on its per-pixel planes); --resume re-renders the "
                   "frames after the last one, identically")
    p.add_argument("--cuts", metavar="FILE|detect",
                   help="scene cuts: the observer starts afresh (fully adapted to the frame) "
                   "at these frames; a file of frame numbers, or detect (from the shot's "
                   "statistics, a jump of more than 1 log10 unit in the cone adaptation "
                   "goal; needs the measure/integrate passes). Default: no cuts")
    p.add_argument("--stills", action="store_true",
                   help="the frames are independent stills (views of a room, a year of "
                   "daylight renderings): each gets its own observer, adapted to it as a lone "
                   "still is (with --preadapt: that), no state files; start-up paid once")
    p.add_argument("--missing", choices=["error", "hold", "skip"], default="error",
                   help="a frame missing inside a sequence: error (default, before any frame "
                   "is processed), hold (repeat the previous frame at its time) or skip")
    p.add_argument("--backend", default=None, choices=["opencl", "reference"],
                   help="opencl (default) or reference (float64 NumPy)")
    p.add_argument("--quality", choices=list(QUALITY_NAMES), default=None,
                   help="the default of every speed/accuracy knob: draft (fastest: coarsest "
                   "bilateral grid, tables), balanced (default), reference (float64, exact "
                   "filters and flare, OCIO on the CPU); knobs given explicitly win")
    p.add_argument("--device", help="OpenCL device: P:D index, gpu, cpu or a name substring")
    p.add_argument("--out-bits", choices=["8", "16", "half", "float"],
                   help="output sample type (default by extension: EXR half, TIFF 16, PNG/JPEG 8)")
    p.add_argument("--max-memory", type=float, metavar="MIB",
                   help="host memory budget: frames that would take more whole are read, "
                   "mapped and written in row bands (every operator and effect; default: "
                   "stream only frames larger than a quarter of the machine's memory)")
    p.add_argument("--png-level", type=int, default=1, metavar="0-9",
                   help="zlib level of PNG outputs (default 1: 3.5x faster to write than 6, "
                   "files ~13%% larger)")
    p.add_argument("--png-filter", choices=("sub", "none", "adaptive"), default="sub",
                   help="PNG row filter (default sub: 1.6-3x faster to write than libpng's "
                   "adaptive choice, files within -2%%..+15%%)")
    p.add_argument("--serial-io", action="store_true",
                   help="read, map and write each frame in turn on one thread (default: the "
                   "next frame is read and the last one written while the device works)")
    p.add_argument("--channels", metavar="R,G,B",
                   help="input channels to use as R,G,B (or one name: luminance); default the "
                   "R, G, B channels by name")
    p.add_argument("--plot", help="write a PNG of adaptation over time and mapping curves")
    p.add_argument("--plot-frames", help="frame indices (0-based) for the mapping curves")
    p.add_argument("--ocio-export", metavar="DIR",
                   help="also write the observer as an OCIO view: DIR/<name>.ocio (OCIO 2.1 and "
                   "later) and one CLF per frame, replayed by OCIO's tools, oiiotool and Nuke "
                   "with the context variable FRAME (global operators, --flare off --acuity "
                   "off; docs/ocio_export.md)")
    p.add_argument("--ocio-export-size", default="auto", metavar="N|auto",
                   help="nodes per axis of the exported LUTs: 17, 25, 33, 49 or 65 (33: ~3 MB "
                   "of CLF a frame, 65: ~20 MB), or auto (default): 33, else 49, else 65 "
                   "where a frame is not within 1 8-bit code (p99) and 3 (max) of the run")
    p.add_argument("--max-band-pixels", type=int, help=argparse.SUPPRESS)
    _add_operator_args(p)
    g = p.add_argument_group("mechanisms and effects (every operator)")
    g.add_argument("--model", choices=["auto", "full", "none"],
                   help="which mechanisms of vision a frame gets: auto (default) what the frame "
                   "needs, within one JND (Delta E ITP p99) of full; full: every effect the "
                   "operator can take; none: the operator alone. --mode paper implies none; "
                   "an effect given on|off wins")
    for name, what in (("flare", "glare of light sources (Spencer et al. 1995)"),
                       ("acuity", "loss of acuity in the dark (Shaler 1937)"),
                       ("chromatic-adaptation", "von Kries adaptation to the illuminant, tau 5 s"),
                       ("purkinje", "rod colour shift of kirk11 on the scene's colours "
                        "(Kirk & O'Brien 2011)")):
        g.add_argument(f"--{name}", choices=["on", "off", "auto"], help=what)
    g.add_argument("--fov", type=float, help="angular width of the image, degrees, 0..360 "
                   "(default: a Radiance picture's VIEW, else 50)")
    g.add_argument("--illuminant", help="illuminant for chromatic adaptation: x,y or a name "
                   "(D65, D50, A, F2, F11, LED-B3 ...); default: EXR adoptedNeutral, else "
                   "estimated from the frame")
    g.add_argument("--flare-method", choices=["fast", "exact"],
                   help="fast: Gaussians on a pyramid (default); exact: FFT of the full PSF")
    g.add_argument("--flare-threshold", type=float,
                   help="light sources are pixels above this x the adaptation level (default 7)")
    g.add_argument("--flare-sampling", type=int, metavar="N",
                   help="fast flare: Gaussians per octave (default 1)")


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


def operator_flags() -> list:
    """The command-line options of every registered operator, generated from their
    option specs: [(Option, operators declaring it)], one entry per flag (``--mode``,
    shared by all, is a run option). Given for another operator, a flag is ignored
    with a warning (one rule for all of them)."""
    out: dict = {}
    for name, cls in registry().items():
        for o in cls.options:
            if not o.flag or o.flag == "--mode":
                continue
            if o.flag not in out:
                out[o.flag] = (o, [])
            out[o.flag][1].append(name)
    return [(o, tuple(ops)) for o, ops in out.values()]


def _add_operator_args(p: argparse.ArgumentParser) -> None:
    groups: dict = {}
    for o, ops in operator_flags():
        title = ", ".join(ops)
        if title not in groups:
            groups[title] = p.add_argument_group(f"{title} options")
        kw = {"help": o.help, "default": o.default}
        for k in ("type", "choices", "metavar"):
            if getattr(o, k) is not None:
                kw[k] = getattr(o, k)
        groups[title].add_argument(o.flag, dest=o.dest, **kw)


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


def _add_shot_args(g, chunk: bool = False, chunk_frames: bool = False,
                   keyframes: bool = False) -> None:
    g.add_argument("--store", help="the shot's statistics and states, a folder every worker "
                   "sees (default: beside the output, OUTPUT without frame number + .shot)")
    if chunk:
        g.add_argument("--chunk", metavar="A-B",
                       help="this task's frames (default: the whole shot, --frames)")
    if chunk_frames:
        g.add_argument("--chunk-frames", type=int, metavar="N",
                       help="frames per task (and per-pixel keyframe interval); default: "
                       "four tasks per worker (dask), 50 (farm)")
    if keyframes:
        g.add_argument("--keyframe-every", type=int, metavar="N",
                       help="local operators: keep the per-pixel state every N frames "
                       "(the apply chunk size; default 50)")


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
    """argparse with its errors in one line (``ocl-tonemap ERROR: ...``), exit 2."""

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
            _add_run_args(p)
    p = sub.add_parser("run", help="tone map an image or a sequence")
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
    _add_shot_args(g, chunk_frames=True)
    for name, what in (("measure", "pass 1: each frame's statistics into the shot store "
                        "(parallel over chunks)"),
                       ("integrate", "pass 2: the adaptation state through the whole shot "
                        "from the statistics (serial)"),
                       ("apply", "pass 3: tone map a chunk of frames from the integrated "
                        "state (parallel over chunks)"),
                       ("export", "pass 3 without pixels: the observer as an OCIO view "
                        "(--ocio-export DIR) from the integrated state; frames are read, "
                        "none mapped or written (parallel over chunks)")):
        p = sub.add_parser(name, help=what)
        p.add_argument("input", help="the shot's sequence pattern")
        p.add_argument("output", help="the output pattern (the store defaults to beside it)")
        run_args(p, name)
        g = p.add_argument_group(f"{name} pass")
        _add_shot_args(g, chunk=name != "integrate", keyframes=name == "integrate")
        if name == "measure":
            g.add_argument("--redo", action="store_true",
                           help="measure frames again even when their statistics are stored")
    p = sub.add_parser("farm-template", help="write a render-farm job (OpenJD or OpenCue) "
                       "that runs the shot as measure -> integrate -> apply")
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
    _add_shot_args(g, chunk_frames=True)
    p = sub.add_parser("simulate", help="a still image seen over time after pre-adaptation "
                       "(one output per --at time)")
    p.add_argument("input", help="one image")
    p.add_argument("output", help="output name (a _t<T>s suffix is added) or a frame pattern "
                   "(frames 1..n in --at order)")
    p.add_argument("--at", required=True, help="elapsed times since the switch: T1,T2,... "
                   "seconds, or with an m suffix minutes (e.g. 1m,2m,4m,16m)")
    run_args(p, "simulate")
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
    p = sub.add_parser("demo", help="write the sample and run the main job on it")
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
    level = logging.WARNING if a.quiet else (logging.INFO if a.verbose else logging.WARNING)
    if a.verbose > 1:
        level = logging.DEBUG
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
