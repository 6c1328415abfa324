"""The command line's options, in the groups its help shows them in: declared once,
for every sub-command that takes them (``cli.py`` builds the sub-commands)."""

from __future__ import annotations

import argparse

#: The run options' groups, in the order ``--help`` lists them.
GROUPS = (("input", "input (which frames, from which files)"),
          ("calibration", "calibration (what 1.0 of the input is, in cd/m^2)"),
          ("operator", "operator and observer"),
          ("effects", "mechanisms and effects (every operator)"),
          ("display", "display (OCIO)"),
          ("output", "output"),
          ("run", "run (state, checkpoints, device, memory)"))


class _Group:
    """An argument group, or the parser itself with every help suppressed (an option
    accepted but not listed)."""

    def __init__(self, target, shown: bool):
        self.target, self.shown = target, shown

    def add_argument(self, *args, **kw):
        if not self.shown:
            kw["help"] = argparse.SUPPRESS
        return self.target.add_argument(*args, **kw)

    def add_mutually_exclusive_group(self):
        return _Group(self.target.add_mutually_exclusive_group(), self.shown)


def _registry() -> dict:
    """The operators (imported when the options are made: ``--version`` and ``devices``
    need none of them, nor NumPy)."""
    from .operators import registry
    return registry()


def add_run_options(p: argparse.ArgumentParser, shown: bool = True) -> None:
    """The options every run-like sub-command takes, in groups (:data:`GROUPS`);
    ``shown`` False: accepted but left out of the sub-command's help (the shot passes
    say "every option of run" instead of repeating them)."""
    from .backends.plan import QUALITY_NAMES
    G = {k: _Group(p.add_argument_group(t) if shown else p, shown) for k, t in GROUPS}
    G["input"].add_argument("--frames", help="frame range for sequence patterns: A-B, A-BxSTEP, or a list")
    G["input"].add_argument("--fps", type=float, help="frames per second, up to 1e6 (default: "
                   "FramesPerSecond metadata, else 24)")
    ops = _registry()
    G["operator"].add_argument("--operator", default="pattanaik00", choices=sorted(ops),
                   help="the model (default pattanaik00; README: the operators)")
    G["operator"].add_argument("--mode", choices=["default", "paper"],
                   help="default: the operator as it looks right on photographs; paper: its "
                   "paper taken literally (docs/models.md says where they differ)")
    G["operator"].add_argument("--metering", default="logmean",
                   help="logmean (default) | mean | max | centre[:mean] | spot:X,Y[,SIGMA] | "
                   "percentile:P | mask:WEIGHTS.exr (README: Metering)")
    G["calibration"].add_argument("--luminance-scale", metavar="S|auto:LEVEL",
                   help="cd/m^2 of pixel value 1.0, or auto:LEVEL (1e-6..1e8 cd/m^2, or night, "
                   "dusk, interior, overcast, daylight) for the first frame's log-average "
                   "(default: the file's calibration, else 1 with a warning)")
    G["calibration"].add_argument("--exposure", type=float, default=0.0, help="extra scale in stops (EV), "
                   "-100..100")
    G["display"].add_argument("--colorconfig", help="OCIO config: file, ocio:// URI or 'ocl-tonemap' "
                   "(default: $OCIO, else ocio://default)")
    G["input"].add_argument("--iscolorspace", help="input colourspace (default: file metadata, file "
                   "rules, scene_linear)")
    G["display"].add_argument("--display", help="OCIO display (default: the config's default)")
    G["display"].add_argument("--view", help="OCIO view (default: the un-tone-mapped view)")
    G["display"].add_argument("--display-model", default="display", choices=["display", "paper-crt"],
                   help="display observer: from the chosen display (default), or Pattanaik "
                   "2000's CRT")
    G["display"].add_argument("--display-white", type=float, help="display white, cd/m^2 (default: 100 SDR, "
                   "peak for HDR)")
    G["display"].add_argument("--display-peak", type=float, default=1000.0, help="HDR display peak, cd/m^2 "
                   "(default 1000)")
    G["display"].add_argument("--display-black", type=float, help="display black, cd/m^2 (default: white/1000 "
                   "for SDR, 0.005 for HDR)")
    g = G["input"].add_mutually_exclusive_group()
    g.add_argument("--unpremult", dest="unpremult", action="store_true", default=None,
                   help="the input's colour is premultiplied by alpha: divide before tone "
                   "mapping, multiply after (default: from the file, oiio:UnassociatedAlpha)")
    g.add_argument("--no-unpremult", dest="unpremult", action="store_false",
                   help="tone map the colour as stored")
    G["output"].add_argument("--encode", action="store_true",
                   help="EXR/HDR outputs: display-encoded code values (tagged with the display "
                   "colourspace) instead of display-linear light (the default for float outputs)")
    G["display"].add_argument("--display-encode", choices=["auto", "table", "ocio"], default=None,
                   help="auto (default: OCIO's display baked into a table on the device where "
                   "within one 10-bit code), table or ocio (OCIO's CPU processor)")
    G["operator"].add_argument("--preadapt", help="initial adaptation: CD_M2 (0 or 1e-6..1e8; fully adapted) or "
                   "CD_M2:SECONDS (0..1e7, an m suffix: minutes; exposed that long from dark)")
    G["run"].add_argument("--state-in", help="start from this adaptation state: a state JSON, or an "
                   "output frame of ocl-tonemap (its ocltm:state; global operators)")
    G["run"].add_argument("--state-out", help="write the adaptation state here (default: OUTPUT without frame number + "
                   ".state.json)")
    G["run"].add_argument("--resume", action="store_true",
                   help="continue an interrupted run from its checkpoint, to the frames of one run")
    G["run"].add_argument("--no-checkpoint", dest="checkpoint", action="store_false",
                   help="do not write the state after every frame")
    G["run"].add_argument("--checkpoint-every", type=int, default=1, metavar="N",
                   help="write the state every N frames (default 1)")
    G["run"].add_argument("--cuts", metavar="FILE|detect",
                   help="scene cuts, where the observer starts afresh: a file of frame numbers, or "
                   "detect (a jump of more than 1 log10 in the cone goal; shot passes)")
    G["input"].add_argument("--stills", action="store_true",
                   help="independent stills: each frame its own observer, no state files")
    G["input"].add_argument("--missing", choices=["error", "hold", "skip"], default="error",
                   help="a frame missing inside a sequence: error (default), hold or skip")
    G["run"].add_argument("--backend", default=None, choices=["opencl", "reference"],
                   help="opencl (default) or reference (float64 NumPy)")
    G["run"].add_argument("--quality", choices=list(QUALITY_NAMES), default=None,
                   help="draft, balanced (default) or reference: the default of every speed/accuracy "
                   "knob (README: Speed or accuracy)")
    G["run"].add_argument("--device", help="OpenCL device: P:D index, gpu, cpu or a name substring")
    G["output"].add_argument("--out-bits", choices=["8", "16", "half", "float"],
                   help="output sample type (default by extension: EXR half, TIFF 16, PNG/JPEG 8)")
    G["run"].add_argument("--max-memory", type=float, metavar="MIB",
                   help="host memory budget: larger frames are read, mapped and written in row "
                   "bands (default: a quarter of the machine's memory)")
    G["output"].add_argument("--png-level", type=int, default=1, metavar="0-9",
                   help="zlib level of PNG outputs (default 1)")
    G["output"].add_argument("--png-filter", choices=("sub", "none", "adaptive"), default="sub",
                   help="PNG row filter (default sub)")
    G["run"].add_argument("--serial-io", action="store_true",
                   help="read, map and write each frame in turn (default: the next frame read and "
                   "the last written while the device works)")
    G["input"].add_argument("--channels", metavar="R,G,B",
                   help="input channels to use as R,G,B (or one name: luminance); default the "
                   "R, G, B channels by name")
    G["output"].add_argument("--plot", help="write a PNG of adaptation over time and mapping curves")
    G["output"].add_argument("--plot-frames", help="frame indices (0-based) for the mapping curves")
    G["output"].add_argument("--ocio-export", metavar="DIR",
                   help="also write the observer as an OCIO view: DIR/<name>.ocio and a CLF per frame "
                   "(docs/ocio_export.md)")
    G["output"].add_argument("--ocio-export-size", default="auto", metavar="N|auto",
                   help="nodes per axis of the exported LUTs: 17, 25, 33, 49, 65 or auto (default)")
    G["run"].add_argument("--max-band-pixels", type=int, help=argparse.SUPPRESS)
    add_operator_options(p, shown)
    g = G["effects"]
    g.add_argument("--model", choices=["auto", "full", "none"],
                   help="auto (default): each frame the mechanisms it needs, within one JND of full; "
                   "full: every effect; none: the operator alone")
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


def operator_flags() -> list:
    """The command-line options of every registered operator, generated from their
    option specs: [(Option, operators declaring it)], one entry per flag (``--mode``,
    shared by all, is a run option). Given for another operator, a flag is ignored
    with a warning (one rule for all of them)."""
    out: dict = {}
    for name, cls in _registry().items():
        for o in cls.options:
            if not o.flag or o.flag == "--mode":
                continue
            if o.flag not in out:
                out[o.flag] = (o, [])
            out[o.flag][1].append(name)
    return [(o, tuple(ops)) for o, ops in out.values()]


def add_operator_options(p: argparse.ArgumentParser, shown: bool = True) -> None:
    """Each operator's own options (its ``Option`` specs), a group per operator set."""
    groups: dict = {}
    for o, ops in operator_flags():
        title = ", ".join(ops)
        if title not in groups:
            groups[title] = _Group(p.add_argument_group(f"{title} options") if shown else p,
                                   shown)
        kw = {"help": o.help, "default": o.default}
        for k in ("type", "choices", "metavar"):
            if getattr(o, k) is not None:
                kw[k] = getattr(o, k)
        groups[title].add_argument(o.flag, dest=o.dest, **kw)


def add_shot_options(g, chunk: bool = False, chunk_frames: bool = False,
                     keyframes: bool = False) -> None:
    """The shot store and chunk options of the split passes."""
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
