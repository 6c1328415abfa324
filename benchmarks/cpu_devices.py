"""CPU OpenCL devices side by side, and the time to the first frame.

Which CPU device a run takes by default where two work (pyopencl's bundled PoCL and
Intel's CPU runtime from the ``intel-cpu`` extra) is decided from this table:

1. per device and operator (defaults): ms per frame in process at 1920x1080 (the
   tunnel sample's frame at t = 5.5 s, median of 5 after a warm-up), and Delta E ITP
   (BT.2124, display light, 100 cd/m^2 white) against the float64 reference backend
   at 640x360 (median / p99 / max), and against the other device;
2. time to the first frame: the whole command on one 320x180 EXR frame to an 8-bit
   PNG, warm (every cache filled; median of 5), per device, beside
   ``pfsin | pfstmo_pattanaik00 | pfsout`` on the same frame, and, with ``--before
   REV``, the same command of that revision (a git worktree) for a before/after.

One command:  python -m benchmarks.cpu_devices [--before REV] [--out-dir DIR | --out FILE]
Writes cpu_devices.md into DIR (default ./benchmark-results; the committed one:
--out-dir benchmarks/results, i.e. benchmarks/results/cpu_devices.md).
"""

from __future__ import annotations

import argparse
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.scenes import tunnel
from benchmarks.lib.timing import child_peak

HERE = Path(__file__).resolve().parent
OPS = ("pattanaik00", "durand00", "ledda04", "kirk11")


def cpu_devices():
    """[(key, device)] of the CPU devices that pass the probe."""
    from ocl_tonemap.backends.opencl import probe
    from ocl_tonemap.backends.opencl.runtime import cl_api, list_devices
    cl = cl_api()
    return [(k, d) for k, d in list_devices()
            if d.type & cl.device_type.CPU and probe.verdict(d).ok]


def ictcp(display_linear: np.ndarray) -> np.ndarray:
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    M = colour.matrix_RGB_to_RGB(colour.RGB_COLOURSPACES["ITU-R BT.709"],
                                 colour.RGB_COLOURSPACES["ITU-R BT.2020"])
    rgb = np.clip(np.asarray(display_linear, np.float64)[..., :3], 0, None) * 100.0
    return colour.RGB_to_ICtCp(rgb @ M.T)


def delta_e(a, b) -> tuple[float, float, float]:
    Ia, Ib = ictcp(a), ictcp(b)
    d = 720.0 * np.sqrt((Ia[..., 0] - Ib[..., 0]) ** 2 + (0.5 * (Ia[..., 1] - Ib[..., 1])) ** 2
                        + (Ia[..., 2] - Ib[..., 2]) ** 2).ravel()
    return float(np.median(d)), float(np.percentile(d, 99)), float(d.max())


def frames(w, h):
    return [tunnel(w, h, t=5.5 + i / 30.0) for i in range(6)]


def per_frame_ms(op, backend, device, imgs) -> tuple[float, list]:
    from ocl_tonemap import Tonemapper
    tm = Tonemapper(op, backend=backend, device=device)
    outs, ts = [], []
    for i, img in enumerate(imgs):
        t0 = time.perf_counter()
        out = tm.process(img, time_s=i / 30.0)
        ts.append(time.perf_counter() - t0)
        outs.append(np.array(out, np.float32))
    return statistics.median(ts[1:]) * 1e3, outs


def section_devices(devs) -> list[str]:
    big, small = frames(1920, 1080), frames(640, 360)[:3]
    rows, outs = [], {}
    for op in OPS:
        _, ref = per_frame_ms(op, "reference", None, small)
        for key, d in devs:
            ms, _ = per_frame_ms(op, "opencl", key, big)
            _, o = per_frame_ms(op, "opencl", key, small)
            outs[(op, key)] = o
            de = delta_e(np.concatenate(o), np.concatenate(ref))
            rows.append((op, f"{key} {d.platform.name.strip()}", f"{ms:.0f}",
                         " / ".join(f"{v:.2g}" for v in de)))
        if len(devs) == 2:
            de = delta_e(np.concatenate(outs[(op, devs[0][0])]),
                         np.concatenate(outs[(op, devs[1][0])]))
            rows.append((op, "device vs device", "", " / ".join(f"{v:.2g}" for v in de)))
    out = ["## 1. Per frame, in process", "",
           "ms per frame at 1920x1080 (median of 5 after a warm-up); Delta E ITP median / "
           "p99 / max at 640x360 over 3 frames against the float64 reference backend (and "
           "between the devices).", "",
           "| operator | device | ms / frame 1080p | Delta E ITP vs reference |", "|---|---|---|---|"]
    out += [f"| {' | '.join(r)} |" for r in rows]
    return out + [""]


def timed(cmd, env, repeat=5, cwd=None) -> tuple[float, float] | None:
    """(median wall seconds, peak RSS MiB of the largest run) of ``repeat`` runs of
    ``cmd`` after a warm-up run; None when it fails."""
    shell = isinstance(cmd, str)
    run = dict(env=env, cwd=cwd, capture_output=True, shell=shell,
               executable="/bin/bash" if shell else None)
    subprocess.run(cmd, **run)                                  # warm
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        r = subprocess.run(cmd, **run)
        ts.append(time.perf_counter() - t0)
        if r.returncode != 0:
            print(f"  failed: {cmd}: {(r.stderr or r.stdout)[-300:]!r}", file=sys.stderr)
            return None
    return statistics.median(ts), peak_of(cmd, env, cwd)


def peak_of(cmd, env, cwd=None) -> float | None:
    """Peak RSS (MiB) of one run of ``cmd`` (a shell pipeline: its largest process)."""
    return child_peak(cmd, env, cwd)[0]


def section_first_frame(devs, before: str | None) -> list[str]:
    from ocl_tonemap.io.sample import write_tunnel_sequence
    tmp = Path(tempfile.mkdtemp(prefix="ocltm-ttff-"))
    pattern, fr = write_tunnel_sequence(str(tmp / "in"), 320, 180, 30.0, 0.1)
    src = pattern.replace("####", f"{fr[0]:04d}")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(HERE.parent)       # "now": this tree, as section 1 imports it
    rows = []
    py = [sys.executable, "-m", "ocl_tonemap", "run", src]
    if before:
        wt = tmp / "before"
        subprocess.run(["git", "worktree", "add", "-f", "--detach", str(wt), before],
                       cwd=HERE.parent, check=True, capture_output=True)
        try:
            benv = {**env, "PYTHONPATH": str(wt)}
            subprocess.run([sys.executable, "-m", "compileall", "-q", str(wt / "ocl_tonemap")],
                           capture_output=True)
            for op in ("pattanaik00", "durand00"):
                t = timed(py + [str(tmp / "b.png"), "--operator", op, "-q"], benv, cwd=tmp)
                rows.append((f"before ({before[:10]})", op, "default device", t))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(wt)], cwd=HERE.parent,
                           capture_output=True)
    for op in ("pattanaik00", "durand00"):
        t = timed(py + [str(tmp / "a.png"), "--operator", op, "-q"], env, cwd=tmp)
        rows.append(("now", op, "default device", t))
    for key, d in devs:
        t = timed(py + [str(tmp / "a.png"), "--device", key, "-q"], env, cwd=tmp)
        rows.append(("now", "pattanaik00", f"{key} {d.platform.name.strip()}", t))
    t = timed(py + [str(tmp / "r.png"), "--backend", "reference", "-q"], env, cwd=tmp)
    rows.append(("now", "pattanaik00", "--backend reference", t))
    if all(shutil.which(p) for p in ("pfsin", "pfsout", "pfstmo_pattanaik00")):
        t = timed(f"pfsin {src} | pfstmo_pattanaik00 | pfsout {tmp / 'p.png'}", env)
        rows.append(("pfstools", "pfstmo_pattanaik00", "CPU", t))
    else:
        rows.append(("pfstools", "pfstmo_pattanaik00", "not installed (apt-get install "
                     "pfstools pfstmo)", None))
    t = timed([sys.executable, "-c", "pass"], env)
    rows.append(("python -c pass", "", "", t))
    shutil.rmtree(tmp, ignore_errors=True)
    out = ["## 2. Time to the first frame", "",
           "The whole command on one 320x180 EXR frame of the tunnel sample to an 8-bit PNG, "
           "warm (kernel, probe and table caches filled by a first run), median of 5 wall "
           "times; peak memory: the largest process of one run (RSS).", "",
           "| code | operator | device | seconds | peak MiB |", "|---|---|---|---|---|"]
    out += [f"| {a} | {b} | {c} | {'—' if t is None else f'{t[0]:.3f}'} | "
            f"{'—' if t is None or t[1] is None else f'{t[1]:.0f}'} |" for a, b, c, t in rows]
    return out + [""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", help="a git revision to time the first frame of, for a "
                    "before/after")
    add_out_args(ap, "cpu_devices.md")
    ap.add_argument("--sections", default="1,2")
    a = ap.parse_args(argv)
    devs = cpu_devices()
    lines = ["# CPU OpenCL devices and the time to the first frame", "",
             f"Machine: {platform.machine()}, {os.cpu_count()} cores ({platform.processor() or '?'}), "
             f"Python {platform.python_version()}. Working CPU devices: "
             + (", ".join(f"{k} {d.name.strip()} on {d.platform.name.strip()} "
                          f"(driver {d.driver_version.strip()})" for k, d in devs) or "none"),
             "", "`python -m benchmarks.cpu_devices --out-dir benchmarks/results` writes "
             "this file.", ""]
    secs = a.sections.split(",")
    if "1" in secs:
        lines += section_devices(devs)
    if "2" in secs:
        lines += section_first_frame(devs, a.before)
    Path(out_path(a, "cpu_devices.md")).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
