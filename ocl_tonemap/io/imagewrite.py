"""Image writes through OpenImageIO: every output written to a temporary file
beside its target, checked, read back, fsynced and renamed into place
(``safeio.commit``), whole (:func:`write_frame`) or in row bands
(:class:`BandWriter`), with the input's windows and metadata and ours (``ocltm:*``;
in ``ImageDescription`` for the formats that keep only standard tags). A write
that fails, a full disk included, raises :class:`~ocl_tonemap.io.imageio.FrameError`
naming the file and frame and leaves nothing behind. The reading side:
``imageio.py``.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from ..base import safeio
from .imageio import (BITS_TYPES, DEFAULT_BITS, PNG_FILTER, PNG_FILTERS, PNG_LEVEL,
                      PREMULTIPLIED_FORMATS, FrameError, oiio_error)


def output_bits(path: str, bits: str | None = None) -> str:
    """The bit depth a file of this name is written with (``bits`` or the format's default)."""
    return bits or DEFAULT_BITS.get(Path(path).suffix.lower(), "float")


def write_frame(path: str, pixels: np.ndarray, in_spec, colorspace: str,
                metadata: dict, bits: str | None = None, frame: int | None = None,
                chromaticities: tuple | None = None, white_luminance: float | None = None,
                straight_alpha: bool = False, png_level: int = PNG_LEVEL,
                png_filter: str = PNG_FILTER) -> None:
    """Write pixels atomically, keeping the input's windows and metadata.

    ``colorspace`` and ``chromaticities`` say what the pixels hold (the input's
    own tags are replaced); ``white_luminance``: cd/m^2 of 1.0 for outputs in
    absolute light (EXR ``whiteLuminance``), else the attribute is dropped.
    ``straight_alpha``: the colour is not premultiplied by alpha; formats that
    store premultiplied colour (EXR) get it premultiplied, the others are told
    (``oiio:UnassociatedAlpha``) so that OIIO writes it as it is.
    """
    ext = Path(path).suffix.lower()
    bits = output_bits(path, bits)
    if bits not in BITS_TYPES:
        raise FrameError(path, frame, f"unknown output bit depth {bits!r} (8, 16, half, float)")
    code_bits = {np.dtype(np.uint8): "8", np.dtype(np.uint16): "16"}.get(pixels.dtype)
    if code_bits is not None and bits != code_bits:
        raise FrameError(path, frame, f"{code_bits}-bit code values given for a {bits}-bit "
                         "output")
    pix, straight_alpha = _alpha_for_format(pixels, ext, straight_alpha, path)
    nch = pix.shape[2]
    spec = output_spec(in_spec, pix.shape[1], pix.shape[0], nch, ext, bits, colorspace,
                        metadata, chromaticities, white_luminance, straight_alpha, png_level,
                        png_filter)
    d = output_folder(path, frame)
    tmp = os.path.join(d, f".{Path(path).stem}.tmp{os.getpid()}{ext}")
    room_for(path, frame, ext, pix.shape[1], pix.shape[0], nch)
    _claim(tmp, path, frame)
    try:
        # straight to the format's writer: an ImageBuf's set_pixels costs ~30 ms a 1080p
        # frame before the writer even starts (benchmarks/results/speed_accuracy.md)
        out = oiio.ImageOutput.create(tmp)
        if out is None:
            raise FrameError(path, frame, f"cannot write: {oiio_error(oiio.geterror())}")
        if spec.tile_width and not out.supports("tiles"):
            spec.tile_width = spec.tile_height = spec.tile_depth = 0
        ok = bool(out.open(tmp, spec)) and bool(out.write_image(pix))
        err = "" if ok else out.geterror()
        ok = bool(out.close()) and ok
        if not ok:
            raise FrameError(path, frame,
                             f"cannot write: {_write_error(tmp, err or out.geterror())}")
        verify_written(tmp, path, frame, pix.shape[1], pix.shape[0], nch)
        safeio.commit(tmp, path)
    except safeio.WriteFailed as exc:
        raise FrameError(path, frame, f"cannot write: {exc.why}") from None
    finally:
        safeio.remove(tmp)


#: Formats whose library ends the process on a failed write (libjpeg's stdio
#: destination: "Output file write error --- out of disk space?", exit 1, its
#: temporary left): they are written only where the disk has room for the
#: uncompressed pixels, checked first (a disk filled by another process between the
#: check and the write is the one case left).
EXITS_ON_WRITE_ERROR = (".jpg", ".jpeg")


def room_for(path: str, frame, ext: str, width: int, height: int, nch: int) -> None:
    if ext not in EXITS_ON_WRITE_ERROR:
        return
    need = int(width) * int(height) * max(1, min(int(nch), 3)) + safeio.FULL_BELOW
    free = safeio.free_bytes(path)
    if free is not None and free < need:
        raise FrameError(path, frame, f"cannot write: no space left on device (a {ext[1:].upper()} "
                         f"of {width}x{height} needs up to {need} bytes; {free} free)")


def output_folder(path: str, frame: int | None = None, what: str = "output") -> str:
    """The folder of a file to write, made where missing (as oiiotool and Nuke's
    Write do); ``what`` names the file in the error (output, state). A folder this
    process cannot make a file in (a read-only file system, its permissions, /proc) is
    refused in our words, before any free space is looked at: ``<folder>: the folder
    is not writable (a read-only file system); cannot write o.png``."""
    d = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(d):
        try:
            os.makedirs(d, exist_ok=True)
        except OSError as exc:
            up = os.path.dirname(d)
            while up != os.path.dirname(up) and not os.path.isdir(up):
                up = os.path.dirname(up)
            why = safeio.folder_refuses(up) if os.path.isdir(up) else None
            if why:                        # where it stopped: a folder that takes nothing
                raise FrameError(up, frame, f"the folder is not writable ({why}); cannot "
                                 f"make the {what} folder {d} in it") from None
            raise FrameError(path, frame, f"cannot make the {what} folder {d}: "
                             f"{safeio.reason(exc)}") from None
    _writable(d, path, frame)
    return d


def _writable(d: str, path: str, frame) -> None:
    """The existing folder ``d`` of ``path`` takes a new file (``safeio.folder_refuses``),
    else a :class:`FrameError` naming the folder as given."""
    why = safeio.folder_refuses(d)
    if why:
        raise FrameError(os.path.dirname(path) or ".", frame, f"the folder is not writable "
                         f"({why}); cannot write {os.path.basename(path)}")


#: The formats named in the error for an output name no writer takes.
KNOWN_OUTPUTS = ".exr, .png, .tif, .jpg, .hdr ..."


def check_output(path: str, frame: int | None = None) -> None:
    """An output name, before any frame is made: not a folder nor another thing that is
    not a file, a name some image format writes (its extension), in a folder this
    process can write in; each refused in one :class:`FrameError` in our words
    (OIIO's own error is read, so none is left pending for it to print at exit)."""
    if os.path.isdir(path):
        raise FrameError(path, frame, "is a folder; give an image file name in it "
                         f"({os.path.join(path, 'out.exr')} ...)")
    try:
        safeio.check_input(path)
    except safeio.NotAFile as exc:
        raise FrameError(path, frame, exc.why) from None
    out = oiio.ImageOutput.create(path)
    if out is None:
        oiio.geterror()
        ext = Path(path).suffix
        raise FrameError(path, frame, (f"no image format writes the extension {ext}"
                                       if ext else "no extension, so no image format to "
                                       "write it") + f" (use {KNOWN_OUTPUTS})")
    d = os.path.dirname(os.path.abspath(path))
    if os.path.isdir(d):
        _writable(d, path, frame)


def _claim(tmp: str, path: str, frame) -> None:
    """The temporary file made ours before OIIO writes it by name (``safeio.claim_temp``:
    a link, FIFO or folder in its place is refused, nothing written through it)."""
    try:
        safeio.claim_temp(tmp, path)
    except safeio.WriteFailed as exc:
        raise FrameError(path, frame, f"cannot write: {exc.why}") from None


def _write_error(tmp: str, text: str) -> str:
    """A writer's error in words: the disk's state where it is full (the library's
    own message is about its buffers)."""
    if safeio.disk_full(tmp):
        return "no space left on device"
    return oiio_error(text) if text else "failed"


#: The bytes a complete file of these formats ends with (the writer's last act):
#: PNG's IEND chunk, JPEG's end-of-image marker.
_TRAILERS = {".png": b"\x00\x00\x00\x00IEND\xaeB`\x82", ".jpg": b"\xff\xd9",
             ".jpeg": b"\xff\xd9"}
#: Formats whose directory is written after the pixel data at close (TIFF's IFD):
#: a file that opens with the right header was written whole.
_DIRECTORY_LAST = (".tif", ".tiff")


def _trailer_ok(tmp: str, trailer: bytes) -> bool:
    try:
        with open(tmp, "rb") as fh:
            fh.seek(0, os.SEEK_END)
            n = fh.tell()
            if n < len(trailer):
                return False
            fh.seek(n - len(trailer))
            return fh.read(len(trailer)) == trailer
    except OSError:
        return False


def verify_written(tmp: str, path: str, frame: int | None, width: int, height: int,
                   nch: int) -> None:
    """Read a just-written file back before it counts: its header (size, channels),
    and that it is whole: PNG and JPEG end with their last chunk or marker (libpng
    loses data on a full disk without an error); TIFF's directory, which the writer
    puts after the pixels, opened; anything else (EXR ...) gives back its last row
    (one chunk). benchmarks/results/write_safety.md has the cost."""
    why = None
    ext = Path(path).suffix.lower()
    inp = oiio.ImageInput.open(tmp)
    if inp is None:
        why = _write_error(tmp, oiio.geterror()) + " (the file written cannot be read back)"
    else:
        try:
            s = inp.spec()
            if (s.width, s.height) != (width, height) or s.nchannels < min(nch, 3):
                why = (f"the file written reads back as {s.width}x{s.height}x{s.nchannels}, "
                       f"not {width}x{height}x{nch}")
            elif ext in _TRAILERS:
                if not _trailer_ok(tmp, _TRAILERS[ext]):
                    why = _write_error(tmp, "data lost") + " (the file written is incomplete)"
            elif ext not in _DIRECTORY_LAST:
                row = inp.read_scanlines(0, 0, s.y + s.height - 1, s.y + s.height, 0, 0,
                                         s.nchannels, oiio.UNKNOWN)
                if row is None:
                    why = _write_error(tmp, inp.geterror()) + " (the file written is incomplete)"
        finally:
            inp.close()
    oiio.geterror()                      # nothing pending is left for the next call
    if why:
        safeio.remove(tmp)
        raise FrameError(path, frame, f"cannot write: {why}")


def format_supports_alpha(path: str) -> bool:
    """Whether OIIO's writer for this file name stores alpha (JPEG, Radiance do not)."""
    out = oiio.ImageOutput.create(path)
    if out is None:
        oiio.geterror()                  # (nothing left pending: OIIO prints it at exit)
        return True
    return bool(out.supports("alpha"))


def _alpha_for_format(pixels, ext: str, straight_alpha: bool, path: str = ""):
    """(pixels as the format stores them, still straight?): formats without alpha
    (JPEG, Radiance) drop it; premultiplied formats (EXR) get straight colour
    premultiplied; integer code values stay as they are."""
    pix = pixels if pixels.dtype in (np.uint8, np.uint16) else \
        np.ascontiguousarray(pixels, np.float32)
    if pix.shape[2] == 4 and (ext in (".jpg", ".jpeg") or
                              (path and not format_supports_alpha(path))):
        pix = np.ascontiguousarray(pix[..., :3])
    if pix.shape[2] == 4 and straight_alpha and ext in PREMULTIPLIED_FORMATS:
        pix = pix.copy()
        pix[..., :3] *= pix[..., 3:4]
        straight_alpha = False
    return pix, straight_alpha


def output_spec(in_spec, width, height, nch, ext, bits, colorspace, metadata,
                 chromaticities, white_luminance, straight_alpha, png_level,
                 png_filter=PNG_FILTER):
    """The output's ImageSpec: the input's windows and metadata, the output's tags."""
    spec = oiio.ImageSpec(in_spec) if in_spec is not None else \
        oiio.ImageSpec(width, height, nch, oiio.FLOAT)
    spec.nchannels = nch
    spec.channelnames = ("R", "G", "B", "A")[:nch]
    spec.alpha_channel = 3 if nch == 4 else -1
    spec.set_format(BITS_TYPES[bits])
    # the input's tags of what its pixels were: none of them holds for the output's
    for k in ("whiteLuminance", "ocltm:timestamp", "chromaticities", "oiio:UnassociatedAlpha",
              "adoptedNeutral", "oiio:ColorSpace", "colorInteropID", "CICP", "ICCProfile",
              "oiio:Gamma", "oiio:BitsPerSample",
              # a texture's (maketx, an EXR envmap): OIIO's EXR writer then expects MIP
              # levels and leaves the file empty at close; the output is one level
              # (its angle: ocltm:fov)
              "textureformat", "oiio:updirection", "oiio:sampleborder"):
        spec.erase_attribute(k)
    if nch == 4 and straight_alpha:
        spec.attribute("oiio:UnassociatedAlpha", 1)
    spec.attribute("oiio:ColorSpace", colorspace)
    if ext in (".exr", ".sxr", ".mxr"):
        spec.attribute("colorInteropID", colorspace)
    if chromaticities is not None:
        spec.attribute("chromaticities", oiio.TypeDesc("float[8]"),
                       tuple(float(v) for v in chromaticities))
    if white_luminance is not None:
        spec.attribute("whiteLuminance", float(white_luminance))
    if ext == ".png":
        spec.attribute("png:compressionLevel", int(png_level))
        spec.attribute("png:filter", PNG_FILTERS[png_filter])
    for k, v in metadata.items():
        if k == "FramesPerSecond":         # a rational, as OIIO reads it
            from fractions import Fraction
            r = Fraction(float(v)).limit_denominator(1001)
            spec.attribute(k, oiio.TypeDesc("rational"), (r.numerator, r.denominator))
            continue
        if ext == ".png" and k.startswith("ocltm:") and isinstance(v, (int, float)):
            # PNG keeps text only: a number would be dropped (ocltm:time_s, for --plot)
            v = repr(float(v)) if isinstance(v, float) else str(int(v))
        spec.attribute(k, v if isinstance(v, (str, int, float)) else json.dumps(v, sort_keys=True))
    if ext not in KEEPS_ATTRIBUTES:
        # TIFF, JPEG, DPX, .hdr drop attributes they have no tag for: ours go in the one
        # tag they all keep, as JSON after a marker (``ocltm_metadata`` reads them back)
        ours = {k: v for k, v in metadata.items() if k.startswith("ocltm:")}
        if ours:
            spec.attribute("ImageDescription", DESCRIPTION_MARK + json.dumps(
                ours, sort_keys=True, default=str))
    return spec


#: Formats whose files keep arbitrary string attributes (``ocltm:*``).
KEEPS_ATTRIBUTES = (".exr", ".sxr", ".mxr", ".png")
DESCRIPTION_MARK = "ocl-tonemap metadata: "


def ocltm_metadata(spec) -> dict:
    """The ``ocltm:*`` attributes of a file ocl-tonemap wrote: its attributes, or for
    formats that keep only standard tags, the JSON in its ImageDescription."""
    out = {}
    for a in spec.extra_attribs:
        if a.name.startswith("ocltm:"):
            out[a.name] = a.value
    if not out:
        d = spec.getattribute("ImageDescription")
        if isinstance(d, str) and d.startswith(DESCRIPTION_MARK):
            try:
                doc = json.loads(d[len(DESCRIPTION_MARK):])
                out = {k: v for k, v in doc.items() if k.startswith("ocltm:")} \
                    if isinstance(doc, dict) else {}
            except json.JSONDecodeError:
                out = {}
    return out


class BandWriter:
    """An output written in row bands (OIIO scanline writes) to a temporary file,
    renamed over the target by :meth:`commit` (nothing partial is ever left)."""

    def __init__(self, path: str, in_spec, nch: int, colorspace: str, metadata: dict,
                 bits: str | None = None, frame: int | None = None,
                 chromaticities: tuple | None = None, white_luminance: float | None = None,
                 straight_alpha: bool = False, png_level: int = PNG_LEVEL,
                 png_filter: str = PNG_FILTER):
        self.path, self.frame = path, frame
        self.ext = Path(path).suffix.lower()
        bits = output_bits(path, bits)
        if bits not in BITS_TYPES:
            raise FrameError(path, frame, f"unknown output bit depth {bits!r} (8, 16, half, float)")
        if self.ext in (".jpg", ".jpeg"):
            nch = min(nch, 3)
        self.straight = straight_alpha and not (nch == 4 and self.ext in PREMULTIPLIED_FORMATS)
        self.premultiply = nch == 4 and straight_alpha and self.ext in PREMULTIPLIED_FORMATS
        self.nch = nch
        if nch == 4 and not format_supports_alpha(path):
            nch = 3
            self.straight = self.premultiply = False
        self.nch = nch
        self.spec = output_spec(in_spec, in_spec.width, in_spec.height, nch, self.ext, bits,
                                 colorspace, metadata, chromaticities, white_luminance,
                                 self.straight, png_level, png_filter)
        self.spec.tile_width = self.spec.tile_height = self.spec.tile_depth = 0
        d = output_folder(path, frame)
        self.tmp = os.path.join(d, f".{Path(path).stem}.tmp{os.getpid()}{self.ext}")
        room_for(path, frame, self.ext, in_spec.width, in_spec.height, nch)
        _claim(self.tmp, path, frame)
        self.out = oiio.ImageOutput.create(self.tmp)
        if self.out is None or not self.out.open(self.tmp, self.spec):
            err = oiio_error(oiio.geterror() if self.out is None else self.out.geterror())
            self.abort()
            raise FrameError(path, frame, f"cannot write: {err}")
        self.spec = self.out.spec()          # the origin the format keeps (JPEG, TIFF: 0)

    def write(self, y0: int, pixels: np.ndarray) -> None:
        pix = np.ascontiguousarray(pixels[..., :self.nch], np.float32)
        if self.premultiply:
            pix = pix.copy()
            pix[..., :3] *= pix[..., 3:4]
        s = self.spec
        if not self.out.write_scanlines(s.y + y0, s.y + y0 + pix.shape[0], 0, pix):
            err = oiio_error(self.out.geterror())
            self.abort()
            raise FrameError(self.path, self.frame, f"cannot write rows from {y0}: {err}")

    def commit(self) -> None:
        out, self.out = self.out, None
        ok = out.close()
        if not ok:
            err = _write_error(self.tmp, out.geterror())
            self.abort()
            raise FrameError(self.path, self.frame, f"cannot finish writing: {err}")
        try:
            verify_written(self.tmp, self.path, self.frame, self.spec.width, self.spec.height,
                           self.nch)
            safeio.commit(self.tmp, self.path)
        except safeio.WriteFailed as exc:
            raise FrameError(self.path, self.frame, f"cannot write: {exc.why}") from None
        finally:
            safeio.remove(self.tmp)

    def abort(self) -> None:
        if getattr(self, "out", None) is not None:
            try:
                self.out.close()
            except Exception:  # noqa: BLE001
                pass
            self.out = None
        safeio.remove(self.tmp)
