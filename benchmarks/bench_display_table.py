"""Benchmark of the display encoding: OCIO's CPU processor against the baked table on
the OpenCL device (colour.bake_display_table, kernels/display.cl), time and error.

One command:  python -m benchmarks.bench_display_table [--quick] [--out-dir DIR]
Writes display_table.md into DIR (default ./benchmark-results; the committed one:
--out-dir benchmarks/results) and prints it.

1. Every display/view of the bundled config (and, for the 3D form, HLG and an ACES
   output transform of OCIO's built-in studio config): the table's form and bake
   time; its error against OCIO over >= 1e6 RGB (the grey axis and the primaries and
   secondaries dense, random triples over log-luminance, saturated colours) in 10-bit
   code values, max and 99.9th percentile, of the device's output; the kernel against
   its float64 NumPy reference; ms per frame (1080p, 4K) of OCIO's encode and of the
   table (upload + kernel + download), on a smooth display-linear frame.
2. Whole runs (not with --quick): the built-in sample at 1080p to PNG, with
   --display-encode ocio and table, overlapped and serial I/O.
Machines are noisy: compare the ratios, not the absolute times.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.scenes import display_frame
from benchmarks.lib.timing import table, timeit
from ocl_tonemap import colour
from ocl_tonemap.backends.opencl.display import DeviceDisplayTable
from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime

STUDIO = "ocio://studio-config-latest"
EXTRA_3D = [(STUDIO, "Rec.2100-HLG - Display", "Un-tone-mapped"),
            (STUDIO, "sRGB - Display", "ACES 2.0 - SDR 100 nits (Rec.709)")]


def cases():
    cfg = colour.load_config("ocl-tonemap")
    out = [("ocl-tonemap", d, v) for d, views in colour.list_displays(cfg) for v in views]
    return out + EXTRA_3D


def bench_tables(rt, sizes, reps, n_probe):
    probe = colour.display_probe_set(n_probe, seed=11)
    frames = {s: display_frame(*s) for s in sizes}
    rows = []
    for src, display, view in cases():
        cp = colour.ColourPipeline(colour.load_config(src), display, view)
        t0 = time.perf_counter()
        tab = cp.display_table()
        bake = time.perf_counter() - t0
        name = f"{'' if src == 'ocl-tonemap' else 'studio: '}{display} / {view}"
        ocio_ms = [timeit(lambda f=f: cp.encode(f), reps) * 1e3 for f in frames.values()]
        if tab.kind == "identity":
            rows.append((name, "identity (OCIO no-op)", f"{bake * 1e3:.0f}", "0", "0", "-",
                         *(f"{m:.1f}" for m in ocio_ms), *("-" for _ in sizes)))
            continue
        dev = DeviceDisplayTable(tab, runtime=rt)
        x = probe.reshape(1, -1, 3)
        want = cp.encode(x)[0].astype(np.float64)
        got = dev.encode(x)[0].astype(np.float64)
        e = np.abs(got - want).max(axis=1) * 1023
        kref = np.abs(got - tab.apply(probe)).max()
        table_ms = [timeit(lambda f=f: dev.encode(f), reps) * 1e3 for f in frames.values()]
        form = (f"1D {tab.size} x 3" if tab.kind == "1d" else f"3D {tab.size}^3") + \
            f", {tab.shaper} 2^{np.log2(tab.eps):g}"
        rows.append((name, form, f"{bake * 1e3:.0f}", f"{e.max():.3g}",
                     f"{np.percentile(e, 99.9):.3g}", f"{kref:.1e}",
                     *(f"{m:.1f}" for m in ocio_ms), *(f"{m:.1f}" for m in table_ms)))
        dev.release()
    labels = [f"{w}x{h}" for w, h in sizes]
    head = ("display / view", "table", "bake ms", "max err (10-bit)", "99.9% err (10-bit)",
            "kernel - ref", *(f"OCIO ms {s}" for s in labels),
            *(f"table ms {s}" for s in labels))
    return table(head, rows), len(probe)


def bench_runs(reps):
    from ocl_tonemap.cli.table import main
    from ocl_tonemap.io.sample import write_tunnel_sequence
    rows = []
    with tempfile.TemporaryDirectory() as d:
        pattern, frames = write_tunnel_sequence(d, 1920, 1080, 30.0, 0.4)
        for io in ("overlapped", "serial"):
            for mode in ("ocio", "table"):
                ts = []
                for r in range(reps):
                    t = time.perf_counter()
                    args = ["run", pattern, os.path.join(d, f"o_{mode}.#.png"),
                            "--display-encode", mode, "-q"]
                    if io == "serial":
                        args.append("--serial-io")
                    assert main(args) == 0
                    ts.append(time.perf_counter() - t)
                ts.sort()
                rows.append((io, mode, len(frames), f"{ts[len(ts) // 2]:.2f}",
                             f"{ts[len(ts) // 2] / len(frames) * 1e3:.0f}"))
    return table(("I/O", "--display-encode", "frames", "run s (median)", "ms/frame"), rows)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    add_out_args(ap)
    a = ap.parse_args()
    rt = get_runtime()
    reps = 3 if a.quick else 7
    sizes = [(960, 540)] if a.quick else [(1920, 1080), (3840, 2160)]
    tab_text, n = bench_tables(rt, sizes, reps, 100_000 if a.quick else 1_000_000)
    parts = [
        "# Display encoding: OCIO CPU processor against the baked device table\n",
        f"Device: {describe_device(rt.device)}; host: "
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs. Command: `python -m benchmarks.bench_display_table"
        f"{' --quick' if a.quick else ''}`. Median of {reps} runs after a warm-up.\n",
        f"## 1. Per display/view\n\nErrors: the device's output against OCIO's CPU processor "
        f"over {n} working-space RGB in [0, 100] (`colour.display_probe_set`), in 10-bit "
        "code values (1/1023); `kernel - ref`: the largest |float32 kernel - float64 "
        "reference| in code values. Times: one frame of smooth display-linear RGB "
        "(`display_frame`); the table's time is upload + kernel + download. The bound "
        "is one 10-bit code value; `--display-encode auto` uses the table only within it. "
        "On a shared CPU the device's times are bimodal (PoCL's threads on all cores: "
        "x2 when another process holds one); OCIO's encode is one thread.\n",
        tab_text, ""]
    if not a.quick:
        parts += ["## 2. Whole runs: the built-in sample, 1080p, pattanaik00 -> 8-bit PNG\n",
                  "The encode runs on the writer thread beside the device's next frame "
                  "(overlapped) or in turn (`--serial-io`). On a CPU OpenCL device the "
                  "table's kernel shares the cores with the operator's kernels.\n",
                  bench_runs(3), ""]
    text = "\n".join(parts)
    with open(out_path(a, "display_table.md"), "w") as fh:
        fh.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
