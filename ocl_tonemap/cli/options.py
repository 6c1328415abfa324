"""The command line's options, in the groups its help shows them in. Each group
declares its flags once, for every sub-command that takes them, and builds its
part of the job's options (:func:`job_options`); the operators' and the effects'
flags are made from their declared options (``Option``, ``EffectOption``), so a
plugin's come with it."""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Callable, NamedTuple

from ..base.quantities import RUN

log = logging.getLogger("ocl_tonemap")


class _Shown:
    """An argument group, or the parser itself with every help suppressed (an option
    accepted but not listed)."""

    def __init__(self, target, shown: bool):
        self.target, self.shown = target, shown

    def add_argument(self, *args, **kw):
        if not self.shown:
            kw["help"] = argparse.SUPPRESS
        return self.target.add_argument(*args, **kw)

    def add_mutually_exclusive_group(self):
        return _Shown(self.target.add_mutually_exclusive_group(), self.shown)


class Group(NamedTuple):
    """One group of run options: ``flags(g)`` declares them on ``g``; ``build(a, tier)``
    their part of :class:`~ocl_tonemap.job.options.JobOptions` from the parsed ``a``."""

    key: str
    title: str
    flags: Callable
    build: Callable


def _registry() -> dict:
    """The operators (imported when the options are made: ``--version`` and ``devices``
    need none of them, nor NumPy)."""
    from ..operators import registry  # lazy: --help loads no NumPy
    return registry()


def declared_flag(g, flag: str, text: str, key: str | None = None, **kw) -> None:
    """A flag whose value is declared in ``quantities.RUN`` (by its JobOptions field, by
    default the flag's name): its parser's check and its help's range come from there."""
    d = RUN[key or flag[2:].replace("-", "_")]
    g.add_argument(flag, type=d.arg(flag), help=d.help(text), **kw)


def _ignored(flag: str, where: str, operator: str) -> None:
    log.warning("%s applies to %s: ignored for %s", flag, where, operator)


# -- input -----------------------------------------------------------------------------------
def _input_flags(g) -> None:
    declared_flag(g, "--frames", "frame range for sequence patterns", metavar="A-B[xSTEP],...")
    declared_flag(g, "--fps", "frames per second (default: FramesPerSecond metadata, else 24)")
    g.add_argument("--iscolorspace", metavar="NAME", help="input colourspace (default: file metadata, file "
                   "rules, scene_linear)")
    x = g.add_mutually_exclusive_group()
    x.add_argument("--unpremult", dest="unpremult", action="store_true", default=None,
                   help="the input's colour is premultiplied by alpha: divide before tone "
                   "mapping, multiply after (default: from the file, oiio:UnassociatedAlpha)")
    x.add_argument("--no-unpremult", dest="unpremult", action="store_false",
                   help="tone map the colour as stored")
    g.add_argument("--stills", action="store_true",
                   help="independent stills: each frame its own observer, no state files")
    g.add_argument("--missing", choices=["error", "hold", "skip"], default="error",
                   help="a frame missing inside a sequence: error (default), hold or skip")
    g.add_argument("--channels", metavar="R,G,B",
                   help="input channels to use as R,G,B (or one name: luminance); default the "
                   "R, G, B channels by name")


def _input_build(a, tier) -> dict:
    return {"frames": a.frames, "fps": a.fps,
            "iscolorspace": a.iscolorspace, "unpremult": a.unpremult, "stills": a.stills,
            "missing": a.missing,
            "channels": [c.strip() for c in a.channels.split(",")] if a.channels else None}


# -- calibration -----------------------------------------------------------------------------
def _calibration_flags(g) -> None:
    declared_flag(g, "--luminance-scale", "cd/m^2 of pixel value 1.0, or auto:LEVEL: the first "
              "frame's log-average (default: the file's calibration, else 1 with a warning)",
              metavar="S|auto:LEVEL")
    declared_flag(g, "--exposure", "extra scale in stops (default 0)", default=0.0)


def _calibration_build(a, tier) -> dict:
    return {"luminance_scale": a.luminance_scale, "exposure": a.exposure}


# -- operator --------------------------------------------------------------------------------
def _operator_flags(g) -> None:
    g.add_argument("--operator", default="pattanaik00", choices=sorted(_registry()),
                   help="the model (default pattanaik00; the README's table, docs/models.md)")
    g.add_argument("--mode", choices=["default", "paper"],
                   help="default: the operator as it looks right on photographs; paper: its "
                   "paper taken literally (docs/models.md says where they differ)")
    g.add_argument("--metering", default="logmean",
                   help="logmean (default) | mean | max | centre[:mean] | spot:X,Y[,SIGMA] | "
                   "percentile:P | mask:WEIGHTS.exr (docs/models.md: Metering)")
    declared_flag(g, "--preadapt", "initial adaptation (default: to the first frame)",
              metavar="CD_M2[:SECONDS]")


def _operator_build(a, tier) -> dict:
    return {"operator": a.operator, "metering": a.metering, "preadapt": a.preadapt,
            "operator_options": _operator_options(a, tier)}


def _operator_options(a, tier) -> dict | None:
    """The operator's options given on the command line over the ``--quality`` tier's
    (only those the chosen operator declares); a flag given for another operator is
    ignored with a warning (one rule for all of them)."""
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
    reg = _registry()
    if reg[a.operator].metering == "local" and a.metering != "logmean":
        metered = ", ".join(n for n, c in reg.items() if c.metering != "local")
        _ignored("--metering", f"the global operators ({metered}); "
                 f"{a.operator} adapts locally", a.operator)
    declared = [o.name for o in reg[a.operator].options]
    return {**tier.options_for(declared), **opts} or None


def operator_flags() -> list:
    """The command-line options of every registered operator, from their option specs:
    [(Option, operators declaring it)], one entry per flag (``--mode``, shared by all,
    is a run option)."""
    out: dict = {}
    for name, cls in _registry().items():
        for o in cls.options:
            if not o.flag or o.flag == "--mode":
                continue
            if o.flag not in out:
                out[o.flag] = (o, [])
            out[o.flag][1].append(name)
    return [(o, tuple(ops)) for o, ops in out.values()]


def _add_declared(g, o, default=None) -> None:
    """A flag made from a declared option (an operator's or an effect's)."""
    kw = {"help": o.help_text, "default": default}
    for k in ("type", "choices", "metavar"):
        if getattr(o, k) is not None:
            kw[k] = getattr(o, k)
    g.add_argument(o.flag, dest=o.dest, **kw)


def add_operator_options(p: argparse.ArgumentParser, shown: bool = True) -> None:
    """Each operator's own options (its ``Option`` specs), a group per operator set."""
    groups: dict = {}
    for o, ops in operator_flags():
        title = ", ".join(ops)
        if title not in groups:
            groups[title] = _Shown(p.add_argument_group(f"{title} options") if shown else p,
                                   shown)
        _add_declared(groups[title], o, o.default)


# -- effects ---------------------------------------------------------------------------------
def _effect_flags(g) -> None:
    from ..effects.settings import options  # lazy: --help loads no NumPy
    g.add_argument("--model", choices=["auto", "full", "none"],
                   help="auto (default): each frame the mechanisms it needs, within one JND of "
                   "full; full: every effect; none: the operator alone")
    for o, _ in options().values():
        _add_declared(g, o)


def _effect_build(a, tier) -> dict:
    """The effects asked for, over the ``--quality`` tier's defaults; a parameter given
    for effects that are all off is ignored with a warning (one rule for all)."""
    from ..effects.settings import EffectSettings, options  # lazy: --help loads no NumPy
    given = {k: getattr(a, o.dest) for k, (o, _) in options().items()}
    fx = EffectSettings.for_operator(
        a.operator, a.model or "auto", paper=a.mode == "paper",
        **{**dict(tier.effects), **{k: v for k, v in given.items() if v is not None}})
    for k, (o, owners) in options().items():
        if k in owners or given[k] is None:
            continue                        # a switch, or not given
        if all(getattr(fx, e) == "off" for e in owners):
            flags = "/".join("--" + e.replace("_", "-") for e in owners)
            log.warning("%s applies to an effect that is off: ignored (switch it on with "
                        "%s on|auto)", o.flag, flags)
    return {"effects": fx, "fov_given": getattr(a, "fov", None) is not None}


# -- display, output, run --------------------------------------------------------------------
def _display_flags(g) -> None:
    g.add_argument("--colorconfig", metavar="CONFIG", help="OCIO config: file, ocio:// URI or 'ocl-tonemap' "
                   "(default: $OCIO, else ocio://default)")
    g.add_argument("--display", metavar="NAME", help="OCIO display (default: the config's default)")
    g.add_argument("--view", metavar="NAME", help="OCIO view (default: the un-tone-mapped view)")
    g.add_argument("--display-model", default="display", choices=["display", "paper-crt"],
                   help="display observer: from the chosen display (default), or Pattanaik "
                   "2000's CRT")
    declared_flag(g, "--display-white", "display white (default: 100 SDR, peak for HDR)",
              metavar="CD_M2")
    declared_flag(g, "--display-peak", "HDR display peak (default 1000)", default=1000.0,
              metavar="CD_M2")
    declared_flag(g, "--display-black", "display black, below its white (default: white/1000 "
              "for SDR, 0.005 for HDR)", metavar="CD_M2")
    g.add_argument("--display-encode", choices=["auto", "table", "ocio"], default=None,
                   help="auto (default: OCIO's display baked into a table on the device where "
                   "within one 10-bit code), table or ocio (OCIO's CPU processor)")


def _display_build(a, tier) -> dict:
    return {"colorconfig": a.colorconfig, "display": a.display, "view": a.view,
            "display_model": a.display_model, "display_white": a.display_white,
            "display_peak": a.display_peak, "display_black": a.display_black,
            "display_encode": a.display_encode or tier.display_encode}


def _output_flags(g) -> None:
    g.add_argument("--encode", action="store_true",
                   help="EXR/HDR outputs: display-encoded code values (tagged with the display "
                   "colourspace) instead of display-linear light (the default for float outputs)")
    g.add_argument("--out-bits", choices=["8", "16", "half", "float"],
                   help="output sample type (default by extension: EXR half, TIFF 16, PNG/JPEG 8)")
    declared_flag(g, "--png-level", "zlib level of PNG outputs (default 1)", default=1,
              metavar="0-9")
    g.add_argument("--png-filter", choices=("sub", "none", "adaptive"), default="sub",
                   help="PNG row filter (default sub)")
    g.add_argument("--plot", metavar="FILE", help="write a PNG of adaptation over time and mapping curves")
    declared_flag(g, "--plot-frames", "frame indices (0-based) for the mapping curves",
              metavar="I1,I2,...")
    g.add_argument("--ocio-export", metavar="DIR",
                   help="also write the observer as an OCIO view: DIR/<name>.ocio and a CLF per "
                   "frame (docs/ocio_export.md)")
    declared_flag(g, "--ocio-export-size", "nodes per axis of the exported LUTs (default auto)",
              default="auto", metavar="N|auto")


def _output_build(a, tier) -> dict:
    if a.plot_frames and not a.plot:
        log.warning("--plot-frames applies to --plot: ignored")
    return {"encode": a.encode, "out_bits": a.out_bits, "png_level": a.png_level,
            "png_filter": a.png_filter, "plot": a.plot,
            "plot_frames": list(a.plot_frames) if a.plot_frames else None,
            "ocio_export": a.ocio_export, "ocio_export_size": a.ocio_export_size}


# -- visibility ------------------------------------------------------------------------------
def _visibility_flags(g) -> None:
    g.add_argument("--visibility", metavar="OUT.####.exr",
                   help="also write what the observer can see: La, Lveil, Lb, dLth, VL")
    g.add_argument("--visibility-view", metavar="OUT.####.png",
                   help="also write VL in false colour over the shown frame")
    declared_flag(g, "--target", "a target (its centre's pixel, its size): its VL per frame, "
              "--plot", metavar="X,Y,SIZE")
    from ..base.quantities import OBSERVATION_S, TARGET_ARCMIN  # lazy: no NumPy
    declared_flag(g, "--target-size", f"--visibility: the target (default {TARGET_ARCMIN:g})",
              default=TARGET_ARCMIN, metavar="ARCMIN")
    declared_flag(g, "--observation-time", f"... the look (default {OBSERVATION_S:g}, RP-8's)",
              default=OBSERVATION_S, metavar="S")
    # lazy: the run's parser (NumPy already there)
    from ..models.adrian1989 import ADRIAN_1989, VARIANTS
    g.add_argument("--adrian", choices=sorted(VARIANTS), default=ADRIAN_1989.name,
                   help="... Adrian's threshold: 1989 (default) or RP-8-00's")
    g.add_argument("--visibility-type", choices=("half", "float"), default="half",
                   help="... the planes' samples (default half)")
    g.add_argument("--veil-halo", action="store_true",
                   help="... add the flare's lenticular halo to Lveil")


def _visibility_build(a, tier) -> dict:
    from ..models.adrian1989 import ADRIAN_1989  # lazy: the parser's NumPy, as above
    from ..base.quantities import OBSERVATION_S, TARGET_ARCMIN
    seen = a.visibility or a.visibility_view or a.target
    maps = a.visibility or a.visibility_view
    every = "--visibility, --visibility-view and --target"
    for flag, given, used, where in (
            ("--veil-halo", a.veil_halo, seen, every),
            ("--observation-time", a.observation_time != OBSERVATION_S, seen, every),
            ("--adrian", a.adrian != ADRIAN_1989.name, seen, every),
            ("--target-size", a.target_size != TARGET_ARCMIN, maps,
             "--visibility and --visibility-view (--target has its SIZE)")):
        if given and not used:
            log.warning("%s applies to %s: ignored", flag, where)
    if a.visibility_type != "half" and not a.visibility:
        log.warning("--visibility-type applies to --visibility: ignored")
    return {"visibility": a.visibility, "target_size": a.target_size,
            "observation_time": a.observation_time, "adrian": a.adrian,
            "visibility_type": a.visibility_type, "veil_halo": a.veil_halo,
            "visibility_view": a.visibility_view,
            "target": a.target}


def _state_flags(g) -> None:
    g.add_argument("--state-in", metavar="FILE", help="start from this adaptation state: a state JSON, or an "
                   "output frame of ocl-tonemap (its ocltm:state; global operators)")
    g.add_argument("--state-out", metavar="FILE", help="write the adaptation state here (default: OUTPUT "
                   "without frame number + .state.json)")
    g.add_argument("--resume", action="store_true",
                   help="continue an interrupted run from its checkpoint, to the frames of one run")
    g.add_argument("--no-checkpoint", dest="checkpoint", action="store_false",
                   help="do not write the state after every frame")
    declared_flag(g, "--checkpoint-every", "write the state every N frames (default 1)",
              default=1, metavar="N")
    g.add_argument("--cuts", metavar="FILE|detect",
                   help="scene cuts, where the observer starts afresh: a file of frame numbers, "
                   "or detect (a jump of more than 1 log10 in the cone goal; shot passes)")


def _state_build(a, tier) -> dict:
    from ..job.options import parse_cuts  # lazy: the parser loads no OIIO
    return {"state_in": a.state_in, "state_out": a.state_out, "resume": a.resume,
            "checkpoint": a.checkpoint, "checkpoint_every": a.checkpoint_every,
            "cuts": parse_cuts(a.cuts)}


def _device_flags(g) -> None:
    from ..backends.quality import QUALITY_NAMES  # lazy: --help loads no dataclasses
    g.add_argument("--backend", default=None, choices=["opencl", "reference"],
                   help="opencl (default) or reference (float64 NumPy)")
    g.add_argument("--quality", choices=list(QUALITY_NAMES), default=None,
                   help="draft, balanced (default) or reference: the default of every "
                   "speed/accuracy knob (docs/guide.md: Speed or accuracy)")
    g.add_argument("--device", help="OpenCL device: P:D index, gpu, cpu or a name substring")
    declared_flag(g, "--max-memory", "host memory budget: larger frames are read, mapped and "
              "written in row bands (default: a quarter of the machine's memory)",
              metavar="MIB")
    g.add_argument("--serial-io", action="store_true",
                   help="read, map and write each frame in turn (default: the next frames read "
                   "and the last written while the device works)")
    declared_flag(g, "--threads", "threads that decode and encode frames beside the device's "
              "work (half read ahead, half write behind; default: the machine's cores, at "
              "least 2); memory: about (2 + N) frames", metavar="N")
    g.add_argument("--max-band-pixels", type=RUN["max_band_pixels"].arg("--max-band-pixels"),
                   help=argparse.SUPPRESS)


def _device_build(a, tier) -> dict:
    return {"device": a.device, "quality": tier.name,
            "max_memory": a.max_memory, "overlap_io": not a.serial_io,
            "threads": a.threads, "max_band_pixels": a.max_band_pixels,
            "progress": (not a.quiet) and (a.verbose > 0 or sys.stderr.isatty())}


#: The run options' groups, in the order ``--help`` lists them (a user's reading order:
#: what goes in, the model, what comes out, time and state, what can be seen, how it
#: runs; each operator's own options follow "operator", a shot on many machines
#: ``run``'s last group, cli.py).
GROUPS = (
    Group("input", "input (which frames, from which files)", _input_flags, _input_build),
    Group("calibration", "calibration (what 1.0 of the input is, in cd/m^2)",
          _calibration_flags, _calibration_build),
    Group("operator", "operator and observer", _operator_flags, _operator_build),
    Group("effects", "mechanisms and effects (every operator)", _effect_flags, _effect_build),
    Group("display", "display (OCIO)", _display_flags, _display_build),
    Group("output", "output", _output_flags, _output_build),
    Group("state", "time and state (state files, checkpoints, scene cuts)", _state_flags,
          _state_build),
    Group("visibility", "visibility (what the observer can see: Adrian 1989, "
          "docs/visibility.md)", _visibility_flags, _visibility_build),
    Group("device", "device and memory", _device_flags, _device_build),
)


def add_run_options(p: argparse.ArgumentParser, shown: bool = True) -> None:
    """The options every run-like sub-command takes, in groups (:data:`GROUPS`);
    ``shown`` False: accepted but left out of the sub-command's help (the shot passes
    say "every option of run" instead of repeating them)."""
    made = {}
    for grp in GROUPS:
        made[grp.key] = _Shown(p.add_argument_group(grp.title) if shown else p, shown)
        if grp.key == "operator":                     # its own options next to it
            add_operator_options(p, shown)
    for grp in GROUPS:
        grp.flags(made[grp.key])


def job_options(a, input_, output, defer_backend: bool = False):
    """The run's :class:`~ocl_tonemap.job.options.JobOptions`, each group building its
    part; ``defer_backend``: the backend "auto", probed by ``job.run.run_job``."""
    from ..job.options import JobOptions  # lazy: the parser loads no OIIO
    from ..backends.quality import quality_tier  # lazy: --help loads no dataclasses
    tier = quality_tier(a.quality)
    parts = {}
    for grp in GROUPS:
        parts.update(grp.build(a, tier))
    return JobOptions(input=input_, output=output, backend=_backend(a, tier, defer_backend),
                      **parts)


def _backend(a, tier, defer: bool = False) -> str:
    """The backend a run uses. ``--backend`` given: that one (a broken or missing
    OpenCL device is then an error, as is a ``--device`` naming a broken one).
    Otherwise OpenCL on the first working device, else the float64 reference with one
    warning line (``backends.select.resolve_backend``; ``defer``: "auto", for the job
    to resolve)."""
    if a.backend:
        return a.backend
    name = "auto" if tier.backend == "opencl" else tier.backend
    from ..backends.select import resolve_backend  # lazy: --help loads no NumPy
    return name if defer and name == "auto" else resolve_backend(name, a.device)


def add_shot_options(g, chunk: bool = False, chunk_frames: bool = False,
                     keyframes: bool = False) -> None:
    """The shot store and chunk options of the split passes."""
    g.add_argument("--store", metavar="FOLDER", help="the shot's statistics and states, a folder every worker "
                   "sees (default: beside the output, OUTPUT without frame number + .shot)")
    if chunk:
        g.add_argument("--chunk", metavar="A-B",
                       help="this task's frames (default: the whole shot, --frames)")
    if chunk_frames:
        declared_flag(g, "--chunk-frames", "frames per task (and keyframe interval); "
                  "default: four tasks per worker, and for local operators at least 16 frames "
                  "up to a worker's share (dask); 50 (farm)", metavar="N")
    if keyframes:
        declared_flag(g, "--keyframe-every", "keep the state every N frames (local operators: "
                  "with its per-pixel planes; the apply chunk size; default 50)", metavar="N")
