"""The float64 NumPy reference backend: every stage straight from ``models/``."""

from __future__ import annotations

import numpy as np

from ...models import durand2000, metering as met
from ...models.photometry import photopic_luminance, sanitize, scotopic_luminance
from ...models.spencer1995 import source_part
from ...operators.base import FrameStats
from ..base import HostBackend, Levels, load_schedule, NoPixelState


def _mask(spec: met.MeteringSpec, w: int, h: int):
    if spec.mode != "mask":
        return None
    from ..weights import read_weight_mask  # lazy: OIIO only for a mask file
    return read_weight_mask(spec.mask, w, h)


class ReferenceBackend(HostBackend):
    _last_rgb = None            # the last working frame (source_proxy)
    """Float64 NumPy, straight from the equations; the ground truth. Frames are done
    whole, on the host (:class:`~ocl_tonemap.backends.base.HostBackend`)."""

    name = "reference"

    def describe(self) -> str:
        return "float64 NumPy reference"

    def schedule(self, op):
        spec = op.schedules.get(self.name)
        if spec:
            return load_schedule(spec)(self, op)
        return PointwiseSchedule(self, op)

    def working(self, pixels: np.ndarray, scale: float, spec: met.MeteringSpec,
                illuminant: bool = True, on_device: bool = False,
                proxy_stride: int = 0, metered: Levels | None = None) -> Levels:
        """Colour stage and metering: rgb in cd/m^2 (float64), repairs, (G_rod, G_cone),
        the illuminant estimate (made when called: ``illuminant`` changes nothing here),
        the largest luminance, the block means of ``proxy_stride`` (0: none);
        ``metered`` known: the colour stage only."""
        rgb, repairs = sanitize(pixels[..., :3], scale)
        self._last_rgb = rgb
        if metered is not None:
            return metered._replace(rgb=rgb, proxy=None)
        h, w = rgb.shape[:2]
        Y, Ys = photopic_luminance(rgb), scotopic_luminance(rgb)
        G = met.reference_goal(Y, Ys, spec, _mask(spec, w, h))
        proxy = met.block_means(rgb, proxy_stride) if proxy_stride else None
        self._last_rgb = rgb
        return Levels(rgb, repairs, G, lambda: durand2000.illuminant_estimate_reference(rgb),
                      float(Y.max(initial=0.0)), proxy, float(Ys.max(initial=0.0)))

    def source_proxy(self, shape, stride: int, lim: float) -> np.ndarray | None:
        """Block means of the flare's source part of the last :meth:`working` frame."""
        rgb = self._last_rgb
        if rgb is None or rgb.shape[:2] != tuple(shape[:2]):
            return None
        return met.block_means(source_part(rgb, 1.0, lim), int(stride))

    def scene_levels(self, source, scale: float, spec: met.MeteringSpec,
                     illuminant: bool, proxy_stride: int = 0) -> Levels:
        """:meth:`working` of a band source, read whole (the reference has no bands)."""
        lv = self.working(source[0:source.shape[0]], scale, spec, proxy_stride=proxy_stride)
        illum = lv.illuminant() if illuminant else None
        return Levels(None, lv.repairs, lv.goal, None if illum is None else (lambda: illum),
                      lv.max_Y, lv.proxy, lv.max_Ys)

    def working_rows(self, pixels: np.ndarray, scale: float) -> np.ndarray:
        rgb, _ = sanitize(pixels[..., :3], scale)
        return np.asarray(rgb, np.float32)


class PointwiseSchedule(NoPixelState):
    """Colour, metering, the host's state step, one per-pixel map (float64). Also the
    OpenCL backend's schedule for an operator without a kernel."""

    #: chromatic adaptation's gains go on the cone signals before the map (Eq. 6).
    receptor_gains = True
    streams = False
    encodes_output = False
    applies_stored = True

    def __init__(self, backend, op):
        self.backend, self.op = backend, op

    def measure(self, frame, spec: met.MeteringSpec, want_illuminant: bool = False) -> FrameStats:
        rgb, repairs = sanitize(frame.pixels[..., :3], frame.scale)
        Y, Ys = photopic_luminance(rgb), scotopic_luminance(rgb)
        h, w = Y.shape
        G_rod, G_cone = met.reference_goal(Y, Ys, spec, _mask(spec, w, h))
        return FrameStats(w, h, G_rod, G_cone, repairs,
                          lambda: durand2000.illuminant_estimate_reference(rgb),
                          handle=(frame.pixels, rgb, Y, Ys))

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        self.op.integrate(state, stats, dt, fresh)

    def apply(self, frame, state, stats, params, gains=None, sink=None, encoding=None):
        px, rgb, Y, Ys = stats.handle if stats.handle is not None and \
            stats.handle[0] is frame.pixels else (None, *self._working(frame))
        if gains is not None:                      # Eq. 6: cone signals only
            rgb = rgb * np.asarray(gains, np.float64)
            Y = photopic_luminance(rgb)
        out = self.op.map_reference(rgb, Y, Ys, params).astype(np.float32)
        if sink is not None:
            sink(0, out)
            return None
        return out

    @staticmethod
    def _working(frame):
        rgb, _ = sanitize(frame.pixels[..., :3], frame.scale)
        return rgb, photopic_luminance(rgb), scotopic_luminance(rgb)
