"""Benchmark of kirk11: time per frame beside error, the Eq. 15 fallback rate and cost.

One command:  python -m benchmarks.bench_kirk [--quick] [--out-dir DIR]
Writes kirk11.md into DIR (default ./benchmark-results; the committed one:
--out-dir benchmarks/results) and prints it.

1. Whole frame, RGB and spectral (31 channels) input, OpenCL with the fast and the
   exact bilateral, and the float64 reference (small size only: its brute-force
   bilateral is slow); error against the reference.
2. The Purkinje pass alone (kernels/kirk11.cl, kirk11_shift) across exposures:
   the share of pixels where the unconstrained solve of Eq. 15 went negative
   and the exact 3-variable NNLS took over, and what that costs.
Machines are noisy: compare the ratios, not the absolute times.
"""

from __future__ import annotations

import argparse
import os
import platform

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.scenes import sine_texture, spectral_chart
from benchmarks.lib.timing import table, timeit
from ocl_tonemap.models import kirk2011 as ko
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime


def bench_frames(sizes, ref_size, reps):
    rows = []
    for w, h in sizes:
        img = sine_texture(w, h)
        lam, cube = spectral_chart(w, h)
        for label, frame, kw in (("RGB", img, {}), ("spectral 31", cube, {"wavelengths": lam})):
            ref = None
            if (w, h) == ref_size:
                tr = Tonemapper("kirk11", "reference")
                ref = tr.process(frame, **kw)
                t_ref = timeit(lambda: tr.process(frame, dt=0.04, **kw), 1)
            for method in ("fast", "exact"):
                if method == "exact" and (w, h) != ref_size:
                    continue
                tm = Tonemapper("kirk11", "opencl", options={"bilateral": method})
                out = tm.process(frame, **kw)
                t = timeit(lambda: tm.process(frame, dt=0.04, **kw), reps)
                err = "-" if ref is None else f"{np.max(np.abs(out - ref)):.1e}"
                ratio = "-" if ref is None else f"{t_ref / t:.0f}x"
                rows.append((f"{w}x{h}", label, method, f"{t * 1e3:.0f}", ratio, err,
                             f"{tm.last.params['fallback_fraction']:.1%}"))
    return table(("size", "input", "bilateral", "OpenCL ms/frame", "float64 / OpenCL",
                  "max abs err vs float64 (display-linear)", "Eq. 15 fallback"), rows)


def bench_nnls(w, h, reps):
    """The shift kernel per exposure, for the paper (x = y = 15, exact NNLS of Eq. 15)
    and the default (white-referenced, x = y = 0.5, gamut map): how often the
    unconstrained solve fails, and what the fallback costs."""
    import pyopencl as cl
    from ocl_tonemap.models import lmsr
    rt = get_runtime()
    from ocl_tonemap.backends.opencl.lmsr import KERNEL_CONSTANTS
    k_shift = rt.kernel("kirk11.cl", "kirk11_shift", KERNEL_CONSTANTS)
    n = w * h
    mf = cl.mem_flags
    rows = []
    base = sine_texture(w, h) / np.float32(sine_texture(w, h).mean())
    for mode in ("paper", "default"):
        st = ko.KirkSettings(kappa="full", mode=mode)
        M, D = ko.display_matrix(np.eye(3)), np.eye(3)
        paper = mode == "paper"
        dw = np.ones(3) if paper else ko.white_norm()[:3]
        for exposure in (1e5, 1e3, 10.0, 0.1, 1e-3):
            q = lmsr.rgb_to_lmsr(base.reshape(-1, 3) * exposure).astype(np.float32)
            area = ko.model_scale()
            par = np.array([area, ko.KAPPA1, ko.KAPPA2, 1.0, *st.shift_xyz, *ko.RHO, *dw,
                            1.0 if paper else 0.0], np.float32)
            bufs = {k: cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR,
                                 hostbuf=np.ascontiguousarray(v, np.float32))
                    for k, v in (("q", q), ("par", par), ("inv", np.linalg.inv(M).reshape(-1)),
                                 ("sol", ko.subset_solvers(M).reshape(-1)), ("M", M),
                                 ("D", D))}
            out3 = cl.Buffer(rt.context, mf.READ_WRITE, n * 12)
            o1, o2 = (cl.Buffer(rt.context, mf.READ_WRITE, n * 4) for _ in range(2))
            fb = cl.Buffer(rt.context, mf.READ_WRITE, 4)

            def run():
                cl.enqueue_fill_buffer(rt.queue, fb, np.int32(0), 0, 4)
                k_shift(rt.queue, (-(-n // 64) * 64,), (64,), bufs["q"], np.int32(n),
                        bufs["par"], bufs["inv"], bufs["sol"], bufs["M"], bufs["D"], out3, o1,
                        o2, fb)
                rt.queue.finish()
            t = timeit(run, reps)
            c = np.empty(1, np.int32)
            cl.enqueue_copy(rt.queue, c, fb)
            rows.append((mode, f"{exposure:g}", f"{c[0] / n:.1%}", f"{t * 1e3:.2f}",
                         f"{n / t / 1e6:.0f}"))
    return table(("mode", "exposure (x mean 1 cd/m^2)", "Eq. 15 fallback", "shift kernel ms",
                  "MPix/s"), rows)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    add_out_args(ap)
    a = ap.parse_args()
    rt = get_runtime()
    reps = 3 if a.quick else 5
    sizes = [(160, 90)] if a.quick else [(160, 90), (640, 360), (1920, 1080)]
    nw, nh = (320, 180) if a.quick else (1920, 1080)
    text = "\n".join([
        "# kirk11 benchmark\n",
        f"Device: {describe_device(rt.device)}; host: {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs. Command: `python -m benchmarks.bench_kirk"
        f"{' --quick' if a.quick else ''}`. Median of {reps} runs after a warm-up.\n",
        "## 1. Whole frame\n", bench_frames(sizes, (160, 90), reps),
        f"\n## 2. Purkinje shift + Eq. 15 solve alone, {nw}x{nh}, fixed (paper) kappa\n",
        bench_nnls(nw, nh, reps), ""])
    with open(out_path(a, "kirk11.md"), "w") as fh:
        fh.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
