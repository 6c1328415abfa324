"""Frames in row bands, never whole in memory (``Tonemapper.process_stream``): the
working rows of a band source through the backend's colour stage, the scene
effects band by band, and the sink that keeps a band's alpha."""

from __future__ import annotations

import numpy as np


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
    """A band source with the scene effects on (``Tonemapper.process_stream``):
    rows [y0, y1) are the working rows flared (from the rows around them),
    Purkinje-shifted and multiplied by the chromatic gains, as ``_scene_effects``
    changes the whole frame; cd/m^2, so the frame's scale is 1."""

    def __init__(self, rows: WorkingRows, flare, purkinje, gains, channels: int):
        self.rows, self.flare, self.purkinje, self.gains = rows, flare, purkinje, gains
        self._alpha = channels == 4
        self.shape = (rows.h, rows.w, 4 if self._alpha else 3)

    def __getitem__(self, sl: slice) -> np.ndarray:
        y0, y1, _ = sl.indices(self.rows.h)
        if self.flare is not None:
            rgb = self.flare.rows(y0, y1)
        else:
            rgb = np.array(self.rows.get(y0, y1)[..., :3])
        if self.purkinje is not None:
            rgb = self.purkinje(y0, rgb)
        if self.gains is not None:
            rgb = (rgb * self.gains).astype(np.float32)
        if self._alpha:
            rgb = np.concatenate([rgb, self.rows.get(y0, y1)[..., 3:4]], axis=2)
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
