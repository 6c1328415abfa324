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
        """The whole frame's rows (``[0:H]``, ``[:]``) are this image; anything else comes
        from the host copy."""
        if isinstance(key, slice) and key.step in (None, 1) and \
                range(*key.indices(self.shape[0])) == range(self.shape[0]):
            return self
        return np.asarray(self)[key]

    def __len__(self) -> int:
        return self.shape[0]

    def copy_to(self, queue, dst) -> None:
        """Copy the pixels into device buffer ``dst`` (device to device)."""
        transfer(queue, dst, self.buffer, byte_count=self.nbytes)
