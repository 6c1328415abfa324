"""One frame, the same for every entry (run, simulate, the shot's measure and apply
passes, the ImageBuf API): its input in the working space and calibrated
(:func:`frame_input`), mapped (:func:`map_frame`), and made ready to write
(:func:`output_metadata`, :func:`encode_pixels`, :func:`render_output`)."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..pipeline.alpha import restore_alpha, straight_colour
from ..colour.config import interop_id
from ..io.imageio import illuminant_from_metadata
from ..models.lmsr import spectral_to_rgb
from ..pipeline.state import AUTO_SCALE_KEY
from ..version import __version__
from .setup import RunSetup

if TYPE_CHECKING:                                  # annotations only
    from ..pipeline import Tonemapper

log = logging.getLogger("ocl_tonemap")


def remember_auto(tm: Tonemapper, run: RunSetup) -> None:
    """Keep the run's ``auto`` calibration constant in the state (resume uses it)."""
    if run.calibrator.auto_scale is not None:
        tm.remember(AUTO_SCALE_KEY, float(run.calibrator.auto_scale))


def _frame_input(run: RunSetup, tm: Tonemapper, fr, path):
    """(pixels, wavelengths or None, description of the input colour) for one frame:
    the spectrum for an operator that takes spectra, else working-space RGB (from
    the spectrum through the CIE 1931 observer when the file has no RGB)."""
    if fr.wavelengths is not None and "spectral" in tm.op.inputs:
        lam = fr.wavelengths
        return fr.spectral, lam, (f"spectral, {len(lam)} channels {lam[0]:g}-{lam[-1]:g} nm "
                                  "(radiance, W sr^-1 m^-2 nm^-1)")
    if fr.rgb_from_spectrum:
        return fr.pixels, None, f"{run.colour.working} (from the spectrum, CIE 1931 2-degree)"
    ic = run.input_colour(fr, path)
    return run.colour.convert_input(fr.pixels, ic), None, ic.describe()


@dataclass
class FrameInput:
    """One frame at the front door: what the operator is given, and what the output's
    metadata says about it."""

    pixels: np.ndarray            # working-space RGB (or the spectrum), float32 (a half
                                  # file's RGB in the working space: float16 as stored)
    wavelengths: np.ndarray | None
    colour_text: str              # the input colour, described
    scale: float                  # cd/m^2 per unit (calibration x 2^exposure)
    scale_source: str             # where the calibration came from
    illuminant: object            # the file's own illuminant (EXR adoptedNeutral) or None
    premultiplied: bool


def frame_input(run: RunSetup, tm: Tonemapper, fr, path) -> FrameInput:
    """The front door for one frame (a :class:`~ocl_tonemap.io.imageio.Frame` read
    from ``path``): its pixels in the working space (or spectrum), the description
    of its colour, and its calibration."""
    if fr.channel_note:
        run.once(logging.WARNING, "%s: %s", path, fr.channel_note)
    pix, lam, cs_text = _frame_input(run, tm, fr, path)

    def working_rgb():
        if lam is None:
            return np.asarray(pix, np.float32)
        return spectral_to_rgb(lam, pix)
    scale, why = run.calibrate(fr, working_rgb)
    remember_auto(tm, run)
    return FrameInput(pix, lam, cs_text, scale, why, illuminant_from_metadata(fr.spec),
                      run.premultiplied(fr))


def map_frame(tm: Tonemapper, fin: FrameInput, time_s: float | None,
              frame_number: int | None = None, encoding=None, measure_only: bool = False,
              dt: float | None = None, weights: dict | None = None):
    """The one per-frame step of every entry: ``fin`` through the observer at
    ``time_s`` (or ``dt`` after the last frame; measure -> integrate -> apply). Returns the
    :class:`~ocl_tonemap.pipeline.FrameResult` (display-linear light, or code values of
    ``encoding`` where the frame allows it), or with ``measure_only`` the frame's
    :class:`~ocl_tonemap.operators.base.FrameStats`, the state untouched."""
    return tm.process_frame(fin.pixels, dt=dt, time_s=time_s, frame_number=frame_number,
                            luminance_scale=fin.scale, illuminant=fin.illuminant,
                            wavelengths=fin.wavelengths, premultiplied=fin.premultiplied,
                            encoding=encoding, measure_only=measure_only, weights=weights)


@dataclass
class Rendered:
    """The last processed frame, ready to write: pixels in the output colourspace
    and what to tag them with (shared by the CLI and ``Tonemapper.process_imagebuf``)."""

    pixels: np.ndarray
    colorspace: str
    metadata: dict
    chromaticities: tuple
    white_luminance: float | None
    straight_alpha: bool


def output_metadata(run: RunSetup, tm: Tonemapper, fr, fin: FrameInput, info,
                    extra: dict | None, linear: bool, alpha: bool, fps: float | None = None):
    """(metadata, output colour tag, chromaticities, whiteLuminance, straight alpha) of a
    mapped frame (``info``: its :class:`~ocl_tonemap.pipeline.FrameInfo`; ``fps``: the
    frame rate its time was taken at, written as ``FramesPerSecond``). The tag is the
    output colourspace's colour interop ID where it has one (what OIIO writes to EXR's
    ``colorInteropID`` and PNG's cICP), else its name in the config."""
    colour, disp = run.colour, tm.display
    t, scale = info.time_s, fin.scale
    out_cs = colour.linear_output()[0] if linear else colour.output_colorspace
    tag = interop_id(colour.cfg, out_cs) or out_cs
    premult = fin.premultiplied
    meta = {
        "Software": f"ocl-tonemap {__version__}",
        "ocltm:operator": tm.operator_name,
        "ocltm:backend": tm.backend.name,
        "ocltm:quality": tm.quality,
        "ocltm:metering": tm.metering.describe() if tm.op.metering != "local"
        else "local (bilateral)",
        "ocltm:input_colorspace": fin.colour_text,
        "ocltm:output_colorspace": out_cs,
        "ocltm:output_interop_id": tag,
        "ocltm:output_encoding": (f"display-linear light, 1.0 = {disp.unit_cd:g} cd/m^2"
                                  if linear else "display-encoded (OCIO display/view)"),
        "ocltm:view": f"{colour.display} / {colour.view}",
        "ocltm:luminance_scale": float(scale),
        "ocltm:luminance_scale_source": fin.scale_source,
        "ocltm:display": json.dumps(disp.as_dict(), sort_keys=True),
        "ocltm:time_s": float(t),
        "ocltm:goal": json.dumps({"G_rod": info.G_rod, "G_cone": info.G_cone}),
        "ocltm:state": json.dumps(info.state.to_json(), sort_keys=True),
        "ocltm:params": json.dumps(info.params, sort_keys=True, default=float),
        "ocltm:repairs": json.dumps(info.repairs.as_dict(), sort_keys=True),
        "ocltm:effects": json.dumps(info.effects, sort_keys=True, default=float),
        "ocltm:effects_ran": ",".join(k for k, v in info.effects.items() if v.get("ran")) or "none",
        "ocltm:media_gain": float(tm.media_gain),
        "ocltm:fov": f"{tm.effects.settings.fov_deg:.6g} degrees ("
                     f"{run.fov_note or run.opts.fov_source or ('--fov' if run.opts.fov_given else 'default')})",
    }
    if info.plan:
        meta["ocltm:plan"] = json.dumps(info.plan["weights"], sort_keys=True)
        meta["ocltm:plan_detail"] = json.dumps(
            {k: v for k, v in info.plan.items() if k not in ("weights", "sig")}, sort_keys=True,
            default=float)
    if fr.channel_note:
        meta["ocltm:channels"] = fr.channel_note
    if alpha:
        meta["ocltm:alpha"] = ("premultiplied: colour divided by alpha for the operator, "
                               "multiplied again" if premult else
                               ("straight (unassociated)" if fr.unassociated_alpha else
                                "tone mapped as stored (--no-unpremult)"))
    if fps:
        meta["FramesPerSecond"] = float(fps)
    meta.update(extra or {})
    return (meta, tag, colour.output_chromaticities(encoded=not linear),
            disp.unit_cd if linear else None, alpha and not premult)


def encode_pixels(colour, disp_lin: np.ndarray, alpha_info, linear: bool,
                  bits: int = 0) -> np.ndarray:
    """Display-linear light (with alpha) to the output's values: the display's linear
    colourspace, or the display encoding (``colour.encode_fast``: the baked device table
    chosen by ``--display-encode``, else OCIO's CPU processor). ``bits`` 8 or 16: the
    output is an 8- or 16-bit file; with the device table the code values come back as
    the values OIIO would write (quantised on the device: a quarter or half of the
    download, no conversion)."""
    rgb = disp_lin[..., :3]
    alpha = disp_lin.shape[2] == 4
    pm = alpha and alpha_info is not None and alpha_info[2]
    if bits and not linear and not pm and colour.device_table is not None:
        return colour.encode_fast(disp_lin, bits=bits)
    encode = colour.encode_fast
    if pm and not linear:
        # a display encoding is not linear: encode the straight colour, then
        # premultiply the code values again (encode(c) a, not encode(c a))
        a = disp_lin[..., 3:4]
        rgb = np.where(a > 0, rgb / np.where(a > 0, a, 1.0), rgb).astype(np.float32)
        return restore_alpha(encode(rgb), alpha_info)
    pixels = colour.linear(rgb) if linear else encode(rgb)
    if alpha:
        pixels = np.concatenate([pixels, disp_lin[..., 3:4]], axis=2)
    return pixels


def export_frame(exporter, run: RunSetup, fr, fin: FrameInput, res, path, frame,
                 linear: bool, bits: int):
    """The frame to the OCIO export (``colour/export.py``), checked against what the run
    writes: its pixels as its file holds them (what a replay reads) and the run's own
    display-encoded output (straight colour where there is alpha: a replay
    unpremultiplies first). Returns the output's pixels as :func:`encode_pixels` makes
    them (written as they are, not encoded twice)."""
    pixels = res.output if res.encoded else \
        encode_pixels(run.colour, res.output, res.alpha, linear, bits)
    work, src, codes = fin.pixels, None if fr.rgb_from_spectrum else fr.pixels, pixels
    if linear or res.output.shape[-1] == 4:        # the display encoding of the colour
        disp = res.output                          # (its alpha divided out again)
        if disp.shape[-1] == 4:
            prem = res.alpha is not None and res.alpha[2]
            disp = straight_colour(disp, prem)[0]
            work = straight_colour(np.asarray(work, np.float32), prem)[0]
            src = None if src is None else straight_colour(np.asarray(src, np.float32), prem)[0]
        codes = run.colour.encode_fast(np.ascontiguousarray(disp[..., :3]))
    exporter.add_frame(frame, np.asarray(work, np.float32), fin.scale, res.info.effects,
                       run.input_colour(fr, path) if src is not None else None, codes, src)
    return pixels


def render_output(run: RunSetup, tm: Tonemapper, fr, fin: FrameInput, res,
                  extra: dict | None, linear: bool) -> Rendered:
    """A mapped frame (``res``: :class:`~ocl_tonemap.pipeline.FrameResult`, display-linear)
    encoded (display-linear light in the display's linear colourspace, or the display
    encoding) with its ``ocltm:*`` metadata."""
    pixels = encode_pixels(run.colour, res.output, res.alpha, linear)
    meta, out_cs, chroma, white, straight = output_metadata(
        run, tm, fr, fin, res.info, extra, linear, res.output.shape[2] == 4)
    return Rendered(pixels, out_cs, meta, chroma, white, straight)
