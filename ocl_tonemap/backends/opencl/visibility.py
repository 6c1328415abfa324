"""``run --visibility``'s planes on an OpenCL device (kernels/visibility.cl), the steps
of ``models/visibility_map.reference_planes`` in float32:

1. the scene's photopic luminance: the frame through the backend's colour stage
   (``to_working``; its bad-value policy, as every stage's);
2. the target's and the surround's grids: block means (``vis_block_means``) blurred
   along x and y with reflected edges (``convolution.cl`` ``blur_axis``);
3. the veil's cells: their block means, then the veil of the whole field at their
   centres: a GPU sums every cell's weighted light (``vis_veil_cells``); a CPU device
   hands the cells (120 x 68 at 1080p and 50 degrees, 32 KiB) to the host's FFT,
   which is faster there than the sum; ``--veil-halo`` adds the flare's halo on the
   host;
4. per pixel (``vis_planes``): the three grids brought back bilinearly, the
   background, log2 dL_th from the run's tables (``threshold_tables.threshold_tables``:
   Adrian's threshold x a global observer's TAF, made on the host each frame, ~110
   KiB), or for ledda04 TAF from its per-pixel state where it is (``OBSERVER_LEDDA04``:
   ledda04.cl's observer), the visibility level; the five planes as half or float
   samples, interleaved as the EXR stores them, come down once.

An operator whose per-pixel observer has no kernel (a plugin's) gets the host's
planes (``backends.base.planes_on_host``).
"""

from __future__ import annotations

import math

import numpy as np

from ...models import adrian1989 as ad
from ...models import threshold_tables as tt
from ...models import visibility_map as vmap
from ...models.cie146 import field_veil
from ...models.convolution import EDGE_REFLECT
from ..base import VisibilityPlanes, VisibilityRequest, planes_on_host
from .runtime import frame_params, round_up
from .transfers import host_buffer, transfer

#: Where the veil's cells are convolved on a CPU device: the host's FFT (a 1080p
#: frame's 8160 cells: ~1 ms, against tens of ms for the device's sum over every pair
#: of cells on 2 cores; a GPU sums them in well under a millisecond).
HOST_VEIL = True

#: Constants of kernels/visibility.cl, as build options (never retyped).
KERNEL_CONSTANTS = (("TAF_LOG2_MAX", math.log2(ad.TAF_MAX)),
                    ("LB_FLOOR", vmap.LB_FLOOR), ("VIS_HALF_MAX", vmap.HALF_MAX))


def _log2(s: int) -> int:
    """log2 of a grid's step (a power of two: visibility_map.blur_step, veil_step)."""
    if s < 1 or s & (s - 1):
        raise ValueError(f"a grid's step must be a power of two (got {s})")
    return s.bit_length() - 1


class DeviceVisibility:
    """The planes of whole frames on ``backend``'s device (its pool's buffers: ``vis_``)."""

    def __init__(self, backend):
        self.be = backend
        self.rt = rt = backend.rt
        self._k_means = rt.kernel("visibility.cl", "vis_block_means", KERNEL_CONSTANTS)
        self._k_veil = rt.kernel("visibility.cl", "vis_veil_cells", KERNEL_CONSTANTS)
        self._k_blur = rt.kernel("convolution.cl", "blur_axis")
        self._weights = {}                    # id(recipe) -> (recipe, device weights)
        self._last = None                     # (planes, their device buffer, half)
        self.host_veil = HOST_VEIL and rt.vector_pixels

    def _planes_kernel(self, half: bool, observer):
        defs = KERNEL_CONSTANTS + (("VIS_HALF", int(half)),)
        if observer is None:
            return self.rt.kernel("visibility.cl", "vis_planes", defs)
        file, consts = observer[:2]
        return self.rt.kernel(f"{file}+visibility.cl", "vis_planes",
                              tuple(consts) + defs + (("OBSERVER_LEDDA04", 1),))

    def _means(self, src, w: int, h: int, s: int, unit: float, name: str):
        """(buffer, cw, ch) of ``src``'s s x s block means x ``unit`` (``src`` itself at
        s = 1 and unit 1)."""
        if s == 1 and unit == 1.0:
            return src, w, h
        cw, ch = -(-w // s), -(-h // s)
        out = self.be.buffer(name, cw * ch * 4)
        self._k_means(self.rt.queue, (round_up(cw, 8), round_up(ch, 8)), (8, 8), src,
                      np.int32(w), np.int32(h), np.int32(s), np.float32(unit), out,
                      np.int32(cw), np.int32(ch))
        return out, cw, ch

    def _grid(self, Y, w: int, h: int, s: int, taps, unit: float, name: str):
        """A target's or a surround's grid: block means blurred by ``taps`` (reflected)."""
        g, cw, ch = self._means(Y, w, h, s, unit, name)
        if len(taps) > 1:
            q = self.rt.queue
            src = g
            if g is Y:                            # (never blur the luminance in place)
                g = self.be.buffer(name, w * h * 4)
            tmp = self.be.buffer(name + ":tmp", cw * ch * 4)
            tb = self.be.constant(np.asarray(taps, np.float32))
            gs = (round_up(cw, 16), round_up(ch, 4))
            for axis, (a, b) in enumerate(((src, tmp), (tmp, g))):
                self._k_blur(q, gs, (16, 4), a, b, np.int32(cw), np.int32(ch), tb,
                             np.int32(len(taps) - 1), np.int32(axis), np.int32(EDGE_REFLECT))
        return g, cw, ch

    def _veil(self, Y, w: int, h: int, unit: float, req: VisibilityRequest):
        """(device veil cells, their float64 host copy)."""
        r = req.recipe
        cells, cw, ch = self._means(Y, w, h, r.veil_step, unit, "vis_veil_means")
        q = self.rt.queue
        if self.host_veil or req.halo is not None:
            L = np.empty((ch, cw), np.float32)
            transfer(q, L, cells)
            veil = field_veil(L.astype(np.float64), r.veil_weights)
            if req.halo is not None:
                veil = veil + req.halo(L.astype(np.float64))
            out = self.be.buffer("vis_veil", cw * ch * 4)
            transfer(q, out, np.ascontiguousarray(veil, np.float32))
            return out, veil
        key = id(r)
        if self._weights.get(key, (None,))[0] is not r:
            self._weights = {key: (r, host_buffer(self.rt.context,
                                                  r.veil_weights.astype(np.float32)))}
        out = self.be.buffer("vis_veil", cw * ch * 4)
        self._k_veil(q, (round_up(cw, 8), round_up(ch, 8)), (8, 8), cells, np.int32(cw),
                     np.int32(ch), self._weights[key][1], out)
        veil = np.empty((ch, cw), np.float32)
        transfer(q, veil, out)
        return out, veil.astype(np.float64)

    def planes(self, req: VisibilityRequest) -> VisibilityPlanes | None:
        """The planes of ``req`` (a whole frame), or None where its observer is per
        pixel and has no kernel (the caller makes them on the host)."""
        op = req.op
        observer = None
        if op.observer_per_pixel:
            get = getattr(req.schedule, "visibility_observer", None)
            observer = get() if get is not None else None
            if observer is None:
                return None
        be, q = self.be, self.rt.queue
        h, w = req.pixels.shape[:2]
        n = h * w
        kept = be.kept_scene_luminance(req.pixels)
        if kept is None:                                  # the colour stage again
            be.to_working(req.pixels, req.scale, count=False)
            kept = be.bufs["Y"], req.scale
        Y, unit = kept[0], req.scale / kept[1]            # (the media's gain undone)
        r, view = req.recipe, req.view
        g = view.media_gain
        tg = self._grid(Y, w, h, r.target_step, r.target_taps, unit, "vis_target")
        sg = self._grid(Y, w, h, r.surround_step, r.surround_taps, unit, "vis_surround")
        vg, veil_cells = self._veil(Y, w, h, unit, req)
        vh, vw = r.veil_shape
        obs = req.observer() if observer is None else None
        seg, tab = tt.threshold_tables(op, obs, view)
        tb = be.buffer("vis_tables", tab.nbytes)
        transfer(q, tb, np.ascontiguousarray(tab))
        sb = be.constant(np.append(seg.as_buffer(), len(seg.nodes)))
        params = np.zeros(16, np.float32)
        params[:3] = g, 0.0, len(seg.nodes)
        if observer is None:
            params[1] = float(op.observer_level(obs)) / g
            state, stride = tb, 0
        else:
            _, _, state, stride, params[3] = observer
        half = np.dtype(req.dtype) == np.float16
        out = be.buffer("vis_out", n * 5 * (2 if half else 4))
        clamped = be.buffer("vis_clamped", 4)
        import pyopencl as cl
        cl.enqueue_fill_buffer(q, clamped, np.int32(0), 0, 4)
        i32 = np.int32
        quads = -(-w // 4) if self.rt.vector_pixels else w
        self._planes_kernel(half, observer)(
            q, (round_up(quads, 16), round_up(h, 4)), (16, 4), i32(w), i32(h),
            tg[0], i32(tg[1]), i32(tg[2]), i32(_log2(r.target_step)),
            sg[0], i32(sg[1]), i32(sg[2]), i32(_log2(r.surround_step)),
            vg, i32(vw), i32(vh), i32(_log2(r.veil_step)), sb, tb, state, i32(stride),
            frame_params(params), out, clamped)
        data = np.empty((h, w, 5), np.float16 if half else np.float32)
        transfer(q, data, out)
        c = np.empty(1, np.int32)
        transfer(q, c, clamped)
        planes = VisibilityPlanes(data, veil_cells, int(c[0]))
        self._last = (planes, out, half)
        return planes

    def view(self, planes: VisibilityPlanes, shown: np.ndarray, paint, u8: bool):
        """``vis_view`` of the planes :meth:`planes` made last (their VL where it still
        is: the view's only upload is the shown frame's codes), or None for others."""
        if self._last is None or self._last[0] is not planes:
            return None
        _, buf, half = self._last
        h, w = planes.data.shape[:2]
        a = np.ascontiguousarray(np.asarray(shown)[..., :3])
        bits = {np.dtype(np.uint8): 8, np.dtype(np.uint16): 16}.get(a.dtype, 0)
        if not bits:
            a = a.astype(np.float32)
        be, q = self.be, self.rt.queue
        src = be.buffer("vis_shown", a.nbytes)
        transfer(q, src, a)
        out = np.empty((h, w, 3), np.uint8 if u8 else np.float32)
        dst = be.buffer("vis_view", out.nbytes)
        k = self.rt.kernel("visibility.cl", "vis_view", KERNEL_CONSTANTS + (
            ("VIS_HALF", int(half)), ("SHOWN_BITS", bits), ("VIEW_U8", int(u8))))
        k(q, (round_up(w, 16), round_up(h, 4)), (16, 4), src, np.int32(w), np.int32(h), buf,
          be.constant(paint.as_array()), np.int32(paint.step), dst)
        transfer(q, out, dst)
        return out


def _array_key(a) -> tuple | None:
    """What makes a host array the same frame: its memory, shape, type and strides."""
    if not isinstance(a, np.ndarray):
        return None
    return (a.__array_interface__["data"][0], a.shape, a.dtype.str, a.strides)


class VisibilityStage:
    """The OpenCL backend's visibility planes (its mixin): :class:`DeviceVisibility`
    made on first use, fed the luminance the frame's own colour stage made."""

    def visibility(self, request: VisibilityRequest) -> VisibilityPlanes:
        """The planes of a whole frame on the device, or the host's where the operator's
        per-pixel observer has no kernel."""
        if self._visibility is None:
            self._visibility = DeviceVisibility(self)
        planes = self._visibility.planes(request)
        return planes if planes is not None else planes_on_host(request)

    def visibility_view(self, planes: VisibilityPlanes, shown: np.ndarray, paint,
                        u8: bool):
        """The view's pixels on the device, from the planes just made there."""
        return None if self._visibility is None else \
            self._visibility.view(planes, shown, paint, u8)

    def keep_scene_luminance(self, pixels) -> None:
        """Keep the luminance the next colour stage of ``pixels`` (the very array,
        whole) makes, for the planes: no second upload and colour stage of the frame."""
        self._keep = _array_key(pixels) if pixels is not None else None
        self._kept = None

    def keep_luminance_of(self, band, scale: float, n: int) -> None:
        """After a colour stage of ``band`` (``to_working``): its luminance copied aside
        where it is the frame :meth:`keep_scene_luminance` named (the frame's later
        colour stages write over ``bufs["Y"]``)."""
        if self._keep is None or _array_key(band) != self._keep:
            return
        import pyopencl as cl
        kept = self.buffer("vis_scene_Y", n * 4)
        cl.enqueue_copy(self.rt.queue, kept, self.bufs["Y"], byte_count=n * 4)
        self._kept = (self._keep, float(scale), kept)

    def kept_scene_luminance(self, pixels):
        """(device buffer of ``pixels``' luminance, the scale it was made at) where
        :meth:`keep_scene_luminance` kept it, else None."""
        k = self._kept
        return None if k is None or k[0] != _array_key(pixels) else (k[2], k[1])
