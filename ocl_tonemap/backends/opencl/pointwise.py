"""Pointwise passes on a frame held on the device (``kernels/colour.cl``), as a mixin of
the OpenCL backend: chromatic gains (``scale_rgb``) and the observer's absolute
threshold (``absolute_threshold_rgb``), in place, their kernels made on first use."""

from __future__ import annotations

import numpy as np

from .image import DeviceImage
from .runtime import round_up


class PointwiseStages:
    """``scale_image`` and ``threshold_image`` (``backends/base.py`` says what each
    does); needs ``self.rt``."""

    def scale_image(self, img: DeviceImage, gains) -> DeviceImage:
        """``img``'s RGB times ``gains`` in place (``colour.cl:scale_rgb``): chromatic
        gains on a frame that stays on the device. A new image of the same buffer comes
        back (another frame to the schedules' residency checks: its colour stage runs
        again)."""
        g = np.asarray(gains, np.float32)
        n = img.shape[0] * img.shape[1]
        if getattr(self, "_scale", None) is None:
            self._scale = self.rt.kernel("colour.cl", "scale_rgb")
        self._scale(self.rt.queue, (round_up(n, 64),), (64,), img.buffer, np.int32(n),
                    g[0], g[1], g[2])
        return DeviceImage(img.rt, img.buffer, img.shape)

    def threshold_image(self, img: DeviceImage, T_rod: float, T_cone: float, beta: float,
                        x_sure: float) -> DeviceImage:
        """``img``'s pixels weighted by the share seen beyond the threshold, in place
        (``colour.cl:absolute_threshold_rgb``; ``models/absolute_threshold.py``)."""
        n = img.shape[0] * img.shape[1]
        if getattr(self, "_threshold", None) is None:
            self._threshold = self.rt.kernel("colour.cl", "absolute_threshold_rgb")
        self._threshold(self.rt.queue, (round_up(n, 64),), (64,), img.buffer, np.int32(n),
                        np.float32(1.0 / T_cone), np.float32(1.0 / T_rod), np.float32(beta),
                        np.float32(x_sure))
        return DeviceImage(img.rt, img.buffer, img.shape)
