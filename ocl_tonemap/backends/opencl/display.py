"""The baked display transform on an OpenCL device (kernels/display.cl).

:class:`DeviceDisplayTable` holds one :class:`~ocl_tonemap.colour.DisplayTable` on the
device and encodes frames with it: upload, one kernel, download. It may be called from
any thread (a writer thread of ``job/overlap.py``): it has its own command queue
and kernel object in the chosen device's context, and a lock around each frame.
"""

from __future__ import annotations

import threading

import numpy as np

from .runtime import get_runtime, round_up
from . import pinned
from .stats import TAIL, statistics
from .transfers import host_buffer, transfer

_WG = 64


def code_bits(bits) -> int:
    """8 or 16 (integer code values), else 0 (float); True is 8 (the older ``u8``)."""
    b = 8 if bits is True else int(bits or 0)
    if b not in (0, 8, 16):
        raise ValueError(f"display code values are 8 or 16 bits, or float (got {bits!r})")
    return b


def code_dtype(bits) -> np.dtype:
    return np.dtype({8: np.uint8, 16: np.uint16}.get(code_bits(bits), np.float32))


class DeviceDisplayTable:
    """A display table on the device: :meth:`encode` (H, W, C >= 3) float32 -> code values."""

    def __init__(self, table, runtime=None, device: str | None = None):
        import pyopencl as cl
        if table.kind not in ("1d", "3d"):
            raise ValueError(f"no device form for a {table.kind!r} display table")
        self.table = table
        self.rt = runtime if runtime is not None else get_runtime(device)
        ctx = self.rt.context
        self.queue = cl.CommandQueue(ctx, self.rt.device)
        self._name = "display_lut1d" if table.kind == "1d" else "display_lut3d"
        # RGB through a 1D table: four pixels per work-item (PoCL: ~4x faster)
        self._vector = table.kind == "1d" and bool(self.rt.device.endian_little)
        self._knl: dict = {}
        par = np.zeros(16, np.float32)
        par[0:9] = np.asarray(table.matrix, np.float64).reshape(9)
        par[9:12] = np.asarray(table.offset, np.float64)
        par[12] = table.eps
        par[13] = table.s_lo
        par[14] = (table.size - 1) / (table.s_hi - table.s_lo)
        self._e_eps = np.int32(round(np.log2(table.eps)) + 127)
        self._par = host_buffer(ctx, par)
        lut = np.asarray(table.table, np.float32)
        if table.kind == "1d":      # kernels/display.cl: per channel, (value, step) pairs
            step = np.vstack([lut[1:], lut[-1:]]) - lut          # float32, as the kernel did
            lut = np.stack([lut, step], axis=-1).transpose(1, 0, 2)
        lut = np.ascontiguousarray(lut, np.float32).reshape(-1)
        self._lut = host_buffer(ctx, lut)
        self._lock = threading.Lock()
        self._bufs: dict = {}

    def _kernel(self, bits: int, vector: bool):
        """This table's kernel object for 8-bit or float output, 4-pixel or scalar: the
        program is built on first use (once per process: the runtime's cache; a run
        needs one output kind), the kernel object is this table's own, so that its
        arguments are not shared with another thread."""
        import pyopencl as cl
        key = (code_bits(bits), bool(vector))
        k = self._knl.get(key)
        if k is None:
            name = "display_lut1d_rgb4" if vector else self._name
            b = code_bits(bits)
            prg = self.rt.kernel("display.cl", name, (("OUT_U8", int(b == 8)),
                                                      ("OUT_U16", int(b == 16)))).program
            self._knl[key] = k = cl.Kernel(prg, name)
        return k

    def describe(self) -> str:
        return f"{self.table.describe()} on {self.rt.name}"

    def _buffer(self, role: str, nbytes: int):
        import pyopencl as cl
        buf = self._bufs.get(role)
        if buf is None or buf.size < nbytes:
            self._bufs[role] = buf = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE,
                                               max(int(nbytes), 4))
        return buf

    def encode(self, pixels: np.ndarray, bits: int = 0) -> np.ndarray:
        """Display-linear working-space RGB (..., C >= 3) -> display code values (new
        float32 array of the same shape; channels after RGB copied as they are).
        ``bits`` 8 or 16: integer code values (uint8, uint16), quantised as OIIO
        quantises float when it writes such a file (C = 3 or 4: a 4th channel
        quantised too); 0 (or False): float."""
        bits = code_bits(bits)
        x = np.asarray(pixels)
        if x.ndim < 1 or x.shape[-1] < 3:
            raise ValueError(f"display encoding needs RGB pixels (got shape {x.shape})")
        c = x.shape[-1]
        if c not in (3, 4):
            if bits:
                raise ValueError("integer display encoding needs 3 or 4 channels")
            out = np.array(x, dtype=np.float32, copy=True, order="C")
            out[..., :3] = self.encode(x[..., :3])
            return out
        x = np.ascontiguousarray(x, np.float32)
        n = x.size // c
        out = np.empty(x.shape, code_dtype(bits))
        if n == 0:
            return out
        with self._lock:
            src = self._buffer("src", x.nbytes)
            transfer(self.queue, src, x, is_blocking=False)
            self._encode_enqueued(self.queue, src, n, c, out, bits)
        return out

    def encode_buffer(self, queue, src, n: int, out: np.ndarray, bits: int) -> None:
        """:meth:`encode` of ``n`` RGB pixels already on the device: ``src`` holds them
        as interleaved float32 (an operator's output buffer, in this table's context),
        ``queue`` is the queue that wrote them (so the kernel runs after), ``out`` (n x 3
        values, C-contiguous, of :func:`code_dtype` of ``bits``) receives the code values.
        Nothing display-linear comes back to the host."""
        if out.dtype != code_dtype(bits) or not out.flags.c_contiguous \
                or out.size != 3 * n:
            raise ValueError("encode_buffer: out must be n x 3 C-contiguous code values")
        if n == 0:
            return
        with self._lock:
            self._encode_enqueued(queue, src, n, 3, out, bits)

    def _encode_enqueued(self, queue, src, n: int, c: int, out: np.ndarray, bits: int) -> None:
        """The kernels on ``queue`` from ``src`` (n pixels of c floats) into ``out``
        (blocking download). Call with the lock held."""
        dst = self._buffer("dst", out.nbytes + TAIL)      # (room for the statistics)
        size = np.int32(self.table.size)
        start = 0
        if c == 3 and self._vector and n >= 4:
            n4 = n // 4
            self._kernel(bits, True)(queue, (round_up(n4, _WG),), (_WG,), src, dst,
                                     np.int32(n), self._par, self._e_eps, size, self._lut)
            start = 4 * n4
        if start < n:
            self._kernel(bits, False)(queue, (n - start,), None, src, dst, np.int32(n),
                                    np.int32(c), np.int32(c), self._par, self._e_eps, size,
                                    self._lut, global_offset=(start,))
        if queue is self.rt.queue:      # the frame's last statistics come down with it
            statistics(self.rt).download(out, dst)
        else:
            transfer(queue, out, dst, is_blocking=True)

    def release(self) -> None:
        """Drop the frame buffers (they are made again on the next :meth:`encode`)."""
        with self._lock:
            self._bufs.clear()


class DeviceOutputEncoding:
    """The display encoding a run writes, applied where the operator's output already is
    (``process_frame(..., encoding=)``): the operator's last kernel leaves display-linear
    RGB in a device buffer and only code values come back (a quarter of the bytes for
    8-bit files, half for 16-bit ones) -- no download of the display-linear frame, no
    upload for encoding."""

    def __init__(self, table: DeviceDisplayTable, bits: int):
        self.table, self.bits = table, code_bits(bits)
        self.dtype = code_dtype(self.bits)

    def fetch(self, queue, src, n: int, out: np.ndarray) -> None:
        """Encode ``n`` pixels of ``src`` (display-linear RGB on the device) into ``out``."""
        self.table.encode_buffer(queue, src, n, out.reshape(-1), self.bits)

    def array(self, h: int, w: int) -> np.ndarray:
        """Where a frame's code values come back: a host array (page-locked for a GPU:
        ``pinned.py``) with room after it for the frame's last statistics."""
        return pinned.outputs(self.table.rt).empty((h, w, 3), self.dtype, TAIL)


class BlurredOutputEncoding:
    """A :class:`DeviceOutputEncoding` with the loss-of-acuity blur before it, on the
    device where the operator left the frame (``blur(src)``: in place, the whole frame
    of ``n`` pixels): a frame that blurs still sends only code values to the host, and
    no display-linear frame is fetched, blurred and blended on the host (a 4K still's
    acuity ~1.2 s and ~400 MiB of float64 temporaries)."""

    def __init__(self, inner, blur, n: int):
        self.inner, self.blur, self.n = inner, blur, int(n)
        self.dtype = inner.dtype

    def array(self, h: int, w: int):
        return self.inner.array(h, w)

    def fetch(self, queue, src, n: int, out: np.ndarray) -> None:
        if n != self.n:               # a band: the blur needs its neighbours' rows
            raise RuntimeError(f"device acuity on {n} of the frame's {self.n} pixels")
        self.blur(src)
        self.inner.fetch(queue, src, n, out)
