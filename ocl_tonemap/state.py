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
        saved beside the JSON as ``<name>.pixels.exr`` (one channel per plane).
    """

    operator: str
    values: dict = field(default_factory=dict)
    time_s: float | None = None
    frame: int | None = None
    extra: dict = field(default_factory=dict)
    pixels: dict | None = None

    def copy(self) -> "AdaptationState":
        px = None if self.pixels is None else {k: np.array(v, copy=True)
                                              for k, v in self.pixels.items()}
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
        return cls(op, vals, t, frame, extra)

    def save(self, path: str | os.PathLike, checkpoint: bool = False) -> None:
        """Write atomically (temp file in the same folder, then rename); per-pixel
        state goes first to a side file beside it, named in ``extra``:
        ``<stem>.pixels.exr``, or with ``checkpoint`` ``<stem>.pixels.<n>.exr``, a new
        name each time, so that the JSON and its planes always belong together
        whenever the writer is killed; older side files are removed after the
        JSON is replaced."""
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
            _write_planes(side, self.pixels)
            doc["extra"] = dict(doc["extra"], pixel_state=side.name)
        tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
        tmp.write_text(json.dumps(doc, indent=2, sort_keys=True) + "\n")
        os.replace(tmp, path)
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
        p = Path(path)
        try:
            raw = p.read_bytes()
        except OSError as exc:
            raise ValueError(f"cannot read adaptation state {path}: {exc.strerror or exc}") from None
        try:
            doc = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError):
            doc = _state_from_image(p)
        if not isinstance(doc, dict):
            raise ValueError(f"{path} is not an ocl-tonemap adaptation state")
        st = cls.from_json(doc)
        side = st.extra.pop("pixel_state", None)    # (it names a file beside *this* JSON)
        if side:
            st.pixels = _read_planes(p.with_name(side))
        return st


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
        v = inp.spec().getattribute("ocltm:state")
    finally:
        inp.close()
    if not v:
        raise ValueError(f"{path} has no ocltm:state attribute (not an ocl-tonemap output?)")
    try:
        return json.loads(v)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: its ocltm:state is not JSON ({exc})") from None


def _write_planes(path: Path, planes: dict) -> None:
    """Float32 EXR, one channel per plane, written atomically."""
    import OpenImageIO as oiio
    names = list(planes)
    h, w = np.shape(planes[names[0]])
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    # uncompressed: a checkpoint is written after every frame, and zip took
    # longer than the frame (1080p ledda04: 0.4 s of a 0.9 s frame)
    spec.attribute("compression", "none")
    data = np.ascontiguousarray(np.stack([np.asarray(planes[k], np.float32) for k in names],
                                         axis=-1))
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.exr")
    out = oiio.ImageOutput.create(str(tmp))
    if out is None or not out.open(str(tmp), spec):
        raise OSError(f"cannot write per-pixel state {path}: {oiio.geterror()}")
    ok = out.write_image(data)
    out.close()
    if not ok:
        raise OSError(f"cannot write per-pixel state {path}: {out.geterror()}")
    os.replace(tmp, path)


def _read_planes(path: Path) -> dict:
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"cannot read per-pixel state {path}: {oiio.geterror()}")
    spec = inp.spec()
    data = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
    inp.close()
    if data is None:
        raise ValueError(f"cannot read per-pixel state {path}")
    data = np.asarray(data).reshape(spec.height, spec.width, spec.nchannels)
    return {name: np.array(data[..., i]) for i, name in enumerate(spec.channelnames)}
