"""Radiance pictures read as Radiance's own tools read them: the text header.

OIIO reads a Radiance picture's pixels and one EXPOSURE value (``hdr:exposure``); the
rest of the header is read here, bounded (at most :data:`HEADER_CAP` bytes, text
lines up to the blank line that ends it; Radiance's ``getinfo`` shows the same):

* ``EXPOSURE=`` lines: the picture's values are the scene's times their product
  (``pfilt -e 2`` writes one, each filter after another); Radiance's tools divide by
  it, so do we, before any calibration. ``COLORCORR= r g b`` likewise per channel.
* a Radiance renderer's command line (``rpict``, ``rtrace``, ``rvu``, ``rcontrib``)
  makes the picture absolute: 179 cd/m^2 per unit (Radiance's white efficacy), no
  warning. Photographs (``hdrgen``) or pictures of unknown origin keep the warning.
* ``VIEW=`` (and a renderer's own ``-v`` options): the view type and angles give the
  field of view the spatial effects need (:func:`fov_for`).
* ``PRIMARIES=`` (rx ry gx gy bx by wx wy): the RGB's chromaticities, converted to the
  working space as EXR ``chromaticities`` are; a renderer's picture without the line
  has Radiance's standard primaries (:data:`STANDARD_PRIMARIES`, white E).
* ``FORMAT=32-bit_rle_xyze``: CIE XYZ instead of RGB, the same RLE: read by OIIO
  from a copy whose FORMAT line says rgbe (:func:`rgbe_copy`), its chromaticities
  those of XYZ (white E).
"""

from __future__ import annotations

import logging
import math
import os
import shutil
import tempfile
from dataclasses import dataclass, field

import numpy as np

from ..base.safeio import regular_file

log = logging.getLogger("ocl_tonemap")

#: Largest header read (bytes): Radiance headers are a few hundred bytes to a few KiB.
HEADER_CAP = 1 << 16
#: Radiance's standard primaries (ray/src/common/color.h STDPRIMS): rx ry gx gy bx by wx wy.
STANDARD_PRIMARIES = (0.640, 0.330, 0.290, 0.600, 0.150, 0.060, 1.0 / 3.0, 1.0 / 3.0)
#: The chromaticities of CIE XYZ as RGB (an XYZE picture), white E.
XYZ_PRIMARIES = (1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0 / 3.0, 1.0 / 3.0)
#: File name endings of Radiance pictures (whose VIEW a run looks for before its first
#: frame; any file is read as one by its "#?" first line).
SUFFIXES = (".hdr", ".pic", ".rgbe", ".xyze", ".unf")
#: Programs whose pictures are renderings in Radiance's absolute units.
RENDERERS = ("rpict", "rtrace", "rvu", "rcontrib")
#: Programs whose pictures are photographs.
PHOTOGRAPHIC = ("hdrgen",)
#: View types (``-vt?``) and what they are.
VIEW_TYPES = {"v": "perspective", "l": "parallel", "c": "cylindrical panorama",
              "h": "hemispherical fisheye", "a": "angular fisheye", "s": "planisphere "
              "(stereographic) fisheye"}


@dataclass
class View:
    """A Radiance view: type letter and horizontal/vertical angles (degrees)."""

    type: str = "v"
    vh: float = 45.0
    vv: float = 45.0


@dataclass
class RadianceHeader:
    """What a Radiance picture's header says (module doc)."""

    exposure: float = 1.0
    colorcorr: tuple = (1.0, 1.0, 1.0)
    primaries: tuple | None = None
    view: View | None = None
    xyze: bool = False
    renderer: str | None = None
    photographic: bool = False
    lines: list = field(default_factory=list)
    #: header lines whose value is not used, each with why (:func:`warn_ignored`)
    ignored: list = field(default_factory=list)

    @property
    def chromaticities(self) -> tuple | None:
        """The RGB's chromaticities: XYZ's for XYZE, the PRIMARIES line's, Radiance's
        standard ones for a renderer's picture, else None (as OIIO says: Rec.709)."""
        if self.xyze:
            return XYZ_PRIMARIES
        if self.primaries is not None:
            return self.primaries
        return STANDARD_PRIMARIES if self.renderer else None

    @property
    def chromaticities_source(self) -> str:
        if self.xyze:
            return "Radiance XYZE (CIE XYZ, white E)"
        if self.primaries is not None:
            return "Radiance PRIMARIES"
        return "Radiance standard primaries (a rendering without PRIMARIES)"

    @property
    def absolute(self) -> bool:
        return self.renderer is not None and not self.photographic


class HeaderError(ValueError):
    pass


def is_radiance(path: str) -> bool:
    if not os.path.isfile(path):       # a FIFO is never opened (its reader refuses it)
        return False
    try:
        with open(path, "rb") as fh:
            return fh.read(2) == b"#?"
    except OSError:
        return False


def read_header(path: str) -> RadianceHeader:
    """The header of the Radiance picture at ``path`` (:class:`HeaderError` when it is
    not one or its header does not end within :data:`HEADER_CAP` bytes)."""
    regular_file(path, "a Radiance picture")
    with open(path, "rb") as fh:
        data = fh.read(HEADER_CAP)
    if not data.startswith(b"#?"):
        raise HeaderError("not a Radiance picture (no #? first line)")
    end = data.find(b"\n\n")
    if end < 0:
        raise HeaderError(f"its header does not end within {HEADER_CAP} bytes")
    text = data[:end].decode("latin-1")
    h = parse_header(text.split("\n")[1:])
    warn_ignored(path, h)
    return h


#: The ignored header lines already said (a sequence's frames, or a picture read twice:
#: its view, then its pixels, say them once).
_SAID: set = set()


def warn_ignored(path: str, h: RadianceHeader) -> None:
    """One warning line for the header values of ``path`` that are not used (a
    non-positive or non-finite EXPOSURE, a COLORCORR that is not three positive
    numbers, a PRIMARIES line that is not eight chromaticities); said once per run for
    the same lines."""
    if not h.ignored:
        return
    key = tuple(h.ignored)
    if key in _SAID:
        return
    _SAID.add(key)
    log.warning("%s: Radiance header value%s ignored: %s", path,
                "s" if len(h.ignored) > 1 else "", "; ".join(h.ignored))


def parse_header(lines) -> RadianceHeader:
    h = RadianceHeader(lines=list(lines))
    for raw in lines:
        line = raw.strip()
        if not line:
            continue
        key, eq, value = line.partition("=")
        key = key.strip().upper()
        if eq and key == "EXPOSURE":
            v = _number(value)
            if v is not None and 0 < v < math.inf:
                h.exposure *= v
            else:
                h.ignored.append(f"{_shown(line)} (EXPOSURE must be a positive number)")
        elif eq and key == "COLORCORR":
            v = [_number(x) for x in value.split()]
            if len(v) == 3 and all(x is not None and 0 < x < math.inf for x in v):
                h.colorcorr = tuple(a * b for a, b in zip(h.colorcorr, v))
            else:
                h.ignored.append(f"{_shown(line)} (COLORCORR must be three positive numbers)")
        elif eq and key == "PRIMARIES":
            v = [_number(x) for x in value.split()]
            # (Photoshop writes PRIMARIES=0 0 0 0 0 0 0 0: a placeholder, not primaries;
            # ignored without a word, as the picture is then OIIO's Rec.709)
            if len(v) == 8 and all(x == 0 for x in v):
                continue
            why = _primaries_why(v)
            if why:
                h.ignored.append(f"{_shown(line)} (PRIMARIES must be {why})")
            else:
                h.primaries = tuple(v)
        elif eq and key == "FORMAT":
            h.xyze = "xyze" in value.lower()
        elif eq and key == "VIEW":
            h.view = parse_view(value.split(), h.view)
        elif not eq or " " in key:                    # a command line
            words = line.split()
            prog = os.path.basename(words[0]) if words else ""
            if prog in RENDERERS:
                h.renderer = prog
                if any(w.startswith("-v") for w in words[1:]):
                    h.view = parse_view(words[1:], h.view)
            elif prog in PHOTOGRAPHIC:
                h.photographic = True
    return h


def _shown(line: str) -> str:
    """A header line as a warning shows it (bounded, printable)."""
    text = "".join(c if c.isprintable() else "?" for c in line)
    return text if len(text) <= 80 else text[:77] + "..."


def _primaries_why(v) -> str:
    """Why PRIMARIES numbers ``v`` are no chromaticities (empty when they are): eight
    finite numbers, rx ry gx gy bx by wx wy, each y > 0, each within -1..2 (wide gamuts
    such as ACES AP0 reach beyond the spectrum locus), the three primaries a
    triangle."""
    want = "eight numbers rx ry gx gy bx by wx wy, each y > 0, the primaries a triangle"
    if len(v) != 8 or any(x is None for x in v) or any(not -1.0 <= x <= 2.0 for x in v) \
            or not all(y > 0 for y in v[1::2]):
        return want
    (rx, ry, gx, gy, bx, by) = v[:6]
    if abs((gx - rx) * (by - ry) - (bx - rx) * (gy - ry)) < 1e-6:
        return want
    return ""


def _number(text: str) -> float | None:
    try:
        v = float(text)
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def parse_view(words, base: View | None = None) -> View:
    """The view options among ``words`` (``-vt?``, ``-vh``, ``-vv``), over ``base``."""
    v = View(**vars(base)) if base is not None else View()
    i = 0
    while i < len(words):
        w = words[i]
        if w.startswith("-vt") and len(w) == 4 and w[3] in VIEW_TYPES:
            v.type = w[3]
        elif w in ("-vh", "-vv") and i + 1 < len(words):
            x = _number(words[i + 1])
            if x is not None and x > 0:
                setattr(v, w[1:], x)
            i += 1
        i += 1
    return v


def fov_for(view: View) -> tuple[float | None, str]:
    """(horizontal field of view in degrees that gives the view's degrees per pixel at
    the image centre over the image's width, or None; what it is). The spatial effects
    take the image as ``fov / width`` degrees per pixel: exact for the angular fisheye
    and the cylindrical panorama (equal angles per pixel), right at the centre and
    approximate off it for the others (docs/models.md)."""
    t, vh = view.type, view.vh
    name = VIEW_TYPES.get(t, t)
    if t == "l":
        return None, "parallel view (no angle)"
    if t in ("a", "c"):                         # equal angles per pixel
        return vh, f"{name} -vh {vh:g}"
    if t == "v":                                # image width 2 tan(vh/2), unit focal length
        return 2.0 * math.degrees(math.tan(math.radians(min(vh, 179.0)) / 2.0)), \
            f"{name} -vh {vh:g}, at the centre"
    if t == "h":                                # image width 2 sin(vh/2)
        return 2.0 * math.degrees(math.sin(math.radians(min(vh, 180.0)) / 2.0)), \
            f"{name} -vh {vh:g}, at the centre"
    if t == "s":                                # r = 2 tan(theta/2): width 4 tan(vh/4)
        return 4.0 * math.degrees(math.tan(math.radians(min(vh, 359.0)) / 4.0)), \
            f"{name} -vh {vh:g}, at the centre"
    return None, f"view type {t!r}"


def rgbe_copy(path: str) -> str:
    """A temporary copy of an XYZE picture whose FORMAT line says rgbe (the pixels'
    encoding is the same), for OIIO to read; the caller removes it."""
    with open(path, "rb") as fh:
        head = fh.read(HEADER_CAP)
    end = head.find(b"\n\n")
    fixed = head[:end].replace(b"32-bit_rle_xyze", b"32-bit_rle_rgbe")
    fd, tmp = tempfile.mkstemp(suffix=".hdr", prefix="ocltm_xyze_")
    try:
        with os.fdopen(fd, "wb") as out, open(path, "rb") as src:
            src.seek(end)
            out.write(fixed)
            shutil.copyfileobj(src, out, 1 << 20)
    except BaseException:
        os.unlink(tmp)
        raise
    return tmp


def tools() -> tuple[str, dict] | None:
    """(bin folder, environment) of Radiance's programs from the ``pyradiance`` wheel
    (``pip install "ocl-tonemap[radiance]"``): ``PATH`` with that folder first and
    ``RAYPATH`` at its library; None where it is not installed."""
    try:
        import importlib.util
        spec = importlib.util.find_spec("pyradiance")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    root = list(spec.submodule_search_locations)[0]
    b, lib = os.path.join(root, "bin"), os.path.join(root, "lib")
    if not os.path.isfile(os.path.join(b, "pcond")):
        return None
    env = {**os.environ, "PATH": b + os.pathsep + os.environ.get("PATH", ""), "RAYPATH": lib}
    return b, env


def as_read(fr, rad):
    """A Radiance picture's frame (``imageio.Frame``) as Radiance's tools read it: divided by its EXPOSURE
    and COLORCORR, its chromaticities from PRIMARIES (or XYZ, or Radiance's standard
    primaries for a rendering) in place of OIIO's Rec.709 tag."""
    if rad is None:
        return fr
    fr.radiance = rad
    if fr.pixels.size:
        fr.pixels = divided(fr.pixels, rad)
    chrom = rad.chromaticities
    if chrom is not None:
        fr.chromaticities, fr.colorspace = tuple(float(v) for v in chrom), None
    return fr


def divided(pixels: np.ndarray, rad) -> np.ndarray:
    """RGB (+alpha) of a Radiance picture divided by its EXPOSURE and COLORCORR."""
    div = np.asarray(rad.colorcorr, np.float64) * rad.exposure
    if np.all(div == 1.0):
        return pixels
    out = np.array(pixels, np.float32, copy=True)
    out[..., :3] = (out[..., :3] / div).astype(np.float32)
    return out
