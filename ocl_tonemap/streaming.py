"""Frames in row bands, never whole in memory (``Tonemapper.process_stream``): the
working rows of a band source through the backend's colour stage, the scene
effects band by band, and the sink that keeps a band's alpha."""

from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger("ocl_tonemap")


#: Effects that reach across band edges (flare, acuity) work on this many bands' pixels
#: at a time when frames stream: their halo rows cost less the more rows share them
#: (~100 bytes a pixel each while they work, inside the streaming path's budget).
STREAM_EFFECT_BANDS = 1


class WorkingRows:
    """Rows of a band source through the backend's colour stage (working RGB in
    cd/m^2, float32; the straight alpha after it when the source has one), read
    in pieces of at most ``max_rows`` rows. The rows of the last request are kept:
    the next band's rows around it mostly overlap them and are not read again."""

    def __init__(self, backend, source, scale: float, max_rows: int):
        self.be, self.source, self.scale = backend, source, float(scale)
        self.h, self.w, self.nc = source.shape
        self.max_rows = max(1, int(max_rows))
        self._rows = np.zeros((0, self.w, 4 if self.nc == 4 else 3), np.float32)
        self._c0 = 0

    def _read(self, a: int, b: int) -> np.ndarray:
        nc = 4 if self.nc == 4 else 3
        out = np.empty((b - a, self.w, nc), np.float32)
        for y in range(a, b, self.max_rows):
            z = min(b, y + self.max_rows)
            pix = np.asarray(self.source[y:z], np.float32)
            out[y - a:z - a, :, :3] = self.be.working_rows(pix, self.scale)
            if nc == 4:
                out[y - a:z - a, :, 3] = pix[..., 3]
        return out

    def get(self, a: int, b: int) -> np.ndarray:
        """Rows [a, b) (H x W x 3, or 4 with alpha)."""
        a, b = max(0, int(a)), min(self.h, int(b))
        c0, c1 = self._c0, self._c0 + len(self._rows)
        if c0 <= a and b <= c1:
            return self._rows[a - c0:b - c0]
        lo, hi = max(a, c0), min(b, c1)
        if lo >= hi:
            rows = self._read(a, b)
        else:
            parts = [self._read(a, lo)] if a < lo else []
            parts.append(self._rows[lo - c0:hi - c0])
            if hi < b:
                parts.append(self._read(hi, b))
            rows = np.concatenate(parts)
        self._rows, self._c0 = rows, a
        return rows


class SceneBands:
    """A band source with scene effects on (``Tonemapper.process_stream``): rows
    [y0, y1) of ``rows`` (:class:`WorkingRows`, or another SceneBands), flared (from
    the rows around them: ``flare``, a ``BandedFlare``), then passed through
    ``per_band(y0, rgb)`` (pointwise: the Purkinje shift, chromatic gains), as the
    whole frame's effects change it; cd/m^2, so the frame's scale is 1."""

    def __init__(self, rows, flare=None, per_band=None):
        self.rows, self.flare, self.per_band = rows, flare, per_band
        self.h, self.w, nc = rows.shape if isinstance(rows, SceneBands) else \
            (rows.h, rows.w, rows.nc)
        self._alpha = nc == 4
        self.shape = (self.h, self.w, 4 if self._alpha else 3)

    def _alpha_rows(self, y0: int, y1: int) -> np.ndarray:
        if isinstance(self.rows, SceneBands):
            return self.rows[y0:y1][..., 3:4]
        return self.rows.get(y0, y1)[..., 3:4]

    def __getitem__(self, sl: slice) -> np.ndarray:
        y0, y1, _ = sl.indices(self.h)
        if self.flare is not None:
            rgb = self.flare.rows(y0, y1)
        elif isinstance(self.rows, SceneBands):
            rgb = np.array(self.rows[y0:y1][..., :3])
        else:
            rgb = np.array(self.rows.get(y0, y1)[..., :3])
        if self.per_band is not None:
            rgb = self.per_band(y0, rgb)
        if self._alpha:
            rgb = np.concatenate([rgb, self._alpha_rows(y0, y1)], axis=2)
        return np.ascontiguousarray(rgb, np.float32)


def alpha_sink(source, sink):
    """``sink`` behind a check that the source still holds the alpha of the band
    the sink gets (``job/stream.py`` ``WorkingBands.alpha``: that of the last band read):
    effects that read rows around a band, or send bands on later, read it again."""
    if source.shape[2] != 4 or not callable(getattr(source, "alpha", None)):
        return sink
    alpha = source.alpha

    def out(y0, band):
        a = alpha(y0)
        if a is None or len(a[0]) != len(band):
            source[y0:y0 + len(band)]
        sink(y0, band)
    return out


def stream_flare(fx, rows: WorkingRows, levels, lim: float, eff: dict, band_px: int):
    """The flare of a frame in row bands (``Tonemapper.process_stream``), before its
    metering pass: (a ``BandedFlare`` or None, functions to call once the metering
    pass has swept the frame: the share of light kept in it). ``fx``: the run's
    ``Effects``; ``levels``: the source's scene pass; ``lim``: the source limit."""
    G_rod, G_cone = levels.goal
    flare, eff["flare"] = fx.flare_stream((rows.h, rows.w), G_rod, G_cone, lim, rows.get,
                                          band_px, levels.max_Y, STREAM_EFFECT_BANDS * band_px)
    if "streamed" in eff["flare"] and "streamed flare" not in fx.said:
        fx.said.add("streamed flare")
        log.warning("flare: streamed frames use --flare-method fast (the exact method's FFT "
                    "needs the whole frame)")
    if flare is None:
        return None, []

    def done(info=eff["flare"]):
        e = flare.energy_in_frame()
        if e is not None:
            info["energy_in_frame"] = e
    return flare, [done]


def stream_seen(fx, metered, levels, eff: dict, own_chroma: bool, primaries):
    """The effects after the state step of a frame in row bands: (the frame to map,
    ``metered`` where nothing changes it, with the Purkinje shift and chromatic gains
    on the scene band by band; functions to call once its bands have been made:
    the shift's gamut fallbacks)."""
    from .operators.base import Frame
    ca = eff.get("chromatic_adaptation") or {}
    gains = np.asarray(ca["gains"], np.float32) if (own_chroma and ca.get("ran")) else None
    purk = fx.purkinje_banded(eff["purkinje"], metered.shape[0])
    if purk is None and gains is None:
        return metered, []

    def per_band(y0, rgb):
        if purk is not None:
            rgb = purk(y0, rgb)
        return rgb if gains is None else (rgb * gains).astype(np.float32)
    src = metered.pixels
    if not isinstance(src, SceneBands):
        # the source itself: its rows through the colour stage first
        src = SceneBands(WorkingRows(fx.backend, src, metered.scale,
                                     max(1, (fx.backend.max_band_pixels or src.shape[0] *
                                             src.shape[1]) // max(src.shape[1], 1))))
    after = []
    if purk is not None:
        def done(info=eff["purkinje"]):
            fb = purk.fallback_fraction()
            if fb is not None:
                info["fallback_fraction"] = fb
        after.append(done)
    return Frame(SceneBands(src, None, per_band), 1.0, None, primaries), after
