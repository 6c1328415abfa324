"""Level 0 of the fast flare on an OpenCL runtime (kernels/flare.cl): the frame's own
resolution, made band by band and only in the tiles a source reaches, so that no
level-0 pyramid plane is ever held whole (:class:`~.flare.DeviceFlare`'s mixin)."""

from __future__ import annotations

import numpy as np

from ...models import spencer1995 as fl
from ...models.convolution import gaussian_taps
from .. import flare_exec as fx
from .runtime import round_up


class FlareLevel0:
    """Level 0 of :class:`~.flare.DeviceFlare`: its kernels per set of Gaussian widths
    and the fused pass that makes the flared frame (it uses the flare's ``rt``,
    ``_k``, ``_buf``, ``_consts``, ``_defines``, ``local`` and ``_scratch64``)."""

    #: Level 0's tiles (kernels/flare.cl TILE0): its Gaussians are made only in the
    #: tiles with a source within their reach (``flare_tiles``).
    TILE0 = 8

    #: Level 0's Gaussians are made along x for bands of about this many pixels (their
    #: planes: 16 bytes a pixel each, with the halo rows the y taps reach).
    BAND0_PIXELS = 1 << 17

    #: Level 0's kernels, built for a frame's Gaussians (their count, radii and taps
    #: as compile-time constants: kernels/flare.cl, L0_*), kept per set of widths.
    LEVEL0_KERNELS = ("flare_source_band", "flare_blur0_x", "flare_finish0")

    def _level0(self, plan: fl.FastPlan):
        """(kernels, weights buffer, count, largest radius) of level 0's Gaussians: the
        kernels built per set of widths (a frame size's), the weights (the pupil's)
        made per frame."""
        gs = plan.by_level.get(0, [])
        key = tuple(float(sc) for sc, _ in gs)
        if key not in self._level0_kernels:
            taps, first, radii = [], [], []
            for sc, _ in gs:
                t = np.asarray(gaussian_taps(sc), np.float32)
                first.append(len(taps))
                radii.append(len(t) - 1)
                taps.extend(float(v) for v in t)
            R = max(radii, default=0)
            defines = self._defines() + (("L0_NK", len(gs)), ("L0_RMAX", R))
            if gs:
                defines += (("L0_RADII", tuple(radii)), ("L0_FIRST", tuple(first)),
                            ("L0_TAPS", tuple(taps)))
            self._level0_kernels[key] = ({n: self.rt.kernel("flare.cl", n, defines)
                                          for n in self.LEVEL0_KERNELS}, R)
        from pyopencl import cltypes
        kern, R = self._level0_kernels[key]
        # the pupil's weights change every frame: a kernel argument (float16), no upload
        if len(gs) > 16:                    # (the fit's at most 4 a octave: 16 at most)
            raise ValueError(f"level 0 of the flare has {len(gs)} Gaussians; 16 at most")
        wts = np.zeros(16, np.float32)
        wts[:len(gs)] = [wk for _, wk in gs]
        return kern, cltypes.make_float16(*wts), len(gs), R

    def _finish0(self, d_rgb, lim: float, acc1, stored, plan, h: int, w: int, d_out, occ):
        """Level 0 and the flared frame, band by band: the band's source part
        (``flare_source_band``, padded with zeros), its Gaussians along x
        (``flare_blur0_x``) and the flared rows (``flare_finish0``): no level-0 source
        part, accumulator or planes beyond one band's, and the Gaussians only in the
        tiles with a source within their reach (``flare_tiles``, from level 1's flags
        ``occ``; a night frame's lamps: ~15% of the tiles). Returns the buffer of the
        flare's per-group sums (all bands) and their count."""
        q = self.rt.queue
        k, wts, nk, R = self._level0(plan)
        ch, cw = stored[1]
        cm = fx.level_margin(1)
        T = self.TILE0
        tw, th = -(-w // T), -(-h // T)
        gs = (round_up(tw, 16), round_up(th, 4))
        near = self._buf("tilenear", tw * th)
        self._k["flare_tiles_x"](q, gs, (16, 4), occ, np.int32(cw), np.int32(ch), np.int32(cm),
                                 np.int32(tw), np.int32(th), np.int32(R), near)
        tiles, rows_on = self._buf("tiles", tw * th), self._buf("tilerows", tw * th)
        for out, ry in ((tiles, R), (rows_on, 2 * R + T)):
            self._k["flare_tiles_y"](q, gs, (16, 4), near, np.int32(tw), np.int32(th),
                                     np.int32(-(-ry // T)), out)
        rows = max(1, min(h, self.BAND0_PIXELS // max(w, 1)))
        bands = [(y0, min(h, y0 + rows)) for y0 in range(0, h, rows)]
        quads = (w + 3) // 4                    # blur0_x and finish0: 4 pixels an item
        gcount = [(round_up(quads, 16) // 16) * (round_up(y1 - y0, 4) // 4) for y0, y1 in bands]
        part = self._buf("partial0", 16 * sum(gcount))
        trows_most = min(h, rows) + 2 * R
        # (+ 64 bytes: a short last quad's loads reach past the row)
        tmp = self._buf("tmp", 16 * max(nk, 1) * w * trows_most + 64)
        S0 = self._buf("Sband", 16 * (w + 2 * R) * trows_most + 64)
        if acc1 is None:
            ch, cw = 1, 1
        gbase = 0
        for (y0, y1), g in zip(bands, gcount):
            t0, trows = y0 - R, (y1 - y0) + 2 * R
            k["flare_source_band"](q, (round_up(w + 2 * R, 16), round_up(trows, 4)), (16, 4),
                                   d_rgb, np.int32(w), np.int32(h), np.int32(t0),
                                   np.int32(trows), np.float32(lim), tiles, np.int32(tw), S0)
            if nk:
                k["flare_blur0_x"](q, (round_up(quads, 16), round_up(trows, 4)), (16, 4), S0,
                                   np.int32(w), np.int32(h), np.int32(t0), np.int32(trows),
                                   rows_on, np.int32(tw), tmp)
            k["flare_finish0"](q, (round_up(quads, 16), round_up(y1 - y0, 4)), (16, 4), d_rgb,
                               S0, np.int32(w), np.int32(y0), np.int32(y1 - y0), tmp,
                               np.int32(t0), np.int32(trows), wts,
                               acc1 if acc1 is not None else S0, np.int32(cw), np.int32(ch),
                               np.int32(cm), np.int32(0 if acc1 is None else 1),
                               np.float32(plan.a0), np.int32(h), tiles, np.int32(tw), d_out,
                               part, np.int32(gbase),
                               self._scratch64)
            gbase += g
        return part, gbase
