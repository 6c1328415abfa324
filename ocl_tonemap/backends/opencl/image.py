"""A frame held on the device between stages of the same frame.

:class:`DeviceImage` is working RGB (cd/m^2, float32, H x W x 3, C order) in a device
buffer. The scene effects that run on the device (the fast flare) take it and give it
back, and the operator's colour stage copies it on the device
(``OpenCLBackend.to_working``), so a flared frame never crosses to the host. A stage
that needs host pixels gets them with ``np.asarray``. It is valid while its buffer is
not written again: the working frame until the backend's next colour stage, the
flared frame until the next flare.
"""

from __future__ import annotations

import numpy as np

from .transfers import transfer


class DeviceImage:
    """``shape`` (H, W, 3) float32 pixels in ``buffer`` on ``rt``'s device."""

    dtype = np.dtype(np.float32)
    ndim = 3

    def __init__(self, rt, buffer, shape):
        self.rt, self.buffer = rt, buffer
        self.shape = tuple(int(s) for s in shape)
        if len(self.shape) != 3 or self.shape[2] != 3:
            raise ValueError(f"a device image is H x W x 3 (got {self.shape})")

    @property
    def nbytes(self) -> int:
        return 4 * self.shape[0] * self.shape[1] * 3

    def __array__(self, dtype=None, copy=None):
        out = np.empty(self.shape, np.float32)
        transfer(self.rt.queue, out, self.buffer)
        return out if dtype is None else out.astype(dtype, copy=False)

    def __getitem__(self, key):
        """The whole frame's rows (``[0:H]``, ``[:]``) are this image; other rows
        (``[a:b]``) come to the host alone (the plan's patches: no whole frame);
        anything else from the host copy."""
        if isinstance(key, slice) and key.step in (None, 1):
            rows = range(*key.indices(self.shape[0]))
            if rows == range(self.shape[0]):
                return self
            out = np.empty((len(rows),) + self.shape[1:], np.float32)
            if len(rows):
                transfer(self.rt.queue, out, self.buffer,
                         src_offset=rows.start * self.shape[1] * 3 * 4)
            return out
        return np.asarray(self)[key]

    def __len__(self) -> int:
        return self.shape[0]

    def patches(self, ys, xs, ph: int, pw: int) -> dict:
        """The ph x pw patches at each (y, x) of ``ys`` x ``xs`` (the plan's full-
        resolution samples): gathered on the device by rectangular copies and read in
        one transfer, not their rows whole. {(y, x): (ph, pw, C) float32}."""
        import pyopencl as cl
        h, w, c = self.shape
        item = 4 * c
        at = [(int(y), int(x)) for y in ys for x in xs]
        out = np.empty((len(at), ph, pw, c), np.float32)
        if not at or ph <= 0 or pw <= 0:
            return {}
        dev = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, out.nbytes)
        for k, (y, x) in enumerate(at):
            cl.enqueue_copy(self.rt.queue, dev, self.buffer, src_origin=(x * item, y, 0),
                            dst_origin=(0, k * ph, 0), region=(pw * item, ph, 1),
                            src_pitches=(w * item, 0), dst_pitches=(pw * item, 0))
        transfer(self.rt.queue, out, dev)
        return {yx: out[k] for k, yx in enumerate(at)}

    def copy_to(self, queue, dst) -> None:
        """Copy the pixels into device buffer ``dst`` (device to device)."""
        transfer(queue, dst, self.buffer, byte_count=self.nbytes)


def device_image(rt, arr) -> DeviceImage | None:
    """A ``pyopencl.array.Array`` of working RGB (H x W x 3 float32, C order, on
    ``rt``'s context) as a :class:`DeviceImage` of its memory (read, never written);
    None where ``arr`` is no device array."""
    import pyopencl.array as cla
    if not isinstance(arr, cla.Array):
        return None
    if arr.context.int_ptr != rt.context.int_ptr:
        raise ValueError("a device array must be on the backend's OpenCL context "
                         "(Tonemapper(...).backend.device_runtime().context)")
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.float32 or \
            not arr.flags.c_contiguous or arr.offset:
        raise ValueError(f"a device array is H x W x 3 float32, C order (got {arr.shape} "
                         f"{arr.dtype})")
    return DeviceImage(rt, arr.base_data, arr.shape)


class DeviceArrayOutput:
    """A frame's display-linear output left on the device: the schedules' output goes
    into a new ``pyopencl.array.Array`` (device to device) in place of a host array.
    It stands where a display encoding would (``fetch``, ``array``, ``dtype``), so the
    acuity blur on the device composes with it."""

    dtype = np.dtype(np.float32)

    def __init__(self, rt, allocator=None):
        self.rt, self.allocator = rt, allocator

    def array(self, h: int, w: int):
        import pyopencl.array as cla
        return cla.empty(self.rt.queue, (h, w, 3), np.float32, allocator=self.allocator)

    def fetch(self, queue, src, n: int, out) -> None:
        """Copy ``n`` pixels of RGB from device buffer ``src`` into ``out`` (a row slice
        of :meth:`array`'s array)."""
        transfer(queue, out.base_data, src, byte_count=12 * n, dst_offset=out.offset)
