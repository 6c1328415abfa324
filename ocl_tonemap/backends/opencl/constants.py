"""Model constants every kernel program gets (``kernels/common.h`` and any file after it),
generated from ``ocl_tonemap/models/`` as ``-D`` build options (:func:`runtime.build_options`),
never retyped in the kernels. Per-operator constants come the same way from the
operator's own module (``backends/opencl/ledda04.py``, ``backends/opencl/lmsr.py``
``KERNEL_CONSTANTS``; ``operators/pattanaik00.py`` through its ``KernelCall``).

Each value reaches the kernel as the float32 of the model's float64 value
(:func:`runtime.define_value`); tests/backends/test_kernel_constants.py checks that no model
constant is typed into a kernel again.
"""

from __future__ import annotations

from ...models import display, photometry


def _rgb_to_xyz() -> tuple:
    """M_<row><column>: BT.709 linear RGB -> CIE XYZ (D65), photometry.RGB709_TO_XYZ."""
    m = photometry.RGB709_TO_XYZ
    return tuple((f"M_{r}{c}", float(m[i, j]))
                 for i, r in enumerate("XYZ") for j, c in enumerate("RGB"))


#: (NAME, value) pairs of common.h: its colour matrix (the Y row: photopic luminance),
#: Ward-Larson et al. 1997's scotopic luminance, the scene ceiling and the repair kinds
#: of the bad-value policy, the display's signal ceiling, clamp and the shoulder's
#: channel knee.
COMMON = (
    *_rgb_to_xyz(),
    ("WARD97_GAIN", photometry.WARD97_GAIN), ("WARD97_OFFSET", photometry.WARD97_OFFSET),
    ("L_MAX", photometry.L_MAX), ("NREPAIR", len(photometry.RepairCounts.KEYS)),
    ("SIGNAL_CEILING", display.SIGNAL_CEILING), ("CHANNEL_KNEE", display.CHANNEL_KNEE),
    ("SHOULDER_POWER", display.SHOULDER_POWER),
    ("DISPLAY_LINEAR_MAX", display.DISPLAY_LINEAR_MAX),
)


def define_value(v) -> str:
    """A -D value: ints as they are, floats as float32 literals that round-trip, a
    tuple as its items' values joined by commas (an array's initialiser)."""
    if isinstance(v, tuple):
        return ",".join(define_value(x) for x in v)
    if isinstance(v, (bool, int)):
        return str(int(v))
    import numpy as np
    return f"{float(np.float32(v))!r}f".replace("inff", "INFINITY")


def common_options() -> list:
    """COMMON as compiler options, ``-DNAME=value``."""
    return [f"-D{k}={define_value(v)}" for k, v in COMMON]
