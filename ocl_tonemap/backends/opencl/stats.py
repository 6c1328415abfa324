"""A frame's small statistics, read from the device at a few sync points (issue 47).

Each stage that reduces a frame on the device (the metering sums, the plan's block
means, the flare's sums, a count of repaired or shifted pixels) leaves its finished
values in its own small buffer; :meth:`FrameStatistics.put` copies them, on the
device, into one staging buffer and hands back a :class:`Pending`. The first
:class:`Pending` whose value is asked for reads everything put since the last read
in one transfer: values that are only recorded (the flared sums, a fallback count)
come down with the next values a stage waits for, not in a transfer of their own.
"""

from __future__ import annotations

import threading

import numpy as np

from .transfers import transfer


#: Bytes an output's host array and device buffer keep after the frame, for the
#: statistics that ride its download (:meth:`FrameStatistics.download`).
TAIL = 4096


class Pending:
    """Values put in a :class:`FrameStatistics`: ``get()`` them (a read where they have
    not come yet)."""

    __slots__ = ("_stats", "_offset", "_dtype", "_shape", "_value")

    def __init__(self, stats: "FrameStatistics", offset: int, dtype, shape):
        self._stats, self._offset = stats, offset
        self._dtype, self._shape = np.dtype(dtype), tuple(shape)
        self._value = None

    def _resolve(self, host: np.ndarray) -> None:
        n = int(np.prod(self._shape)) * self._dtype.itemsize
        self._value = host[self._offset:self._offset + n].copy().view(self._dtype) \
            .reshape(self._shape)

    @property
    def ready(self) -> bool:
        return self._value is not None

    def get(self) -> np.ndarray:
        if self._value is None:
            self._stats.read()
        if self._value is None:
            raise RuntimeError("a frame statistic asked for after its frame was over")
        return self._value


class FrameStatistics:
    """The staging buffer of a runtime's statistics (grown as a frame needs; 16-byte
    aligned slots)."""

    ALIGN = 16

    def __init__(self, rt, nbytes: int = 1 << 16):
        self.rt = rt
        self._size = 0
        self._buf = None
        self._used = 0
        self._pending: list[Pending] = []
        self._grow(nbytes)

    def _grow(self, nbytes: int) -> None:
        """A larger staging buffer, holding what was put in the old one."""
        import pyopencl as cl
        old, self._size = self._buf, max(int(nbytes), self._size)
        self._buf = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, self._size)
        if old is not None and self._used:
            cl.enqueue_copy(self.rt.queue, self._buf, old, byte_count=self._used)

    def put(self, src, nbytes: int, dtype, shape=None, src_offset: int = 0) -> Pending:
        """Copy ``nbytes`` of device buffer ``src`` (from ``src_offset``) here, to come
        down with the next read, as ``dtype`` of ``shape`` (default: flat)."""
        import pyopencl as cl
        nbytes = int(nbytes)
        if shape is None:
            shape = (nbytes // np.dtype(dtype).itemsize,)
        if self._used + nbytes > self._size:           # a frame that needs more
            self._grow(max(self._used + nbytes, 2 * self._size))
        off = self._used
        cl.enqueue_copy(self.rt.queue, self._buf, src, byte_count=nbytes, src_offset=src_offset,
                        dst_offset=off)
        self._used = off + -(-nbytes // self.ALIGN) * self.ALIGN
        p = Pending(self, off, dtype, shape)
        self._pending.append(p)
        return p

    def read(self) -> None:
        """Everything put since the last read, in one transfer."""
        if not self._pending:
            return
        host = np.empty(self._used, np.uint8)
        transfer(self.rt.queue, host, self._buf)
        self._resolve_all(host)

    def _resolve_all(self, host: np.ndarray) -> None:
        for p in self._pending:
            p._resolve(host)
        self._pending = []
        self._used = 0

    def drop(self) -> None:
        """A new frame: what the last one put and nobody asked for (a source proxy made
        ahead for a plan that reused its predictions, a flare the plan skipped) does not
        come down with this frame's statistics."""
        self._pending = []
        self._used = 0

    def download(self, host: np.ndarray, buf) -> None:
        """``host`` <- device buffer ``buf`` (a frame's output), with what is pending here
        in the same transfer where ``host`` has :data:`TAIL` bytes of its memory after
        it (``pinned.HostArrays.empty``'s ``tail``) and ``buf`` has as much room after
        the frame: the frame's last statistics (the
        Purkinje shift's fallbacks, the flared sums) come down with its output."""
        import pyopencl as cl
        base = host.base
        if not (self._pending and self._used <= TAIL and isinstance(base, np.ndarray)
                and base.nbytes == host.nbytes + TAIL and host.flags.c_contiguous
                and base.ctypes.data == host.ctypes.data and buf.size >= base.nbytes):
            transfer(self.rt.queue, host, buf)
            return
        cl.enqueue_copy(self.rt.queue, buf, self._buf, byte_count=self._used,
                        dst_offset=host.nbytes)
        whole = base[:host.nbytes + self._used]
        transfer(self.rt.queue, whole, buf)
        self._resolve_all(whole[host.nbytes:])


_local = threading.local()


def statistics(rt) -> FrameStatistics:
    """This thread's staging buffer on runtime ``rt`` (a frame runs in one thread; runs
    in other threads on the same device keep their own)."""
    d = getattr(_local, "d", None)
    if d is None:
        d = _local.d = {}
    s = d.get(id(rt))
    if s is None or s.rt is not rt:
        s = d[id(rt)] = FrameStatistics(rt)
    return s
