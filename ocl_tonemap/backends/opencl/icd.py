"""OpenCL drivers installed from PyPI, made visible to the ICD loader.

pyopencl's wheel carries the ocl-icd loader. It reads the ``.icd`` files of one vendors
folder (``$OCL_ICD_VENDORS``, else ``/etc/OpenCL/vendors``) and those in pyopencl's own
``.libs`` (where ``pocl-binary-distribution`` puts PoCL). Intel's CPU runtime from PyPI
(``intel-opencl-rt`` with ``intel-cmplr-lib-rt``) installs ``<prefix>/lib/libintelocl.so``
but no ``.icd`` file the loader can use (its ``etc/OpenCL/vendors/intel-cpu.icd`` names a
build machine's path), so it is invisible until registered.

:func:`register` does that before the first OpenCL call, writing nothing outside the
user's cache: a vendors folder there that links every ``.icd`` of the system's folder
(a GPU driver stays visible: ``OCL_ICD_VENDORS`` replaces ``/etc/OpenCL/vendors``, it
does not add to it) and adds one ``.icd`` naming the venv's ``libintelocl.so``; then
``OCL_ICD_VENDORS`` points there, for this process and its children. A user's own
``OCL_ICD_VENDORS`` (or ``OPENCL_VENDOR_PATH``) is left alone.
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

from ...base.resources import user_cache_dir

#: The system's vendors folder (``OCLTM_SYSTEM_ICD_DIR`` overrides it: tests).
SYSTEM_VENDORS = "/etc/OpenCL/vendors"
#: The name of the ``.icd`` this module writes for Intel's CPU runtime.
INTEL_ICD = "ocl-tonemap-intel-cpu.icd"
#: pip names of Intel's CPU runtime (the ``intel-cpu`` extra).
INTEL_PACKAGES = ("intel-opencl-rt", "intel-cmplr-lib-rt")

_registered: str | None = None
_done = False


def cache_dir() -> Path:
    return user_cache_dir()


def intel_library() -> Path | None:
    """``libintelocl.so`` of Intel's CPU runtime installed in this environment, if any."""
    for prefix in dict.fromkeys((sys.prefix, sys.base_prefix)):
        p = Path(prefix) / "lib" / "libintelocl.so"
        if p.is_file():
            return p
    return None


def system_vendors() -> Path:
    return Path(os.environ.get("OCLTM_SYSTEM_ICD_DIR") or SYSTEM_VENDORS)


def _system_icds() -> list[Path]:
    d = system_vendors()
    try:
        return sorted(p for p in d.iterdir() if p.name.endswith(".icd"))
    except OSError:
        return []


def vendors_folder(lib: Path, system: list[Path]) -> Path | None:
    """A vendors folder in the user's cache holding links to the ``system`` ``.icd``
    files and one ``.icd`` naming ``lib``; None where ``lib`` is registered among the
    system's already, or the cache cannot be written."""
    for p in system:
        try:
            if Path(p.read_text().strip()).resolve() == lib.resolve():
                return None
        except OSError:
            continue
    # One folder per (library, system ICD set): a driver installed or removed later
    # makes a new folder rather than editing one another process may be reading.
    tag = hashlib.sha256("\n".join([str(lib)] + [str(p) for p in system]).encode()) \
        .hexdigest()[:16]
    folder = cache_dir() / "icd" / tag
    if (folder / INTEL_ICD).is_file():
        return folder
    try:
        tmp = folder.with_name(f"{tag}.tmp{os.getpid()}")
        tmp.mkdir(parents=True, exist_ok=True)
        for p in system:
            link = tmp / p.name
            if not link.is_symlink():
                link.symlink_to(p)
        (tmp / INTEL_ICD).write_text(f"{lib}\n")
        try:
            tmp.rename(folder)
        except OSError:                 # another process made it first
            for q in tmp.iterdir():
                q.unlink()
            tmp.rmdir()
    except OSError:
        return None                     # no cache folder: the library stays unseen
    return folder if (folder / INTEL_ICD).is_file() else None


def register() -> str | None:
    """Make the venv's Intel CPU runtime visible to the ICD loader (once a process;
    before the first OpenCL call). Returns the vendors folder set in
    ``OCL_ICD_VENDORS``, or None where nothing was needed or the user set their own."""
    global _done, _registered
    if _done:
        return _registered
    _done = True
    if os.environ.get("OCL_ICD_VENDORS") or os.environ.get("OPENCL_VENDOR_PATH"):
        return None
    lib = intel_library()
    if lib is None:
        return None
    folder = vendors_folder(lib, _system_icds())
    if folder is None:
        return None
    os.environ["OCL_ICD_VENDORS"] = str(folder)
    _registered = str(folder)
    return _registered
