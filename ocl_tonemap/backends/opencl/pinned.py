"""Page-locked host memory for a discrete device's transfers (issue 47).

A copy between a GPU and pageable NumPy memory goes through the driver's own staging
at a fraction of the bus's speed; from page-locked memory it is one DMA. The frames a
run reads (``imageio.FramePool`` given :meth:`HostArrays.empty` as its allocator) and
the outputs that come back (``OpenCLBackend.output_array``, the device display
encoding's code values) are made in buffers the driver allocates in host memory
(``ALLOC_HOST_PTR``), mapped once and kept, and used again once nothing refers to them
(CPython's reference count of the mapped array, which every view raises through its
``base``: the frame pool's rule). On a CPU device host memory is the device's memory:
plain NumPy arrays, not kept.
"""

from __future__ import annotations

import threading

import numpy as np

from ...base.reuse import Reused


class HostArrays(Reused):
    """Host arrays for transfers to and from ``rt``'s device: page-locked where it is
    not a CPU, at most ``keep`` of them kept for reuse (a run's frames in flight;
    ``base/reuse.py``: the mapped owner is what is kept, so that every view counts)."""

    def __init__(self, rt, keep: int = 4, pinned: bool | None = None):
        import pyopencl as cl
        super().__init__(keep)
        self.rt = rt
        self.pinned = not bool(rt.device.type & cl.device_type.CPU) if pinned is None \
            else bool(pinned)

    def empty(self, shape, dtype=np.float32, tail: int = 0) -> np.ndarray:
        """An array of ``shape`` and ``dtype`` (contents undefined) with ``tail`` bytes
        of the same memory after it (``stats.TAIL``: an output's statistics)."""
        shape, dtype = tuple(int(v) for v in shape), np.dtype(dtype)
        n = int(np.prod(shape)) * dtype.itemsize
        need = max(n + int(tail), 1)
        if not self.pinned:
            return np.empty(need, np.uint8)[:n].view(dtype).reshape(shape)
        owner = self._take(lambda a: a.nbytes == need, lambda: self._map(need))
        return owner[:n].view(dtype).reshape(shape)

    def _map(self, nbytes: int) -> np.ndarray:
        import pyopencl as cl
        mf = cl.mem_flags
        buf = cl.Buffer(self.rt.context, mf.READ_WRITE | mf.ALLOC_HOST_PTR, nbytes)
        arr, ev = cl.enqueue_map_buffer(self.rt.queue, buf,
                                        cl.map_flags.READ | cl.map_flags.WRITE, 0,
                                        (nbytes,), np.uint8)
        ev.wait()
        return arr


_outputs: dict = {}
_outputs_lock = threading.Lock()


def outputs(rt) -> HostArrays:
    """The runtime's arrays for outputs coming back (shared by the backend and the
    device display encoding of the same device)."""
    with _outputs_lock:
        h = _outputs.get(id(rt))
        if h is None or h.rt is not rt:
            h = _outputs[id(rt)] = HostArrays(rt, keep=6)
        return h
