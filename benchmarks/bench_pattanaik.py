"""Benchmark of the pattanaik00 pipeline: OpenCL vs the float64 reference.

One command:  python -m benchmarks.bench_pattanaik [--quick] [--out-dir DIR | --out FILE]
Writes pattanaik00.md into DIR (default ./benchmark-results; the committed one:
--out-dir benchmarks/results) and prints it.

For 640x360, 1920x1080 and 3840x2160 frames of a generated HDR scene:
* ms/frame and MPix/s of the whole frame on the device path (upload, colour
  stage, metering reductions, host scheduler, per-pixel pass, download), and
  of the per-pixel kernel alone;
* the same for the float64 reference (ratio = reference / OpenCL);
* a copy-bandwidth roofline: device buffer-to-buffer copy bandwidth measured on
  the same device, and the time the per-pixel pass would take if it only moved
  its bytes (rgb + Y + Y' in, rgb out = 32 B/pixel) at that bandwidth;
* max and mean error of the OpenCL output against the reference, scaled as in
  the tests (|d| / max(1, |ref|)), display-linear.
Also measures scalar pow() vs exp2(e*log2(x)), scalar and float4, on the device.
Machines are noisy: compare the ratios, not the absolute times.
"""

from __future__ import annotations

import argparse
import os
import platform

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.scenes import sky_gradient
from benchmarks.lib.timing import copy_bandwidth, timeit
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime

SIZES = [(640, 360), (1920, 1080), (3840, 2160)]

POW_SRC = r"""
__kernel void k_pow(__global const float *x, __global float *y, const float e, const int n)
{ int i = get_global_id(0); if (i < n) y[i] = pow(x[i], e); }
__kernel void k_exp2log2(__global const float *x, __global float *y, const float e, const int n)
{ int i = get_global_id(0); if (i < n) y[i] = exp2(e * log2(x[i])); }
__kernel void k_pow4(__global const float4 *x, __global float4 *y, const float e, const int n)
{ int i = get_global_id(0); if (i < n) y[i] = pow(x[i], (float4)(e)); }
__kernel void k_exp2log2_4(__global const float4 *x, __global float4 *y, const float e, const int n)
{ int i = get_global_id(0); if (i < n) y[i] = exp2(e * log2(x[i])); }
"""


def pow_bench(rt, n=1 << 22):
    import pyopencl as cl
    prg = cl.Program(rt.context, POW_SRC).build()
    x = np.random.default_rng(0).uniform(1e-3, 1e4, n).astype(np.float32)
    mf = cl.mem_flags
    xb = cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=x)
    yb = cl.Buffer(rt.context, mf.READ_WRITE, x.nbytes)
    ref = x.astype(np.float64) ** 0.73
    rows = []
    for name, vec in (("k_pow", 1), ("k_exp2log2", 1), ("k_pow4", 4), ("k_exp2log2_4", 4)):
        k = cl.Kernel(prg, name)
        m = n // vec

        def go():
            k(rt.queue, (m,), None, xb, yb, np.float32(0.73), np.int32(m))
            rt.queue.finish()
        t = timeit(go, 5)
        y = np.empty_like(x)
        cl.enqueue_copy(rt.queue, y, yb)
        rel = np.abs(y / ref - 1).max()
        rows.append((name, t * 1e3, n / t / 1e6, rel))
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer repetitions")
    add_out_args(ap, "pattanaik00.md")
    args = ap.parse_args()
    reps = 3 if args.quick else 7
    rt = get_runtime()
    lines = ["# pattanaik00 benchmark", "",
             f"- device: {describe_device(rt.device)}",
             f"- host: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
             f"Python {platform.python_version()}, NumPy {np.__version__}",
             f"- command: `python -m benchmarks.bench_pattanaik{' --quick' if args.quick else ''}`",
             f"- median of {reps} runs after a warm-up; ratios are what to compare across machines.", ""]
    lines += ["## Whole frame and per-pixel pass", "",
              "| size | OpenCL ms/frame | MPix/s | kernel ms (vector: 8 px/item) | kernel ms (scalar) "
              "| roofline ms | kernel/roofline | reference ms | reference/OpenCL | max err | mean err |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for w, h in SIZES:
        img = sky_gradient(w, h)
        tm = Tonemapper(backend="opencl")
        tm.process(img)
        t_ocl = timeit(lambda: tm.process(img, dt=1 / 30), reps)
        # per-pixel kernel alone, on the resident buffers of the last frame
        be = tm.backend
        b = be.bufs
        from ocl_tonemap.models import pattanaik2000 as P
        params = P.frame_params(tm.scalar_state(), tm.display)

        def kern(vector=True):
            be.run_pointwise(tm.op.kernel_call(params, vector), b["rgb"], b["Y"], b["Ys"],
                             b["out"], w * h)
            be.rt.queue.finish()
        t_k = timeit(kern, reps)
        t_ks = timeit(lambda: kern(False), reps)
        bw = copy_bandwidth(rt, w * h * 16)
        t_roof = w * h * 32 / bw
        ref = Tonemapper(backend="reference")
        ref.process(img)
        t_ref = timeit(lambda: ref.process(img, dt=1 / 30), 1 if w > 2000 else 3)
        # error: same state on both
        a = Tonemapper(backend="reference")
        o = Tonemapper(backend="opencl")
        for s in (1.0, 0.01, 1.0):
            ra = a.process(img * s, dt=0.1)
            ro = o.process(img * s, dt=0.1)
        err = np.abs(ro.astype(np.float64) - ra) / np.maximum(1.0, np.abs(ra))
        lines.append(f"| {w}x{h} | {t_ocl*1e3:.1f} | {w*h/t_ocl/1e6:.1f} | {t_k*1e3:.2f} | "
                     f"{t_ks*1e3:.2f} | {t_roof*1e3:.2f} | {t_k/t_roof:.1f} | {t_ref*1e3:.0f} | {t_ref/t_ocl:.1f} | "
                     f"{err.max():.2e} | {err.mean():.2e} |")
        print(lines[-1], flush=True)
    lines += ["", f"Copy bandwidth (buffer to buffer, read+write): {bw/1e9:.1f} GB/s at the 4K size.", ""]
    lines += ["## pow() vs exp2(e*log2(x)), x^0.73 on 4M values", "",
              "| kernel | ms | Mvalues/s | max rel err vs float64 |", "|---|---|---|---|"]
    for name, ms, mv, rel in pow_bench(rt):
        lines.append(f"| {name} | {ms:.2f} | {mv:.0f} | {rel:.1e} |")
    text = "\n".join(lines) + "\n"
    out = out_path(args, "pattanaik00.md")
    tmp = out + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(text)
    os.replace(tmp, out)
    print(text)


if __name__ == "__main__":
    main()
