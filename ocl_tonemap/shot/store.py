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
    integrate.json              written last by the integrate pass: frames, keyframes, cuts,
                                the identity of every input frame it integrated

Each frame's statistics keep the identity of the input they were measured from
(``input_stat``: size, modification time and a hash of the content,
:func:`input_identity`). integrate, apply and export refuse an input changed since
(:meth:`ShotStore.check_inputs`), naming the frames and the measure command that
mends it; measure run again measures those frames again.

Every file is written to a temporary name in its folder and renamed, so many
workers may write at once and a reader never sees half a file; a frame's JSON is
renamed after its planes, so a JSON that exists is complete. The manifest is
created once (the first worker to link it wins); a worker with other settings is
refused, naming the settings that differ.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
import shlex
import stat as stat_kinds
from pathlib import Path

import numpy as np

from ..base import safeio
from ..backends.planes import band_readable
from ..pipeline.state import AdaptationState, plan_state_ok
from ..io.state_files import load_state, read_planes, save_state, side_file, write_planes
from ..version import __version__

STORE_FORMAT = "ocl-tonemap.shot-store/1"
STATS_FORMAT = "ocl-tonemap.frame-stats/1"
INTEGRATED_FORMAT = "ocl-tonemap.shot-states/1"
log = logging.getLogger("ocl_tonemap")
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


# -- the identity of an input frame ---------------------------------------------------------
def input_identity(path, digest: bool = True) -> list | None:
    """``[size, modification time (ns), "blake2b:<32 hex>"]`` of an input frame
    (``digest=False``: the first two alone); None where it cannot be opened or is no
    regular file (its read names the problem). The stat and the hash are of one open
    file, taken before the measure pass reads it: a file changed after differs.

    The hash is BLAKE2b (128 bits) of the *whole* file. Measured on this 2-core
    machine on a 1080p EXR in the page cache: 9 ms for 10.7 MB (half RGB, zip), 22 ms
    for 24.9 MB (float RGB, uncompressed), ~0.85 ms a MB, against ~235 ms a frame of
    the measure pass on the same file (4-9 %, only for the frames measured). The
    first and last MiB and the size took 1.8 ms, but miss a change in the middle of
    a file whose layout stays (an uncompressed EXR keeps every scanline in its
    place), and the hash is what lets a file with a new modification time but the
    content measured (a ``touch``, a copy) be used as measured: it has to see every
    byte. The checks stat every frame and hash only those whose size or time differ
    from the record (:func:`input_changes`)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))   # (a FIFO: no wait)
    except OSError:
        return None
    try:
        st = os.fstat(fd)
        if not stat_kinds.S_ISREG(st.st_mode):
            return None
        out = [st.st_size, st.st_mtime_ns]
        if digest:
            h, buf = hashlib.blake2b(digest_size=16), bytearray(1 << 20)
            view = memoryview(buf)
            with os.fdopen(fd, "rb", buffering=0, closefd=False) as f:
                while n := f.readinto(buf):
                    h.update(view[:n])
            out.append("blake2b:" + h.hexdigest())
        return out
    except OSError:
        return None
    finally:
        os.close(fd)


def input_changes(jobs, identities) -> tuple[list, list]:
    """``(changed, touched)``: [(frame, input)] of ``jobs`` ((frame, input, ...))
    whose input is not the one measured (``identities[k]``: ``jobs[k]``'s record; a
    frame without one is not checked), and those whose size or time differ but whose
    content is the one measured (its hash). A record without a hash (a store
    written before it was kept) is checked by its size and time alone."""
    changed, touched = [], []
    for (f, inp, *_), was in zip(jobs, identities):
        if not (isinstance(was, list) and len(was) >= 2):
            continue
        now = input_identity(inp, digest=False)
        if now == list(was[:2]):
            continue
        full = input_identity(inp) if len(was) > 2 and now is not None else None
        (touched if full is not None and full[2] == was[2] else changed).append((f, inp))
    return changed, touched


def changed_inputs_line(changed, store, shot) -> str:
    """The one line that refuses ``changed`` ([(frame, input)]): the first few, a
    count, and the measure command of the shot (``shot``: its input and output
    patterns) that mends it."""
    few = ", ".join(f"{f} ({p})" for f, p in changed[:3])
    more = f" and {len(changed) - 3} more" if len(changed) > 3 else ""
    cmd = shlex.join(["ocl-tonemap", "measure", str(shot[0]), str(shot[1]), "--store",
                      str(store)])
    return (f"frame{'s' if len(changed) > 1 else ''} {few}{more} changed since the measure "
            f"pass of {store}: run the measure pass again ({cmd}, with this pass's other "
            "options; it measures only the changed frames), then integrate")


class ShotStore:
    """One shot's statistics and states (see the module docstring)."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self.stats_dir = self.path / "stats"
        self.states_dir = self.path / "states"

    # -- manifest --------------------------------------------------------------------
    def folders(self) -> list:
        """The store's own folders (where a killed pass's temporaries are removed)."""
        return [self.path, self.stats_dir, self.states_dir]

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
            fd = safeio.open_temp(tmp, self.manifest_path)
            try:
                with os.fdopen(fd, "w") as fh:
                    fh.write(json.dumps(doc, indent=2, sort_keys=True) + "\n")
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
        as it is now (``input_stat``: its size and modification time, the first two
        of its :func:`input_identity`; None: not known, so not current). A file with
        other times is measured again, even with the content measured (a ``touch``):
        measure reads it anyway, where the other passes take its hash instead."""
        if input_stat is None or not self.has_stats(frame):
            return False
        try:
            doc = json.loads(self.stats_path(frame).read_text())
        except (OSError, ValueError):
            return False
        was = doc.get("input_stat")
        return isinstance(was, list) and was[:2] == list(input_stat)[:2]

    def check_inputs(self, jobs, identities=None, shot=("INPUT", "OUTPUT")) -> list:
        """The identities of ``jobs``' inputs as measured (``identities``: as recorded
        by the integrate pass, in the order of ``jobs``; None: from each frame's
        statistics); an input changed since (:func:`input_changes`) is refused in one
        line (ValueError) naming the frames and the measure command of ``shot``
        (its input and output patterns). One stat a frame; a hash only for a frame
        whose size or time differ (a ``touch`` with the content measured is used as
        measured, and said at -v)."""
        if not isinstance(identities, list) or len(identities) != len(jobs):
            identities = [self.stats_document(f).get("input_stat") for f, *_ in jobs]
        changed, touched = input_changes(jobs, identities)
        if changed:
            raise ValueError(changed_inputs_line(changed, self.path, shot))
        if touched:
            log.info("frame(s) %s: another modification time, the content measured "
                     "(BLAKE2b): used as measured", ", ".join(str(f) for f, _ in touched[:10])
                     + (f" and {len(touched) - 10} more" if len(touched) > 10 else ""))
        return identities

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
            safeio.claim_temp(tmp, path)
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
                    "plan": dict, "input_stat": (list, None), "illuminant": (dict, list, str, None),
                    "illuminant_hint": (dict, list, str, None), "scene_goal": (list, None),
                    "scene_max_Y": (int, float, None), "scene_repairs": (dict, None),
                    "scene_max_Ys": (int, float, None)}),
    INTEGRATED_FORMAT: ({"frames": _INTS, "keyframes": _INTS, "cuts": _INTS}, {"inputs": list}),
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
    ids = {STATS_FORMAT: [doc.get("input_stat")],
           INTEGRATED_FORMAT: doc.get("inputs") or []}.get(fmt, [])
    if not all(v is None or _identity_ok(v) for v in ids):
        again = "measure the frame" if fmt == STATS_FORMAT else "run the integrate pass"
        raise ValueError(f"{path}: damaged (an input's identity: size, modification time, "
                         f"hash); {again} again, or use a new --store")


def _identity_ok(v) -> bool:
    """An :func:`input_identity` record: [size, time] (a store of before) or with its hash."""
    return (isinstance(v, list) and len(v) in (2, 3) and all(
        isinstance(x, int) and not isinstance(x, bool) for x in v[:2])
        and (len(v) == 2 or isinstance(v[2], str)))


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
