"""``run --visibility OUT.####.exr``: what the observer can see, per frame.

For each frame the run mapped: a ``backends.base.VisibilityRequest`` (its input,
the run's observer and target, the operator's state after it), made into
``models/visibility_map.PLANES`` by the backend (``Backend.visibility``: kernels on
an OpenCL device, the float64 reference on the host) and written as a half-float
(``--visibility-type float``: float) EXR, the channels' meaning and units in its
header; ``--target`` follows one target through the shot with the same observer
(``visibility.seen``, the calculator's formula).
"""

from __future__ import annotations

import logging
import math
import os

import numpy as np
import OpenImageIO as oiio

from ..base import safeio
from ..backends import flare_exec as fx
from ..backends.base import ViewPaint, VisibilityPlanes, VisibilityRequest, paint_view
from ..io.imageio import PNG_FILTER, PNG_FILTERS, PNG_LEVEL, FrameError
from ..io.imagewrite import verify_written
from ..models import adrian1989 as ad
from ..models import cie88
from ..models import spencer1995 as fl
from ..models.cie146 import EXCLUDE_DEG
from ..models.photometry import Y_WEIGHTS
from ..models.visibility_map import (PLANES, Geometry, below_a_pixel, recipe, scene_luminance,
                                     value_at)
from ..io.patterns import frame_path, is_sequence, same_file
from ..base.quantities import RUN
from ..effects.visibility import Viewing, seen

log = logging.getLogger("ocl_tonemap")

#: The flags that give the run's observer (``Viewing.check`` names them in errors).
RUN_FLAGS = {"size": "--target-size", "time": "--observation-time", "age": "--age"}


def viewing(opts, age, check: bool = True) -> Viewing:
    """The map's target and observer: ``--target-size``, ``--observation-time``,
    ``--adrian`` and the run's ``--age`` (the flare's option; ``spencer``, no age,
    takes Adrian's at the default 25); checked (and Adrian's extrapolations said) once
    a run, before its first frame."""
    view = Viewing(opts.target_size, fl.DEFAULT_AGE if fl.is_literal(age) else float(age),
                   opts.observation_time, ad.FIELD_FACTOR, opts.adrian)
    return view.check(RUN_FLAGS) if check else view


#: What ``Lveil`` counts (the header's ``ocltm:visibility:veil``), without and with
#: ``--veil-halo``.
VEIL_KINDS = {False: f"disability glare of the whole field: CIE 146's general equation at "
                     f"the observer's age over every pixel's light, the field within "
                     f"{EXCLUDE_DEG:g} degree of the point left out (CIE 88's fixation field)",
              True: "the disability glare of the whole field plus the flare's lenticular "
                    "halo (f3) of the light above its source limit"}


def halo(flare: dict | None, settings, geometry: Geometry, step: int):
    """``--veil-halo``: a function of the veil's luminance cells giving the flare's
    lenticular halo there (Spencer's f3 at the frame's pupil over the light above the
    frame's source limit, the picture's flare), or None where the flare did not run."""
    if not flare or not flare.get("ran") or "pupil_mm" not in flare:
        return None
    lim, D = float(flare.get("source_limit_cd", math.inf)), float(flare["pupil_mm"])
    deg = geometry.deg_per_px * step

    def ring(cells: np.ndarray) -> np.ndarray:
        S = np.maximum(cells - lim, 0.0)
        if not S.any():
            return np.zeros_like(cells)
        whole = fx.convolve_exact_cached(np.repeat(S[..., None], 3, axis=2), deg, D,
                                         settings.age) @ Y_WEIGHTS
        return np.maximum(whole - fx.convolve_scatter_cached(S, deg, D, settings.age), 0.0)
    return ring


def frame_request(tm, fin, info, opts, once=None) -> VisibilityRequest:
    """The planes' request of one mapped frame (its input ``fin``, its record ``info``);
    ``once(level, msg, *args)`` says a warning once a run."""
    if fin.wavelengths is not None:
        raise ValueError("--visibility needs the frame's luminance: this operator takes "
                         "the spectrum (give RGB input, or an operator that maps RGB)")
    s = tm.effects.settings
    h, w = fin.pixels.shape[:2]
    view = viewing(opts, s.age, check=False)          # (checked before the first frame)
    g = Geometry(h, w, s.fov_deg)
    r = recipe(g, view.size_arcmin, view.age)
    say = once or (lambda level, msg, *args: log.log(level, msg, *args))
    if (opts.visibility or opts.visibility_view) and below_a_pixel(g, view.size_arcmin):
        say(logging.WARNING, "--target-size %g arcmin is below a pixel of this %dx%d frame "
            "at %g degrees: target and surround are the same, VL is 0 (give a larger size)",
            view.size_arcmin, w, h, s.fov_deg)
    flare = info.effects.get("flare")
    if opts.veil_halo and not (flare and flare.get("ran")):
        say(logging.WARNING, "--veil-halo: the flare did not run on a frame; its Lveil is "
            "the disability veil alone (the header says which)")
    op = tm.op
    # a local operator's observer is its per-pixel state (on a device: the backend
    # reads it where it is; the host's planes download it)
    observer = (lambda: op.observer_of(tm.state)) if op.observer_per_pixel else \
        (lambda: op.observer_of(info.state))
    return VisibilityRequest(fin.pixels, fin.scale, r, view, op, observer, tm.schedule,
                             halo(flare, s, g, r.veil_step) if opts.veil_halo else None,
                             np.float16 if opts.visibility_type == "half" else np.float32)


def frame_visibility(tm, req: VisibilityRequest) -> VisibilityPlanes:
    """The planes of one mapped frame, made by the run's backend."""
    return tm.backend.visibility(req)


def check_target(target) -> tuple[float, float, float]:
    """``--target X,Y,SIZE`` as declared (``quantities.RUN``): pixel column and row of
    the target's centre (0, 0 the top-left pixel), its size in arcmin."""
    return tuple(float(v) for v in RUN["target"].check(target, "--target"))


def target_visibility(tm, req: VisibilityRequest, planes: VisibilityPlanes, opts) -> dict:
    """The tracked target (``--target X,Y,SIZE``) on one frame: its luminance (a disc
    of SIZE), its surround (the ring out to 3 sizes), the veil there (the planes'
    cells, brought to the pixel as the planes bring them), and what the run's
    observer sees of it (``visibility.seen``: the calculator's formula); beside the
    veil, CIE 88's L_seq of the same picture there (``models/cie88.py``)."""
    x, y, size = opts.target
    h, w = req.pixels.shape[:2]
    if not (0 <= x < w and 0 <= y < h):
        raise ValueError(f"--target {x:g},{y:g}: outside the frame ({w} x {h} pixels)")
    px = req.recipe.geometry.px_per_arcmin * size
    r = max(0.5, px / 2.0)
    R = int(math.ceil(3.0 * r)) + 1
    y0, y1, x0, x1 = max(0, int(y) - R), min(h, int(y) + R + 1), max(0, int(x) - R), \
        min(w, int(x) + R + 1)
    Yc = scene_luminance(req.pixels[y0:y1, x0:x1], req.scale)
    yy, xx = np.mgrid[y0:y1, x0:x1]
    d = np.hypot(xx + 0.5 - (x + 0.5), yy + 0.5 - (y + 0.5))
    inner, ring = d <= r, (d > r) & (d <= 3.0 * r)
    L_t = float(Yc[inner].mean()) if inner.any() else float(Yc[int(y) - y0, int(x) - x0])
    L_s = float(Yc[ring].mean()) if ring.any() else L_t
    veil = max(value_at(planes.veil_cells, req.recipe.veil_step, int(x), int(y)), 0.0)
    view = Viewing(size, req.view.age, req.view.time_s, req.view.k, req.view.adrian)
    op = tm.op
    if op.observer_per_pixel:
        at = getattr(tm.schedule, "observer_at", None)
        obs = at(int(x), int(y)) if at is not None else \
            {k: np.asarray(v)[int(y), int(x)] for k, v in req.observer().items()}
    else:
        obs = req.observer()
    s = seen(op, obs, view, L_s, veil, L_t)
    # CIE 88's L_seq at the target, from the same picture (the polar diagram's reach)
    R = int(math.ceil(cie88.ring_radii()[-1] / req.recipe.geometry.deg_per_px)) + 1
    cy0, cx0 = max(0, int(y) - R), max(0, int(x) - R)
    crop = req.pixels[cy0:int(y) + R + 1, cx0:int(x) + R + 1]
    Lseq, _ = cie88.l_seq(scene_luminance(crop, req.scale), x - cx0, y - cy0,
                          req.recipe.geometry.deg_per_px)
    return {"x": x, "y": y, "size_arcmin": size, "L_target": L_t, "L_surround": L_s,
            "Lveil": veil, "Lb": s.L_b, "La": s.L_a, "TAF": s.TAF, "dLth": s.dL_th,
            "VL": s.VL, "observation_s": view.time_s, "adrian": view.adrian,
            "Lseq_cie88": Lseq}


def write_visibility(path: str, planes: VisibilityPlanes, f, view: Viewing, operator: str,
                     fov_deg: float, halo: bool = False) -> None:
    """The planes as a half (or float) EXR, channels named and described in the
    header with the observer, verified before it counts."""
    names = [n for n, _, _ in PLANES]
    h, w = planes.data.shape[:2]
    fmt = oiio.HALF if planes.data.dtype == np.float16 else oiio.FLOAT
    spec = oiio.ImageSpec(w, h, len(names), fmt)
    spec.channelnames = tuple(names)
    # uncompressed: zip took a quarter of a 1080p frame's time (0.26 s of ~1 s)
    spec.attribute("compression", "none")
    for n, unit, what in PLANES:
        spec.attribute(f"ocltm:visibility:{n}", f"{what} [{unit}]")
    d = view.describe()
    spec.attribute("ocltm:visibility:target_arcmin", d["target_arcmin"])
    spec.attribute("ocltm:visibility:age", d["age"])
    spec.attribute("ocltm:visibility:observation_s", d["observation_s"])
    spec.attribute("ocltm:visibility:k", d["k"])
    spec.attribute("ocltm:visibility:adrian", d["adrian"])
    spec.attribute("ocltm:visibility:fov_deg", float(fov_deg))
    spec.attribute("ocltm:visibility:veil", VEIL_KINDS[bool(halo)])
    if fmt == oiio.HALF:
        spec.attribute("ocltm:visibility:clamped", int(planes.clamped))
    spec.attribute("ocltm:operator", operator)
    if f is not None:
        spec.attribute("ocltm:frame", int(f))
    _write_verified(path, planes.data, spec, f)


def _write_verified(path: str, data: np.ndarray, spec, f) -> None:
    """Write ``data`` with ``spec`` through a temporary file, read it back, then rename."""
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise FrameError(path, f, f"cannot write: no folder {folder}")
    tmp = safeio.temp_path(path)
    try:
        safeio.claim_temp(tmp, path)
    except safeio.WriteFailed as exc:
        raise FrameError(path, f, f"cannot write: {exc.why}") from None
    try:
        out = oiio.ImageOutput.create(tmp)
        if out is None or not out.open(tmp, spec):
            raise FrameError(path, f, f"cannot write: {oiio.geterror() or 'no writer'}")
        ok = out.write_image(np.ascontiguousarray(data))
        ok = bool(out.close()) and ok
        if not ok:
            raise FrameError(path, f, "cannot write: " + (
                "no space left on device" if safeio.disk_full(tmp) else
                (out.geterror() or "failed")))
        verify_written(tmp, path, f, spec.width, spec.height, spec.nchannels)
        safeio.commit(tmp, path)
    finally:
        safeio.remove(tmp)


# --- the false-colour view (--visibility-view) ----------------------------------------------

#: VL bands of the view, (upper bound, colour, label): no colour where the scene has
#: no detail at the target's size (a uniform wall is no target), red and hatched
#: below CIE 140's threshold 1, then RP-8's steps.
VIEW_BANDS = ((0.1, None, "VL < 0.1: no detail"), (1.0, (0.9, 0.05, 0.05), "0.1-1: not seen"),
              (3.0, (1.0, 0.55, 0.0), "1-3"), (10.0, (1.0, 0.92, 0.15), "3-10"),
              (math.inf, (0.15, 0.8, 0.35), "> 10"))
#: How much of the band colour covers the (dimmed) picture.
VIEW_OPACITY = 0.5


#: The bands as the backends paint them (``backends.base.ViewPaint``): each band the
#: picture dimmed to 60 %, then (above the first) VIEW_OPACITY of its colour over it.
VIEW_PAINT = dict(
    edges=tuple(e for e, _, _ in VIEW_BANDS[:-1]),
    scale=(0.6,) + (0.6 * (1.0 - VIEW_OPACITY),) * (len(VIEW_BANDS) - 1),
    add=((0.0, 0.0, 0.0),) + tuple(tuple(VIEW_OPACITY * c for c in col)
                                   for _, col, _ in VIEW_BANDS[1:]),
    hatch=VIEW_BANDS[1][1])


def view_paint(h: int, w: int) -> ViewPaint:
    """The view's paint for an h x w frame (the hatch's step: a 120th of its short side)."""
    return ViewPaint(**VIEW_PAINT, step=max(2, min(h, w) // 120))


def view_pixels(backend, planes: VisibilityPlanes, shown: np.ndarray, u8: bool) -> np.ndarray:
    """The view's pixels (without the legend) of a frame whose output's code values are
    ``shown`` (integers as written, or floats): on the backend's device where it made
    the planes, else (``backend`` None: off the main thread) on the host
    (``backends.base.paint_view``)."""
    h, w = planes.data.shape[:2]
    paint = view_paint(h, w)
    out = None if backend is None else backend.visibility_view(planes, shown, paint, u8)
    if out is None:
        out = paint_view(shown_codes(shown), planes.plane("VL").astype(np.float32), paint)
        if u8:
            out = np.round(np.clip(out, 0.0, 1.0) * 255.0).astype(np.uint8)
    return out


def view_legend(w: int, h: int) -> np.ndarray:
    """The view's legend, float32 code values (lh x w x 3): a box and a label a band
    (no font: boxes without labels)."""
    lh = max(18, min(48, h // 10))
    legend = np.full((lh, w, 3), 0.08, np.float32)
    buf = oiio.ImageBuf(oiio.ImageSpec(w, lh, 3, oiio.FLOAT))
    buf.set_pixels(oiio.ROI(), legend)
    size = max(8, int(lh * 0.5))
    x = 4
    for _, c, label in VIEW_BANDS:
        oiio.ImageBufAlgo.fill(buf, c or (0.36, 0.36, 0.36),
                               oiio.ROI(x, x + lh // 2, lh // 4, lh // 4 + lh // 2))
        oiio.ImageBufAlgo.render_text(buf, x + lh // 2 + 4, int(lh * 0.72), label, size, "",
                                      (1.0, 1.0, 1.0))
        tw = oiio.ImageBufAlgo.text_size(label, size, "")
        x += lh // 2 + 4 + (tw.width if tw.defined else size * len(label) // 2) + lh // 2
    oiio.geterror()
    return buf.get_pixels(oiio.FLOAT)[..., :3]


def shown_codes(pixels: np.ndarray) -> np.ndarray:
    """Display code values 0..1 of an output's pixels (integers normalised)."""
    a = np.asarray(pixels)
    if np.issubdtype(a.dtype, np.integer):
        return a[..., :3].astype(np.float32) / float(np.iinfo(a.dtype).max)
    return a[..., :3].astype(np.float32)


def write_view(path: str, pixels: np.ndarray, f, png_level: int = PNG_LEVEL,
               png_filter: str = PNG_FILTER) -> None:
    """The view (its pixels, :func:`view_pixels`) with the legend below: 8-bit (a PNG
    at the run's zlib level and row filter, as its frames), or half floats for an EXR."""
    h, w = pixels.shape[:2]
    exr = path.lower().endswith(".exr")
    legend = view_legend(w, h)
    if exr:
        data = np.concatenate([np.clip(pixels, 0.0, 1.0), legend], axis=0)
    else:
        data = np.concatenate([pixels, np.round(np.clip(legend, 0.0, 1.0) * 255.0)
                               .astype(np.uint8)], axis=0)
    spec = oiio.ImageSpec(w, data.shape[0], 3, oiio.HALF if exr else oiio.UINT8)
    spec.attribute("oiio:ColorSpace", "sRGB")
    spec.attribute("ImageDescription", "ocl-tonemap visibility view: VL bands "
                   + ", ".join(lab for _, _, lab in VIEW_BANDS))
    spec.attribute("png:compressionLevel", int(png_level))
    spec.attribute("png:filter", PNG_FILTERS[png_filter])
    _write_verified(path, data, spec, f)


def check_visibility(opts, jobs) -> None:
    """Refuse a bad ``--visibility`` or ``--visibility-view`` before the first frame:
    their names, their patterns against the run's frames, an input or output they
    would overwrite, the observer (``Viewing.check``: what the API gives unchecked by
    the flags' parsers too)."""
    if not (opts.visibility or opts.visibility_view or opts.target):
        return
    viewing(opts, getattr(opts.effects, "age", None) or fl.DEFAULT_AGE)
    if opts.target is not None:
        check_target(opts.target)
    if opts.visibility_type not in ("half", "float"):
        raise ValueError(f"--visibility-type must be half or float (got "
                         f"{opts.visibility_type!r})")
    if opts.visibility and not opts.visibility.lower().endswith(".exr"):
        raise ValueError(f"--visibility writes OpenEXR: name it .exr (got {opts.visibility})")
    numbered = any(f is not None for f, *_ in jobs)
    for flag, p in (("--visibility", opts.visibility), ("--visibility-view",
                                                        opts.visibility_view)):
        if not p:
            continue
        if flag == "--visibility-view" and oiio.ImageOutput.create(p) is None:
            raise ValueError(f"--visibility-view {p}: no image format for this name "
                             "(.png, .tif, .jpg, .exr ...)")
        if numbered and not is_sequence(p):
            raise ValueError(f"{flag} {p}: the run has numbered frames; give a frame "
                             "pattern (#, @ or %04d)")
        if not numbered and is_sequence(p):
            raise ValueError(f"{flag} {p}: a frame pattern, but the input is one image")
        for f, inp, outp, _ in jobs:
            v = visibility_path(p, f)
            if same_file(v, inp) or os.path.abspath(v) == os.path.abspath(outp):
                raise FrameError(v, f, f"{flag} would overwrite the frame's input or output")
    if opts.visibility and opts.visibility_view and \
            os.path.abspath(opts.visibility) == os.path.abspath(opts.visibility_view):
        raise ValueError("--visibility and --visibility-view name the same file")


def visibility_path(pattern: str, f) -> str:
    return frame_path(pattern, f) if f is not None and is_sequence(pattern) else pattern


def refuse_visibility(opts, where: str) -> None:
    """The visibility outputs are made by the serial run's frame loop; elsewhere
    (``where``) they are refused rather than silently left out."""
    for flag, given in (("--visibility", opts.visibility),
                        ("--visibility-view", opts.visibility_view),
                        ("--target", opts.target)):
        if given:
            raise ValueError(f"{flag} is made by a serial run (ocl-tonemap run without "
                             f"--scheduler); {where} does not make it")
