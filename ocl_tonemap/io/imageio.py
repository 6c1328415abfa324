"""Image reads through OpenImageIO: frames and the formats' tables.

Only the channels a frame uses are read. File-name patterns of a sequence:
``patterns.py``; reads in row bands: ``imagebands.py``; writes (temporary file,
read back, fsync, rename): ``imagewrite.py``.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np
import OpenImageIO as oiio

from ..base import safeio
from . import radiance
from ..base.reuse import Reused
from .channels import MIN_SPECTRAL_CHANNELS, channel_runs, select_channels, spectral_channels
from ..models.lmsr import spectral_to_rgb
from ..models.photometry import xy_to_rgb


#: Default output sample type by file extension.
DEFAULT_BITS = {".exr": "half", ".tif": "16", ".tiff": "16", ".png": "8", ".jpg": "8",
                ".jpeg": "8", ".hdr": "float", ".dpx": "16"}
BITS_TYPES = {"8": oiio.UINT8, "16": oiio.UINT16, "half": oiio.HALF, "float": oiio.FLOAT}
#: zlib level of PNG outputs: 1 writes a 1080p photograph 3.5x faster than OIIO's
#: default 6 (117 vs 416 ms here) for a 13% larger file (--png-level).
PNG_LEVEL = 1
#: PNG row filters (libpng's flags; OIIO's ``png:filter``): ``sub`` at zlib level 1 writes
#: tone-mapped photographs 1.6x and the tunnel sample 3x faster than libpng's adaptive
#: choice, with files 2% smaller to 15% larger (benchmarks/results/speed_accuracy.md);
#: ``adaptive`` (libpng's default) for the smallest files (--png-filter).
PNG_FILTERS = {"sub": 16, "none": 8, "adaptive": 0}
PNG_FILTER = "sub"
#: Formats whose colour is premultiplied by alpha by definition.
PREMULTIPLIED_FORMATS = (".exr", ".sxr", ".mxr")
#: Outputs written as display-linear light by default (float formats);
#: the others get the display encoding.
LINEAR_FORMATS = (".exr", ".sxr", ".mxr", ".hdr")


class FrameError(RuntimeError):
    """A failure tied to one file and frame: ``ocl-tonemap ERROR: <file> frame <n>: <why>``."""

    def __init__(self, path, frame, why):
        self.path, self.frame, self.why = str(path), frame, str(why)
        super().__init__(f"{self.path}{'' if frame is None else f' frame {frame}'}: {why}")

    def __reduce__(self):          # pickled whole (a Dask worker's error reaches the client)
        return (type(self), (self.path, self.frame, self.why))


def one_line(e: BaseException, kind: bool = False) -> str:
    """An exception as one line (a library's message can span several)."""
    text = " ".join(str(e).split()) or type(e).__name__
    if len(text) > 600:
        text = text[:600] + " ..."
    name = type(e).__name__
    if kind and name not in text:
        mod = type(e).__module__
        text = f"{'' if mod in ('builtins', None) else mod.split('.')[0] + ' '}{name}: {text}"
    return text


@dataclass
class Frame:
    """One input frame: pixels of its data window and where they came from."""

    path: str
    frame: int | None
    pixels: np.ndarray          # (H, W, 3 or 4) float32: RGB [+ alpha]
    spec: object                # the file's oiio.ImageSpec (metadata, windows)
    colorspace: str | None      # the file's oiio:ColorSpace, if any
    white_luminance: float | None
    fps: float | None
    timestamp: float | None
    format_name: str
    wavelengths: np.ndarray | None = None   # spectral channels (nm), when the file has them
    spectral: np.ndarray | None = None      # (H, W, N) spectral radiance
    rgb_from_spectrum: bool = False         # pixels were computed from the spectrum (working RGB)
    chromaticities: tuple | None = None     # EXR chromaticities (rx ry gx gy bx by wx wy)
    unassociated_alpha: bool = False        # the alpha is straight (oiio:UnassociatedAlpha)
    channel_note: str | None = None         # what select_channels assumed, if anything
    radiance: object = None                 # a Radiance picture's header (radiance.py)

    @property
    def has_alpha(self) -> bool:
        return self.pixels.ndim == 3 and self.pixels.shape[2] == 4


def _fps(spec) -> float | None:
    v = spec.getattribute("FramesPerSecond")
    if v is None:
        return None
    try:
        if isinstance(v, (tuple, list)) and len(v) == 2:
            return float(v[0]) / float(v[1]) if v[1] else None
        if isinstance(v, str) and "/" in v:
            a, b = v.split("/")
            return float(a) / float(b)
        f = float(v)
        return f if f > 0 else None
    except (TypeError, ValueError, ZeroDivisionError):
        return None


def oiio_error(text: str) -> str:
    """OIIO's error text without its repeated lines, on one line."""
    seen = []
    for line in (text or "").splitlines():
        line = line.strip()
        if line and line not in seen:
            seen.append(line)
    return "; ".join(seen[:3]) or "unknown error"


def max_frame_bytes() -> float:
    """The largest frame read whole, as float32: a quarter of physical memory (the
    pipeline holds a few copies). Larger declared sizes are refused before any
    allocation (a corrupt header must not exhaust memory)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        total = 16 * 2**30
    return 0.25 * float(total)


class FramePool(Reused):
    """Float32 arrays for frames read whole, used again once nothing else holds them.

    A frame read into fresh memory pays a page fault for every 4 KiB of it, every
    frame (the kernel zeroes each page), and OIIO's Python ``read_image`` fills a
    buffer of its own and then copies it into a new array: two frames of fresh
    memory a read, about 6% of a 1080p sequence's CPU on this project's machines.
    Read in row bands into an array of the pool (:func:`read_frame` ``pool``), a
    frame takes neither. An array is free when the pool alone refers to it
    (``reuse.py``); at most ``keep`` arrays are kept (a run's frames in flight:
    the one read ahead, the one mapped, the one still being written)."""

    def __init__(self, keep: int = 4):
        super().__init__(keep)
        self._host = None                      # a backend's host arrays (use)

    def use(self, backend) -> None:
        """Take the arrays from ``backend``'s ``host_arrays`` where it has them (an
        OpenCL device: page-locked memory for a GPU's transfers), kept by it under the
        same rule and bound."""
        make = getattr(backend, "host_arrays", None)
        self._host = make(self.keep) if make is not None else None

    def take(self, shape, dtype=np.float32) -> np.ndarray:
        """An array of ``shape`` and ``dtype`` (float32, or float16 for frames kept as
        stored) that nothing else refers to (contents undefined)."""
        shape, dtype = tuple(int(v) for v in shape), np.dtype(dtype)
        if self._host is not None and self._host.pinned:
            return self._host.empty(shape, dtype)
        return self._take(lambda a: a.shape == shape and a.dtype == dtype,
                          lambda: np.empty(shape, dtype))


#: Bytes of a band of rows when a frame is read into a :class:`FramePool` array:
#: OIIO's temporaries (a band and its NumPy copy) under the command's mmap threshold
#: (``__main__.MMAP_THRESHOLD``) come back from malloc's heap, not fresh pages.
POOL_BAND_BYTES = 1 * 2**20


def read_frame(path: str, frame: int | None = None, channels: list[str] | None = None,
               pool: FramePool | None = None, keep_half: bool = False) -> Frame:
    """Read the RGB (+alpha) of an image OIIO can read, as float32 (channels by
    :func:`select_channels`; what was assumed is in ``Frame.channel_note``).
    ``pool``: a scanline image is read in row bands into one of its arrays;
    ``keep_half``: a half-float file of R, G, B alone stays half (float16: half the
    memory, and the upload to a device of half the bytes; every half is a float32)."""
    check_readable(path, frame)
    # Ask for alpha as the file stores it: straight-alpha formats (PNG, TIFF with
    # unassociated alpha) then say so in oiio:UnassociatedAlpha, and are not
    # premultiplied and divided again on the way through (8-bit rounding).
    hint = oiio.ImageSpec()
    hint.attribute("oiio:UnassociatedAlpha", 1)
    many = _extra_channels(path)
    if many:                       # read the channels used, not a thousand AOVs beside them
        r = BandReader(path, frame, channels)
        try:
            h, w, n = r.shape
            need = float(h) * w * n * 4
            if need > max_frame_bytes():
                raise FrameError(path, frame, f"{w}x{h}x{n} would take {need / 2**30:.1f} GiB "
                                 "as float32, more than this machine can hold")
            fr = r.header
            fr.pixels = r.read(0, h)
            return fr
        finally:
            r.close()
    rad, src = radiance_source(path, frame)
    try:
        fr = frame_from_file(src, hint, path, frame, channels, pool,
                             keep_half and channels is None and rad is None)
    finally:
        if src != path:
            safeio.remove(src)
    return radiance.as_read(fr, rad)


def check_readable(path: str, frame: int | None = None) -> None:
    """An input image, before anything opens it: there, and a regular file (a FIFO,
    a socket, a device or a folder is refused here: OIIO's open would wait on a FIFO
    inside the library, where no signal reaches), in one :class:`FrameError`."""
    try:
        safeio.check_input(path)
    except safeio.NotAFile as exc:
        raise FrameError(path, frame, exc.why) from None
    if not os.path.exists(path):
        raise FrameError(path, frame, "no such file")


#: What a deep image (OpenEXR's per-pixel sample lists) is told.
DEEP_WHY = "a deep image (per-pixel samples); flatten it first (oiiotool --flatten)"


def check_flat(spec, path: str, frame: int | None) -> None:
    """A deep image is refused on read: its pixels are lists of samples, not colours."""
    if getattr(spec, "deep", False):
        raise FrameError(path, frame, DEEP_WHY)


def radiance_source(path: str, frame: int | None):
    """(header or None, the file OIIO reads) of a picture: a Radiance picture's header
    (``radiance.py``); an XYZE picture is read from a copy that says rgbe."""
    if not radiance.is_radiance(path):
        return None, path
    try:
        rad = radiance.read_header(path)
    except (radiance.HeaderError, OSError) as exc:
        raise FrameError(path, frame, f"cannot read its Radiance header: {exc}") from None
    return rad, (radiance.rgbe_copy(path) if rad.xyze else path)


def _extra_channels(path: str) -> bool:
    """Whether a file holds channels beyond what a frame uses (not a spectral image,
    whose channels are all used): then only R, G, B (and alpha) are read."""
    inp = oiio.ImageInput.open(path)
    if inp is None:
        oiio.geterror()
        return False
    try:
        s = inp.spec()
        if s.deep:
            return False               # (refused where it is read, in its own words)
        if s.nchannels <= 4 or s.depth > 1:
            return False
        short = [n.split(".")[-1].upper() for n in s.channelnames]
        return all(c in short for c in "RGB") or \
            len(spectral_channels(s.channelnames)) < MIN_SPECTRAL_CHANNELS
    finally:
        inp.close()


def _check_size(spec, path: str, frame: int | None) -> None:
    """A frame OIIO declares is not empty, and fits this machine as float32."""
    if spec.width < 1 or spec.height < 1 or spec.nchannels < 1:
        raise FrameError(path, frame, f"empty image ({spec.width}x{spec.height}, "
                         f"{spec.nchannels} channels)")
    need = float(spec.width) * spec.height * max(spec.depth, 1) * spec.nchannels * 4
    if need > max_frame_bytes():
        raise FrameError(path, frame, f"{spec.width}x{spec.height}x{spec.nchannels} would take "
                         f"{need / 2**30:.1f} GiB as float32, more than this machine can hold "
                         f"({max_frame_bytes() / 2**30:.1f} GiB allowed); a corrupt header, or "
                         "split the image")


def frame_from_imagebuf(buf, path: str = "<ImageBuf>", frame: int | None = None,
                        channels: list[str] | None = None) -> Frame:
    """A :class:`Frame` from an OIIO ImageBuf (the file's or the caller's)."""
    if buf.has_error:
        raise FrameError(path, frame, f"cannot read: {oiio_error(buf.geterror())}")
    try:
        spec = buf.spec()
    except Exception as exc:  # noqa: BLE001 -- an ImageBuf of a file that is not there
        raise FrameError(path, frame, f"cannot read: {exc}") from None
    if not buf.initialized:
        raise FrameError(path, frame, "cannot read: the ImageBuf holds no image")
    check_flat(spec, path, frame)
    _check_size(spec, path, frame)
    pix = buf.get_pixels(oiio.FLOAT)
    if buf.has_error or pix is None:
        raise FrameError(path, frame, f"cannot read pixels: {oiio_error(buf.geterror())}")
    return frame_from_pixels(spec, pix, buf.file_format_name or "", path, frame, channels)


def frame_from_file(src: str, hint, path: str, frame: int | None = None,
                    channels: list[str] | None = None, pool: FramePool | None = None,
                    keep_half: bool = False) -> Frame:
    """A :class:`Frame` of the file ``src`` (named ``path`` in messages), its first
    subimage read straight into one float32 array by its ImageInput (``hint``: the
    open's configuration): an ImageBuf's get_pixels keeps a float copy of its own
    beside it, a frame's size more at the peak (95 MiB at 4K) and ~30% slower.
    ``pool``: a scanline image goes into one of its arrays in row bands."""
    inp = oiio.ImageInput.open(src, hint)
    if inp is None:
        raise FrameError(path, frame, f"cannot read: {oiio_error(oiio.geterror())}")
    try:
        spec = inp.spec()
        check_flat(spec, path, frame)
        _check_size(spec, path, frame)
        if pool is not None and spec.tile_width == 0 and spec.depth <= 1:
            half = keep_half and spec.format == oiio.TypeDesc("half") and \
                list(spec.channelnames) == ["R", "G", "B"]
            pix = _read_bands(inp, spec, pool.take((spec.height, spec.width, spec.nchannels),
                                                   np.float16 if half else np.float32))
        else:
            pix = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        if pix is None:
            raise FrameError(path, frame, f"cannot read pixels: {oiio_error(inp.geterror())}")
        fmt = inp.format_name() or ""
    finally:
        inp.close()
        oiio.geterror()
    return frame_from_pixels(spec, pix, fmt, path, frame, channels)


def _read_bands(inp, spec, out: np.ndarray) -> np.ndarray | None:
    """The image's scanlines into ``out`` (height x width x channels; float32, or
    float16 read as stored), a band of :data:`POOL_BAND_BYTES` at a time; None where
    OIIO fails."""
    h, w, n = out.shape
    step = max(1, POOL_BAND_BYTES // (w * n * 4))
    kind = oiio.HALF if out.dtype == np.float16 else oiio.FLOAT
    for y0 in range(0, h, step):
        y1 = min(h, y0 + step)
        rows = inp.read_scanlines(0, 0, spec.y + y0, spec.y + y1, spec.z, 0, n, kind)
        if rows is None:
            return None
        out[y0:y1] = np.asarray(rows, out.dtype).reshape(y1 - y0, w, n)
    return out


def frame_from_pixels(spec, pix, fmt: str, path: str, frame: int | None,
                      channels: list[str] | None) -> Frame:
    """A :class:`Frame` from an image's spec, its float pixels and its format's name
    (float32; float16 kept where it was read so)."""
    if np.asarray(pix).dtype != np.float16:
        pix = np.asarray(pix, np.float32)
    if pix.ndim == 4:  # volume images: take the first slice
        pix = pix[0]
    if pix.ndim == 2:
        pix = pix[..., None]
    lam, cube = _spectral_part(spec, pix, path, frame)
    names = [n.split(".")[-1].upper() for n in spec.channelnames]
    from_spectrum = False
    if lam is not None and not all(c in names for c in "RGB"):
        pix = spectral_to_rgb(lam, cube).astype(np.float32)     # working RGB, cd/m^2
        from_spectrum = True
    note = None
    if not from_spectrum:
        try:
            idx, note = select_channels(spec, channels)
        except ValueError as exc:
            raise FrameError(path, frame, exc) from None
        if list(idx) != list(range(pix.shape[2])):     # (a fancy index always copies)
            pix = np.ascontiguousarray(pix[..., idx])
    wl = spec.getattribute("whiteLuminance")
    ts = spec.getattribute("ocltm:timestamp")
    chrom = spec.getattribute("chromaticities")
    if not (isinstance(chrom, (tuple, list)) and len(chrom) == 8):
        chrom = None
    return Frame(path, frame, pix, spec, spec.getattribute("oiio:ColorSpace") or None,
                 float(wl) if isinstance(wl, (int, float)) and math.isfinite(wl) and wl > 0
                 else None, _fps(spec),
                 float(ts) if isinstance(ts, (int, float)) else None, fmt, lam, cube,
                 from_spectrum, tuple(float(v) for v in chrom) if chrom else None,
                 bool(spec.getattribute("oiio:UnassociatedAlpha") or 0), note)


def _spectral_part(spec, pix_all: np.ndarray, path: str, frame):
    chans = spectral_channels(spec.channelnames)
    if not chans:
        return None, None
    lam = np.array([w for _, w in chans])
    if np.any(np.diff(lam) <= 0):
        raise FrameError(path, frame, "spectral channels repeat a wavelength")
    return lam, np.ascontiguousarray(pix_all[..., [i for i, _ in chans]], np.float32)


def illuminant_from_metadata(spec) -> np.ndarray | None:
    """The EXR ``adoptedNeutral`` chromaticity (x, y) of a frame, as normalised RGB."""
    if spec is None:
        return None
    v = spec.getattribute("adoptedNeutral")
    try:
        x, y = float(v[0]), float(v[1])
        return xy_to_rgb(x, y)
    except (TypeError, ValueError, IndexError):
        return None


class BandReader:
    """A file read in row bands (OIIO scanline reads): ``header`` is the Frame
    without pixels; ``read(y0, y1)`` gives rows [y0, y1) of the selected
    channels (R, G, B [, A]) as float32."""

    def __init__(self, path: str, frame: int | None = None, channels: list[str] | None = None):
        check_readable(path, frame)
        hint = oiio.ImageSpec()
        hint.attribute("oiio:UnassociatedAlpha", 1)
        self.path, self.frame = path, frame
        self.rad, self._src = radiance_source(path, frame)
        self.inp = oiio.ImageInput.open(self._src, hint)
        if self.inp is None:
            self._drop_copy()
            raise FrameError(path, frame, f"cannot read: {oiio_error(oiio.geterror())}")
        spec = self.inp.spec()
        if spec.deep or spec.width < 1 or spec.height < 1 or spec.nchannels < 1:
            self.close()
            raise FrameError(path, frame, DEEP_WHY if spec.deep else "empty image")
        try:
            self.idx, note = select_channels(spec, channels)
        except ValueError as exc:
            raise FrameError(path, frame, exc) from None
        self.spec = spec
        wl = spec.getattribute("whiteLuminance")
        ts = spec.getattribute("ocltm:timestamp")
        chrom = spec.getattribute("chromaticities")
        self.header = Frame(path, frame, np.zeros((0, 0, len(self.idx)), np.float32), spec,
                            spec.getattribute("oiio:ColorSpace") or None,
                            float(wl) if isinstance(wl, (int, float)) and math.isfinite(wl)
                            and wl > 0 else None, _fps(spec),
                            float(ts) if isinstance(ts, (int, float)) else None,
                            self.inp.format_name(), None, None, False,
                            tuple(float(v) for v in chrom)
                            if isinstance(chrom, (tuple, list)) and len(chrom) == 8 else None,
                            bool(spec.getattribute("oiio:UnassociatedAlpha") or 0), note)
        radiance.as_read(self.header, self.rad)

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.spec.height, self.spec.width, len(self.idx)

    def read(self, y0: int, y1: int) -> np.ndarray:
        s = self.spec
        if s.tile_width > 0:                 # tiled: whole tile rows, then the rows wanted
            th = s.tile_height
            a = (y0 // th) * th
            b = min(s.height, -(-y1 // th) * th)
            xe = s.x + -(-s.width // s.tile_width) * s.tile_width


            def part(cb, ce):
                return self.inp.read_tiles(0, 0, s.x, min(xe, s.x + s.width), s.y + a, s.y + b,
                                           s.z, s.z + max(s.depth, 1), cb, ce, oiio.FLOAT)
            data = self._channels(part, b - a, y0, y1)
            return self._radiance(np.ascontiguousarray(data[y0 - a:y1 - a]))
        return self._radiance(self._channels(lambda cb, ce: self.inp.read_scanlines(
            0, 0, s.y + y0, s.y + y1, 0, cb, ce, oiio.FLOAT), y1 - y0, y0, y1))

    def _radiance(self, rows: np.ndarray) -> np.ndarray:
        return rows if self.rad is None else radiance.divided(rows, self.rad)

    def _drop_copy(self) -> None:
        if getattr(self, "_src", self.path) != self.path:
            safeio.remove(self._src)
            self._src = self.path

    def _channels(self, read, rows: int, y0: int, y1: int) -> np.ndarray:
        """The selected channels of ``rows`` rows, read as runs of adjacent channels
        (``read(cb, ce)``): a file's other channels (a thousand AOVs) are never read
        into memory."""
        s = self.spec
        out = np.empty((rows, s.width, len(self.idx)), np.float32)
        for cb, ce in channel_runs(self.idx):
            data = read(cb, ce)
            if data is None:
                raise FrameError(self.path, self.frame, f"cannot read rows {y0}-{y1}: "
                                 f"{oiio_error(self.inp.geterror())}")
            data = np.asarray(data, np.float32).reshape(rows, s.width, ce - cb)
            for k, c in enumerate(self.idx):
                if cb <= c < ce:
                    out[..., k] = data[..., c - cb]
        return out

    def close(self) -> None:
        if self.inp is not None:
            self.inp.close()
            self.inp = None
        self._drop_copy()
