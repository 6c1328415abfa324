"""Adaptation state: small, explicit, serialisable.

A dict of named float64 scalars per operator plus the time (s) and number of the
last frame shown. It serialises to a short JSON document so a shot can be split
into chunks and resumed; per-pixel state (local operators) travels in a side file
named in the JSON.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

STATE_FORMAT = "ocl-tonemap.adaptation-state/1"
#: AdaptationState.extra key of the ``auto`` calibration constant of a run.
AUTO_SCALE_KEY = "luminance_scale_auto"


def _num(v, lo=-math.inf, hi=math.inf) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) \
        and lo <= v <= hi


def _num_dict(d, lo=-math.inf, hi=math.inf) -> bool:
    return isinstance(d, dict) and all(isinstance(k, str) and _num(v, lo, hi)
                                       for k, v in d.items())


def plan_state_ok(p) -> bool:
    if not isinstance(p, dict) or not _num_dict(p.get("weights", {}), 0.0, 1.0):
        return False
    if "G_cone" in p and not _num(p["G_cone"], 0.0):
        return False
    ref = p.get("ref")
    if ref is None:
        return True
    return isinstance(ref, dict) and _num_dict(ref.get("predicted", {}), 0.0) and (
        ref.get("sig") is None or (isinstance(ref["sig"], list) and all(
            isinstance(x, int) and not isinstance(x, bool) for x in ref["sig"])))


#: The ``extra`` entries the run reads back, checked on load (a hand-edited or
#: damaged state is refused in one line rather than failing inside a frame).
_EXTRA_CHECKS = {
    "run": lambda v: isinstance(v, dict),
    "luminance_scale_auto": lambda v: _num(v, 1e-30),
    "illuminant_rgb": lambda v: isinstance(v, list) and len(v) == 3 and all(_num(x, 0.0) for x in v),
    "purkinje_levels": lambda v: _num_dict(v),
    "plan": plan_state_ok,
    "pixel_state": lambda v: isinstance(v, str),
}


@dataclass
class AdaptationState:
    """Serialisable adaptation state of one observer.

    Attributes
    ----------
    operator : name of the operator that owns ``values`` (``pattanaik00`` ...).
    values : named scalars in the papers' terms (``A_rod`` cd/m^2, ``B_rod`` 0..1 ...).
    time_s : time of the last frame shown, seconds; None before the first frame.
    frame : number of the last frame shown, or None.
    extra : operator-specific JSON-able data (e.g. the path of per-pixel state).
    pixels : per-pixel state of local operators: name -> float32 (h, w) array,
        saved beside the JSON as ``<name>.pixels.exr`` (one channel per plane); or,
        for frames too large to hold whole, a band-readable view
        (``backends/planes.py``: a spilled store, or the side file opened lazily),
        which ``copy`` shares rather than copies.
    """

    operator: str
    values: dict = field(default_factory=dict)
    time_s: float | None = None
    frame: int | None = None
    extra: dict = field(default_factory=dict)
    pixels: dict | None = None

    def copy(self) -> "AdaptationState":
        from .backends.planes import band_readable
        px = self.pixels
        if px is not None and not band_readable(px):
            px = {k: np.array(v, copy=True) for k, v in px.items()}
        return AdaptationState(self.operator, dict(self.values), self.time_s, self.frame,
                               json.loads(json.dumps(self.extra)), px)

    def to_json(self) -> dict:
        return {"format": STATE_FORMAT, "operator": self.operator, "time_s": self.time_s,
                "frame": self.frame, "values": self.values, "extra": self.extra}

    @classmethod
    def from_json(cls, doc: dict) -> "AdaptationState":
        if doc.get("format") != STATE_FORMAT:
            raise ValueError(f"not an ocl-tonemap adaptation state (format {doc.get('format')!r}, "
                             f"expected {STATE_FORMAT!r})")
        try:
            vals = {str(k): float(v) for k, v in dict(doc.get("values") or {}).items()}
            op = str(doc["operator"])
            t = doc.get("time_s")
            t = None if t is None else float(t)
            frame = doc.get("frame")
            frame = None if frame is None else int(frame)
            extra = dict(doc.get("extra") or {})
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"malformed adaptation state ({exc!r})") from None
        for k, v in vals.items():
            if not math.isfinite(v):
                raise ValueError(f"state value {k} is not finite ({v})")
        if t is not None and not math.isfinite(t):
            raise ValueError(f"state time {t} is not finite")
        for key, check in _EXTRA_CHECKS.items():
            if key in extra and not check(extra[key]):
                raise ValueError(f"malformed adaptation state (extra {key!r}: "
                                 f"{str(extra[key])[:60]})")
        return cls(op, vals, t, frame, extra)

    def save(self, path: str | os.PathLike, checkpoint: bool = False,
             compression: str = "none") -> None:
        """Write atomically (temp file in the same folder, then rename); per-pixel
        state goes first to a side file beside it, named in ``extra``:
        ``<stem>.pixels.exr``, or with ``checkpoint`` ``<stem>.pixels.<n>.exr``, a new
        name each time, so that the JSON and its planes always belong together
        whenever the writer is killed; older side files are removed after the
        JSON is replaced. ``compression``: the side file's EXR compression (lossless
        ``zip`` for a shot store on shared storage: ~5x smaller)."""
        path = Path(path)
        doc = self.to_json()
        stem = path.name[:-len(path.suffix)] if path.suffix else path.name
        if self.pixels is not None:
            if checkpoint:
                n = 0
                while path.with_name(f"{stem}.pixels.{n}.exr").exists():
                    n += 1
                side = path.with_name(f"{stem}.pixels.{n}.exr")
            else:
                side = path.with_name(stem + ".pixels.exr")
            write_planes(side, self.pixels, compression)
            doc["extra"] = dict(doc["extra"], pixel_state=side.name)
        from .safeio import write_text
        write_text(path, json.dumps(doc, indent=2, sort_keys=True) + "\n")
        keep = doc["extra"].get("pixel_state")
        for old in path.parent.glob(f"{glob_escape(stem)}.pixels.*.exr"):
            if old.name != keep:
                try:
                    old.unlink()
                except OSError:
                    pass

    @classmethod
    def load(cls, path: str | os.PathLike) -> "AdaptationState":
        """From a state JSON (with its per-pixel side file), or from an output frame
        of ocl-tonemap, whose ``ocltm:state`` attribute holds the scalar state."""
        from . import safeio
        p = Path(path)
        what = "adaptation state"
        safeio.regular_file(p, what)            # (a FIFO is refused, not waited on)
        try:
            with open(p, "rb") as fh:
                head = fh.read(64).lstrip()
        except OSError as exc:
            raise ValueError(f"cannot read {what} {path}: {safeio.reason(exc)}") from None
        if head.startswith(b"{"):
            try:
                doc = json.loads(safeio.read_text(p, what))
            except json.JSONDecodeError as exc:
                raise ValueError(f"{path} is not an ocl-tonemap adaptation state (JSON: "
                                 f"{exc.msg} at line {exc.lineno})") from None
        else:
            doc = _state_from_image(p)
        if not isinstance(doc, dict):
            raise ValueError(f"{path} is not an ocl-tonemap adaptation state")
        try:
            st = cls.from_json(doc)
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None
        side = st.extra.pop("pixel_state", None)    # (it names a file beside *this* JSON)
        if side is not None:
            st.pixels = read_planes(side_file(p, side, what))
        return st


def side_file(doc_path: Path, name, what: str) -> Path:
    """A file a JSON document names beside itself: a plain name (no folder, no
    ``..``), a regular file in the JSON's own folder; anything else is refused."""
    from . import safeio
    if not isinstance(name, str) or not name or name != Path(name).name or \
            name in (".", "..") or "\x00" in name:
        raise ValueError(f"{doc_path}: {what} names {name!r} as its side file; a file "
                         "name beside it is needed")
    p = doc_path.with_name(name)
    safeio.regular_file(p, f"{what} side file")
    if p.resolve().parent != doc_path.resolve().parent:       # a link out of the folder
        raise ValueError(f"{doc_path}: its side file {name} leads out of its folder")
    return p


def glob_escape(text: str) -> str:
    import glob
    return glob.escape(text)


def _state_from_image(path: Path) -> dict:
    """The ``ocltm:state`` attribute of an image ocl-tonemap wrote."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"{path} is neither a state JSON nor an image with ocltm:state")
    try:
        from .imagewrite import ocltm_metadata
        v = ocltm_metadata(inp.spec()).get("ocltm:state")
    finally:
        inp.close()
    if not v:
        raise ValueError(f"{path} has no ocltm:state attribute (not an ocl-tonemap output?)")
    try:
        return json.loads(v)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: its ocltm:state is not JSON ({exc})") from None


#: Side files larger than this are opened lazily and read by row bands.
LAZY_PLANES_BYTES = 256 * 2**20
#: Rows per band when planes are written or read by bands: about 64 MiB.
_BAND_BYTES = 64 * 2**20


def write_planes(path: Path, planes, compression: str = "none") -> None:
    """Float32 EXR, one channel per plane, written atomically; a band-readable
    source (``backends/planes.py``) is written by row bands, never whole."""
    import OpenImageIO as oiio

    from .backends.planes import band_readable, plane_shape, read_rows
    names = list(planes.names if band_readable(planes) else planes)
    h, w = plane_shape(planes)
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    # uncompressed by default: a checkpoint is written after every frame, and zip
    # took longer than the frame (1080p ledda04: 0.4 s of a 0.9 s frame)
    spec.attribute("compression", compression)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.exr")
    out = oiio.ImageOutput.create(str(tmp))
    if out is None or not out.open(str(tmp), spec):
        raise OSError(f"cannot write per-pixel state {path}: {oiio.geterror()}")
    from . import safeio
    rows = max(1, _BAND_BYTES // max(1, 4 * w * len(names)))
    ok = True
    try:
        for y0 in range(0, h, rows):
            y1 = min(h, y0 + rows)
            band = np.ascontiguousarray(np.moveaxis(read_rows(planes, names, y0, y1), 0, -1))
            ok = ok and out.write_scanlines(y0, y1, 0, band)
        ok = bool(out.close()) and ok
        if ok:                            # read back: the last row (the last chunk)
            inp = oiio.ImageInput.open(str(tmp))
            ok = inp is not None and inp.read_scanlines(0, 0, h - 1, h, 0, 0, len(names),
                                                       oiio.FLOAT) is not None
            if inp is not None:
                inp.close()
            oiio.geterror()
        if not ok:
            raise safeio.WriteFailed(path, "no space left on device" if safeio.disk_full(tmp)
                                     else f"per-pixel state: {out.geterror() or 'failed'}")
        safeio.commit(tmp, path)
    finally:
        safeio.remove(tmp)


class PlaneFile:
    """A per-pixel state side file opened lazily: band-readable (``names``,
    ``shape``, ``read(y0, y1, names)``), for state too large to read whole."""

    def __init__(self, path: Path, spec):
        self.path = path
        self.names = tuple(spec.channelnames)
        self.shape = (spec.height, spec.width)

    def read(self, y0: int, y1: int, names=None) -> np.ndarray:
        import OpenImageIO as oiio
        inp = oiio.ImageInput.open(str(self.path))
        if inp is None:
            raise ValueError(f"cannot read per-pixel state {self.path}: {oiio.geterror()}")
        try:
            data = inp.read_scanlines(0, 0, y0, y1, 0, 0, len(self.names), oiio.FLOAT)
        finally:
            inp.close()
        if data is None:
            raise ValueError(f"cannot read per-pixel state {self.path} rows {y0}-{y1}")
        data = np.asarray(data, np.float32).reshape(y1 - y0, self.shape[1], len(self.names))
        idx = [self.names.index(k) for k in (names or self.names)]
        return np.ascontiguousarray(np.moveaxis(data[..., idx], -1, 0))


def read_planes(path: Path):
    """The side file's planes: a dict of (h, w) arrays, or a :class:`PlaneFile`
    when larger than :data:`LAZY_PLANES_BYTES`."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"cannot read per-pixel state {path}: {oiio.geterror()}")
    spec = inp.spec()
    if float(spec.width) * spec.height * spec.nchannels * 4 > LAZY_PLANES_BYTES:
        inp.close()
        return PlaneFile(path, spec)
    data = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    inp.close()
    if data is None:
        raise ValueError(f"cannot read per-pixel state {path}")
    data = np.asarray(data).reshape(spec.height, spec.width, spec.nchannels)
    return {name: np.array(data[..., i]) for i, name in enumerate(spec.channelnames)}
