"""The observer as an OCIO view: a run's frames exported as per-frame CLF files and a
config that OCIO's tools, oiiotool and Nuke replay (``run ... --ocio-export DIR``).

For a global operator each frame's per-pixel mapping is one fixed function of the
pixel's RGB; ``lattice.py`` carries it as OCIO transforms. The folder:

``<name>.ocio``   profile version 2 (OCIO 2.1 and later); ``search_path: .``;
                  ``environment: {FRAME: <first frame>}``; the run's input colour
                  space as ``scene_linear``; the run's display with one view,
                  the observer, as its default.
``frames/<N>.clf`` frame N: the run's working space (file values x the luminance
                  scale) -> display-linear, the operator, its per-pixel effects, the
                  highlight shoulder.
``input.clf``     the run's input colour space -> its working space (when they differ).
``display.clf``   display-linear working space -> the run's display and view, as the
                  run encodes it (OCIO's own processor, written by OCIO).

The view is ``FileTransform frames/${FRAME}.clf`` then ``display.clf``: set ``FRAME``
(the environment, ``oiiotool --ociodisplay:key=FRAME:value=N``, a Nuke OCIO node's
context) to replay frame N. What cannot be a per-pixel transform is refused in one
line naming it (:func:`export_blocker`): local adaptation (ledda04), a bilateral base
layer (kirk11), veiling glare and loss of acuity (spatial), durand00's nearest-entry
tables, scene-slot plugins.
"""

from __future__ import annotations

import json
import logging
import os
import time
from dataclasses import replace

import numpy as np
import PyOpenColorIO as ocio

from ..base import safeio
from ..effects.purkinje import apply_purkinje
from ..models.display import DISPLAY_LINEAR_MAX, apply_shoulder
from ..models.photometry import L_MAX, Y_WEIGHTS, photopic_luminance, scotopic_luminance
from ..operators import get_operator
from . import clf, lattice
from . import replay_check as check
from .config import remember_source
from .lut_files import cpu_processor, processor

from ..base.quantities import EXPORT_SIZES

log = logging.getLogger("ocl_tonemap")

#: The bound an exported frame is held to (issue 32): 8-bit code values against the
#: run's own mapping, at the 99th percentile and anywhere.
BOUND_P99, BOUND_MAX = 1.0, 3.0
#: Lattice sizes offered (``--ocio-export-size``; declared in quantities.py).
SIZES = EXPORT_SIZES
#: ``--ocio-export-size auto`` (the default): these in turn, until a frame is within
#: the bound (measured on the frame), else the closest.
AUTO_SIZES = (33, 49, 65)
REPORT = "report.json"


class ExportError(ValueError):
    """An export that cannot be made (said in one line)."""


def operator_blocker(name: str, blocker: str | None = None) -> str | None:
    """Why operator ``name`` (its ``export_blocker``, else its class's) cannot be a
    per-pixel OCIO transform (one line), or None: known before any device work."""
    blocker = blocker if blocker is not None else get_operator(name).export_blocker
    if blocker:
        return (f"{name}'s {blocker} is not a per-pixel transform, and "
                "an OCIO view is one (pattanaik00 and durand00 export)")
    return None


def export_blocker(tm) -> str | None:
    """Why the run's mapping cannot be a per-pixel OCIO transform (one line), or None."""
    op = tm.op
    if op.export_blocker:
        return operator_blocker(tm.operator_name, op.export_blocker)
    if op.options.get("lut"):
        return (f"{tm.operator_name} --lut: its Sec. 5 tables are nearest-entry steps; "
                "export without --lut")
    fx = tm.effects.settings
    spatial = [(name, what) for name, what in
               (("flare", "veiling glare"), ("acuity", "loss of acuity"))
               if getattr(fx, name) != "off"]
    if spatial:
        names = " and ".join(f"{what} (--{name} {getattr(fx, name)})" for name, what in spatial)
        return (f"{names} {'are' if len(spatial) > 1 else 'is'} spatial (light spread across "
                "the frame), not per-pixel; run with "
                + " ".join(f"--{name} off" for name, _ in spatial))
    plugins = [p.name for p in tm.effects.plugins]
    if plugins:
        return f"effect plugins ({', '.join(plugins)}) are not known to be per-pixel"
    return None


def frozen_raw(op, params, gains, purkinje: dict | None):
    """The smooth part of a frame's per-pixel map, working cd/m^2 (K, 3) -> raw
    display-linear (K, 3), float64: the Purkinje shift as the frame had it, the
    receptor gains on the cone signals, the operator's ``map_reference`` with
    ``raw=True`` (its positive part is the output before the shoulder)."""
    p = replace(params, raw=True)
    g = None if gains is None else np.asarray(gains, np.float64)
    purk = purkinje if purkinje and purkinje.get("ran") else None

    def raw(rgb):
        rgb = np.asarray(rgb, np.float64)
        if purk is not None:
            rgb = np.asarray(apply_purkinje(rgb, purk["A_rod"], 0.0, None,
                                            purk["rod_sensitivity"])[0], np.float64)
        Ys = scotopic_luminance(rgb)
        rg = rgb if g is None else rgb * g
        return np.asarray(op.map_reference(rg, photopic_luminance(rg), Ys, p), np.float64)
    return raw


def frozen_shoulder(params):
    """The frame's highlight shoulder and clip, display-linear (K, 3) -> (K, 3)."""
    white, knee = float(params.white_signal), float(params.shoulder_knee)
    return lambda x: np.clip(apply_shoulder(np.maximum(x, 0.0), white, knee), 0.0,
                             DISPLAY_LINEAR_MAX)


def apply_ops(ops, rgb: np.ndarray) -> np.ndarray:
    """``ops`` (``clf.py``) applied by OCIO's CPU processor to (N, 3) ``rgb`` (float32)."""
    return check.apply_cpu(cpu_processor(ocio.Config.CreateRaw(), clf.to_transform(ops)), rgb)


def frame_ops(tm, effects: dict, pixels: np.ndarray, scale: float,
              size: int = lattice.LATTICE, judge=None, full=None) -> tuple[list, dict]:
    """The last frame ``tm`` mapped as colour operations (``clf.py``) from working-space
    file values (x ``scale`` = cd/m^2) to display-linear, and what they are made of.
    ``effects``: the frame's ``FrameInfo.effects``; ``pixels``: its working-space
    pixels (file values). ``judge(ops) -> (max, p99)``: the two stage-B lattices are
    both made and the better kept (else the log-opponent one). ``full``: every pixel
    of the frame where ``pixels`` are a sample of them: the lattices' extents cover
    them all (a colour beyond a lattice is clamped to its edge)."""
    op, params, gains = tm.last_mapping()
    raw = frozen_raw(op, params, gains, effects.get("purkinje"))
    scale = scale * tm.media_gain                  # the observer's media (CIE 203, --age)
    px = np.asarray(pixels, np.float64).reshape(-1, 3)
    px = lattice.sample_rows(px[np.isfinite(px).all(axis=1)])
    cd = np.maximum(px, 0.0) * scale
    cd_full = None if full is None else np.maximum(full, 0.0) * np.float32(scale)
    a = lattice.stage_a(raw, cd, size, cd_full)
    shoulder = frozen_shoulder(params)
    a_out = np.maximum(raw(cd), 0.0)
    # the run's bad-value policy (photometry.sanitize): below 0 and NaN -> 0, +Inf and
    # above L_MAX cd/m^2 -> L_MAX
    head = [lattice.range_op(0.0, L_MAX / scale), lattice.matrix_op(np.eye(3) * scale),
            *a.ops]
    a_full = None if full is None else apply_ops(head, full)   # stage A as OCIO applies it
    w, k = params.white_signal, params.shoulder_knee
    b = lattice.stage_b(w, k, a_out, shoulder, size, a_full)
    if judge is not None and b.kind != "clip":
        b2 = lattice.stage_b_rgb(w, k, a_out, shoulder, size, a_full)
        if judge(head + b2.ops) < judge(head + b.ops):
            b = b2
    return head + b.ops, {"stage_a": a.kind, "stage_b": b.kind}


def reference_codes(tm, effects: dict, pixels: np.ndarray, scale: float, encode) -> np.ndarray:
    """The frame's own mapping of ``pixels`` (N x 3 working file values), float64,
    through ``encode`` (display-linear -> code values): what the export is held to."""
    op, params, gains = tm.last_mapping()
    raw = frozen_raw(op, params, gains, effects.get("purkinje"))
    cd = np.maximum(np.asarray(pixels, np.float64), 0.0) * (scale * tm.media_gain)
    return encode(frozen_shoulder(params)(np.maximum(raw(cd), 0.0)).astype(np.float32))


def code_errors(got: np.ndarray, ref: np.ndarray) -> dict:
    """Differences of code values (display-encoded, [0, 1] clipped as files hold them):
    8-bit and 10-bit codes at the 99th percentile and the maximum; half float: the
    difference of the unclipped values in steps of a half float at the value (its
    11-bit significand; below one 10-bit code the step of one 10-bit code's value)."""
    d = np.abs(np.clip(got, 0, 1) - np.clip(ref, 0, 1)).reshape(-1)
    half_ulp = np.maximum(np.abs(ref.reshape(-1)), 1.0 / 1023.0) * 2.0 ** -10
    with np.errstate(invalid="ignore"):
        f = np.nan_to_num(np.abs(got - ref).reshape(-1) / half_ulp, nan=np.inf)
    out = {}
    for bits, full in (("8bit", 255.0), ("10bit", 1023.0)):
        out[f"p99_{bits}"] = float(np.percentile(d, 99) * full) if d.size else 0.0
        out[f"max_{bits}"] = float(d.max() * full) if d.size else 0.0
    out["p99_half_steps"] = float(np.percentile(f, 99)) if f.size else 0.0
    out["max_half_steps"] = float(f.max()) if f.size else 0.0
    return out


# --- the folder ------------------------------------------------------------------

def _q(name: str) -> str:
    """A YAML double-quoted string."""
    return json.dumps(str(name))


def _clf_or_ctf(group: ocio.GroupTransform, folder: str, stem: str, cfg) -> str:
    """Write ``group`` with OCIO's own writer: CLF, or CTF (OCIO's superset, read by
    2.1 too) where it holds operations CLF has not; returns the file's name."""
    for fmt, ext in (("Academy/ASC Common LUT Format", ".clf"), ("Color Transform Format", ".ctf")):
        try:
            text = group.write(formatName=fmt, config=cfg)
        except Exception:                       # noqa: BLE001 -- OCIO's own Exception
            continue
        safeio.write_text(os.path.join(folder, stem + ext), text)
        return stem + ext
    raise ExportError(f"OCIO cannot write the {stem} transform as CLF or CTF")


class OcioExport:
    """A run's frames as an OCIO config and per-frame CLF files (module doc).

    ``folder``: where (created; files in it are replaced, never other files);
    ``colour``: the run's :class:`~ocl_tonemap.colour.ColourPipeline`; ``tm``: its
    Tonemapper (refused here, in one line, when its mapping is not per-pixel);
    ``first_frame``: the shot's first frame number (the config's default FRAME);
    ``size``: lattice nodes per axis, or "auto" (:data:`AUTO_SIZES`)."""

    def __init__(self, folder: str, colour, tm, first_frame: int | None = None,
                 size: int | str = "auto", name: str | None = None):
        why = export_blocker(tm)
        if why:
            raise ExportError(f"--ocio-export: {why}")
        if size != "auto" and size not in SIZES:
            raise ExportError(f"--ocio-export-size must be auto or one of "
                              f"{', '.join(map(str, SIZES))} (got {size})")
        self.sizes = AUTO_SIZES if size == "auto" else (int(size),)
        self.folder = os.path.abspath(folder)
        self.colour, self.tm = colour, tm
        self.first = 1 if first_frame is None else int(first_frame)
        self.name = name or f"ocl-tonemap_{tm.operator_name}"
        self.view = f"{tm.operator_name} observer"
        self.input_cs: str | None = None
        self._cfg = None
        self._display = processor(colour.cfg, colour.working, colour.display, colour.view,
                                  ocio.TRANSFORM_DIR_FORWARD)
        self._display_cpu = self._display.getDefaultCPUProcessor()
        self._display_group = self._display.createGroupTransform()
        self.report = self._load_report()
        if os.path.exists(self.folder) and not os.path.isdir(self.folder):
            raise ExportError(f"--ocio-export {folder}: exists and is not a folder")
        os.makedirs(os.path.join(self.folder, "frames"), exist_ok=True)

    @property
    def config_path(self) -> str:
        return os.path.join(self.folder, self.name + ".ocio")

    def _load_report(self) -> dict:
        path = os.path.join(self.folder, REPORT)
        if os.path.isfile(path):
            try:
                doc = json.loads(safeio.read_text(path, "the export's report"))
                if isinstance(doc, dict) and isinstance(doc.get("frames"), dict):
                    return doc
            except (OSError, ValueError):
                pass
        return {"frames": {}}

    def encode(self, display_linear: np.ndarray) -> np.ndarray:
        """Display-linear working RGB (N x 3) -> the run's display code values (OCIO)."""
        x = np.ascontiguousarray(np.asarray(display_linear, np.float32).reshape(-1, 3))
        self._display_cpu.applyRGB(x)
        return x

    def _judge(self, px: np.ndarray, ref: np.ndarray):
        def judge(ops):
            g = clf.to_transform(ops)
            g.appendTransform(self._display_group)
            x = np.ascontiguousarray(px.astype(np.float32))
            cpu_processor(self.colour.cfg, g).applyRGB(x)
            e = code_errors(x, ref)
            return (e["max_8bit"], e["p99_8bit"])
        return judge

    # -- the shared files --------------------------------------------------------------
    def _start(self, input_colour) -> None:
        """input.clf, display.clf and the config, from the first frame exported."""
        cp = self.colour
        self.input_cs = input_colour.colorspace if input_colour is not None else cp.working
        files = {"display": _clf_or_ctf(self._display_group, self.folder, "display", cp.cfg)}
        group = cp.input_transform(input_colour) if input_colour is not None else None
        if group is not None:
            files["input"] = _clf_or_ctf(group, self.folder, "input", cp.cfg)
        safeio.write_text(self.config_path, self._config_text(files))
        ocio.ClearAllCaches()
        try:
            cfg = remember_source(ocio.Config.CreateFromFile(self.config_path), self.config_path)
            cfg.validate()
        except Exception as exc:                    # noqa: BLE001 -- OCIO's own Exception
            raise ExportError(f"{self.config_path}: the written config does not load: "
                              f"{exc}") from None
        self._cfg = cfg
        self.report.update({"operator": self.tm.operator_name,
                            "lattice": "auto" if len(self.sizes) > 1 else self.sizes[0],
                            "config": os.path.basename(self.config_path),
                            "display": cp.display, "view": self.view,
                            "input_colorspace": self.input_cs,
                            "bound_8bit": {"p99": BOUND_P99, "max": BOUND_MAX}})

    def _config_text(self, files: dict) -> str:
        cp, tm = self.colour, self.tm
        work, inp = cp.working, self.input_cs
        obs = f"ocl-tonemap {tm.operator_name}"
        L = ["ocio_profile_version: 2", "",
             f"# Written by ocl-tonemap: {tm.operator_name} as an OCIO view, one CLF per frame.",
             "# Set the context variable FRAME to a frame number to replay that frame;",
             "# the default is the shot's first frame.",
             f"name: {_q(self.name)}",
             f"description: {_q(f'{tm.operator_name} observer exported by ocl-tonemap')}",
             "environment:", f"  FRAME: {_q(str(self.first))}",
             'search_path: "."', "strictparsing: true",
             "luma: [" + ", ".join(f"{w:.6f}" for w in Y_WEIGHTS) + "]", "",
             "roles:", f"  default: {_q(inp)}", f"  scene_linear: {_q(inp)}",
             '  data: "Raw"', "",
             "file_rules:", f"  - !<Rule> {{name: Default, colorspace: {_q(inp)}}}", "",
             "displays:", f"  {_q(cp.display)}:",
             f"    - !<View> {{name: {_q(self.view)}, colorspace: {_q(obs)}}}",
             '    - !<View> {name: "Raw", colorspace: "Raw"}', "",
             f"active_displays: [{_q(cp.display)}]",
             f"active_views: [{_q(self.view)}, \"Raw\"]", "", "colorspaces:"]

        def cs(name, desc, extra=(), isdata="false"):
            return ["  - !<ColorSpace>", f"    name: {_q(name)}", f"    description: {_q(desc)}",
                    f"    isdata: {isdata}", *extra, ""]
        L += cs(work, "the run's working space (this config's scene reference)")
        if inp != work:
            L += cs(inp, "the run's input colour space",
                    [f"    to_scene_reference: !<FileTransform> {{src: {_q(files['input'])}}}"])
        L += cs(obs, f"the scene as {tm.operator_name} shows it on {cp.display} "
                f"({cp.view}), frame $FRAME",
                ["    from_scene_reference: !<GroupTransform>", "      children:",
                 '        - !<FileTransform> {src: "frames/${FRAME}.clf", interpolation: '
                 "tetrahedral}",
                 f"        - !<FileTransform> {{src: {_q(files['display'])}}}"])
        L += cs("Raw", "no conversion", isdata="true")
        return "\n".join(L)

    # -- frames --------------------------------------------------------------------------
    def add_frame(self, number: int | None, pixels: np.ndarray, scale: float = 1.0,
                  effects: dict | None = None, input_colour=None, output=None,
                  file_pixels=None) -> dict:
        """Export the frame ``tm`` has just mapped: ``pixels`` its working-space RGB (file
        values; x ``scale`` = cd/m^2), ``effects`` its ``FrameInfo.effects`` (default:
        ``tm.last``'s), ``input_colour`` its :class:`~ocl_tonemap.colour.InputColour`
        (None: the working space). Writes frames/<number>.clf and checks it as a replay
        does (``replay_check.py``): the written config's view applied by OCIO to the
        frame's pixels -- ``file_pixels``, its RGB as its file holds them, from
        ``input_colour``'s space (None: ``pixels`` from the working space) -- against
        ``output``, the run's own display-encoded RGB of the frame (code values, float
        or integer, the pixels' order; None: the frame's own float64 mapping through
        the display). Returns its record (those errors, sizes, times)."""
        if effects is None:
            effects = self.tm.last.effects if self.tm.last is not None else {}
        n = self.first if number is None else int(number)
        if self._cfg is None:
            self._start(input_colour)
        elif input_colour is not None and input_colour.colorspace != self.input_cs:
            raise ExportError(f"frame {n}: input colour {input_colour.colorspace!r} differs "
                              f"from the export's {self.input_cs!r} (one export per colour "
                              "space)")
        t0 = time.perf_counter()
        work = check.rgb_rows(pixels)
        px = lattice.sample_rows(work).astype(np.float64)
        px = np.where(np.isfinite(px), px, 0.0)
        # a frame larger than the nodes' sample: its extents from every pixel
        full = work if work.shape[0] > px.shape[0] else None
        ref = reference_codes(self.tm, effects, px, scale, self.encode)
        judge = self._judge(px, ref)
        best = None
        for size in self.sizes:                  # smallest first, until within the bound
            ops, info = frame_ops(self.tm, effects, px, scale, size, judge, full)
            err = judge(ops)
            if best is None or err < best[0]:
                best = (err, ops, {**info, "lattice": size})
            if err[0] <= BOUND_MAX and err[1] <= BOUND_P99:
                break
        _, ops, info = best
        t1 = time.perf_counter()
        path = os.path.join(self.folder, "frames", f"{n}.clf")
        text = clf.to_text(ops, f"frame {n}", f"{self.tm.operator_name}, frame {n}: "
                           "working-space file values -> display-linear")
        safeio.write_text(path, text)
        t2 = time.perf_counter()
        rec = {**info, **self._check(n, work, scale, effects, output, file_pixels),
               "bytes": len(text), "ms_build": round(1e3 * (t1 - t0), 1),
               "ms_write": round(1e3 * (t2 - t1), 1),
               "ms_verify": round(1e3 * (time.perf_counter() - t2), 1)}
        rec["within_bound"] = rec["p99_8bit"] <= BOUND_P99 and rec["max_8bit"] <= BOUND_MAX
        if not rec["within_bound"]:          # (the lattices: once, in the summary)
            log.warning("frame %s: the exported view, replayed through OCIO over %d pixels, "
                        "is %.2f 8-bit codes off the %s at the 99th percentile, %.2f at "
                        "most (%g in 8-bit files; bound %g, %g)", n, rec["checked"]["pixels"],
                        rec["p99_8bit"], rec["checked"]["against"], rec["max_8bit"],
                        rec["files_max_8bit"], BOUND_P99, BOUND_MAX)
        self.report["frames"][str(n)] = rec
        safeio.write_text(os.path.join(self.folder, REPORT),
                          json.dumps(self.report, indent=1, sort_keys=True))
        return rec

    def _check(self, n: int, work: np.ndarray, scale: float, effects: dict, output,
               file_pixels) -> dict:
        """Frame ``n``'s view replayed over its pixels (every pixel up to
        ``replay_check.CHECK_PIXELS``) against the run's output (or the frame's own
        mapping): ``code_errors`` and ``replay_check.file_errors``, and what was checked."""
        step = check.check_step(work.shape[0])
        if file_pixels is not None:
            got = self.replay(n, check.rgb_rows(file_pixels, step), self.input_cs)
        else:
            got = self.replay(n, work[::step])
        if output is not None:
            ref, against = check.as_codes(check.rgb_rows(output, step)), "run's output"
        else:
            # the run's bad-value policy (photometry.sanitize), on file values
            lim = L_MAX / (scale * self.tm.media_gain)
            x = np.clip(np.nan_to_num(work[::step].astype(np.float64), nan=0.0, posinf=lim,
                                      neginf=0.0), 0.0, lim)
            ref = np.concatenate([reference_codes(self.tm, effects, x[i:i + check.CHUNK],
                                                  scale, self.encode)
                                  for i in range(0, max(x.shape[0], 1), check.CHUNK)])
            against = "frame's own mapping"
        return {**code_errors(got, ref), **check.file_errors(got, ref),
                "checked": {"pixels": int(got.shape[0]), "of": int(work.shape[0]),
                            "from": self.input_cs if file_pixels is not None
                            else self.colour.working, "against": against}}

    def replay(self, number: int, rgb: np.ndarray, colorspace: str | None = None) -> np.ndarray:
        """RGB (N x 3 file values in ``colorspace``, default the working space) through
        the written config's view with FRAME = ``number``: the export read back as OCIO
        reads it (code values; what oiiotool's --ociodisplay and ocioconvert apply)."""
        cfg = self._cfg
        ctx = cfg.getCurrentContext()      # (the export's own config: set in place)
        ctx.setStringVar("FRAME", str(number))
        try:
            proc = processor(cfg, ctx, colorspace or self.colour.working, self.colour.display,
                             self.view, ocio.TRANSFORM_DIR_FORWARD)
        except Exception as exc:                    # noqa: BLE001 -- in one line (lut_files)
            raise ExportError(f"frame {number}: the written CLF does not load: {exc}") from None
        return check.apply_cpu(proc.getDefaultCPUProcessor(), np.asarray(rgb).reshape(-1, 3))

    def summary(self) -> str:
        fr = self.report.get("frames", {})
        if not fr:
            return f"OCIO export: nothing exported to {self.folder}"
        p99 = max(v["p99_8bit"] for v in fr.values())
        mx = max(v["max_8bit"] for v in fr.values())
        files = max(v.get("files_max_8bit", 0.0) for v in fr.values())
        over = [f for f, v in fr.items() if not v["within_bound"]]
        mib = sum(v["bytes"] for v in fr.values()) / 2 ** 20
        said = (f"OCIO export: {len(fr)} frame(s) -> {self.config_path} ({mib:.1f} MiB of CLF); "
                f"replayed through OCIO: worst p99 {p99:.2f}, max {mx:.2f} 8-bit codes "
                f"({files:g} in 8-bit files); lattices {check.lattices_text(fr)}")
        if not over:
            return said
        said += (f"; {len(over)} frame(s) beyond the bound (p99 {BOUND_P99:g}, max "
                 f"{BOUND_MAX:g}): frame{'s' if len(over) > 1 else ''} "
                 f"{check.frames_text(over)}")
        if len(self.sizes) > 1:
            return said + (" (auto: " + ", then ".join(f"{v}^3" for v in self.sizes)
                           + " while the frame's sample is beyond it, the closest kept; "
                           "docs/ocio_export.md says where a LUT falls short)")
        larger = [str(v) for v in SIZES if v > self.sizes[0]]
        return said + (f" (--ocio-export-size auto or {' or '.join(larger)} may come closer)"
                       if larger else " (the largest lattice; docs/ocio_export.md says where "
                       "a LUT falls short)")
