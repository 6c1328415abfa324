"""What one run decides once: colour, display, calibration, and the notices given."""

from __future__ import annotations

import logging

from ..colour.calibration import ASSUMED_HELP, CalibrationRequest, Calibrator
from ..colour import (ColourPipeline, InputColour, is_builtin_source, load_config,
                      resolve_config_source, resolve_input)
from ..colour.config import interop_id
from ..io.imageio import DEFAULT_BITS, FrameError
from ..models.display import display_for
from ..pipeline.state import AUTO_SCALE_KEY
from .options import JobOptions, output_is_linear

log = logging.getLogger("ocl_tonemap")

class RunSetup:
    """What one run decides once: colour, display, calibration, and the notices
    already given (an assumption is reported once per run, not per frame)."""

    def __init__(self, opts: JobOptions, tm_state_extra: dict | None = None):
        self.opts = opts
        self.config_source = resolve_config_source(opts.colorconfig)
        self.cfg = load_config(opts.colorconfig)
        self.colour = _colour(self.cfg, opts)
        # --display-encode: the baked device table or OCIO's CPU processor (encode_pixels)
        log.info("%s", self.colour.set_display_encode(opts.display_encode, opts.backend,
                                                      opts.device))
        self.disp = display_for(self.colour.display, opts.display_white, opts.display_peak,
                                opts.display_model, opts.display_black)
        self.request = CalibrationRequest.parse(opts.luminance_scale)
        self.calibrator = Calibrator(self.request, (tm_state_extra or {}).get(AUTO_SCALE_KEY))
        self._said: set = set()
        #: Where the frame's field of view came from, where it is its own (``--stills``).
        self.fov_note = ""

    def once(self, level: int, msg: str, *args) -> None:
        key = (level, msg % args if args else msg)
        if key not in self._said:
            self._said.add(key)
            log.log(level, msg, *args)

    def input_colour(self, fr, path) -> InputColour:
        chrom = fr.chromaticities if (fr.format_name == "openexr"
                                      or fr.radiance is not None) else None
        ic = resolve_input(self.cfg, path, fr.colorspace, self.opts.iscolorspace, chrom,
                           chromaticities_from=fr.radiance.chromaticities_source
                           if fr.radiance is not None else "EXR chromaticities",
                           rules_from_user_config=not is_builtin_source(self.config_source))
        self.once(logging.WARNING if ic.assumed else logging.INFO,
                  "input colour: %s (%s)", ic.colorspace, ic.why)
        return ic

    def calibrate(self, fr, pix_fn) -> tuple[float, str]:
        cal = self.calibrator.frame(fr.spec, fr.format_name, pix_fn, fr.radiance)
        if cal.assumed:
            self.once(logging.WARNING, "calibration: 1.0 = %.6g cd/m^2 (%s); %s",
                      cal.scale, cal.source, ASSUMED_HELP)
        else:
            self.once(logging.INFO, "calibration: 1.0 = %.6g cd/m^2 (%s)", cal.scale, cal.source)
        return cal.scale * 2.0 ** self.opts.exposure, cal.source

    def premultiplied(self, fr) -> bool:
        """Whether the frame's colour is premultiplied (to be divided by alpha)."""
        if self.opts.unpremult is not None:
            return bool(self.opts.unpremult)
        return not fr.unassociated_alpha


def _colour(cfg, opts: JobOptions) -> ColourPipeline:
    colour = ColourPipeline(cfg, opts.display, opts.view)
    if not colour.view_is_plain:
        log.warning("view %r may apply its own tone curve on top of the operator's; the "
                    "un-tone-mapped view is the one meant for display-linear output", colour.view)
    return colour


#: Formats whose only colour tag OIIO writes is sRGB's.
SRGB_TAG_ONLY = (".tif", ".tiff", ".jpg", ".jpeg", ".dpx")


def check_output_tag(colour, opts: JobOptions, jobs) -> None:
    """Display code values other than sRGB's in a format that can tag nothing else
    (TIFF, JPEG and DPX through OIIO): say where the truth is (the output's
    ImageDescription record), once."""
    from pathlib import Path
    if not jobs or output_is_linear(opts, jobs[0][2]):
        return
    out = jobs[0][2]
    if Path(out).suffix.lower() not in SRGB_TAG_ONLY:
        return
    tag = interop_id(colour.cfg, colour.output_colorspace) or colour.output_colorspace
    if tag != "srgb_rec709_display":
        log.warning("%s: %s carries no colour tag but sRGB's; its %s code values are "
                    "named in its ImageDescription (ocltm:output_interop_id) only: use PNG "
                    "(cICP) or EXR for a tag other tools read", out,
                    Path(out).suffix[1:].upper(), tag)


def check_output_depth(opts: JobOptions, disp, jobs) -> None:
    """An HDR (PQ/HLG) encoding in 8 bits bands visibly: say so."""
    from pathlib import Path
    if not jobs:
        return
    out = jobs[0][2]
    ext = Path(out).suffix.lower()
    if opts.out_bits in ("8", "16") and ext in (".exr", ".sxr", ".mxr", ".hdr"):
        raise FrameError(out, None, f"--out-bits {opts.out_bits}: {ext[1:].upper()} stores "
                         "floating point only (half or float for EXR, float for .hdr); use "
                         "PNG or TIFF for integer code values")
    if not disp.hdr:
        return
    bits = opts.out_bits or DEFAULT_BITS.get(Path(out).suffix.lower(), "float")
    if bits == "8" and not output_is_linear(opts, out):
        log.warning("%s: an HDR display encoding (%s) in 8 bits bands in smooth gradients; "
                    "use --out-bits 16 (PNG, TIFF) or EXR", out, disp.name)
