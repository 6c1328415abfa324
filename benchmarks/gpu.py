"""A GPU tool at the speed of its bus and its disks (issue 47): one command, one table.

    python -m benchmarks.gpu [--out-dir DIR] [--sizes 1920x1080,3840x2160] [--frames N]

Measures, on the machine it runs on (the device and the host named in the table):

1. **the floor**: the same frames (half-float zip EXR) decoded and encoded to 8-bit PNG
   on all cores with no tone mapping (OIIO on a pool of threads, sRGB by a plain
   power curve): what the disks and the codecs allow;
2. **the whole command** per operator, with the defaults and with ``--model none``,
   against the floor (throughput ratio), with its host <-> device transfers per frame;
3. **the API**: ``Tonemapper.process`` of a float32 frame from host NumPy (out to the
   host) and of a device array (out as a device array), frames per second.

On a GPU machine it runs 1920x1080 and 3840x2160 (about 4 minutes on an H100); on a
machine whose OpenCL device is a CPU, 480x270 and 960x540 (so CI's 2-core machine
still gets a table). Ratios are the numbers to quote: these machines are shared.
Writes ``gpu.md`` (``--out-dir``; the committed one: ``--out-dir benchmarks/results``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import OpenImageIO as oiio

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import cpu_model
from benchmarks.lib.timing import table

OPERATORS = ("pattanaik00", "durand00", "ledda04", "kirk11")


def write_scene(folder: str, w: int, h: int, n: int) -> str:
    """The tunnel drive at ``w`` x ``h`` (5000 -> 5 cd/m^2 ...), ``n`` frames, as
    half-float zip EXR (the form a renderer hands over); returns its pattern."""
    from ocl_tonemap.io.sample import render_frame
    os.makedirs(folder, exist_ok=True)
    for k in range(n):
        pix = render_frame(2.0 + k / 30.0, w, h, 8.0).astype(np.float32)
        spec = oiio.ImageSpec(w, h, 3, oiio.HALF)
        spec.attribute("compression", "zip")
        path = os.path.join(folder, f"scene.{k + 1:04d}.exr")
        out = oiio.ImageOutput.create(path)
        out.open(path, spec)
        out.write_image(pix)
        out.close()
    return os.path.join(folder, "scene.####.exr")


def floor(pattern: str, n: int, out_dir: str, threads: int) -> float:
    """Seconds to decode ``n`` frames and encode them to 8-bit PNG on ``threads``
    threads (no tone mapping): the disks' and codecs' rate."""
    from ocl_tonemap.io.patterns import frame_path
    os.makedirs(out_dir, exist_ok=True)

    def one(k):
        buf = oiio.ImageBuf(frame_path(pattern, k))
        pix = buf.get_pixels(oiio.FLOAT)
        code = (np.clip(pix, 0.0, 1.0) ** (1 / 2.2) * 255.0 + 0.5).astype(np.uint8)
        out = oiio.ImageBuf(oiio.ImageSpec(pix.shape[1], pix.shape[0], 3, oiio.UINT8))
        out.set_pixels(oiio.ROI(), code)
        out.write(os.path.join(out_dir, f"f.{k:04d}.png"))
    t = time.perf_counter()
    with ThreadPoolExecutor(threads) as ex:
        list(ex.map(one, range(1, n + 1)))
    return time.perf_counter() - t


def whole_command(pattern: str, n: int, op: str, model: str, out_dir: str) -> tuple:
    """(seconds, transfers line) of ``ocl-tonemap run`` over the frames to PNG."""
    os.makedirs(out_dir, exist_ok=True)
    cmd = [sys.executable, "-m", "ocl_tonemap", "run", pattern,
           os.path.join(out_dir, "o.####.png"), "--operator", op, "--model", model,
           "--fps", "30", "--no-checkpoint"]
    t = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    sec = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(f"{op} {model}: {r.stderr.strip().splitlines()[-1:]}")
    moved = [ln.split(": ", 1)[1] for ln in r.stdout.splitlines()
             if ln.startswith("host <-> device per frame")]
    return sec, (moved[0] if moved else "")


def api(op: str, model: str, w: int, h: int, reps: int) -> dict:
    """Frames per second of ``process``: host float32 in and out, and device arrays in
    and out; the transfers of each kind of frame."""
    import pyopencl.array as cla

    from ocl_tonemap import Tonemapper
    from ocl_tonemap.io.sample import render_frame
    frames = [render_frame(2.0 + k / 30.0, w, h, 8.0).astype(np.float32) for k in range(3)]
    out = {}
    for kind in ("host", "device"):
        tm = Tonemapper(op, "opencl", model=model)
        q = tm.backend.device_runtime().queue
        src = frames if kind == "host" else [cla.to_device(q, f) for f in frames]
        tm.process(src[0])
        tm.process(src[1], dt=1 / 30)
        q.finish()
        t = time.perf_counter()
        for k in range(reps):
            res = tm.process(src[k % 3], dt=1 / 30)
        if kind == "device":
            res.finish()
        q.finish()
        out[kind] = reps / (time.perf_counter() - t)
        out[kind + "_moved"] = tm.last.transfers
    return out


def _moved(t: dict | None) -> str:
    if not t:
        return ""
    return (f"{t['up_bytes'] / 2**20:.2f} / {t['down_bytes'] / 2**20:.2f} MiB, "
            f"{t['up_calls'] + t['down_calls']} calls")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", help="WxH,WxH (default: 1920x1080,3840x2160 on a GPU, "
                    "480x270,960x540 on a CPU device)")
    ap.add_argument("--frames", type=int, default=None,
                    help="frames of the whole-command runs (default 48 on a GPU, 12 on a CPU)")
    ap.add_argument("--operators", default=",".join(OPERATORS))
    add_out_args(ap, "gpu.md")
    a = ap.parse_args(argv)
    from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime
    rt = get_runtime()
    import pyopencl as cl
    gpu = bool(rt.device.type & cl.device_type.GPU)
    sizes = a.sizes or ("1920x1080,3840x2160" if gpu else "480x270,960x540")
    sizes = [tuple(int(v) for v in s.split("x")) for s in sizes.split(",")]
    n = a.frames or (48 if gpu else 12)
    ops = a.operators.split(",")
    threads = os.cpu_count() or 1
    t0 = time.perf_counter()
    tmp = tempfile.mkdtemp(prefix="ocltm-gpu-")
    rows_cmd, rows_api = [], []
    try:
        for w, h in sizes:
            pattern = write_scene(os.path.join(tmp, f"{w}x{h}", "in"), w, h, n)
            fl = floor(pattern, n, os.path.join(tmp, f"{w}x{h}", "floor"), threads)
            rows_cmd.append((f"{w}x{h}", "floor (decode + encode, no mapping)", "",
                             f"{n / fl:.1f}", "1.00", ""))
            for op in ops:
                for model in ("auto", "none"):
                    sec, moved = whole_command(pattern, n, op, model,
                                               os.path.join(tmp, f"{w}x{h}", op + model))
                    rows_cmd.append((f"{w}x{h}", op, "defaults" if model == "auto" else
                                     "--model none", f"{n / sec:.1f}", f"{fl / sec:.2f}", moved))
            shutil.rmtree(os.path.join(tmp, f"{w}x{h}"), ignore_errors=True)
        w, h = sizes[-1]
        for op in ops:
            for model in ("auto", "none"):
                r = api(op, model, w, h, 12 if gpu else 4)
                rows_api.append((f"{w}x{h}", op, "defaults" if model == "auto" else
                                 "model='none'", f"{r['host']:.1f}", _moved(r["host_moved"]),
                                 f"{r['device']:.1f}", _moved(r["device_moved"])))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    lines = [
        "# GPU benchmark: the tool at the speed of its bus and its disks",
        "",
        f"Device: {describe_device(rt.device)}. Host: {cpu_model()}, {threads} cores, "
        f"{platform.system()} {platform.machine()}, Python {platform.python_version()}. "
        f"{time.strftime('%Y-%m-%d')}; the whole benchmark took {time.perf_counter() - t0:.0f} s "
        "(`python -m benchmarks.gpu`).",
        "",
        f"Whole command: {n} frames of the tunnel drive, half-float zip EXR in, 8-bit PNG out, "
        f"`--threads` left at the machine's {threads} cores; the floor decodes and encodes the "
        "same frames on as many threads with no tone mapping. `x floor` is the command's "
        "throughput over the floor's (issue 47's goal: >= 0.8 with the defaults). Transfers: "
        "up / down per frame (`host <-> device per frame` of the run's report).",
        "",
        table(("size", "operator", "model", "fps", "x floor", "host <-> device per frame"),
              rows_cmd),
        "",
        f"API: `Tonemapper.process` at {w}x{h}, steady state, a float32 frame from host "
        "NumPy (output to the host), and a `pyopencl.array.Array` in and out (nothing "
        "crosses but statistics). Transfers: up / down MiB and calls per frame.",
        "",
        table(("size", "operator", "model", "host fps", "host: moved", "device fps",
               "device: moved"), rows_api),
        "",
    ]
    path = out_path(a, "gpu.md")
    with open(path, "w") as fh:
        fh.write("\n".join(lines))
    print(f"wrote {path}")
    print(json.dumps({"seconds": round(time.perf_counter() - t0, 1)}))


if __name__ == "__main__":
    main()
