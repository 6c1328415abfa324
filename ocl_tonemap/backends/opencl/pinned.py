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

import sys
import threading

import numpy as np


def _free(arrs: list, i: int) -> bool:
    """Whether the list's own reference is the only one (getrefcount adds its argument's)."""
    return sys.getrefcount(arrs[i]) <= 2


class HostArrays:
    """Host arrays for transfers to and from ``rt``'s device: page-locked where it is
    not a CPU, at most ``keep`` of them kept for reuse (a run's frames in flight)."""

    def __init__(self, rt, keep: int = 4, pinned: bool | None = None):
        import pyopencl as cl
        self.rt, self.keep = rt, int(keep)
        self.pinned = not bool(rt.device.type & cl.device_type.CPU) if pinned is None \
            else bool(pinned)
        self._owners: list[np.ndarray] = []
        self._lock = threading.Lock()
        self.made = 0                          # page-locked arrays allocated

    def empty(self, shape, dtype=np.float32, tail: int = 0) -> np.ndarray:
        """An array of ``shape`` and ``dtype`` (contents undefined) with ``tail`` bytes
        of the same memory after it (``stats.TAIL``: an output's statistics)."""
        shape, dtype = tuple(int(v) for v in shape), np.dtype(dtype)
        n = int(np.prod(shape)) * dtype.itemsize
        need = max(n + int(tail), 1)
        if not self.pinned:
            return np.empty(need, np.uint8)[:n].view(dtype).reshape(shape)
        with self._lock:
            arrs = self._owners
            owner = None
            for i in range(len(arrs)):         # (by index: a name is a reference)
                if arrs[i].nbytes == need and _free(arrs, i):
                    owner = arrs[i]
                    break
            if owner is None:
                if len(arrs) >= self.keep:     # free arrays of another size make room
                    self._owners = arrs = [arrs[i] for i in range(len(arrs))
                                           if arrs[i].nbytes == need or not _free(arrs, i)]
                owner = self._map(need)
                if len(arrs) < self.keep:
                    arrs.append(owner)
        return owner[:n].view(dtype).reshape(shape)

    def _map(self, nbytes: int) -> np.ndarray:
        import pyopencl as cl
        mf = cl.mem_flags
        nbytes = max(int(nbytes), 1)
        buf = cl.Buffer(self.rt.context, mf.READ_WRITE | mf.ALLOC_HOST_PTR, nbytes)
        arr, ev = cl.enqueue_map_buffer(self.rt.queue, buf,
                                        cl.map_flags.READ | cl.map_flags.WRITE, 0,
                                        (nbytes,), np.uint8)
        ev.wait()
        self.made += 1
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
