"""The field of view a run takes from its Radiance pictures' VIEW lines (``--fov``
not given): the first picture's for a shot, each picture's own with ``--stills``."""

from __future__ import annotations

import dataclasses
import logging
import os
from typing import TYPE_CHECKING

from .. import radiance
from ..effects import DEFAULT_FOV
from .options import JobOptions
from .sequence import frame_jobs

if TYPE_CHECKING:
    from ..pipeline import Tonemapper

log = logging.getLogger("ocl_tonemap")


def view_from_header(opts: JobOptions) -> JobOptions:
    """The field of view from the first input's Radiance VIEW when ``--fov`` was not
    given (``radiance.fov_for``); said once, and in every output's ``ocltm:fov``."""
    if opts.fov_given or opts.effects is None or \
            os.path.splitext(opts.input)[1].lower() not in radiance.SUFFIXES:
        return opts                      # (no frame listing for inputs of other kinds)
    try:
        first = frame_jobs(opts)[0][1]
    except Exception:                    # noqa: BLE001 -- the run itself says what is wrong
        return opts
    if not radiance.is_radiance(first):
        return opts
    try:
        view = radiance.read_header(first).view
    except (radiance.HeaderError, OSError):
        return opts                      # (the frame's read says it, naming the file)
    if view is None:
        return opts
    fov, what = radiance.fov_for(view)
    if fov is None:
        log.warning("%s: %s: the field of view stays --fov %g", first, what,
                    opts.effects.fov_deg)
        return opts
    log.info("field of view %.4g degrees from the Radiance VIEW (%s)", fov, what)
    return dataclasses.replace(opts, effects=opts.effects.replace(fov_deg=fov),
                               fov_given=True, fov_source=f"Radiance VIEW: {what}")


def still_view(tm: Tonemapper, run, inp: str, fr=None) -> None:
    """``--stills`` with the field of view from the Radiance VIEW: each picture its own
    (``view_from_header`` read the first's), a picture without one the default; said in
    its ``ocltm:fov`` (``run.fov_note``)."""
    opts = run.opts                      # (with the first picture's VIEW: setup_run)
    if not (opts.stills and opts.fov_source.startswith("Radiance VIEW")):
        return
    view = None
    if fr is not None and fr.radiance is not None:
        view = fr.radiance.view
    elif radiance.is_radiance(inp):
        try:
            view = radiance.read_header(inp).view
        except (radiance.HeaderError, OSError):
            view = None                  # (the frame's read says it, naming the file)
    fov, what = radiance.fov_for(view) if view is not None else (None, "no VIEW")
    tm.set_field_of_view(fov if fov is not None else DEFAULT_FOV)
    run.fov_note = f"Radiance VIEW: {what}" if fov is not None else f"default ({what})"
