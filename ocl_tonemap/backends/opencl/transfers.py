"""Every copy between host memory and a device, counted (issue 47: a frame should
cross once each way). :func:`transfer` stands in for pyopencl's ``enqueue_copy``
and :func:`host_buffer` for a buffer made from host memory; device-to-device copies
are not transfers. Counts are kept per thread (a frame runs in one thread), so a
frame's transfers are the difference of :func:`counted` before and after it."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Transfers:
    """Host-to-device (up) and device-to-host (down) calls and bytes."""

    up_calls: int = 0
    up_bytes: int = 0
    down_calls: int = 0
    down_bytes: int = 0

    def __sub__(self, other: "Transfers") -> "Transfers":
        return Transfers(self.up_calls - other.up_calls, self.up_bytes - other.up_bytes,
                         self.down_calls - other.down_calls,
                         self.down_bytes - other.down_bytes)

    @property
    def calls(self) -> int:
        return self.up_calls + self.down_calls

    def as_dict(self) -> dict:
        return {"up_calls": self.up_calls, "up_bytes": self.up_bytes,
                "down_calls": self.down_calls, "down_bytes": self.down_bytes}


_local = threading.local()


def counted() -> Transfers:
    """This thread's transfers so far."""
    return getattr(_local, "t", Transfers())


def _count(up: bool, nbytes: int) -> None:
    t = counted()
    _local.t = Transfers(t.up_calls + up, t.up_bytes + up * nbytes,
                         t.down_calls + (not up), t.down_bytes + (not up) * nbytes)


def _host_bytes(a, kw: dict) -> int:
    if "byte_count" in kw:
        return int(kw["byte_count"])
    return int(np.asarray(a).nbytes)


def transfer(queue, dest, src, **kw):
    """``pyopencl.enqueue_copy(queue, dest, src, **kw)``, counted where one side is
    host memory."""
    import pyopencl as cl
    if isinstance(dest, np.ndarray):
        _count(False, _host_bytes(dest, kw))
    elif isinstance(src, np.ndarray):
        _count(True, _host_bytes(src, kw))
    return cl.enqueue_copy(queue, dest, src, **kw)


def host_buffer(context, host: np.ndarray):
    """A read-only device buffer made from ``host`` (one upload, counted)."""
    import pyopencl as cl
    host = np.ascontiguousarray(host)
    _count(True, host.nbytes)
    return cl.Buffer(context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                     hostbuf=host)


class ConstantBuffers:
    """Read-only device buffers of small host arrays, kept by content: an array the
    device already holds is not uploaded again (a frame's parameters, tables and
    matrices mostly repeat from frame to frame). At most ``keep`` of them, the least
    recently used given up first."""

    def __init__(self, context, keep: int = 64):
        self.context, self.keep = context, int(keep)
        self._bufs: dict = {}

    def get(self, host: np.ndarray):
        host = np.ascontiguousarray(host)
        key = (host.dtype.str, host.shape, host.tobytes())
        buf = self._bufs.pop(key, None)
        if buf is None:
            buf = host_buffer(self.context, host)
            while len(self._bufs) >= self.keep:
                self._bufs.pop(next(iter(self._bufs)))
        self._bufs[key] = buf                   # (most recent last)
        return buf
