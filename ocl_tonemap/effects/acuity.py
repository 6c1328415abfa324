"""Loss of acuity in the dark: a Gaussian blur of the displayed image (Durand & Dorsey
2000, Sec. 7, Eqs. 9-11 with Shaler's Table 1).

Slot: display. Needs: the adapted scotopic level; the field of view; a blur.
The model is ``models/shaler1937.py``; :class:`Acuity` is the effect.
"""

from __future__ import annotations

import numpy as np

from ..models.convolution import EDGE_CLAMP, blur_axis_reference, gaussian_taps
from ..models.shaler1937 import acuity_a_px, acuity_blend, acuity_info, apply_acuity
from .base import Effect
from .flare import FOV_OPTION


def _mode(settings) -> str:
    """Shaler's table read in Shlaer's photometric units, or literally (``paper``)."""
    return "paper" if settings.paper else "default"


def needed(settings, G_rod: float, width: int) -> bool:
    """Whether a frame of ``width`` pixels at ``G_rod`` gets any blur."""
    return settings.acuity != "off" and \
        float(acuity_blend(acuity_a_px(G_rod, settings.fov_deg, width, mode=_mode(settings)))) > 0


def report(settings, G_rod: float, width: int) -> dict:
    """What :func:`run` reports for a frame it does not blur (``needed`` False)."""
    if settings.acuity == "off":
        return {"ran": False}
    info = acuity_info(G_rod, settings.fov_deg, width, mode=_mode(settings))
    info["ran"] = info["blend"] > 0
    return info


def blur_plan(settings, G_rod: float, width: int, weight: float = 1.0):
    """(taps, blend, info) of a frame ``width`` px wide that blurs: what :func:`run`
    does to it, the blend times the plan's ``weight``; None where it does not blur."""
    info = report(settings, G_rod, width)
    if not info.get("ran"):
        return None
    if weight < 1.0:
        info["weight"] = float(weight)
    return gaussian_taps(info["sigma_px"]), info["blend"] * float(weight), info


def run(settings, img: np.ndarray, G_rod: float, blur=None):
    if settings.acuity == "off":
        return img, {"ran": False}
    dev = None if blur is None else (lambda im, taps: blur(im, taps, EDGE_CLAMP))
    out, info = apply_acuity(img, G_rod, settings.fov_deg, dev, mode=_mode(settings))
    info["ran"] = info["blend"] > 0
    return out, info


class BandedAcuity:
    """A sink that blurs display-linear bands on their way to ``sink`` (frames in
    row bands, ``Tonemapper.process_stream``): the rows come in order, are blurred
    along x as they come, and go on once the rows the taps reach below them have
    come (a window of the rows and their halo is kept), blurred along y with
    clamped edges and blended as :func:`run` does: the whole frame's values (the
    blur's two passes, x then y, with the same intermediate values). Rows go on
    ``min_rows`` at a time at least: the y pass of the halo rows costs less as
    they grow (~70 bytes a pixel of the window)."""

    def __init__(self, sink, shape, taps: np.ndarray, blend: float, blur_axis=None,
                 min_rows: int = 1):
        self.sink, self.h = sink, int(shape[0])
        self.taps, self.t = taps, float(blend)
        self.R = len(taps) - 1
        pas = blur_axis or (lambda im, tp, axis: blur_axis_reference(im, tp, EDGE_CLAMP, axis))
        self.blur_x = lambda im: pas(im, self.taps, 0)
        self.blur_y = lambda im: pas(im, self.taps, 1)
        w = int(shape[1])
        self.win = np.zeros((0, w, 3), np.float32)       # the rows as they came
        self.winx = None                                  # ... blurred along x
        self.w0 = 0                          # first row held in the window
        self.got = 0                         # rows received
        self.sent = 0                        # rows sent on
        self.min_rows = max(1, int(min_rows))

    def __call__(self, y0: int, band: np.ndarray) -> None:
        if y0 != self.got:
            raise RuntimeError(f"acuity: bands out of order (row {y0}, expected {self.got})")
        band = np.asarray(band[..., :3], np.float32)
        bx = self.blur_x(band)
        self.win = np.concatenate([self.win, band])
        self.winx = bx if self.winx is None or not len(self.winx) else \
            np.concatenate([self.winx, bx])
        self.got += len(band)
        e1 = self.h if self.got >= self.h else self.got - self.R
        if e1 >= min(self.h, self.sent + self.min_rows):
            e0 = self.sent
            lo = max(0, e0 - self.R) - self.w0              # the rows with their halo
            hi = min(self.h, e1 + self.R) - self.w0
            blurred = self.blur_y(self.winx[lo:hi])
            k0, k1 = e0 - self.w0 - lo, e1 - self.w0 - lo
            img = self.win[e0 - self.w0:e1 - self.w0]
            out = (np.asarray(blurred[k0:k1], np.float64) * self.t
                   + np.asarray(img, np.float64) * (1.0 - self.t))
            del blurred
            self.sent = e1
            keep = max(0, e1 - self.R) - self.w0             # rows still needed above
            self.win, self.winx, self.w0 = self.win[keep:], self.winx[keep:], self.w0 + keep
            self.sink(e0, out.astype(np.float32))

    @property
    def done(self) -> bool:
        return self.sent >= self.h


def stream(settings, sink, G_rod: float, shape, blur_axis=None, block_pixels: int | None = None,
           weight: float = 1.0):
    """(sink, info) for a frame in row bands: ``sink`` itself when nothing blurs,
    else a :class:`BandedAcuity` in front of it (``blur_axis(img, taps, axis)``:
    one pass of the device blur, clamped), sending rows on ``block_pixels`` at a
    time at least, or twice that where the taps reach further (up to four times
    their radius)."""
    if settings.acuity == "off":
        return sink, {"ran": False}
    info = acuity_info(G_rod, settings.fov_deg, int(shape[1]), mode=_mode(settings))
    info["ran"] = info["blend"] > 0
    if not info["ran"]:
        return sink, info
    taps = gaussian_taps(info["sigma_px"])
    R = len(taps) - 1
    band = int(block_pixels or 0) // max(1, int(shape[1]))
    rows = min(4 * R, max(band, min(2 * R, 2 * band)))
    return BandedAcuity(sink, shape, taps, info["blend"] * float(weight), blur_axis, rows), info


class Acuity(Effect):
    """Acuity as an effect: display-linear frames blurred on the host or with the
    device's blur; on the device before the display encoding where the backend can
    (:meth:`encoding`); frames in bands through :class:`BandedAcuity` in front of
    the sink."""

    name = "acuity"
    slot = "display"
    help = "loss of acuity in the dark (Shaler 1937)"
    gated = True
    blends = True
    capabilities = frozenset({"host", "device", "banded"})
    options = (FOV_OPTION,)

    def host(self, ctx, out):
        res, info = run(self.fx.s, out, ctx.G_rod, self.fx.blur)
        w = self.fx.weight(self.name)
        if info.get("ran") and w < 1.0:
            res = (out + w * (np.asarray(res, np.float32) - out)).astype(np.float32)
            info["weight"] = w
        return res, info

    def needed(self, ctx, width: int) -> bool:
        return needed(self.fx.s, ctx.G_rod, width)

    def report(self, ctx, width: int) -> dict:
        """The record of a frame left unblurred (:meth:`needed` False)."""
        return report(self.fx.s, ctx.G_rod, width)

    def encoding(self, ctx, encoding, h: int, w: int):
        """(``encoding`` with the blur on the device before it, the frame's record) where
        the backend can blur the frame where the operator leaves it
        (``backend.acuity_encoding``), else (None, None): the blur of :meth:`host`
        with the plan's weight, in float32 on the device."""
        plan = blur_plan(self.fx.s, ctx.G_rod, w, self.fx.weight(self.name))
        dev = self.fx.device_blur
        if plan is None or dev is None:
            return None, None
        taps, t, info = plan
        enc = self.fx.backend.acuity_encoding(encoding, h, w, taps, t, dev)
        return (None, None) if enc is None else (enc, info)

    def banded(self, ctx, sink, shape, block_pixels: int | None = None):
        """(sink, info): ``sink`` behind a :class:`BandedAcuity` when it blurs."""
        dev = self.fx.device_blur
        pas = None if dev is None else \
            (lambda im, taps, axis: dev.blur_axis(im, taps, EDGE_CLAMP, axis))
        return stream(self.fx.s, sink, ctx.G_rod, shape, pas, block_pixels,
                      self.fx.weight(self.name))
