"""Where per-pixel planes live: in memory, or spilled to a file and read by row bands.

Local operators keep per-pixel state (ledda04: nine float32 planes, three times a
float32 RGB frame) and per-frame levels. A frame streamed because it would not
fit the memory budget cannot hold them whole either: :class:`PlaneStore` keeps
them in an unlinked raw file (``(plane, row, column)`` order, float32) beside the
run, read and written one band of rows at a time with ``pread``/``pwrite`` (no
mapping, so they never count as the process's resident memory). The file has no
name once opened: a killed run leaves nothing behind.

Anything with ``names``, ``shape`` (h, w) and ``read(y0, y1) -> (planes, rows, w)``
is *band-readable*: a store, a dict of (h, w) arrays (through :func:`read_rows`), or
a state side file opened by ``pipeline/state.py``.
"""

from __future__ import annotations

import os
import tempfile

import numpy as np


class PlaneStore:
    """Named float32 (h, w) planes, read and written by row bands.

    ``directory`` None: in memory; else a raw file created (and at once unlinked) there.
    """

    def __init__(self, names, shape: tuple[int, int], directory: str | os.PathLike | None = None):
        self.names = tuple(names)
        self.shape = (int(shape[0]), int(shape[1]))
        h, w = self.shape
        self.nbytes = len(self.names) * h * w * 4
        self._mem = None
        self._fd = None
        if directory is None:
            self._mem = np.zeros((len(self.names), h, w), np.float32)
        else:
            fd, path = tempfile.mkstemp(prefix=".ocltm-planes-", suffix=".raw", dir=directory)
            os.unlink(path)
            try:
                os.ftruncate(fd, self.nbytes)
            except OSError:
                os.close(fd)
                raise
            self._fd = fd

    @property
    def spilled(self) -> bool:
        return self._fd is not None

    def _offset(self, i: int, y0: int) -> int:
        h, w = self.shape
        return (i * h + y0) * w * 4

    def read(self, y0: int, y1: int, names=None) -> np.ndarray:
        """Rows [y0, y1) of the planes (all, or ``names`` in that order): (n, rows, w)."""
        idx = [self.names.index(k) for k in (names or self.names)]
        w = self.shape[1]
        if self._mem is not None:
            return np.array(self._mem[idx, y0:y1])
        out = np.empty((len(idx), y1 - y0, w), np.float32)
        for j, i in enumerate(idx):
            n, off, view = (y1 - y0) * w * 4, self._offset(i, y0), out[j].reshape(-1).view(np.uint8)
            got = 0
            while got < n:                      # pread may return less than asked
                chunk = os.pread(self._fd, n - got, off + got)
                if not chunk:
                    raise OSError("per-pixel plane file ended early")
                view[got:got + len(chunk)] = np.frombuffer(chunk, np.uint8)
                got += len(chunk)
        return out

    def write(self, y0: int, block: np.ndarray, names=None) -> None:
        """Write (n, rows, w) ``block`` as rows y0.. of the planes (all, or ``names``)."""
        idx = [self.names.index(k) for k in (names or self.names)]
        block = np.asarray(block, np.float32)
        if self._mem is not None:
            self._mem[idx, y0:y0 + block.shape[1]] = block
            return
        for j, i in enumerate(idx):
            data = memoryview(np.ascontiguousarray(block[j])).cast("B")
            off, done = self._offset(i, y0), 0
            while done < len(data):
                done += os.pwrite(self._fd, data[done:], off + done)

    def as_dict(self) -> dict:
        """Whole planes (copies): only for stores that fit in memory."""
        h = self.shape[0]
        return {k: self.read(0, h, [k])[0] for k in self.names}

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
        self._mem = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 -- interpreter shutdown
            pass


class UniformPlanes:
    """Band-readable planes of one value each (a pre-adapted observer's state):
    ``values`` name -> scalar (or a 1x1 array), over ``shape`` (h, w)."""

    def __init__(self, values: dict, shape: tuple[int, int]):
        self.names = tuple(values)
        self.shape = (int(shape[0]), int(shape[1]))
        self._v = {k: np.float32(np.asarray(v, np.float64).reshape(-1)[0]) for k, v in values.items()}

    def read(self, y0: int, y1: int, names=None) -> np.ndarray:
        names = names or self.names
        out = np.empty((len(names), y1 - y0, self.shape[1]), np.float32)
        for j, k in enumerate(names):
            out[j] = self._v[k]
        return out


def band_readable(src) -> bool:
    return hasattr(src, "read") and hasattr(src, "names") and hasattr(src, "shape")


def read_rows(src, names, y0: int, y1: int) -> np.ndarray:
    """Rows [y0, y1) of the planes ``names`` from a dict of arrays or a band-readable
    source, as float32 (n, rows, w)."""
    if band_readable(src):
        return np.asarray(src.read(y0, y1, list(names)), np.float32)
    return np.ascontiguousarray(np.stack([np.asarray(src[k][y0:y1], np.float32) for k in names]))


def plane_shape(src) -> tuple[int, int]:
    if band_readable(src):
        return tuple(src.shape)
    return tuple(np.shape(next(iter(src.values()))))
