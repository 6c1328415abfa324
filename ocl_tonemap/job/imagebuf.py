"""The ImageBuf API (``ocl_tonemap.process_imagebuf(tm, buf)``): an OIIO ImageBuf in,
one out, through the same front door, per-frame step and output tags as the command
line. Above the observer (``pipeline``): it reads and tags as the job does."""

from __future__ import annotations

import weakref
from typing import TYPE_CHECKING

import numpy as np

from ..io.imageio import frame_from_imagebuf
from .frame import frame_input, map_frame, render_output
from .options import JobOptions
from .setup import RunSetup

if TYPE_CHECKING:                                  # annotations only
    from ..pipeline import Tonemapper


#: Each observer's run setup of its last settings (the config, the input's calibration):
#: made once, not per frame; gone with the observer.
_FRONT_DOORS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def process_imagebuf(tm: Tonemapper, buf, dt: float | None = None, time_s: float | None = None,
                     luminance_scale=None, colorconfig: str | None = None,
                     iscolorspace: str | None = None, encode: bool = False,
                     unpremult: bool | None = None, frame_number: int | None = None,
                     channels: list[str] | None = None):
    """ImageBuf in, ImageBuf out, for the observer ``tm``.

    The input's colourspace (``oiio:ColorSpace``, EXR ``chromaticities``, else
    scene-linear Rec.709; ``iscolorspace`` overrides), its calibration
    (``luminance_scale`` S or ``"auto:LEVEL"`` > ``whiteLuminance`` > EXIF
    exposure > ...; see ``colour/calibration.py``) and its alpha
    (``oiio:UnassociatedAlpha``; ``unpremult`` overrides) are read as the CLI
    reads them, with the OCIO config ``colorconfig`` (> $OCIO > ocio://default).
    The result is float display-linear light in the display's linear
    colourspace (``encode``: display code values), tagged and carrying the same
    ``ocltm:*`` attributes as the CLI's outputs.
    """
    import OpenImageIO as oiio
    fr = frame_from_imagebuf(buf, "<ImageBuf>", frame_number, channels)
    key = (colorconfig, iscolorspace, luminance_scale, unpremult)
    front_door = _FRONT_DOORS.get(tm)
    if front_door is None or front_door[0] != key:
        opts = JobOptions("<ImageBuf>", "<ImageBuf>", operator=tm.operator_name,
                          luminance_scale=luminance_scale, colorconfig=colorconfig,
                          iscolorspace=iscolorspace, display=tm.display.name
                          if tm.display.name and not tm.display.paper_crt else None,
                          unpremult=unpremult, encode=encode, checkpoint=False)
        try:
            run = RunSetup(opts, tm.scalar_state().extra)
        except Exception:  # noqa: BLE001 -- a display name the config lacks
            opts.display = None
            run = RunSetup(opts, tm.scalar_state().extra)
        _FRONT_DOORS[tm] = front_door = (key, run)
    run = front_door[1]
    fin = frame_input(run, tm, fr, "<ImageBuf>")
    res = map_frame(tm, fin, time_s, frame_number, dt=dt)
    r = render_output(run, tm, fr, fin, res, None, linear=not encode)
    spec = fr.spec
    nch = r.pixels.shape[2]
    ospec = oiio.ImageSpec(spec)
    ospec.nchannels = nch
    ospec.channelnames = ("R", "G", "B", "A")[:nch]
    ospec.alpha_channel = 3 if nch == 4 else -1
    ospec.set_format(oiio.FLOAT)
    for k in ("whiteLuminance", "chromaticities", "oiio:UnassociatedAlpha", "adoptedNeutral"):
        ospec.erase_attribute(k)
    ospec.attribute("oiio:ColorSpace", r.colorspace)
    ospec.attribute("chromaticities", oiio.TypeDesc("float[8]"), tuple(r.chromaticities))
    if r.white_luminance is not None:
        ospec.attribute("whiteLuminance", float(r.white_luminance))
    if nch == 4 and r.straight_alpha:
        ospec.attribute("oiio:UnassociatedAlpha", 1)
    for k, v in r.metadata.items():
        ospec.attribute(k, v)
    res_buf = oiio.ImageBuf(ospec)
    res_buf.set_pixels(oiio.ROI(spec.x, spec.x + spec.width, spec.y, spec.y + spec.height,
                                spec.z, spec.z + max(spec.depth, 1), 0, nch),
                       np.ascontiguousarray(r.pixels, np.float32))
    return res_buf
