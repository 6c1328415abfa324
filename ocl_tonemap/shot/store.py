"""The per-shot statistics store: what the measure pass found on every frame, and
the states the integrate pass computed from it.

A folder on storage every worker sees (``--store``; default beside the output,
``<output without frame number>.shot``)::

    manifest.json               what shot and settings the store belongs to
    stats/<frame>.json          one frame's statistics   (ocl-tonemap.frame-stats/1)
    stats/<frame>.planes.exr    local operators: their per-pixel adaptation inputs
                                (float32, zstd or zip; .npz for the float64 reference backend)
    states/<frame>.json         the adaptation state after the frame, at keyframes (every
                                --keyframe-every frames and the last)
    states/<frame>.pixels.exr   local operators' per-pixel state, at keyframes only
    integrate.json              written last by the integrate pass: frames, keyframes, cuts

Every file is written to a temporary name in its folder and renamed, so many
workers may write at once and a reader never sees half a file; a frame's JSON is
renamed after its planes, so a JSON that exists is complete. The manifest is
created once (the first worker to link it wins); a worker with other settings is
refused, naming the settings that differ.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path

import numpy as np

from .. import safeio
from ..backends.planes import band_readable
from ..state import AdaptationState, plan_state_ok
from ..state_files import load_state, read_planes, save_state, side_file, write_planes
from ..version import __version__

STORE_FORMAT = "ocl-tonemap.shot-store/1"
STATS_FORMAT = "ocl-tonemap.frame-stats/1"
INTEGRATED_FORMAT = "ocl-tonemap.shot-states/1"
#: EXR compression of the store's planes, lossless: zstd where this OpenEXR writes
#: it (OpenEXR 3.5 and later), else zip. Measured on ledda04's adaptation inputs at 1080p
#: (two float32 planes, this 2-core machine, OpenEXR 3.5): none 16.6 MB, write 35 /
#: read 6 ms; zip 6.3 MB, 65 / 31 ms; zstd 2.7 MB, 52 / 8 ms. The read is the serial
#: integrate pass's (issue 59): zstd takes it from 31 to 8 ms a frame. A worker
#: whose OpenEXR cannot read zstd is refused in one line naming the file.
PLANES_COMPRESSIONS = ("zstd", "zip")


@functools.lru_cache(maxsize=None)
def planes_compression() -> str:
    """The first of :data:`PLANES_COMPRESSIONS` this OpenImageIO/OpenEXR writes and
    reads back exactly (a 4x2 two-plane file in a temporary folder, once a process)."""
    import tempfile
    probe = {"a": np.arange(8, dtype=np.float32).reshape(2, 4) * np.float32(1.5e-3),
             "b": np.full((2, 4), 3.25e7, np.float32)}
    for comp in PLANES_COMPRESSIONS:
        try:
            with tempfile.TemporaryDirectory(prefix="ocltm-probe-") as d:
                f = Path(d) / "probe.exr"
                write_planes(f, probe, comp)
                back = read_planes(f)
                if read_compression(f) == comp and all(
                        np.array_equal(back[k], v) for k, v in probe.items()):
                    return comp
        except (OSError, ValueError, safeio.WriteFailed):
            continue
    return "zip"


def read_compression(path: Path) -> str:
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        return ""
    try:
        return inp.spec().get_string_attribute("compression")
    finally:
        inp.close()


def _atomic_text(path: Path, text: str) -> None:
    safeio.write_text(path, text)


def fingerprint_diff(was: dict, now: dict) -> list[str]:
    """The settings that differ between two run fingerprints (keys in both)."""
    return [f"{k}: {was.get(k)!r} then, {now.get(k)!r} now"
            for k in sorted(set(was) & set(now)) if was.get(k) != now.get(k)]


class ShotStore:
    """One shot's statistics and states (see the module docstring)."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.stats_dir = self.path / "stats"
        self.states_dir = self.path / "states"

    # -- manifest --------------------------------------------------------------------
    @property
    def manifest_path(self) -> Path:
        return self.path / "manifest.json"

    def manifest(self) -> dict:
        return _read_doc(self.manifest_path, STORE_FORMAT, "an ocl-tonemap shot store",
                         f"{self.path} is not a shot store yet (no manifest.json): run "
                         "the measure pass first")

    def open(self, run: dict, frames: list, fps: float, auto_scale: float | None) -> dict:
        """Create the store for this shot, or check that an existing one was made by
        the same settings; returns the manifest."""
        self.stats_dir.mkdir(parents=True, exist_ok=True)
        self.states_dir.mkdir(parents=True, exist_ok=True)
        doc = {"format": STORE_FORMAT, "software": f"ocl-tonemap {__version__}", "run": run,
               "frames": list(frames), "fps": float(fps),
               "luminance_scale_auto": None if auto_scale is None else float(auto_scale)}
        if not self.manifest_path.exists():
            tmp = self.path / f".manifest.json.tmp{os.getpid()}"
            try:
                tmp.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
                safeio.fsync_path(tmp)
                os.link(tmp, self.manifest_path)          # fails if another worker won
                safeio.fsync_path(self.path, folder=True)
            except FileExistsError:
                pass
            except OSError as exc:
                raise safeio.WriteFailed(self.manifest_path, safeio.reason(exc),
                                         exc.errno) from None
            finally:
                safeio.remove(tmp)
        have = self.manifest()
        self.check(have, run, frames)
        return have

    def check(self, have: dict, run: dict, frames=None) -> None:
        diff = fingerprint_diff(have.get("run") or {}, run)
        if diff:
            raise ValueError(f"the shot store {self.path} was made with other settings ("
                             + "; ".join(diff) + "); use the same options in every pass, "
                             "or another --store")
        if frames is not None and list(have.get("frames") or []) != list(frames):
            raise ValueError(f"the shot store {self.path} holds frames "
                             f"{_span(have.get('frames'))}, this shot is {_span(frames)}; "
                             "give the same --frames to every pass, or another --store")

    # -- statistics ----------------------------------------------------------------------
    def stats_path(self, frame: int) -> Path:
        return self.stats_dir / f"{frame:08d}.json"

    def has_stats(self, frame: int) -> bool:
        return self.stats_path(frame).exists()

    def stats_current(self, frame: int, input_stat) -> bool:
        """Whether the frame's statistics are stored and were measured from the input
        as it is now (``input_stat``: its size and modification time)."""
        if not self.has_stats(frame):
            return False
        try:
            doc = json.loads(self.stats_path(frame).read_text())
        except (OSError, ValueError):
            return False
        return doc.get("input_stat") == list(input_stat)

    def missing_stats(self, frames) -> list:
        return [f for f in frames if not self.has_stats(f)]

    def write_stats(self, frame: int, doc: dict, planes=None) -> None:
        """One frame's statistics (``doc``, JSON-able) and per-pixel planes (a dict of
        (h, w) arrays, or band-readable), planes first."""
        doc = {"format": STATS_FORMAT, "frame": frame, **doc}
        if planes is not None:
            name = self._write_stat_planes(frame, planes)
            doc["planes"] = name
        _atomic_text(self.stats_path(frame), json.dumps(doc, sort_keys=True) + "\n")
        try:                          # new statistics: the integrated states are stale
            self.integrated_path.unlink()
        except FileNotFoundError:
            pass

    def _write_stat_planes(self, frame: int, planes) -> str:
        if not band_readable(planes) and any(np.asarray(v).dtype == np.float64
                                             for v in planes.values()):
            name = f"{frame:08d}.planes.npz"              # the float64 reference: exact
            path = self.stats_dir / name
            tmp = self.stats_dir / f".{name}.tmp{os.getpid()}.npz"
            try:
                np.savez(tmp, **{k: np.asarray(v) for k, v in planes.items()})
            except OSError as exc:
                safeio.remove(tmp)
                raise safeio.WriteFailed(path, safeio.reason(exc), exc.errno) from None
            safeio.commit(tmp, path)
            return name
        name = f"{frame:08d}.planes.exr"
        write_planes(self.stats_dir / name, planes, planes_compression())
        return name

    def stats_document(self, frame: int) -> dict:
        """The frame's statistics document alone (its planes not read)."""
        return _read_doc(self.stats_path(frame), STATS_FORMAT, "ocl-tonemap frame statistics",
                         f"no statistics for frame {frame} in {self.path}: measure it first")

    def read_stats(self, frame: int) -> tuple[dict, object]:
        """(the frame's statistics document, its planes or None)."""
        doc = self.stats_document(frame)
        planes = None
        if doc.get("planes"):
            # a name beside the document, inside the store: never a path elsewhere
            pp = side_file(self.stats_path(frame), doc["planes"], "frame statistics")
            if pp.suffix == ".npz":
                with np.load(pp) as z:
                    planes = {k: z[k] for k in z.files}
            else:
                planes = read_planes(pp)
        return doc, planes

    # -- states --------------------------------------------------------------------------
    def state_path(self, frame: int) -> Path:
        return self.states_dir / f"{frame:08d}.json"

    def write_state(self, frame: int, state: AdaptationState) -> None:
        save_state(state, self.state_path(frame), compression=planes_compression())

    def read_state(self, frame: int) -> AdaptationState:
        p = self.state_path(frame)
        if not p.exists():
            raise ValueError(f"no adaptation state for frame {frame} in {self.path}: run "
                             "the integrate pass first")
        st = load_state(p)             # (checked field by field: state.AdaptationState)
        if st.frame is not None and st.frame != frame:
            raise ValueError(f"{p}: holds the state after frame {st.frame}, not frame "
                             f"{frame}; run the integrate pass again")
        return st

    @property
    def integrated_path(self) -> Path:
        return self.path / "integrate.json"

    def write_integrated(self, doc: dict) -> None:
        _atomic_text(self.integrated_path,
                     json.dumps({"format": INTEGRATED_FORMAT, **doc}, indent=2,
                                sort_keys=True) + "\n")

    def integrated(self) -> dict:
        return _read_doc(self.integrated_path, INTEGRATED_FORMAT, "an ocl-tonemap integrate "
                         "record", f"the shot store {self.path} has not been integrated: run "
                         "the integrate pass (after measure) first")

    def bytes_per_frame(self) -> dict:
        """Storage per frame of the shot of the statistics and of the states (mean
        bytes; the states are kept at keyframes only)."""
        frames = max(len(self.manifest().get("frames") or ()), 1)
        out = {}
        for key, d in (("stats", self.stats_dir), ("states", self.states_dir)):
            files = [p for p in d.iterdir() if not p.name.startswith(".")] if d.exists() else []
            out[key] = sum(p.stat().st_size for p in files) / frames
        return out


_NUM = (int, float)
_INTS = ("ints",)
_NUMS = ("numbers",)
#: The keys of each kind of document the passes read, and their types (a tuple:
#: any of; None: may be null; "ints" / "numbers": a list of them); the optional
#: ones are checked where present. A hand-edited or damaged file is refused in one
#: line naming it and the key, before any of it is used.
_SCHEMAS = {
    STORE_FORMAT: ({"run": dict, "frames": _INTS, "fps": _NUM},
                   {"luminance_scale_auto": (int, float, None)}),
    STATS_FORMAT: ({"time_s": _NUM, "width": int, "height": int, "G_rod": _NUM, "G_cone": _NUM},
                   {"held": bool, "repairs": dict, "values": dict, "planes": str,
                    "plan": dict, "input_stat": list, "illuminant": (dict, list, str, None),
                    "illuminant_hint": (dict, list, str, None), "scene_goal": (list, None),
                    "scene_max_Y": (int, float, None), "scene_repairs": (dict, None)}),
    INTEGRATED_FORMAT: ({"frames": _INTS, "keyframes": _INTS, "cuts": _INTS}, {}),
}


def _type_ok(v, t) -> bool:
    if t == _INTS:
        return isinstance(v, list) and all(isinstance(x, int) and not isinstance(x, bool)
                                           and abs(x) < 10 ** 12 for x in v)
    if t == _NUMS:
        return isinstance(v, list) and all(isinstance(x, _NUM) for x in v)
    ts = t if isinstance(t, tuple) else (t,)
    if v is None:
        return None in ts
    if isinstance(v, bool) and bool not in ts:
        return False
    return isinstance(v, tuple(x for x in ts if isinstance(x, type)))


def _check_doc(path: Path, doc: dict, fmt: str) -> None:
    need, may = _SCHEMAS.get(fmt, ({}, {}))
    for key, t in list(need.items()) + list(may.items()):
        if key not in doc:
            if key in need:
                raise ValueError(f"{path}: damaged (no {key!r}); measure the frame again, or "
                                 "use a new --store")
            continue
        if not _type_ok(doc[key], t):
            raise ValueError(f"{path}: damaged ({key!r} is {type(doc[key]).__name__} "
                             f"{str(doc[key])[:40]!r}); measure the frame again, or use a new "
                             "--store")
    if fmt == STATS_FORMAT:
        if not (doc["width"] > 0 and doc["height"] > 0):
            raise ValueError(f"{path}: damaged (size {doc['width']}x{doc['height']})")
        goal = doc.get("scene_goal")
        if goal is not None and not (_type_ok(goal, _NUMS) and len(goal) == 2):
            raise ValueError(f"{path}: damaged ('scene_goal' {str(goal)[:40]!r})")
        for key in ("repairs", "scene_repairs"):
            counts = doc.get(key) or {}
            if not all(_type_ok(v, int) for v in counts.values()):
                raise ValueError(f"{path}: damaged ({key!r}: counts that are not whole "
                                 "numbers)")
        plan = doc.get("plan")
        if plan is not None and not plan_state_ok({"G_cone": plan.get("G_cone", -1.0),
                                              "ref": {"predicted": plan.get("predicted"),
                                                      "sig": plan.get("sig")}}):
            raise ValueError(f"{path}: damaged ('plan': its predictions or signature)")


def _read_doc(path: Path, fmt: str, what: str, missing: str) -> dict:
    """A JSON document of the store, checked to be of ``fmt`` and to hold the keys
    the passes read (:data:`_SCHEMAS`); ``missing``: the error when there is none.
    A regular file of at most ``safeio.TEXT_CAP`` bytes (a FIFO is refused)."""
    if not os.path.lexists(path):
        raise ValueError(missing)
    try:
        doc = json.loads(safeio.read_text(path, what))
    except json.JSONDecodeError as exc:
        raise ValueError(f"cannot read {path}: {exc.msg} at line {exc.lineno}") from None
    have = doc.get("format") if isinstance(doc, dict) else None
    if have != fmt:
        raise ValueError(f"{path}: not {what} (format {str(have)[:40]!r}, expected {fmt!r})")
    _check_doc(path, doc, fmt)
    return doc


def _span(frames) -> str:
    frames = list(frames or [])
    return f"{frames[0]}-{frames[-1]} ({len(frames)})" if frames else "none"
