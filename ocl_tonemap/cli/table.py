"""The command line: a table of sub-commands (:data:`COMMANDS`), each its arguments and a
thin function of ``cli/commands.py``; the run options come from ``cli/options.py``."""

from __future__ import annotations

import argparse
import logging
import re
import sys
import textwrap
from typing import Callable, NamedTuple

from . import commands
from ..base import interrupts
from .options import declared_flag, add_run_options, add_shot_options
from ..base.interrupts import Terminated, exit_code, install
from ..base.quantities import SAMPLE, VISIBILITY
from ..version import __version__

log = logging.getLogger("ocl_tonemap")

#: build_parser's default: every sub-command with all its options.
ALL_COMMANDS = "*"
ALSO = "; also every option of run (ocl-tonemap run --help)"
VERBOSE = "more messages: -v what each step does, -vv debugging"
QUIET = "errors only"


class _Parser(argparse.ArgumentParser):
    """argparse with its errors in one line (``ocl-tonemap ERROR: ...``), exit 2, and no
    abbreviated flags (``--fram`` is an error, not ``--frames``)."""

    def __init__(self, *args, **kw):
        kw.setdefault("allow_abbrev", False)
        super().__init__(*args, **kw)

    def error(self, message):
        # "argument --x: --x must be ...": a declared syntax's parser names the flag itself
        m = re.fullmatch(r"argument (-[-\w]+)(?:/[-\w]+)*: (.*)", message, re.S)
        if m and m.group(2).startswith(m.group(1)):
            message = m.group(2)
        elif m and m.group(2).startswith("must be"):     # a declared value's words
            message = f"{m.group(1)} {m.group(2)}"
        elif m and m.group(2) == "expected one argument":  # (-inf, -1,2: read as flags)
            message = (f"{m.group(1)} needs a value (one that starts with '-' is written "
                       f"{m.group(1)}=VALUE, e.g. {m.group(1)}=-1)")
        self.exit(2, f"ocl-tonemap ERROR: {message} (see {self.prog} --help)\n")


class _Formatter(argparse.HelpFormatter):
    """argparse's help, a description's paragraphs (blank lines apart) kept apart: a
    sub-command's help opens with one line saying what it does."""

    def _fill_text(self, text, width, indent):
        return "\n\n".join(textwrap.fill(" ".join(par.split()), width, initial_indent=indent,
                                         subsequent_indent=indent, break_on_hyphens=False)
                           for par in text.split("\n\n"))


class Command(NamedTuple):
    """One sub-command: its help (one line on what it does: the top-level list's and
    the first line of its own), usage, whether it takes the run options (``runs``:
    listed in its help for ``run``, accepted and pointed to for the others), its own
    arguments (``args(parser)``; ``last(parser)``: after the run options), what it does
    (``run(args, argv) -> exit code``) and ``more``, a paragraph under the help line."""

    name: str
    help: str
    run: Callable
    args: Callable | None = None
    usage: str | None = None
    runs: bool = False
    more: str = ""
    last: Callable | None = None

    def description(self) -> str:
        """Its help line, then what it adds, each a paragraph."""
        pars = [self.help, self.more, ALSO[2:] if self.runs and self.name != "run" else ""]
        return "\n\n".join(p for p in pars if p)


def _io_args(what_in: str, what_out: str):
    def add(p):
        p.add_argument("input", help=what_in)
        p.add_argument("output", help=what_out)
    return add


def _run_args(p) -> None:
    _io_args("image or sequence pattern (shot.#.exr, shot.@@@@.exr, shot.%%04d.exr)",
             "output image or pattern (format by extension)")(p)


def _run_shot_args(p) -> None:
    g = p.add_argument_group("a shot on many machines (measure -> integrate -> apply)")
    g.add_argument("--scheduler", metavar="dask|tcp://HOST:PORT",
                   help="run the three passes on Dask: dask starts a local cluster of "
                   "--workers processes, an address uses a running one (default: serial)")
    declared_flag(g, "--workers", "local cluster size (default 2)", default=2, metavar="N")
    g.add_argument("--scheduler-security", metavar="FILE",
                   help="TLS for a tls:// scheduler: a YAML or JSON file with ca, cert and key "
                   "(PEM paths, relative to the file), Dask's Security; without it, Dask's own "
                   "configuration (distributed.comm.tls.*, DASK_DISTRIBUTED__COMM__TLS__*)")
    add_shot_options(g, chunk_frames=True)


def _pass_args(name: str):
    def add(p):
        _io_args("the shot's sequence pattern",
                 "the output pattern (the store defaults to beside it)")(p)
        g = p.add_argument_group(f"{name} pass")
        add_shot_options(g, chunk=name != "integrate", keyframes=name == "integrate")
        if name == "measure":
            g.add_argument("--redo", action="store_true",
                           help="measure frames again even when their statistics are stored")
    return add


def _farm_args(p) -> None:
    _io_args("the shot's sequence pattern", "the output pattern")(p)
    g = p.add_argument_group("job")
    g.add_argument("--format", required=True, choices=["openjd", "opencue"],
                   help="openjd: an Open Job Description template (Deadline Cloud ...); "
                   "opencue: an OpenCue job spec (XML)")
    g.add_argument("-o", "--job-file", required=True, help="where to write the job")
    g.add_argument("--name", help="job name (default: from the output name)")
    g.add_argument("--command", default="ocl-tonemap",
                   help="the command the farm runs (default ocl-tonemap)")
    add_shot_options(g, chunk_frames=True)


def _simulate_args(p) -> None:
    _io_args("one image", "output name (a _t<T>s suffix is added: seconds, zero-padded "
             "to sort in time order, out_t0060s.png) or a frame pattern (frames 1..n in --at "
             "order)")(p)
    declared_flag(p, "--at", "elapsed times since the switch (e.g. 30,1m,2m,16m)",
              required=True, metavar="T1,T2,...")


def _visibility_args(p) -> None:
    # lazy: this parser is built for its own command only (NumPy with the models)
    from ..models.adrian1989 import ADRIAN_1989, FIELD_FACTOR, VARIANTS
    from ..effects.visibility import INPUTS, OBSERVATION_S, TARGET_ARCMIN  # lazy: as above

    def q(flag, name, help_, **kw):
        d = INPUTS[name]
        p.add_argument(flag, type=d.arg(flag), help=f"{help_}, {d.range_text()}"
                       .replace("%", "%%"), **kw)
    q("--background", "background", "the target's surround luminance L_s, cd/m^2 (the "
      "veil apart: L_b = L_s + Lveil, as in run --target's table)", required=True,
      metavar="L")
    q("--veil", "veil", "veiling luminance Lveil over it, cd/m^2 (CIE 88's L_seq, "
      "a --visibility map's Lveil; default 0)", default=0.0, metavar="L")
    q("--size", "size", f"target size, arcmin (a disc of the same area; default "
      f"{TARGET_ARCMIN:g})", default=TARGET_ARCMIN, metavar="ARCMIN")
    q("--age", "age", "observer age, years (default 25; with --state the run's)",
      metavar="YEARS")
    q("--time", "time", f"observation time, s (default {OBSERVATION_S:g}, RP-8's: the "
      "run's --observation-time too)", default=OBSERVATION_S, metavar="S")
    p.add_argument("--negative", action="store_true",
                   help="a target darker than its background (default: brighter; with "
                   "--target, its luminance says)")
    q("--target", "target", "target luminance, cd/m^2: its visibility level VL",
      metavar="L")
    q("--k", "k", f"field factor (default {FIELD_FACTOR:g}: 99.93% detection, RP-8; "
      "1: the laboratory's 50%)", default=FIELD_FACTOR)
    p.add_argument("--adrian", choices=sorted(VARIANTS), default=ADRIAN_1989.name,
                   help="Adrian's model as this project reads it (1989, default) or as "
                   "ANSI/IES RP-8-00 prints it (rp8): docs/models.md, D1-D7")
    p.add_argument("--state", metavar="FILE",
                   help="the eye as a run left it: a state JSON (--state-out, a checkpoint) "
                   "or an output frame (its ocltm:state); its operator's observer")
    pix = VISIBILITY["pixel"]
    p.add_argument("--pixel", metavar="X,Y", type=pix.arg("--pixel"), help=pix.help(
        "--state of a local operator (ledda04): the pixel whose observer"))
    p.add_argument("--operator", default=None, metavar="NAME",
                   help="whose adaptation time course drives the step (default pattanaik00)")
    q("--adapted-to", "adapted_to", "the eye adapted to L0 cd/m^2 before the surround "
      "steps to L_s", metavar="L0", dest="adapted_to")
    q("--for", "for", "... for S0 seconds (default: fully adapted)", metavar="S0",
      dest="adapted_for")
    after = VISIBILITY["times_after"]
    p.add_argument("--after", metavar="T1,T2,...", type=after.arg("--after"), help=after.help(
        "seconds after the step to report (default 0.5,2,10; needs --adapted-to)"))
    p.add_argument("--plot", metavar="FILE.png",
                   help="draw dL_th over the seconds after the step (needs --adapted-to)")
    p.add_argument("--json", action="store_true", help="the terms as JSON")


def _sample_size(p, seconds_default: float = 8.0) -> None:
    for flag, key, text, kw in (
            ("--size", "size", "frame size (default 320x180)", {"default": (320, 180),
                                                                  "metavar": "WxH"}),
            ("--seconds", "seconds", "length of the drive (default 8)",
             {"default": seconds_default, "metavar": "S"})):
        p.add_argument(flag, type=SAMPLE[key].arg(flag), help=SAMPLE[key].help(text), **kw)


def _sample_args(p) -> None:
    p.add_argument("outdir", help="folder for the frames (tunnel.####.exr, made if missing)")
    p.add_argument("--spectral", action="store_true",
                   help="also write a spectral OpenEXR ColorChecker lit by tungsten at "
                   "0.05 cd/m^2 (colorchecker_spectral.exr, for kirk11)")
    _sample_size(p)
    p.add_argument("--fps", type=SAMPLE["fps"].arg("--fps"), default=30.0, metavar="FPS",
                   help=SAMPLE["fps"].help("frames per second (default 30)"))


def _demo_args(p) -> None:
    p.add_argument("outdir", help="folder for the sample (scene/), the mapped frames "
                   "(display/), the plot and the state")
    _sample_size(p)


def _devices_args(p) -> None:
    p.add_argument("--check", action="store_true",
                   help="exit 1 when no device works (scripts, CI)")


#: The shot passes: (help line, what it adds).
PASSES = {"measure": ("pass 1 of a split shot: measure each frame's statistics",
                      "into the shot store, parallel over chunks"),
          "integrate": ("pass 2: integrate the adaptation state through the whole shot",
                        "from the stored statistics, serially"),
          "apply": ("pass 3: tone map a chunk of frames from the integrated state",
                    "parallel over chunks"),
          "export": ("pass 3 without pixels: the observer as an OCIO view (--ocio-export)",
                     "from the integrated state: frames are read, none mapped or written; "
                     "parallel over chunks")}

#: The sub-commands, in the order the help lists them.
COMMANDS = (
    Command("run", "tone map an image or a sequence as a human observer sees it",
            commands.run, _run_args, "ocl-tonemap run [options] INPUT OUTPUT", runs=True,
            last=_run_shot_args),
    *(Command(n, what, commands.shot_pass, _pass_args(n),
              f"ocl-tonemap {n} [options] INPUT OUTPUT", runs=True, more=more)
      for n, (what, more) in PASSES.items()),
    Command("farm-template", "write a render-farm job (OpenJD or OpenCue) for a split shot",
            commands.farm_template, _farm_args,
            "ocl-tonemap farm-template --format F -o JOB [options] INPUT OUTPUT", runs=True,
            more="the job runs the shot as measure -> integrate -> apply"),
    Command("simulate", "tone map one still as seen at times after a pre-adaptation",
            commands.simulate, _simulate_args,
            "ocl-tonemap simulate --at T1,T2,... [options] INPUT OUTPUT", runs=True,
            more="one output per --at time; --preadapt says what the eye saw before"),
    Command("visibility", "compute a target's threshold and visibility level, term by term",
            commands.visibility, _visibility_args,
            "ocl-tonemap visibility --background L [--veil L] [--size ARCMIN] [--age A]\n"
            "       [--time S] [--k K] [--adrian 1989|rp8] [--target L | --negative]\n"
            "       [--state FILE [--pixel X,Y] | --adapted-to L0 [--for S0] [--after T,..]\n"
            "       [--operator NAME] [--plot FILE]] [--json]",
            more="the threshold luminance difference dL_th of Adrian 1989 on the background "
            "L_b = L_s + Lveil (the symbols of run --target's table) and, with --target, "
            "its visibility level VL"),
    Command("radiance-env", "print the shell lines that put Radiance's programs on PATH",
            commands.radiance_env,
            more="Radiance's programs from pip install 'ocl-tonemap[radiance]': "
            "eval \"$(ocl-tonemap radiance-env)\""),
    Command("devices", "list the OpenCL devices, each probed: ok or broken",
            commands.devices, _devices_args),
    Command("displays", "list an OCIO config's displays and views, the defaults marked",
            commands.displays,
            lambda p: p.add_argument("--colorconfig", metavar="CONFIG", help="OCIO config: "
                                     "file, ocio:// URI "
                                     "or 'ocl-tonemap' (default: $OCIO, else "
                                     "ocio://default)")),
    Command("sample", "write the built-in tunnel-drive sample (EXR frames in cd/m^2)",
            commands.sample, _sample_args),
    Command("demo", "write the sample and run the main job on it", commands.demo, _demo_args,
            "ocl-tonemap demo [options] OUTDIR", runs=True,
            more="the mapped frames, the adaptation plot and the state beside the sample"),
)
BY_NAME = {c.name: c for c in COMMANDS}


def build_parser(command: str | None = ALL_COMMANDS) -> argparse.ArgumentParser:
    """The whole parser; with ``command``, that sub-command's options only (the others
    keep their name and help; None: no sub-command's, as for ``--version`` or the
    top-level ``--help``): the run options of seven sub-commands take ~15 ms to build,
    and the operators they list, and the calculator's declared inputs, import NumPy."""
    ap = _Parser(prog="ocl-tonemap", description=(
        "Show an HDR scene or shot as a human observer would see it (time-dependent "
        "visual adaptation on OpenCL, OIIO/OCIO pipelines)."))
    ap.add_argument("--version", action="version", version=f"ocl-tonemap {__version__}")
    ap.add_argument("-v", "--verbose", action="count", default=0, help=VERBOSE)
    ap.add_argument("-q", "--quiet", action="store_true", help=QUIET)
    # -v/-q also after the sub-command (ocl-tonemap run ... -v)
    common = _Parser(add_help=False)
    common.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS,
                        help=VERBOSE)
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                        help=QUIET)
    sub = ap.add_subparsers(dest="cmd", required=True, parser_class=_Parser, metavar="COMMAND")
    for c in COMMANDS:
        kw = {"help": c.help, "parents": [common], "description": c.description(),
              "formatter_class": _Formatter}
        if c.usage:
            kw["usage"] = c.usage
        p = sub.add_parser(c.name, **kw)
        if command not in (ALL_COMMANDS, c.name):
            continue
        if c.args is not None:
            c.args(p)
        if c.runs:
            add_run_options(p, shown=c.name == "run")
        if c.last is not None:
            c.last(p)
    return ap


def _command_of(argv) -> str | None:
    """The sub-command an argument list names: its first token that is not a flag (the
    top-level flags -v, -q, --version and -h take no value)."""
    return next((t for t in argv if not t.startswith("-")), None)


def main(argv: list[str] | None = None) -> int:
    """The command line: 0 done, 2 bad input or a failure named in one ERROR line
    (never a traceback; ``-vv`` logs it), 130 / 143 interrupted (SIGINT / SIGTERM)."""
    install()
    try:
        return _main(argv)
    except (KeyboardInterrupt, Terminated) as exc:
        ck = sys.modules.get("ocl_tonemap.job.checkpoint")
        if ck is not None:                # a lock whose release the signal cut short
            ck.release_held()
        print("ocl-tonemap: interrupted; the frame in flight was discarded"
              + (f". To finish, run:\n  {interrupts.again}" if interrupts.again else ""),
              file=sys.stderr)
        return exit_code(exc)
    except Exception:                     # a signal a library made its own error (NumPy's
        if not interrupts.received:      # (an import under the parser: ImportError)
            raise
        print("ocl-tonemap: interrupted", file=sys.stderr)
        return exit_code()
    finally:
        _clear_library_errors()


def _clear_library_errors() -> None:
    """OIIO's error left unread on this thread, read and dropped: every failure was
    said in our words already, and OIIO prints one still pending as the process exits
    ("exited with a pending error message that was never retrieved")."""
    oiio = sys.modules.get("OpenImageIO")
    if oiio is None:
        return
    try:
        oiio.geterror()
    except Exception:  # noqa: BLE001 -- nothing to clear is not an error
        pass


def _main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    a = build_parser(_command_of(argv)).parse_args(argv)
    logging.addLevelName(25, "NOTE")    # what the user should know, not a fault
    level = logging.WARNING if a.quiet else (logging.INFO if a.verbose else 25)
    level = logging.DEBUG if a.verbose > 1 else level
    logging.basicConfig(level=level, format="ocl-tonemap %(levelname)s: %(message)s")
    if a.quiet:
        logging.getLogger("ocl_tonemap").setLevel(logging.ERROR)
    from ..io.imageio import FrameError, one_line  # lazy: --help loads no OIIO
    try:
        return BY_NAME[a.cmd].run(a, argv)
    except Exception as e:                                    # noqa: BLE001
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
