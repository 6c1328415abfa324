"""ledda04's per-pixel state on the device (:class:`~.ledda04.LeddaSchedule`'s mixin):
resident between frames when a frame is one band, host planes (or a spilled store)
otherwise; the adaptation levels a shot's integrate pass reads back."""

from __future__ import annotations

import numpy as np

from ...operators.base import FrameStats
from ..base import PixelStateMixin
from ..planes import PlaneStore, band_readable, read_rows
from .transfers import transfer


class LeddaPixelState(PixelStateMixin):
    """The state half of ledda04's device schedule (it uses the schedule's
    ``backend``, ``planes`` and ``_dev``)."""

    # -- per-pixel state ---------------------------------------------------------------
    def pixel_state(self):
        """Per-pixel state as float32 (h, w) arrays (a snapshot; a device copy stays
        authoritative and resident for the next frame); state spilled to a file
        (streamed frames) comes as that band-readable store, valid until the next frame."""
        if self._dev is not None:
            buf, (h, w) = self._dev
            a = np.empty((len(self.planes), h, w), np.float32)
            transfer(self.backend.rt.queue, a, buf)
            return {k: np.array(a[i]) for i, k in enumerate(self.planes)}
        return super().pixel_state()

    def set_pixel_state(self, pixels) -> None:
        super().set_pixel_state(pixels)
        self._dev = None

    def observer_at(self, x: int, y: int) -> dict:
        """The per-pixel state at pixel (x, y), float64 scalars (a small read per plane
        where the state is on the device; ``run --target``)."""
        if self._dev is None:
            return {k: np.float64(np.asarray(v)[y, x]) for k, v in
                    (self.pixel_state() or {}).items()}
        buf, (h, w) = self._dev
        one = np.empty(1, np.float32)
        out = {}
        for i, k in enumerate(self.planes):
            transfer(self.backend.rt.queue, one, buf, src_offset=4 * (i * h * w + y * w + x))
            out[k] = np.float64(one[0])
        return out

    def state_shape(self):
        return self._dev[1] if self._dev is not None else super().state_shape()

    def _store(self, names, shape):
        """Planes of a banded frame: spilled to a file when the run streams frames
        (``backend.spill_dir``), else in memory."""
        return PlaneStore(names, shape, self.backend.spill_dir)

    # -- the statistics apart from the run (shot/: measure -> integrate -> apply) ------
    def stats_planes(self, stats):
        """The per-pixel adaptation inputs ``integrate`` reads (I_A, I_A'; float32):
        host copies, or the band store of a banded frame. I_A' is zero where the
        frame needed no rods (the step then takes it from I_A, as here)."""
        planes = stats.planes
        if band_readable(planes):
            return planes
        h, w = stats.height, stats.width
        out = {"I_c": np.empty((h, w), np.float32), "I_r": np.zeros((h, w), np.float32)}
        transfer(self.backend.rt.queue, out["I_c"], planes["I_c"])
        if stats.values["rods"]:
            transfer(self.backend.rt.queue, out["I_r"], planes["I_r"])
        return out

    def stats_from_planes(self, stats, planes) -> FrameStats:
        """``stats`` (read back from a statistics store) with the stored planes (a
        dict of arrays or band-readable), ready for :meth:`integrate`."""
        stats.planes = planes
        bands = self.backend.bands(stats.height, stats.width, 0)
        stats.handle = (None, bands, len(bands) > 1, 0)
        return stats

    # -- integrate: a band's levels --------------------------------------------------
    def _band_levels(self, stats, y0, nr, rods: bool = True):
        """(Ic, Ir) device buffers of one band: resident, or uploaded from the planes."""
        planes = stats.planes
        if band_readable(planes) or isinstance(planes.get("I_c"), np.ndarray):
            be = self.backend
            n = nr * stats.width
            lv = read_rows(planes, ("I_c", "I_r"), y0, y0 + nr)
            bc, br = be.buffer("ledda_Ic", n * 4), be.buffer("ledda_Ir", n * 4)
            transfer(be.rt.queue, bc, lv[0])
            if rods:
                transfer(be.rt.queue, br, lv[1])
            return bc, br
        return planes["I_c"], planes["I_r"]
