"""OpenCL runtime: device choice, program build and cache.

Device choice, in order: an explicit ``--device`` spec, ``$PYOPENCL_CTX``
(pyopencl's own convention, ``"platform:device"`` indices), else the first working
GPU of any platform, else the first working CPU device (:data:`CPU_PREFERENCE`).
Every device is probed before use (``probe.py``): one that cannot build and run the
probe kernel is skipped with one warning line naming the driver and the fix; a device
named explicitly that is broken is an error (:class:`DeviceBroken`).

Programs are built once per (context, kernel file set) per process and kept in
a module cache; their device binaries are kept in the user's cache
(:func:`program_cache_path`), so a second process loads rather than compiles.
"""

from __future__ import annotations

import functools
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

from ...base.resources import cache_write, user_cache_dir
from . import probe
# the driver layer below the runtime (probe.py builds on it too); names kept here
from .driver import (INSTALL_HINT, DeviceBroken, KernelBuildError,  # noqa: F401
                     OpenCLUnavailable, build_options, cl_api, define_value, kernel_dir,
                     quiet_compiler, vector_pixels)

log = logging.getLogger("ocl_tonemap")


@functools.lru_cache(maxsize=1)
def _device_list() -> tuple:
    cl = cl_api()
    try:
        platforms = cl.get_platforms()
    except cl.Error:
        return ()
    out = []
    for pi, p in enumerate(platforms):
        try:
            devs = p.get_devices()
        except cl.Error:
            continue
        for di, d in enumerate(devs):
            out.append((f"{pi}:{di}", d))
    return tuple(out)


def list_devices() -> list[tuple[str, object]]:
    """All OpenCL devices as ``("P:D", device)`` pairs; empty when none (asked of the
    drivers once a process: the first look loads every ICD)."""
    return list(_device_list())


def describe_device(dev) -> str:
    cl = cl_api()
    kind = cl.device_type.to_string(dev.type)
    return (f"{dev.name.strip()} [{kind}] on {dev.platform.name.strip()} "
            f"({dev.version.strip()}), {dev.max_compute_units} CU, "
            f"{dev.global_mem_size / 2**30:.1f} GiB global, "
            f"max alloc {dev.max_mem_alloc_size / 2**30:.2f} GiB")


#: Among working CPU devices, the automatic choice takes the first platform whose name
#: holds one of these, in this order. Intel's CPU runtime first: on the same 2-core AMD
#: EPYC it ran pattanaik00, ledda04 and kirk11 1.45-2.1x faster per 1080p frame than
#: the bundled PoCL in three runs (durand00 0.7-1.9x: noisy), with the same agreement
#: with the float64 reference (benchmarks/results/cpu_devices.md; README "OpenCL drivers").
CPU_PREFERENCE = ("intel(r) opencl", "portable computing language")

_warned: set = set()


def _match(spec: str, devices):
    """The listed device a ``--device`` spec names (see :func:`choose_device`)."""
    cl = cl_api()
    s = spec.strip()
    listing = "; ".join(f"{k} {d.name.strip()}" for k, d in devices)
    if s in ("gpu", "cpu"):
        want = cl.device_type.GPU if s == "gpu" else cl.device_type.CPU
        found = [(k, d) for k, d in devices if d.type & want]
        if not found:
            raise OpenCLUnavailable(f"no OpenCL {s.upper()} device; available: {listing}")
        return found
    if ":" in s or s.isdigit():
        parts = s.split(":")
        key = f"{parts[0]}:{parts[1] if len(parts) > 1 and parts[1] else 0}"
        for k, d in devices:
            if k == key:
                return [(k, d)]
        raise OpenCLUnavailable(f"no OpenCL device {key!r}; available: {listing}")
    low = s.lower()
    found = [(k, d) for k, d in devices
             if any(low in t.lower() for t in (d.name, d.platform.name, d.platform.version))]
    if not found:
        raise OpenCLUnavailable(f"no OpenCL device matches {spec!r}; available: {listing}")
    return found


def _automatic_order(devices):
    """GPUs first (in listed order), then CPU devices by :data:`CPU_PREFERENCE`, then
    the rest."""
    cl = cl_api()

    def rank(item):
        i, (_, d) = item
        if d.type & cl.device_type.GPU:
            return (0, 0, i)
        pname = d.platform.name.lower()
        pref = next((j for j, n in enumerate(CPU_PREFERENCE) if n in pname),
                    len(CPU_PREFERENCE))
        return (1, pref, i)
    return [kd for _, kd in sorted(enumerate(devices), key=rank)]


def choose_device(spec: str | None = None):
    """Pick a working OpenCL device.

    ``spec`` may be ``"P:D"`` (platform and device index as listed by
    ``ocl-tonemap devices``), ``"P"``, ``"gpu"``, ``"cpu"`` or a
    case-insensitive substring of the device or platform name or the platform's
    version (``"pocl"``, ``"intel"``). A spec
    (or ``$PYOPENCL_CTX``) whose devices all fail the probe raises
    :class:`DeviceBroken`; without one, broken devices are skipped with a warning
    and :class:`OpenCLUnavailable` says when none works.
    """
    devices = list_devices()
    if not devices:
        raise OpenCLUnavailable(INSTALL_HINT)
    spec = spec if spec else os.environ.get("PYOPENCL_CTX") or None
    if spec:
        found = _match(spec, devices)
        for _, d in found:
            if probe.verdict(d).ok:
                return d
        k, d = found[0]
        raise DeviceBroken(f"OpenCL device {k} {probe.describe_driver(d)} is broken: "
                           f"{probe.verdict(d).reason}", probe.fix_hint(d))
    broken = []
    for k, d in _automatic_order(devices):
        v = probe.verdict(d)
        if not v.ok:
            broken.append((k, d, v))
            continue
        for bk, bd, bv in broken:       # skipped for a working one: a line each, once
            if probe.cache_key(bd) not in _warned:
                _warned.add(probe.cache_key(bd))
                log.warning("OpenCL device %s %s is broken, skipped: %s; %s", bk,
                            probe.describe_driver(bd), bv.reason, probe.fix_hint(bd))
        return d
    raise OpenCLUnavailable("no working OpenCL device: " + "; ".join(
        f"{k} {probe.describe_driver(d)} is broken: {v.reason}" for k, d, v in broken),
        probe.fix_hint())


def device_status(spec: str | None = None):
    """``(device, None)`` for the device a run would use, or ``(None, exc)`` with the
    :class:`OpenCLUnavailable` that says why there is none (no driver, or every device
    broken). A spec naming a broken or absent device raises, as :func:`choose_device`
    does."""
    try:
        return choose_device(spec), None
    except DeviceBroken:
        raise
    except OpenCLUnavailable as exc:
        if spec or os.environ.get("PYOPENCL_CTX"):
            raise
        return None, exc


@dataclass
class Runtime:
    """An OpenCL context, queue and the built kernel programs."""

    device: object
    context: object
    queue: object

    @property
    def name(self) -> str:
        return self.device.name.strip()

    def kernel(self, file: str, name: str, defines: tuple = ()):
        """A kernel of ``file`` (``a.cl+b.cl``: the files one after the other in one
        program), retrieved once per process (kernel objects are costly).
        ``defines``: (NAME, value) pairs given to the compiler as -DNAME=value (constants
        and parameter indices generated from the Python side, never retyped).
        With ``OCLTM_PROFILE=1`` in the environment each launch is timed
        (:func:`kernel_times`)."""
        defines = tuple(defines)
        k = _kernel(self.context, self.device, file, name, defines)
        _ASKED.setdefault((file, name, defines), None)
        return _TimedKernel(k, name) if PROFILING else k

    def remember_kernels(self, key: str) -> None:
        """Keep the list of the kernels this process asked for under ``key`` (a run's
        operator and settings) in the user's cache, for :meth:`warm_kernels`."""
        path = _journal_path(self.device, key)
        if path is None or not _ASKED:
            return
        import json
        data = json.dumps([[f, n, [list(d) for d in defs]] for f, n, defs in _ASKED]).encode()
        try:
            if path.read_bytes() == data:
                return
        except OSError:
            pass
        if cache_write(path, data):
            try:                            # the most recent RUN_LISTS lists are kept
                old = sorted(path.parent.glob("run-*.json"), key=lambda p: p.stat().st_mtime)
                for p in old[:max(0, len(old) - RUN_LISTS)]:
                    p.unlink(missing_ok=True)
            except OSError:
                pass

    def warm_kernels(self, key: str, stop) -> int:
        """Make the kernels the last run of ``key`` asked for (:meth:`remember_kernels`)
        until ``stop()`` is true: their programs are loaded from the user's cache, never
        compiled here (a program not there is left to its first use). For the time a
        run waits for its first frame's read: a 4K frame's ~40 ms of program loads then
        cost nothing. Returns the number made."""
        path = _journal_path(self.device, key)
        if path is None:
            return 0
        import json
        try:
            items = json.loads(path.read_bytes())
        except (OSError, ValueError):
            return 0
        made = 0
        for item in items if isinstance(items, list) else ():
            if stop():
                break
            try:
                file, name, defs = item
                defines = tuple((str(k), _frozen(v)) for k, v in defs)
                src, opts = _source(self.device, _files(file), defines)
                cached = program_cache_path(self.device, src, opts)
                if cached is None or not cached.exists():
                    continue
                _kernel(self.context, self.device, file, name, defines)
                made += 1
            except Exception:           # noqa: BLE001 -- a cache: never fails a run
                continue
        return made

    @functools.cached_property
    def vector_pixels(self) -> bool:
        """Whether per-pixel kernels take several pixels a work-item in vector types
        (``common.h`` ``VECTOR_PIXELS``; :func:`vector_pixels`). Asked once: the
        device query costs ~0.1 ms, and this is read at every launch."""
        return vector_pixels(self.device)

    def pixel_items(self, n: int, k: int) -> int:
        """Work-items for ``n`` pixels of a per-pixel kernel written for ``k`` pixels a
        work-item: ceil(n / k) on CPU devices, ``n`` elsewhere (``common.h``
        ``ITEM_PIXELS``: one pixel an item, neighbouring items on neighbouring pixels)."""
        n, k = max(int(n), 0), max(int(k), 1)
        return -(-n // k) if self.vector_pixels else n

    def max_alloc_bytes(self) -> int:
        return int(self.device.max_mem_alloc_size)

    def global_mem_bytes(self) -> int:
        return int(self.device.global_mem_size)


#: (file, name, defines) of every kernel this process asked for, in order
#: (``Runtime.remember_kernels``).
_ASKED: dict = {}


def _frozen(v):
    """A define's value as given (JSON gives lists for tuples)."""
    return tuple(_frozen(x) for x in v) if isinstance(v, list) else v


def _journal_path(device, key: str) -> Path | None:
    """Where the kernels of a run of ``key`` on ``device`` are listed (None with
    ``PYOPENCL_NO_CACHE``: no program cache to load them from)."""
    if os.environ.get("PYOPENCL_NO_CACHE"):
        return None
    import hashlib
    h = hashlib.sha256("\0".join([_device_key(device), key]).encode())
    return user_cache_dir() / "programs" / f"run-{h.hexdigest()[:32]}.json"


#: Lists of a run's kernels (:meth:`Runtime.remember_kernels`) kept at most.
RUN_LISTS = 64


#: ``OCLTM_PROFILE=1``: the queue records each kernel's device time (benchmarks,
#: ``benchmarks/speed_accuracy.py``); costs a little, never on by default.
PROFILING = os.environ.get("OCLTM_PROFILE", "") not in ("", "0")
_EVENTS: list = []


class _TimedKernel:
    """A kernel whose launches are recorded (name, event) for :func:`kernel_times`."""

    def __init__(self, kernel, name: str):
        self._k, self.name = kernel, name

    def __call__(self, *args, **kw):
        ev = self._k(*args, **kw)
        _EVENTS.append((self.name, ev))
        return ev

    def __getattr__(self, attr):
        return getattr(self._k, attr)


def kernel_times(reset: bool = True) -> dict:
    """Device milliseconds per kernel name launched since the last reset, and launches:
    {name: (ms, count)} (``OCLTM_PROFILE=1`` only; else empty)."""
    out: dict = {}
    for name, ev in _EVENTS:
        ev.wait()
        ms = (ev.profile.end - ev.profile.start) * 1e-6
        t, c = out.get(name, (0.0, 0))
        out[name] = (t + ms, c + 1)
    if reset:
        _EVENTS.clear()
    return out


@functools.lru_cache(maxsize=None)
def _runtime_for(device) -> Runtime:
    cl = cl_api()
    ctx = cl.Context([device])
    props = cl.command_queue_properties.PROFILING_ENABLE if PROFILING else 0
    q = cl.CommandQueue(ctx, properties=props)
    return Runtime(device, ctx, q)


def get_runtime(spec: str | None = None) -> Runtime:
    """The process-wide runtime for the chosen device (created once)."""
    return _runtime_for(choose_device(spec))


def index_defines(names, prefix: str = "P_") -> tuple:
    """-D pairs giving each packed parameter's index: P_<name> = i."""
    return tuple((f"{prefix}{n}", i) for i, n in enumerate(names))


def _source(device, files: tuple[str, ...], defines: tuple = ()) -> tuple[str, list]:
    """(source, build options) of a program of ``files`` built with ``defines``."""
    kdir = kernel_dir()
    src = "\n".join((kdir / f).read_text() for f in ("common.h", *files))
    return src, build_options(device) + [f"-D{k}={define_value(v)}" for k, v in defines]


@functools.lru_cache(maxsize=None)
def _build(context, device, files: tuple[str, ...], defines: tuple = ()):
    cl = cl_api()
    src, opts = _source(device, files, defines)
    cached = program_cache_path(device, src, opts)
    if cached is not None:
        try:
            binary = cached.read_bytes()
            return cl.Program(context, [device], [binary]).build(options=opts,
                                                                 devices=[device])
        except (OSError, cl.Error):
            pass                        # absent or not loadable: build from source
    key, t0 = (device.platform.name, device.name), time.perf_counter()
    try:
        with quiet_compiler(lambda: _building_notice(device, cached is not None),
                            max(0.05, 1.0 - _build_spent.get(key, 0.0))):
            prog = cl.Program(context, src).build(options=opts, devices=[device])
    except cl.Error as exc:
        probe.forget(device)            # the next start probes the driver again
        raise KernelBuildError(
            f"OpenCL kernel build failed: kernels/{', kernels/'.join(files)} on "
            f"{probe.describe_driver(device)}: {probe.first_error_line(str(exc))}") from None
    finally:
        _build_spent[key] = _build_spent.get(key, 0.0) + time.perf_counter() - t0
    if cached is not None:
        _keep_binary(prog, cached)
    return prog


#: A notice's level: between INFO and WARNING (the command line shows it, ``-q`` not).
NOTE = 25
_said_building: set = set()
#: Seconds spent compiling per device in this process (the notice comes after 1 s).
_build_spent: dict = {}


def _building_notice(device, kept: bool) -> str | None:
    """The line the builds say once they have taken a second (``quiet_compiler``), once
    per device and process, where notices are shown: the first run on a device (a
    driver or project update) spends seconds to a minute in the compiler, which would
    otherwise look like a hang."""
    key = (device.platform.name, device.name)
    if key in _said_building or not log.isEnabledFor(NOTE):
        return None
    _said_building.add(key)
    where = (f"first run only: later runs load them from {user_cache_dir() / 'programs'}"
             if kept else "not kept: PYOPENCL_NO_CACHE is set")
    return (f"ocl-tonemap NOTE: building the OpenCL kernels for {device.name.strip()} on "
            f"{device.platform.name.strip()} ({where})\n")


#: Programs kept in the user's cache (``programs/``) at most; the oldest go first.
PROGRAM_CACHE_FILES = 256


def program_cache_path(device, src: str, opts: list) -> Path | None:
    """Where the device binary of ``src`` built with ``opts`` is kept: keyed by the
    device's probe key (device, driver, project version, PoCL settings) and the source
    and options. A warm start loads binaries (PoCL: ~3 ms a program, against ~30 ms
    for its own source-keyed cache). None with ``PYOPENCL_NO_CACHE`` set."""
    if os.environ.get("PYOPENCL_NO_CACHE"):
        return None
    import hashlib
    h = hashlib.sha256("\0".join([_device_key(device), src, *opts]).encode())
    return user_cache_dir() / "programs" / f"{h.hexdigest()[:40]}.bin"


@functools.lru_cache(maxsize=None)
def _device_key(device) -> str:
    return probe.cache_key(device)


def _keep_binary(prog, path: Path) -> None:
    try:
        binary = prog.get_info(cl_api().program_info.BINARIES)[0]
        if not binary:
            return
        old = sorted(path.parent.glob("*.bin"), key=lambda p: p.stat().st_mtime)
        for p in old[:max(0, len(old) - PROGRAM_CACHE_FILES + 1)]:
            p.unlink(missing_ok=True)
    except Exception:                   # noqa: BLE001 -- a cache: never fails a run
        return
    cache_write(path, bytes(binary))


def _files(file: str) -> tuple[str, ...]:
    """The kernel files of a program named ``a.cl`` or ``a.cl+b.cl``."""
    return tuple(file.split("+"))


@functools.lru_cache(maxsize=None)
def _kernel(context, device, file: str, name: str, defines: tuple = ()):
    cl = cl_api()
    return cl.Kernel(_build(context, device, _files(file), defines), name)


def frame_params(values):
    """A per-pixel kernel's frame scalars as its float16 argument (kernels/common.h
    FRAME_PARAMS): they travel with the launch, not as an upload."""
    import numpy as np
    from pyopencl import cltypes
    if len(values) > 16:
        raise ValueError(f"a per-pixel kernel takes 16 frame scalars at most, not {len(values)}")
    v = np.zeros(16, np.float32)
    v[:len(values)] = values
    return cltypes.make_float16(*v)


def round_up(n: int, m: int) -> int:
    """Smallest multiple of ``m`` that is >= ``n`` (padded global sizes)."""
    return ((int(n) + m - 1) // m) * m

