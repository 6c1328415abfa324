"""kirk11 in float64: Eqs. 8-16, the exact bilateral base, the composition."""

from __future__ import annotations

import numpy as np

from ...models import durand2000, kirk2011 as K, lmsr
from ...models.bilateral import RangeKernel, bilateral_reference
from ...models.photometry import sanitize
from ...operators.base import FrameStats
from ..base import NoPixelState


class KirkSchedule(NoPixelState):
    """kirk11 in float64: Eqs. 8-16, exact bilateral base, composition."""

    receptor_gains = False
    streams = False
    encodes_output = False

    def __init__(self, backend, op):
        self.backend, self.op = backend, op

    @staticmethod
    def _lmsr(frame):
        """(working rgb or None for a spectral frame, LMSR, repairs) of ``frame``."""
        if frame.wavelengths is not None:
            sp, repairs = sanitize(frame.pixels, frame.scale)
            return None, lmsr.spectral_to_lmsr(frame.wavelengths, sp), repairs
        src, repairs = sanitize(frame.pixels[..., :3], frame.scale)
        return src, lmsr.rgb_to_lmsr(src), repairs

    def measure(self, frame, spec=None, want_illuminant: bool = False) -> FrameStats:
        src, q, repairs = self._lmsr(frame)
        h, w = q.shape[:2]
        return FrameStats(w, h, *K.level_logmeans(q), repairs,
                          handle=(frame.pixels, src, q))

    def integrate(self, state, stats, dt: float, fresh: bool) -> None:
        self.op.integrate(state, stats, dt, fresh)

    def apply(self, frame, state, stats, params=None, gains=None, sink=None, encoding=None):
        op, s, v = self.op, self.op.settings, stats.values
        px, src, q = stats.handle
        if px is not frame.pixels:      # a frame the scene effects changed after metering
            src, q, _ = self._lmsr(frame)
        D = frame.display_primaries if frame.display_primaries is not None else np.eye(3)
        area = K.model_scale()
        q_hat, w = K.purkinje_shift(q, area, v["k1"], v["k2"], s.shift_xyz, v["rod_gain"],
                                    white=not s.paper)
        p, fb = K.solve_display(op.M(D), q_hat, s.paper)
        shift_rgb = p @ np.asarray(D, np.float64).T
        # range reduction of the mesopic image's own luminance (rods add to it)
        logY = np.log10(np.maximum(shift_rgb @ durand2000.Y_WEIGHTS, K.Y_FLOOR))
        h, wd = logY.shape
        base = bilateral_reference(logY, s.sigma_px(wd, h),
                                   RangeKernel("difference", K.SIGMA_RANGE_LOG10))
        out = op.finish(K.compose_reference(src if src is not None else shift_rgb, shift_rgb,
                                            w, logY, base, s, op.display, blend=src is not None),
                        stats)
        v.update(model_scale=area, w_mean=float(w.mean()), fallback_fraction=float(fb.mean()),
                 input="spectral" if frame.wavelengths is not None else "rgb")
        return out.astype(np.float32)
