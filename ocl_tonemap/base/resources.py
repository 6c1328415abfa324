"""Where the package's data folders are (kernels, OCIO configs), installed or in a
source tree."""

from __future__ import annotations

import os
from pathlib import Path

from ..version import __version__


def package_data_dir(name: str, probe: str) -> Path:
    """``ocl_tonemap/<name>`` in an installed wheel (where pyproject maps the
    top-level folder), else ``<name>`` beside the package in a source tree."""
    here = Path(__file__).resolve().parent.parent      # ocl_tonemap/
    for p in (here / name, here.parent / name):
        if (p / probe).is_file():
            return p
    raise FileNotFoundError(f"{name}/{probe} not found in the installed package or the source tree")


def available_memory() -> int:
    """Bytes this machine can give a process now: ``MemAvailable`` of /proc/meminfo
    (Linux), else its physical memory."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return 16 << 30


def free_disk(path: str) -> tuple[str, int]:
    """(the folder, its free bytes) of the nearest existing folder at or above ``path``
    (where a file under ``path`` would go)."""
    import shutil
    p = Path(os.path.abspath(path))
    while not p.exists() and p != p.parent:
        p = p.parent
    if not p.is_dir():
        p = p.parent
    return str(p), shutil.disk_usage(p).free


def gib(n: float) -> str:
    """Bytes in the words of an error line (``3.2 GiB``, ``640 MiB``)."""
    for unit, k in (("PiB", 50), ("TiB", 40), ("GiB", 30)):
        if n >= 2**k:
            return f"{n / 2**k:,.3g} {unit}" if n < 1000 * 2**50 else f"{n / 2**50:,.0f} PiB"
    return f"{n / 2**20:.3g} MiB"


def user_cache_dir() -> Path:
    """The user's cache folder for ocl-tonemap (device verdicts, ICD folders, baked
    display tables): ``$OCLTM_CACHE_DIR``, else ``$XDG_CACHE_HOME/ocl-tonemap``, else
    ``~/.cache/ocl-tonemap``. Everything there can be deleted at any time."""
    own = os.environ.get("OCLTM_CACHE_DIR")
    if own:
        return Path(own)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "ocl-tonemap"


def cache_write(path: Path, data: bytes) -> bool:
    """Write ``data`` to a file of the user cache atomically (a temporary beside it,
    renamed over it; removed when the write fails). False where the cache cannot be
    written: a cache is never a run's error."""
    tmp = path.with_name(f"{path.name}.tmp{os.getpid()}")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_bytes(data)
        os.replace(tmp, path)
        return True
    except OSError:
        try:
            tmp.unlink(missing_ok=True)
        except OSError:
            pass
        return False


def cached_json(kind: str, key, compute):
    """``compute()`` (a JSON-able value) kept in the user cache under ``kind/`` by
    ``key`` (JSON-able; the project version is added), so a warm start reads it.
    JSON keeps float64 exactly. A file that cannot be read is computed again; a cache
    that cannot be written is not an error."""
    import hashlib
    import json
    ident = json.dumps([kind, __version__, key], sort_keys=True, default=str)
    path = user_cache_dir() / kind / f"{hashlib.sha256(ident.encode()).hexdigest()[:32]}.json"
    try:
        with open(path) as fh:
            doc = json.load(fh)
        if isinstance(doc, dict) and doc.get("key") == json.loads(ident):
            return doc["value"]
    except (OSError, ValueError, KeyError):
        pass
    value = compute()
    cache_write(path, json.dumps({"key": json.loads(ident), "value": value}).encode())
    return value
