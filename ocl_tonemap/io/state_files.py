"""Adaptation states on disk: the JSON document (written atomically), the per-pixel
planes of local operators in a side file beside it (float32 EXR, one channel per
plane, read lazily by row bands when large), and the scalar state an output frame
carries (``ocltm:state``)."""

from __future__ import annotations

import glob
import json
import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ..base import safeio
from ..backends.planes import band_readable, plane_shape, read_rows
from .imagewrite import ocltm_metadata
from ..pipeline.state import AdaptationState


def save_state(state: AdaptationState, path: str | os.PathLike, checkpoint: bool = False,
               compression: str = "none") -> None:
    """Write atomically (temp file in the same folder, then rename); per-pixel
    state goes first to a side file beside it, named in ``extra``:
    ``<stem>.pixels.exr``, or with ``checkpoint`` ``<stem>.pixels.<n>.exr``, a new
    name each time, so that the JSON and its planes always belong together
    whenever the writer is killed; older side files are removed after the
    JSON is replaced. ``compression``: the side file's EXR compression (lossless
    ``zip`` for a shot store on shared storage: ~5x smaller)."""
    path = Path(path)
    doc = state.to_json()
    stem = path.name[:-len(path.suffix)] if path.suffix else path.name
    if state.pixels is not None:
        if checkpoint:
            n = 0
            while path.with_name(f"{stem}.pixels.{n}.exr").exists():
                n += 1
            side = path.with_name(f"{stem}.pixels.{n}.exr")
        else:
            side = path.with_name(stem + ".pixels.exr")
        write_planes(side, state.pixels, compression)
        doc["extra"] = dict(doc["extra"], pixel_state=side.name)
    safeio.write_text(path, json.dumps(doc, indent=2, sort_keys=True) + "\n")
    keep = doc["extra"].get("pixel_state")
    for old in path.parent.glob(f"{glob_escape(stem)}.pixels.*.exr"):
        if old.name != keep:
            try:
                old.unlink()
            except OSError:
                pass


def load_state(path: str | os.PathLike) -> AdaptationState:
    """From a state JSON (with its per-pixel side file), or from an output frame
    of ocl-tonemap, whose ``ocltm:state`` attribute holds the scalar state."""
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
        st = AdaptationState.from_json(doc)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    side = st.extra.pop("pixel_state", None)    # (it names a file beside *this* JSON)
    if side is not None:
        st.pixels = read_planes(side_file(p, side, what))
    return st


def side_file(doc_path: Path, name, what: str) -> Path:
    """A file a JSON document names beside itself: a plain name (no folder, no
    ``..``), a regular file in the JSON's own folder; anything else is refused."""
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
    return glob.escape(text)


def _state_from_image(path: Path) -> dict:
    """The ``ocltm:state`` attribute of an image ocl-tonemap wrote."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"{path} is neither a state JSON nor an image with ocltm:state")
    try:
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
    names = list(planes.names if band_readable(planes) else planes)
    h, w = plane_shape(planes)
    spec = oiio.ImageSpec(w, h, len(names), oiio.FLOAT)
    spec.channelnames = tuple(names)
    # uncompressed by default: a checkpoint is written after every frame, and zip
    # took longer than the frame (1080p ledda04: 0.4 s of a 0.9 s frame)
    spec.attribute("compression", compression)
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.exr")
    safeio.claim_temp(tmp, path)
    out = oiio.ImageOutput.create(str(tmp))
    if out is None or not out.open(str(tmp), spec):
        raise OSError(f"cannot write per-pixel state {path}: {oiio.geterror()}")
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
    planes = np.ascontiguousarray(np.moveaxis(data, -1, 0))     # one copy, plane by plane
    return {name: planes[i] for i, name in enumerate(spec.channelnames)}
