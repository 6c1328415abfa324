"""Device probe: whether an OpenCL device can build and run this project's kernels.

A driver can list a device and still fail every build: pyopencl's bundled PoCL 3.0
(LLVM 14) asks for CPU ``generic`` on AMD Zen 5 and every kernel build ends in
``error: unknown target CPU 'generic'``. Before a device is used, :func:`verdict`
builds one small kernel with ``common.h`` and the options the real programs get, runs
it, and checks its answer against float64: ``log2``/``exp2``/``pow`` on ``float4``, a
work-group reduction in local memory (``group_sum4``), a branch and a ``select``.

The verdict is kept in the user's cache (``icd.cache_dir()/probe.json``), keyed by the
device, its platform, the driver's version, this project's version, the probe's source
(with common.h's model constants, given as build options) and the PoCL settings in the
environment (``POCL_*``, the cache folder excepted), so a warm start pays one small JSON
read. A driver or project change asks again. A kernel
that fails to build later, after the probe passed, forgets the verdict
(:func:`forget`).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass

from ... import version
from ...base.resources import cache_write
from . import icd
from .constants import common_options
from .driver import build_options, cl_api, kernel_dir, quiet_compiler

PROBE_KERNEL = r"""
__kernel void ocltm_probe(__global const float4 *x, __global float4 *partial,
                          __local float4 *scratch)
{
    const int i = get_global_id(0);
    const float4 v = x[i];
    float4 y = exp2(0.5f * log2(v)) + pow(v, (float4)(0.25f)) / (1.0f + v);
    y = select(y, -y, isless(v, (float4)(0.0f)));
    if (i % 3 == 0) y *= 2.0f;
    group_sum4(scratch, y, partial);
}
"""
N_ITEMS, LOCAL = 256, 64
#: Relative tolerance of the group sums (64 float32 values of O(1): ~1e-6 expected).
RTOL = 1e-4
#: Bump when the cache record's form changes.
CACHE_VERSION = 1


@dataclass(frozen=True)
class Verdict:
    ok: bool
    reason: str = ""            # the first line of the build error, or what was wrong
    cached: bool = False
    seconds: float = 0.0        # the probe's own time (0 when cached)


def _probe_inputs():
    import numpy as np
    x = np.linspace(0.01, 4.0, N_ITEMS * 4).astype(np.float32).reshape(N_ITEMS, 4)
    v = x.astype(np.float64)
    y = np.sqrt(v) + v ** 0.25 / (1.0 + v)
    y[np.arange(N_ITEMS) % 3 == 0] *= 2.0
    want = y.reshape(N_ITEMS // LOCAL, LOCAL, 4).sum(axis=1)
    return x, want


def _source() -> str:
    return (kernel_dir() / "common.h").read_text() + PROBE_KERNEL


def _source_key() -> str:
    """The probe's source and the model constants common.h gets as build options
    (:mod:`.constants`): the verdict is asked again when either changes."""
    return "\n".join([_source(), *common_options()])


def _pocl_env() -> list:
    return sorted((k, v) for k, v in os.environ.items()
                  if k.startswith("POCL_") and k != "POCL_CACHE_DIR")


def device_record(device) -> dict:
    """What identifies a device and its driver (the cache key's parts)."""
    p = device.platform
    return {"device": device.name.strip(), "vendor": device.vendor.strip(),
            "device_version": device.version.strip(),
            "driver_version": device.driver_version.strip(),
            "platform": p.name.strip(), "platform_version": p.version.strip()}


def cache_key(device) -> str:
    parts = {**device_record(device), "project": version.__version__,
             "probe": hashlib.sha256(_source_key().encode()).hexdigest(),
             "env": _pocl_env(), "form": CACHE_VERSION}
    return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()


def cache_file():
    return icd.cache_dir() / "probe.json"


def _load() -> dict:
    try:
        with open(cache_file()) as fh:
            doc = json.load(fh)
        return doc if isinstance(doc, dict) else {}
    except (OSError, ValueError):
        return {}


def _store(key: str, rec: dict | None) -> None:
    """Write (or, with None, drop) one record; atomic, best effort (no cache folder:
    the probe runs again next time)."""
    path = cache_file()
    doc = _load()
    if rec is None:
        if doc.pop(key, None) is None:
            return
    else:
        doc[key] = rec
    cache_write(path, json.dumps(doc, indent=1, sort_keys=True).encode())


def first_error_line(text: str) -> str:
    """The first line that says what went wrong in a build log or pyopencl's error
    (pyopencl repeats ``clBuildProgram failed: ...`` and names the device first)."""
    body = text.split("Build on", 1)[1].split(":", 1)[-1] if "Build on" in text else text
    lines = [ln.strip() for ln in body.splitlines()]
    for ln in lines:
        if ln and not ln.startswith("(options:") and not ln.startswith("=="):
            return ln[:300]
    return (text.strip().splitlines() or ["unknown error"])[0][:300]


def run_probe(device) -> Verdict:
    """Build and run the probe kernel on ``device`` (no cache)."""
    import numpy as np
    cl = cl_api()
    t0 = time.perf_counter()
    try:
        ctx = cl.Context([device])
        q = cl.CommandQueue(ctx)
        with quiet_compiler():
            prog = cl.Program(ctx, _source()).build(options=build_options(device),
                                                    devices=[device])
        x, want = _probe_inputs()
        mf = cl.mem_flags
        xb = cl.Buffer(ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x)
        out = np.zeros_like(want, dtype=np.float32)
        ob = cl.Buffer(ctx, mf.WRITE_ONLY, out.nbytes)
        local = min(LOCAL, int(device.max_work_group_size))
        if local != LOCAL:
            return Verdict(False, f"work-groups of {LOCAL} items are not supported "
                           f"(max {local})", seconds=time.perf_counter() - t0)
        prog.ocltm_probe(q, (N_ITEMS,), (LOCAL,), xb, ob, cl.LocalMemory(16 * LOCAL))
        cl.enqueue_copy(q, out, ob)
        q.finish()
    except cl.Error as exc:
        return Verdict(False, first_error_line(str(exc)), seconds=time.perf_counter() - t0)
    err = float(np.max(np.abs(out - want) / np.abs(want))) if np.all(np.isfinite(out)) \
        else float("inf")
    if not err <= RTOL:
        return Verdict(False, f"the probe kernel computed wrong values (relative error "
                       f"{err:.2g} > {RTOL:g})", seconds=time.perf_counter() - t0)
    return Verdict(True, seconds=time.perf_counter() - t0)


_verdicts: dict = {}


def verdict(device) -> Verdict:
    """The device's verdict: from this process, else the user's cache, else a probe
    (then cached)."""
    key = cache_key(device)
    v = _verdicts.get(key)
    if v is not None:
        return v
    rec = _load().get(key)
    if isinstance(rec, dict) and isinstance(rec.get("ok"), bool):
        v = Verdict(rec["ok"], str(rec.get("reason", "")), cached=True)
    else:
        v = run_probe(device)
        _store(key, {"ok": v.ok, "reason": v.reason, **device_record(device),
                     "probe_seconds": round(v.seconds, 4),
                     "when": time.strftime("%Y-%m-%dT%H:%M:%S")})
    _verdicts[key] = v
    return v


def forget(device) -> None:
    """Drop the device's verdict (a real kernel failed to build after the probe
    passed: the next start probes again)."""
    key = cache_key(device)
    _verdicts.pop(key, None)
    _store(key, None)


def describe_driver(device) -> str:
    r = device_record(device)
    return f"'{r['device']}' on {r['platform']} ({r['platform_version'].split('  ')[0]}, " \
           f"driver {r['driver_version']})"


def is_pocl(device) -> bool:
    return "portable computing language" in device.platform.name.lower() or \
        "pocl" in device.platform.version.lower()


def fix_hint(device=None) -> str:
    """How to get a working CPU device on this machine: one command per route."""
    import platform
    import shutil
    routes = []
    x86 = platform.machine().lower() in ("x86_64", "amd64")
    if x86 and platform.system() == "Linux" and icd.intel_library() is None:
        routes.append("pip install " + " ".join(icd.INTEL_PACKAGES)
                      + " (Intel's CPU OpenCL runtime, Intel and AMD CPUs; "
                      'or the ".[intel-cpu]" extra)')
    if shutil.which("apt-get"):
        routes.append("apt-get install pocl-opencl-icd (Debian/Ubuntu PoCL)")
    if not routes:
        routes.append("install your GPU or CPU vendor's OpenCL driver")
    return "fix: " + "; or ".join(routes)
