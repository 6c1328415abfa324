"""Render-farm jobs for a shot: three steps (layers) running the passes as plain
commands, so a studio's farm runs them unchanged.

    Measure    ocl-tonemap measure   IN OUT [run options] --store S --chunk A-B  (one task per chunk)
    Integrate  ocl-tonemap integrate IN OUT [run options] --store S --keyframe-every N  (one task)
    Apply      ocl-tonemap apply     IN OUT [run options] --store S --chunk A-B  (one task per chunk)

Integrate depends on every Measure task, Apply on Integrate. Chunks hold ``chunk``
frames and the integrate step keeps local operators' per-pixel state every
``chunk`` frames, so each apply task starts at a keyframe.

``openjd``: an Open Job Description template (``jobtemplate-2023-09``; AWS Deadline
Cloud and other OpenJD runners), the chunks a STRING task parameter, the command
a job parameter (``OclTonemapCommand``). ``opencue``: an OpenCue job spec (XML,
``cjsl-1.14``), the chunks OpenCue's own (``<range>``, ``<chunk>``, the
``#FRAME_START#``/``#FRAME_END#`` tokens), layer-on-layer dependencies.

Paths are written absolute, resolved where the template is made (:func:`absolute`):
INPUT, OUTPUT, ``--store`` and every file a run option names (``--state-in``,
``--state-out``, ``--colorconfig``, ``--metering mask:``, ``--cuts``, ``--plot``,
``--visibility``, ``--visibility-view``, ``--ocio-export``), so that a task runs the
same from any working directory a worker gives it; make the template where the
farm's shared storage has the paths the workers see.
"""

from __future__ import annotations

import dataclasses
import getpass
import json
import os
import re
import shlex
from xml.sax.saxutils import escape, quoteattr

from ..base import safeio
from ..colour import load_config
from ..job.checkpoint import load_state_in
from ..io.patterns import same_file
from ..pipeline import Tonemapper
from . import passes

OPENJD_VERSION = "jobtemplate-2023-09"
OPENCUE_DTD = "http://localhost:8080/spcue/dtd/cjsl-1.14.dtd"
DEFAULT_CHUNK = 50


#: Run options whose value is a file or folder (a value the option takes for something
#: else is kept: ``--cuts detect``, an ``ocio://`` or bundled config, a --metering
#: that is no mask): value -> the value with its path made absolute.
def _abs_colorconfig(v: str) -> str:
    from ..colour.config import BUNDLED_NAMES  # lazy: OCIO loads with it
    return v if v in BUNDLED_NAMES or v.startswith("ocio://") else _abs(v)


def _abs_metering(v: str) -> str:
    if not v.lower().startswith("mask:"):
        return v
    path, stat = v[5:], ""
    for suffix in (":mean", ":logmean"):
        if path.lower().endswith(suffix):
            path, stat = path[: -len(suffix)], path[-len(suffix):]
    return v[:5] + (_abs(path) if path else path) + stat


def _abs(v: str) -> str:
    return os.path.abspath(os.path.expanduser(v)) if v else v


PATH_OPTIONS = {
    "--state-in": _abs, "--state-out": _abs, "--plot": _abs, "--visibility": _abs,
    "--visibility-view": _abs, "--ocio-export": _abs,
    "--cuts": lambda v: v if v == "detect" else _abs(v),
    "--colorconfig": _abs_colorconfig, "--metering": _abs_metering,
}


def absolute_tokens(tokens: list[str]) -> list[str]:
    """Run options with the files they name made absolute (:data:`PATH_OPTIONS`;
    ``--flag VALUE`` and ``--flag=VALUE`` alike, the parser takes no abbreviation)."""
    out, fix = [], None
    for t in tokens:
        if fix is not None:
            out.append(fix(t))
            fix = None
            continue
        flag, eq, value = t.partition("=")
        if flag in PATH_OPTIONS:
            if eq:
                out.append(f"{flag}={PATH_OPTIONS[flag](value)}")
            else:
                out.append(t)
                fix = PATH_OPTIONS[flag]
            continue
        out.append(t)
    return out


def absolute(opts, run_tokens: list[str], store: str):
    """(options, run tokens, store) with every path absolute, resolved here (module
    doc): a farm's task runs in a working directory of the farm's choosing."""
    opts = dataclasses.replace(opts, input=_abs(opts.input), output=_abs(opts.output))
    return opts, absolute_tokens(run_tokens), _abs(store)


def _frames(opts) -> list[int]:
    """The shot's frames: ``--frames`` as given (the submitting machine need not see
    the farm's storage), else those on disk."""
    if opts.frames:
        return list(opts.frames)
    return [j[0] for j in passes.shot_jobs(opts)]


def _name(opts, name: str | None) -> str:
    base = name or os.path.splitext(os.path.basename(passes.default_store(opts))[:-len(".shot")])[0]
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", base).strip("_.-") or "ocl-tonemap"


def pass_args(opts, run_tokens: list[str], store: str, chunk: int) -> dict:
    """The arguments of each pass's command (after the executable); ``{CHUNK}`` marks
    where a task's ``A-B`` goes."""
    base = [opts.input, opts.output, *run_tokens, "--store", store]
    return {"measure": ["measure", *base, "--chunk", "{CHUNK}"],
            "integrate": ["integrate", *base, "--keyframe-every", str(chunk)],
            "apply": ["apply", *base, "--chunk", "{CHUNK}"]}


def openjd_template(opts, run_tokens, store, chunk, name, command) -> dict:
    frames = _frames(opts)
    parts = [f"{a}-{b}" for a, b in passes.chunks(frames, chunk)]
    args = pass_args(opts, run_tokens, store, chunk)

    def script(argv):
        return {"actions": {"onRun": {
            "command": "{{Param.OclTonemapCommand}}",
            "args": [a.replace("{CHUNK}", "{{Task.Param.Chunk}}") for a in argv]}}}
    space = {"taskParameterDefinitions": [{"name": "Chunk", "type": "STRING", "range": parts}]}
    return {
        "specificationVersion": OPENJD_VERSION,
        "name": f"ocl-tonemap {name}",
        "description": (f"{opts.operator} over frames {frames[0]}-{frames[-1]} "
                        f"({len(frames)}) in {len(parts)} chunk(s): measure -> integrate -> "
                        "apply (ocl-tonemap shot passes)"),
        "parameterDefinitions": [{"name": "OclTonemapCommand", "type": "STRING",
                                  "default": command,
                                  "description": "the ocl-tonemap executable on the workers"}],
        "steps": [
            {"name": "Measure", "parameterSpace": space, "script": script(args["measure"])},
            {"name": "Integrate", "dependencies": [{"dependsOn": "Measure"}],
             "script": script(args["integrate"])},
            {"name": "Apply", "dependencies": [{"dependsOn": "Integrate"}],
             "parameterSpace": space, "script": script(args["apply"])},
        ],
    }


def _cue_range(frames: list[int]) -> str:
    """OpenCue frame spec: ``A-B``, ``A-BxS`` or a comma list."""
    if len(frames) == 1:
        return str(frames[0])
    steps = {b - a for a, b in zip(frames, frames[1:])}
    if len(steps) == 1:
        s = steps.pop()
        return f"{frames[0]}-{frames[-1]}" + (f"x{s}" if s != 1 else "")
    return ",".join(map(str, frames))


def opencue_spec(opts, run_tokens, store, chunk, name, command, show="ocltm",
                 user: str | None = None) -> str:
    frames = _frames(opts)
    steps = {b - a for a, b in zip(frames, frames[1:])}
    if len(steps) > 1:
        raise ValueError("opencue: the shot's frames must be evenly spaced (an OpenCue "
                         "layer chunks a frame range)")
    args = pass_args(opts, run_tokens, store, chunk)
    user = user or _user()
    job = f"{show}-{name}-{user}_{name}"           # OpenCue's full job name

    def cmd(argv):
        return escape(shlex.join([command, *[a.replace("{CHUNK}", "#FRAME_START#-#FRAME_END#")
                                             for a in argv]]))

    def layer(lname, argv, rng, size):
        return (f'      <layer name="{lname}" type="Render">\n'
                f"        <cmd>{cmd(argv)}</cmd>\n"
                f"        <range>{rng}</range>\n"
                f"        <chunk>{size}</chunk>\n"
                "        <services><service>shell</service></services>\n"
                "      </layer>\n")

    def depend(layer_, on):
        return (f'    <depend type="LAYER_ON_LAYER" anyframe="False">'
                f"<depjob>{escape(job)}</depjob><deplayer>{layer_}</deplayer>"
                f"<onjob>{escape(job)}</onjob><onlayer>{on}</onlayer></depend>\n")
    rng = _cue_range(frames)
    return ('<?xml version="1.0"?>\n'
            f'<!DOCTYPE spec PUBLIC "SPI Cue  Specification Language" "{OPENCUE_DTD}">\n'
            "<spec>\n"
            f"  <show>{escape(show)}</show>\n  <shot>{escape(name)}</shot>\n"
            f"  <user>{escape(user)}</user>\n"
            f"  <job name={quoteattr(name)}>\n"
            "    <paused>False</paused>\n    <maxretries>2</maxretries>\n"
            "    <layers>\n"
            + layer("measure", args["measure"], rng, chunk)
            + layer("integrate", args["integrate"], str(frames[0]), 1)
            + layer("apply", args["apply"], rng, chunk)
            + "    </layers>\n  </job>\n  <depends>\n"
            + depend("integrate", "measure") + depend("apply", "integrate")
            + "  </depends>\n</spec>\n")


def _user() -> str:
    try:
        u = getpass.getuser()
    except Exception:  # noqa: BLE001 -- no login name (containers)
        u = "render"
    return re.sub(r"[^A-Za-z0-9_]+", "_", u) or "render"


def _check_options(opts, job_file: str, name: str, command: str) -> None:
    """Refuse, at submission, what the run would refuse (the observer made on the
    float64 reference backend: no OpenCL needed to submit; the frames on disk, the
    OCIO config, the --state-in) and a job that could not run or would overwrite the
    shot. Every effect splits."""
    Tonemapper(opts.operator, "reference", options=opts.operator_options,
               effects=opts.effects, quality=opts.quality, preadapt=opts.preadapt,
               state=load_state_in(opts))
    load_config(opts.colorconfig)
    if not command.strip():
        raise ValueError("--command must name the program the farm runs (got '')")
    if not name.strip() or any(c in name for c in "\r\n\t"):
        raise ValueError(f"--name must be one line of text (got {name!r})")
    for _, inp, outp, _ in passes.shot_jobs(opts):
        for what, p in (("an input frame", inp), ("an output frame", outp)):
            if same_file(job_file, p):
                raise ValueError(f"-o {job_file}: is {what} of the shot; write the job "
                                 "elsewhere")


def write_template(fmt: str, opts, run_tokens: list[str], job_file: str,
                   store: str | None = None, chunk: int | None = None,
                   name: str | None = None, command: str = "ocl-tonemap") -> str:
    """Write the job (``openjd`` JSON/YAML template, validated with openjd-model when
    it is installed; ``opencue`` XML spec) atomically; returns its path."""
    chunk = int(chunk or DEFAULT_CHUNK)
    if chunk < 1:
        raise ValueError("--chunk-frames must be >= 1")
    name = _name(opts, name)
    opts, run_tokens, store = absolute(opts, run_tokens, store or passes.default_store(opts))
    _check_options(opts, job_file, name, command)
    if fmt == "openjd":
        doc = openjd_template(opts, run_tokens, store, chunk, name, command)
        try:
            from openjd.model import decode_job_template
        except ImportError:
            decode_job_template = None
        if decode_job_template is not None:
            decode_job_template(template=doc)           # refuses an invalid template
        if job_file.lower().endswith((".yaml", ".yml")):
            import yaml
            text = yaml.safe_dump(doc, sort_keys=False, width=1000)
        else:
            text = json.dumps(doc, indent=2) + "\n"
    elif fmt == "opencue":
        text = opencue_spec(opts, run_tokens, store, chunk, name, command)
    else:
        raise ValueError(f"unknown job format {fmt!r} (openjd | opencue)")
    safeio.write_text(job_file, text)
    return job_file
