"""The driver layer under the OpenCL runtime: pyopencl through the ICD loader
(:func:`cl_api`), where the kernel sources are, and the compiler options every
program and the probe kernel get (:func:`build_options`, with the model constants of
``constants.py``). It imports neither the runtime nor the probe, which both build on it."""

from __future__ import annotations

import functools
import os
from contextlib import contextmanager
from pathlib import Path

from ...base.resources import package_data_dir
from . import icd
from .constants import common_options, define_value  # noqa: F401 (define_value: runtime)


INSTALL_HINT = (
    'no OpenCL platform found. Install a CPU OpenCL driver with '
    '`pip install "pyopencl[pocl]"` (or `pip install pocl-binary-distribution`), '
    "or install your GPU vendor's OpenCL ICD."
)


class OpenCLUnavailable(RuntimeError):
    """Raised when no usable OpenCL platform or device exists. ``detail``: what is
    wrong, ``fix``: how to mend it (``str()`` is both)."""

    def __init__(self, detail: str, fix: str = ""):
        super().__init__(f"{detail}; {fix}" if fix else detail)
        self.detail, self.fix = detail, fix


class DeviceBroken(OpenCLUnavailable):
    """A device named explicitly (``--device``, ``PYOPENCL_CTX``) failed its probe."""


class KernelBuildError(OpenCLUnavailable):
    """A kernel program failed to build on a device that had passed its probe."""


@functools.lru_cache(maxsize=None)
def cl_api():
    icd.register()                      # before the ICD loader's first look
    try:
        import warnings
        import pyopencl as cl
        # A driver's build log on success (Intel's says "Compilation started ... done")
        # is not a warning to a user; a failing build raises and is reported.
        warnings.filterwarnings("ignore", category=cl.CompilerWarning)
    except ImportError as exc:  # pragma: no cover - dependency is required
        raise OpenCLUnavailable(f"pyopencl is not importable ({exc}); {INSTALL_HINT}") from exc
    return cl


#: What an OpenCL compiler prints of itself while it builds (PoCL's clang: "5 warnings
#: generated."; its diagnostics), not the program's or a user's concern: dropped.
COMPILER_CHATTER = (r"^\d+ (warning|error)s? generated\.$", r"^\s*\d+ \| ", r"^\s*\|\s*\^",
                    r"^<built-in>|^<stdin>|^input\.cl|^\S+\.cl:\d+:|^/tmp/\S+:\d+:",
                    r"warning: |note: ")


@contextmanager
def quiet_compiler(notice=None, after_s: float = 1.0):
    """The process's standard error (file descriptor 2, where a driver's compiler
    writes) taken aside while a program builds; what is not the compiler's chatter
    (:data:`COMPILER_CHATTER`; another thread's message) is written back after. A
    failing build raises with the driver's build log, which pyopencl collects.
    ``notice()``: called if the build is still going after ``after_s`` seconds (a
    first run's compiles look like a hang), its line (if any) written to the real
    standard error."""
    import re
    import sys
    import tempfile
    import threading
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):        # no descriptor 2 (an embedding): as it is
        yield
        return
    timer = None

    def say():
        text = notice()
        if text:
            os.write(saved, text.encode())
    if notice is not None:
        timer = threading.Timer(after_s, say)
        timer.daemon = True
        timer.start()
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield
        finally:
            if timer is not None:
                timer.cancel()
                timer.join()
            try:
                sys.stderr.flush()
            except (OSError, ValueError):
                pass
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            text = tmp.read().decode(errors="replace")
            keep = [ln for ln in text.splitlines()
                    if ln.strip() and not any(re.search(p, ln) for p in COMPILER_CHATTER)]
            if keep:
                os.write(2, ("\n".join(keep) + "\n").encode())


def kernel_dir() -> Path:
    """Folder holding the OpenCL sources (``*.cl`` and ``common.h``)."""
    return package_data_dir("kernels", "common.h")


def vector_pixels(device) -> bool:
    """Whether the per-pixel kernels on ``device`` take several pixels a work-item in
    vector types (CPU devices: PoCL vectorises within a work-item only) or one pixel
    a work-item in scalar code (other devices: coalesced loads, and a pixel's value
    cannot depend on its lane). ``OCLTM_VECTOR_PIXELS=0|1`` in the environment forces
    one or the other: the GPU path tested on a CPU device. Set it before the process
    starts: built programs are kept for the life of the process."""
    forced = os.environ.get("OCLTM_VECTOR_PIXELS", "").strip()
    if forced in ("0", "1"):
        return forced == "1"
    return bool(device.type & cl_api().device_type.CPU)


def build_options(device) -> list:
    """Compiler options of every program (and of the probe kernel): the model constants
    of common.h (:data:`constants.COMMON`) among them."""
    cl = cl_api()
    # No -cl-fast-relaxed-math: the kernels rely on IEEE inf/0 behaviour at the
    # extremes (docs/models.md); measured, it bought no time (docs/architecture.md).
    cpu = int(bool(device.type & cl.device_type.CPU))      # common.h share_range
    return ["-cl-std=CL1.2", f"-DDEVICE_CPU={cpu}",
            f"-DVECTOR_PIXELS={int(vector_pixels(device))}", *common_options()]
