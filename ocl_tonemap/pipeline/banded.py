"""Frames in row bands, never whole in memory (``Tonemapper.process_stream``): the same
flow as a whole frame (``frame.py``), band by band -- the working rows of a band
source through the backend's colour stage (:class:`WorkingRows`), the optical and
seen effects on them (:class:`SceneBands`: the flare made from the source's rows
around each band before the metering pass, the Purkinje shift and chromatic gains
on the bands' way to the operator), the display effects on the display bands on
their way to the sink, which keeps a band's alpha (:func:`alpha_sink`)."""

from __future__ import annotations

import numpy as np

from ..backends.base import settle
from ..effects import FrameContext
from ..operators.base import Frame
from .results import FrameInfo, check_scale, transfers_since


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
    the sink gets (``job/banded_io.py`` ``WorkingBands.alpha``: that of the last band read):
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


def run_banded(graph, source, sink, dt, time_s, frame_number, luminance_scale, illuminant,
               measure_only: bool, start, weights: dict | None):
    """One frame in row bands (``Tonemapper.process_stream`` says what it is given and
    returns): its :class:`FrameInfo`, or its :class:`FrameStats` with ``measure_only``."""
    check_scale(luminance_scale)
    obs, fx = graph.observer, graph.effects
    if measure_only:
        step_dt, fresh = 0.0, True
    else:
        time_s, step_dt, fresh = obs.clock(dt, time_s)
    graph.begin_frame()
    moved = graph.backend.transfers()
    h, w = source.shape[:2]
    frame = metered = Frame(source, luminance_scale, None, graph.primaries)
    eff: dict = {}
    levels, sweep = None, []
    band_px = int(graph.backend.max_band_pixels or h * w)
    if graph.plan.active:          # the source's levels and proxy: nothing kept
        levels = graph.backend.scene_levels(source, luminance_scale, graph.metering,
                                            graph.own_chroma() and graph.grey_world(),
                                            graph.plan.proxy_stride(h, w))
        ctx = FrameContext(*levels.goal, eff=eff, lim=graph.source_limit(levels),
                           max_Y=levels.max_Y, frame=frame_number)
        graph.begin_plan(levels, frame, step_dt, fresh, measure_only, weights, frame_number)
        rows = WorkingRows(graph.backend, source, luminance_scale, max(1, band_px // max(w, 1)))
        graph.record["flare_metered"] = fx.metered_weights(levels.max_Y, ctx.lim)
        bands, sweep = fx.optical_banded(ctx, rows, band_px, STREAM_EFFECT_BANDS * band_px)
        if bands is not None:
            metered = Frame(SceneBands(rows, bands), 1.0, None, graph.primaries)
    stats = graph.measure(metered)
    for finish in sweep:          # what the measure pass's sweep added up
        finish()
    graph.scene_stats(stats, levels)
    if measure_only:
        return stats
    params, gains = graph.integrate(stats, time_s, frame_number, step_dt, fresh, illuminant, eff)
    work, after = metered, []
    if levels is not None:
        work, after = _seen(graph, metered, levels, eff, frame_number)
    dctx = FrameContext(stats.G_rod, stats.G_cone, eff=eff, frame=frame_number,
                        time_s=float(time_s), width=w)
    out = fx.display_banded(dctx, alpha_sink(source, sink), (h, w), STREAM_EFFECT_BANDS * band_px)
    info = FrameInfo(frame_number, float(time_s), step_dt, stats.G_rod, stats.G_cone,
                     levels.repairs if metered is not frame else stats.repairs,
                     obs.scalars.copy(),
                     settle(graph.schedule.summary(stats, params, work)), settle(eff),
                     graph.record)
    if start is not None:
        start(info)
    graph.apply(work, stats, params, gains, out)
    if not getattr(out, "done", True):     # a BandedAcuity sink counts its rows
        raise RuntimeError(f"the schedule sent rows up to {out.got} of {h}")
    for finish in after:          # what the bands' sweep added up
        finish()
    info.transfers = transfers_since(graph.backend, moved)
    return info


def _seen(graph, metered: Frame, levels, eff: dict, frame_number):
    """The seen effects of a frame in row bands: (the frame to map, ``metered`` where
    nothing changes it, with them on the scene band by band; functions to call once
    its bands have been made)."""
    fx = graph.effects
    ctx = FrameContext(*levels.goal, eff=eff, frame=frame_number)
    per_band, after = fx.seen_banded(ctx, metered.shape[0], graph.own_chroma())
    if per_band is None:
        return metered, after
    src = metered.pixels
    if not isinstance(src, SceneBands):
        # the source itself: its rows through the colour stage first
        src = SceneBands(WorkingRows(fx.backend, src, metered.scale,
                                     max(1, (fx.backend.max_band_pixels or src.shape[0] *
                                             src.shape[1]) // max(src.shape[1], 1))))
    return Frame(SceneBands(src, None, per_band), 1.0, None, graph.primaries), after
