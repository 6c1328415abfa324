"""The fast flare on an OpenCL runtime (kernels/flare.cl): the frame goes up once,
the source part, the pyramid, its Gaussians and the flared frame are made on the
device, and the flared frame comes down once. The halo ring (f3), on a small level,
is summed over its few nonzero samples there too. What is computed is
:func:`~ocl_tonemap.models.spencer1995.fast_plan`'s plan; the reference is
:func:`~ocl_tonemap.backends.flare_exec.convolve_fast` (float64), whose pyramid
geometry this uses."""

from __future__ import annotations

import numpy as np

from ...models import spencer1995 as fl
from ...models.convolution import gaussian_taps
from .. import flare_exec as fx
from .flare_level0 import FlareLevel0
from .image import DeviceImage
from .runtime import round_up
from .stats import statistics
from .transfers import ConstantBuffers, host_buffer, transfer

#: Bytes of device memory per pixel of the frame, at most (the pyramid written out:
#: source part, accumulator and blur scratch as float4, 4/3 of the frame each, the
#: scratch 1; the frame in and out as float3). The fused level 0 holds less: levels
#: from 1 up (~11 bytes a pixel) and one band's planes.
BYTES_PER_PIXEL = 16 * (4 / 3 + 4 / 3 + 1) + 24


#: A CPU device's ring sums over each nonzero sample of its level, a cost that grows
#: with the sources; where they are more than this share of the frame's pixels the
#: host's FFT makes it instead (its level down and up: 2 x 140 KiB at 1080p). A GPU
#: always sums. (Measured on 2 cores at 1920 x 1080, a frame's time with the sum
#: against the FFT: the same at 7 % sources, +1.3 ms at 14 %, +12 ms at 28 %.)
RING_HOST_SHARE = 0.15


class DeviceFlare(FlareLevel0):
    """``apply(rgb, plan, lim)``: the fast flare of one frame on the device; its
    buffers come from the backend's pool (``buffer(name, nbytes)``, grown as needed),
    and its pyramids and bands go back to it after each frame (``release(prefix)``),
    levels 2 and up already before level 0: scratch that the operator and the later
    effects then do not hold beside their own (on a CPU device, host memory)."""

    def __init__(self, rt, buffer, release=None, spare=None):
        import pyopencl as cl
        self.rt = rt
        self._consts = ConstantBuffers(rt.context)
        self._pool = buffer
        self._release = release
        #: ``spare(nbytes)``: where a resident frame's flared frame may go (the colour
        #: stage's spent upload buffer: ``OpenCLBackend._spare_frame``), or None
        self._spare = spare
        names = ("flare_source", "flare_down", "flare_up", "flare_blur_x", "flare_blur_y_add",
                 "flare_add", "flare_finish", "flare_down_src", "flare_tiles_x",
                 "flare_tiles_y", "flare_nonzero", "flare_ring")
        self._k = {n: rt.kernel("flare.cl", n, self._defines()) for n in names}
        self._k_sum4 = rt.kernel("metering.cl", "sum4_final")
        wg = int(rt.device.max_work_group_size)
        self.local = 1 << (min(256, max(1, wg)).bit_length() - 1)
        self._scratch = cl.LocalMemory(16 * self.local)
        self._scratch64 = cl.LocalMemory(16 * 64)          # flare_finish0's 16 x 4 groups
        self._started = None                  # start()'s passes: (key, what they made)
        self._taps: dict = {}                 # sigma -> (taps buffer, radius)
        self._level0_kernels: dict = {}       # level 0's widths -> (kernels, radius)
        self._ring_k = None                   # ((level size, angle), the f3 kernels)

    @classmethod
    def _defines(cls) -> tuple:
        return (("TILE0", cls.TILE0),)

    def fits(self, h: int, w: int) -> bool:
        """Whether a frame of h x w fits the device (else the host-driven path, in bands)."""
        n = h * w
        return (16 * n <= self.rt.max_alloc_bytes()
                and BYTES_PER_PIXEL * n <= 0.6 * self.rt.global_mem_bytes())

    def _buf(self, name: str, nbytes: int):
        return self._pool(f"flare:{name}", max(int(nbytes), 16))

    def _tap_buf(self, sigma: float):
        key = float(sigma)
        if key not in self._taps:
            t = np.asarray(gaussian_taps(sigma), np.float32)
            self._taps[key] = (host_buffer(self.rt.context, t), len(t) - 1)
        return self._taps[key]

    def _sums_later(self, buf, groups: int):
        """The sum of ``groups`` float4 partials, finished on the device and put in the
        frame's statistics (``stats.py``): a function that gives it (float64, 4)."""
        out = self._buf("sum4", 16)
        self._k_sum4(self.rt.queue, (self.local,), (self.local,), buf, np.int32(groups), out,
                     self._scratch)
        got = statistics(self.rt).put(out, 16, np.float32)
        return lambda: got.get().astype(np.float64)

    def start(self, rgb, plan: fl.FastPlan, lim: float) -> None:
        """Enqueue the first passes of :meth:`apply` of a frame left on the device (its
        source part to level 1, the decimations to the top) and return at once: the
        device works on them while the host plans the frame (``pipeline``). The next
        :meth:`apply` of the same frame, plan and threshold goes on from them; anything
        else first drops them (:meth:`discard`)."""
        self.discard()
        if isinstance(rgb, DeviceImage):
            self._started = (self._first_key(rgb, plan, lim),
                             self._first_passes(rgb.buffer, rgb.shape[:2], plan, lim, True))

    def discard(self) -> None:
        """Drop passes :meth:`start` left for an :meth:`apply` that did not come (the
        plan skipped the flare): their scratch goes back to the pool."""
        if self._started is not None:
            self._started = None
            self._release_scratch()

    @staticmethod
    def _first_key(rgb, plan: fl.FastPlan, lim: float) -> tuple:
        return (id(rgb.buffer), tuple(rgb.shape[:2]), tuple(plan.shape), plan.top, plan.lring,
                float(lim))

    def _first_passes(self, d_rgb, shape, plan: fl.FastPlan, lim: float, downs: bool):
        """The source part made into level 1 (the fused path) or level 0, its sums (on
        their way down with the frame's statistics), and with ``downs`` the decimations
        to the top: (S, stored, fused, a function giving the sums, occ, downs made)."""
        q, k, L = self.rt.queue, self._k, self.local
        h, w = shape
        n = h * w
        groups = round_up(n, L) // L
        sizes = fx.level_sizes(plan.shape, plan.top)
        stored = [(sizes[l][0] + 2 * fx.level_margin(l), sizes[l][1] + 2 * fx.level_margin(l))
                  for l in range(plan.top + 1)]
        # fused: level 0's source part is never whole (16 bytes a pixel): level 1 is made
        # from the frame, level 0 band by band in _finish0 (the ring on level 0 of a
        # tiny frame, or no level 1: the pyramid as it is written out, below)
        fused = plan.lring != 0 and plan.top >= 1
        S = [None if (fused and l == 0) else self._buf(f"S{l}", 16 * hh * ww)
             for l, (hh, ww) in enumerate(stored)]
        occ = None
        if fused:
            ch, cw = stored[1]
            groups = (round_up(cw, 16) // 16) * (round_up(ch, 4) // 4)
            part = self._buf("partial", 16 * groups)
            occ = self._buf("occ", ch * cw)
            k["flare_down_src"](q, (round_up(cw, 16), round_up(ch, 4)), (16, 4), d_rgb,
                                np.int32(w), np.int32(h), np.float32(lim), S[1], np.int32(cw),
                                np.int32(ch), np.int32(fx.level_margin(1)), occ, part,
                                self._scratch64)
        else:
            part = self._buf("partial", 16 * groups)
            k["flare_source"](q, (groups * L,), (L,), d_rgb, np.int32(n), np.float32(lim),
                              S[0], part, self._scratch)
        ssum = self._sums_later(part, groups)       # comes down with the plan's read
        if downs:
            self._downs(S, stored, fused, plan)
        return S, stored, fused, ssum, occ, downs

    def _downs(self, S, stored, fused: bool, plan: fl.FastPlan) -> None:
        for l in range(2 if fused else 1, plan.top + 1):
            (fh, fw), (ch, cw) = stored[l - 1], stored[l]
            self._k["flare_down"](self.rt.queue, (round_up(cw, 16), round_up(ch, 4)), (16, 4),
                                  S[l - 1], np.int32(fw), np.int32(fh),
                                  np.int32(fx.level_margin(l - 1)), S[l], np.int32(cw),
                                  np.int32(ch), np.int32(fx.level_margin(l)))

    def apply(self, rgb: np.ndarray, plan: fl.FastPlan, lim: float):
        """(flared frame or None when no pixel is a source, sources, S sum (3), a function
        giving the F sum (3): it comes down with the frame's next statistics).
        ``rgb``: (H, W, 3) working rgb, cd/m^2, a host array or a :class:`DeviceImage`
        (then read where it is, and the flared frame is a DeviceImage too: it does not
        come to the host); ``lim``: the source threshold, cd/m^2 (threshold x L_wa).
        Goes on from :meth:`start`'s passes where they are of this frame."""
        q, k, L = self.rt.queue, self._k, self.local
        resident = isinstance(rgb, DeviceImage)
        if not resident:
            rgb = np.ascontiguousarray(rgb[..., :3], np.float32)
        h, w = rgb.shape[:2]
        n = h * w
        started, self._started = self._started, None
        if resident and started is not None and started[0] == self._first_key(rgb, plan, lim):
            d_rgb = rgb.buffer
            S, stored, fused, ssum, occ, downs = started[1]
        else:
            if started is not None:
                self._release_scratch()
            if resident:                        # already on the device: read it there
                d_rgb = rgb.buffer
            else:
                d_rgb = self._buf("rgb", 12 * n)
                transfer(q, d_rgb, rgb)
            S, stored, fused, ssum, occ, downs = self._first_passes(
                d_rgb, (h, w), plan, lim, False)
        ssum = ssum()
        sources = int(round(ssum[3]))
        if sources == 0:
            self._release_scratch()
            return None, 0, ssum[:3], lambda: np.zeros(3)
        if not downs:
            self._downs(S, stored, fused, plan)
        acc, have = None, False
        for l in range(plan.top, 0 if fused else -1, -1):
            hh, ww = stored[l]
            gs = (round_up(ww, 16), round_up(hh, 4))
            a = self._buf(f"acc{l}", 16 * hh * ww)
            if have:
                (ch, cw) = stored[l + 1]
                k["flare_up"](q, gs, (16, 4), acc, np.int32(cw), np.int32(ch),
                              np.int32(fx.level_margin(l + 1)), a, np.int32(ww), np.int32(hh),
                              np.int32(fx.level_margin(l)))
            for sc, wk in plan.by_level.get(l, []):
                taps, R = self._tap_buf(sc)
                tmp = self._buf("tmp", 16 * stored[l][0] * stored[l][1])
                k["flare_blur_x"](q, gs, (16, 4), S[l], tmp, np.int32(ww), np.int32(hh), taps,
                                  np.int32(R))
                k["flare_blur_y_add"](q, gs, (16, 4), tmp, a, np.int32(ww), np.int32(hh), taps,
                                      np.int32(R), np.float32(wk), np.int32(0 if have else 1))
                have = True
            if l == plan.lring:
                ring = (self._ring_host if self._host_ring(sources, n) else self._ring)(
                    S[l], hh, ww, plan.deg_per_px * 2.0 ** l, plan.w3)
                if have:
                    k["flare_add"](q, (round_up(hh * ww, L),), (L,), a, ring,
                                   np.int32(hh * ww))
                else:
                    transfer(q, a, ring)
                have = True
            acc = a if have else None
        d_out = self._spare(12 * n) if resident and self._spare is not None else None
        if d_out is None:                       # (a Buffer's truth is not asked)
            d_out = self._buf("out", 12 * n)
        if fused:
            if self._release is not None:       # level 0 needs level 1's accumulator only
                self._release("flare:S", *(f"flare:acc{l}" for l in range(2, plan.top + 1)))
                S = None                        # (freed once their kernels have run)
            part, groups = self._finish0(d_rgb, lim, acc, stored, plan, h, w, d_out, occ)
        else:
            groups = round_up(n, L) // L
            part = self._buf("partial", 16 * groups)
            k["flare_finish"](q, (groups * L,), (L,), d_rgb, S[0], acc if have else S[0],
                              np.int32(1 if have else 0), np.float32(plan.a0), np.int32(n),
                              d_out, part, self._scratch)
        fsum = self._sums_later(part, groups)       # comes down with the next read
        self._release_scratch()
        if resident:                            # stays on the device for the operator
            out = DeviceImage(self.rt, d_out, (h, w, 3))
        else:
            out = np.empty((h, w, 3), np.float32)
            transfer(q, out, d_out)
        return out, sources, ssum[:3], lambda: fsum()[:3]

    def _release_scratch(self) -> None:
        """The pyramids and bands go back to the pool: scratch of this frame only."""
        if self._release is not None:
            self._release("flare:S", "flare:acc", "flare:tmp", "flare:partial0")

    def _host_ring(self, sources: int, n: int) -> bool:
        import pyopencl as cl
        return bool(self.rt.device.type & cl.device_type.CPU) and sources > RING_HOST_SHARE * n

    def _ring_host(self, S_buf, hh: int, ww: int, deg_per_px: float, w3: float):
        """:meth:`_ring` by an FFT on the host (its level down and the ring up again):
        where a CPU device would sum over many sources."""
        lv = np.empty((hh, ww, 4), np.float32)
        transfer(self.rt.queue, lv, S_buf)
        ring = np.zeros((hh, ww, 4), np.float32)
        for c in range(3):
            ring[..., c] = w3 * fx.fftconvolve_same(lv[..., c].astype(np.float64), None,
                                                    fx.ring_kernel_fft((hh, ww), deg_per_px, c))
        buf = self._buf("ring", ring.nbytes)
        transfer(self.rt.queue, buf, ring)
        return buf

    def _ring(self, S_buf, hh: int, ww: int, deg_per_px: float, w3: float):
        """w3 f3 * S on a level (stored size hh x ww), on the device: its nonzero samples
        listed (``flare_nonzero``), each output sample summed over them
        (``flare_ring``) with the f3 kernels, uploaded once per level size and angle."""
        import pyopencl as cl
        q = self.rt.queue
        n = hh * ww
        key = (hh, ww, float(deg_per_px))
        if self._ring_k is None or self._ring_k[0] != key:
            K = np.stack([fl.basis_kernel(fl.channel_bases(c)[3], (hh, ww), deg_per_px)
                          for c in range(3)]).astype(np.float32)
            self._ring_k = (key, host_buffer(self.rt.context, K))
        off, val = self._buf("ring_off", 4 * n), self._buf("ring_val", 16 * n)
        cnt = self._buf("ring_count", 4)
        L = self.local
        self._k["flare_nonzero"](q, (L,), (L,), S_buf, np.int32(n), np.int32(ww), off, val,
                                 cnt, cl.LocalMemory(4 * L))
        buf = self._buf("ring", 16 * n)
        self._k["flare_ring"](q, (round_up(ww, 16), round_up(hh, 4)), (16, 4), np.int32(ww),
                              np.int32(hh), off, val, cnt, self._ring_k[1], np.float32(w3),
                              buf)
        return buf
