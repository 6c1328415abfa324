"""The field of view a run takes from what its inputs state about their projection
(``--fov`` not given): a Radiance picture's VIEW line (``radiance.fov_for``), an
equirectangular (latlong) image's metadata (:func:`stated_projection`: OpenEXR's
``envmap``, which OIIO reads as ``textureformat``, maketx's TIFF tag, XMP GPano); the
first picture's for a shot, each picture's own with ``--stills``. A 2:1 image that
states none is taken as the default 50-degree view, with one note per run that names
``--fov 360`` (:data:`PANORAMA_NOTE`; docs/models.md, "Panoramas and projections")."""

from __future__ import annotations

import dataclasses
import logging
from typing import TYPE_CHECKING

import OpenImageIO as oiio

from ..io import radiance
from ..effects import DEFAULT_FOV
from ..io.imageio import FrameError, check_readable
from ..io.patterns import find_frames, frame_path, is_sequence
from .options import JobOptions

if TYPE_CHECKING:
    from ..pipeline import Tonemapper

log = logging.getLogger("ocl_tonemap")
#: The level of a note (``cli/table.py`` names it NOTE): what the user should know.
NOTE = 25
#: OIIO's ``textureformat`` of a latitude-longitude environment map (OpenEXR's ``envmap``
#: attribute ENVMAP_LATLONG reads as this; maketx writes it to TIFF), and of a cube map.
LATLONG = "LatLong Environment"
CUBE = "CubeFace Environment"
#: The one note of a run whose 2:1 input states no projection (``input``: the run's).
PANORAMA_NOTE = ("%s: a 2:1 image with no projection in its metadata is taken as a "
                 f"{DEFAULT_FOV:g}-degree view; if it is an equirectangular panorama "
                 "(360 x 180 degrees), give --fov 360 for its glare and acuity at their "
                 "true angle")


def stated_projection(spec) -> tuple[float | None, str] | None:
    """(field of view over the image's width in degrees, or None where the projection
    has no one width; what it is) that an image's metadata states (``spec``: its
    ``oiio.ImageSpec``), None where it states none. Equirectangular: 360 degrees over
    the full width (a data window narrower than its display window: its share of 360);
    GPano's cropped panoramas: 360 x CroppedAreaImageWidthPixels / FullPanoWidthPixels."""
    tf = spec.get_string_attribute("textureformat")
    if tf == LATLONG:
        full = spec.full_width if spec.full_width >= spec.width > 0 else spec.width
        return 360.0 * spec.width / max(full, 1), "equirectangular: latlong environment map"
    if tf == CUBE:
        return None, "cube-face environment map (six 90-degree faces)"
    proj = spec.get_string_attribute("GPano:ProjectionType")
    if not proj:
        return None
    if proj.strip().lower() != "equirectangular":
        return None, f"GPano projection {proj[:40]!r}"
    full = spec.get_int_attribute("GPano:FullPanoWidthPixels", 0)
    crop = spec.get_int_attribute("GPano:CroppedAreaImageWidthPixels", 0)
    if 0 < crop < full:
        return 360.0 * crop / full, f"equirectangular: GPano, {crop} of {full} px across"
    return 360.0, "equirectangular: GPano"


def _header(path: str):
    """The ImageSpec of the image at ``path`` (its header only), or None where it cannot
    be opened (the frame's read says why, naming the file)."""
    try:
        check_readable(path)             # (a FIFO is never opened)
    except FrameError:
        return None
    inp = oiio.ImageInput.open(path)
    if inp is None:
        oiio.geterror()                  # (said by the frame's read)
        return None
    try:
        return oiio.ImageSpec(inp.spec())
    finally:
        inp.close()


def stated(path: str, fr=None) -> tuple[float | None, str | None, tuple | None]:
    """(field of view or None, where it comes from or None where nothing is stated,
    (width, height) or None) of the picture at ``path`` (``fr``: its frame, where read):
    its Radiance VIEW, else its metadata's projection (:func:`stated_projection`)."""
    view = None
    if fr is not None and fr.radiance is not None:
        view = fr.radiance.view
    elif fr is None and radiance.is_radiance(path):
        try:
            view = radiance.read_header(path).view
        except (radiance.HeaderError, OSError):
            return None, None, None      # (the frame's read says it, naming the file)
    if view is not None:
        fov, what = radiance.fov_for(view)
        return fov, f"Radiance VIEW: {what}", None
    spec = fr.spec if fr is not None else _header(path)
    if spec is None:
        return None, None, None
    got = stated_projection(spec)
    if got is not None:
        return got[0], got[1], (spec.width, spec.height)
    return None, None, (spec.width, spec.height)


def _first_input(opts: JobOptions) -> str | None:
    """The run's first input on disk (the first of ``--frames`` there, of a sequence)."""
    if not is_sequence(opts.input):
        return opts.input
    present = set(find_frames(opts.input))
    order = opts.frames if opts.frames is not None else sorted(present)
    first = next((f for f in order if f in present), None)
    return None if first is None else frame_path(opts.input, first)


def _uses_fov(opts: JobOptions) -> bool:
    """Whether anything of the run takes the field of view: the flare, acuity, or the
    visibility planes."""
    fx = opts.effects
    return getattr(fx, "flare", "off") != "off" or getattr(fx, "acuity", "off") != "off" \
        or bool(opts.visibility or opts.visibility_view or opts.target)


def _panorama(size) -> bool:
    return size is not None and size[1] > 0 and size[0] == 2 * size[1]


#: The inputs whose :data:`PANORAMA_NOTE` was said (a shot's passes set a run up more
#: than once in one process: said once).
_NOTED: set = set()


def _note_panorama(opts: JobOptions) -> None:
    if opts.input not in _NOTED and _uses_fov(opts):
        _NOTED.add(opts.input)
        log.log(NOTE, PANORAMA_NOTE, opts.input)


def view_from_header(opts: JobOptions) -> JobOptions:
    """The field of view the first input states (:func:`stated`: a Radiance VIEW, an
    equirectangular projection in its metadata) when ``--fov`` was not given; said once,
    and in every output's ``ocltm:fov``. A 2:1 first input that states none: the
    default, with :data:`PANORAMA_NOTE` (``--stills``: :func:`still_view` says it)."""
    if opts.fov_given or opts.effects is None:
        return opts
    try:
        first = _first_input(opts)
    except Exception:                    # noqa: BLE001 -- the run itself says what is wrong
        return opts
    if first is None:
        return opts
    fov, what, size = stated(first)
    if what is None:
        if _panorama(size) and not opts.stills:
            _note_panorama(opts)
        return opts
    if fov is None:
        log.warning("%s: %s: the field of view stays --fov %g", first,
                    what.removeprefix("Radiance VIEW: "), opts.effects.fov_deg)
        return opts
    log.info("field of view %.4g degrees from the %s", fov, what)
    return dataclasses.replace(opts, effects=opts.effects.replace(fov_deg=fov),
                               fov_given=True, fov_source=what)


def still_view(tm: Tonemapper, run, inp: str, fr=None) -> None:
    """``--stills`` without ``--fov``: each picture's own field of view (:func:`stated`;
    ``view_from_header`` read the first's), a picture that states none the default (a
    2:1 one with :data:`PANORAMA_NOTE`, once a run); said in its ``ocltm:fov``
    (``run.fov_note``)."""
    opts = run.opts                      # (with the first picture's view: setup_run)
    if not opts.stills or opts.effects is None or (opts.fov_given and not opts.fov_source):
        return
    fov, what, size = stated(inp, fr)
    if what is None and _panorama(size):
        _note_panorama(opts)
    # the default: 50, or the API's own where the first picture stated nothing
    tm.set_field_of_view(fov if fov is not None else
                         DEFAULT_FOV if opts.fov_given else opts.effects.fov_deg)
    if fov is not None:
        run.fov_note = what
    elif what is not None or opts.fov_given:
        none = "no VIEW" if radiance.is_radiance(inp) else "no projection stated"
        run.fov_note = f"default ({(what or none).removeprefix('Radiance VIEW: ')})"
    else:
        run.fov_note = ""                # (ocltm:fov: "default", as the run's)
