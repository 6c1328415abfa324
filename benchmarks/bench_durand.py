"""Benchmark of durand00 and the effects: speed beside accuracy for every knob.

One command:  python -m benchmarks.bench_durand [--quick] [--out-dir DIR]
Writes durand00.md into DIR (default ./benchmark-results; the committed one:
--out-dir benchmarks/results) and prints it.

Tables:
1. durand00 per frame (effects off): OpenCL vs the float64 reference, error.
2. Look-up tables (Sec. 5): direct evaluation vs 500 / 2000 / 8000 entries over
   12 decades -- per-pixel kernel time and error against direct float64.
3. Flares (Sec. 6): exact float64 FFT vs the fast pyramid (host float64 blur and
   device blur; Gaussians per octave 1/2; minimum coarse sigma 1/2 px) -- time
   and relative error in cd/m^2 against exact, on a night street with lamps.
4. Loss of acuity blur (Sec. 7): device vs reference.
5. A whole durand00 frame with the effects off and on auto.
Machines are noisy: compare the ratios, not the absolute times.
"""

from __future__ import annotations

import argparse
import os
import platform

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.scenes import night_street_lamps
from benchmarks.lib.timing import table, timeit
from ocl_tonemap.models import durand2000 as dd
from ocl_tonemap.models import spencer1995 as fl
from ocl_tonemap.backends import flare_exec as flx
from ocl_tonemap.backends.opencl.convolution import DeviceBlur
from ocl_tonemap.models.convolution import EDGE_CLAMP, blur_reference, gaussian_taps
from ocl_tonemap.effects import EffectSettings
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime

OFF = EffectSettings()


def bench_operator(sizes, reps):
    rows = []
    for w, h in sizes:
        img = night_street_lamps(w, h)
        ocl = Tonemapper("durand00", "opencl", effects=OFF)
        ref = Tonemapper("durand00", "reference", effects=OFF)
        ocl.process(img)
        ref.process(img)
        t_o = timeit(lambda: ocl.process(img, dt=1 / 30), reps)
        t_r = timeit(lambda: ref.process(img, dt=1 / 30), max(1, reps // 3))
        a = Tonemapper("durand00", "opencl", effects=OFF).process(img)
        b = Tonemapper("durand00", "reference", effects=OFF).process(img)
        err = float(np.max(np.abs(a - b) / np.maximum(1.0, np.abs(b))))
        rows.append((f"{w}x{h}", f"{t_o * 1e3:.1f}", f"{w * h / t_o / 1e6:.0f}",
                     f"{t_r * 1e3:.0f}", f"{t_r / t_o:.1f}x", f"{err:.1e}"))
    return table(("size", "OpenCL ms/frame", "MPix/s", "float64 ms/frame", "reference / OpenCL",
                  "max err (display-linear)"), rows)


def bench_lut(w, h, reps):
    import pyopencl as cl
    rt = get_runtime()
    img = night_street_lamps(w, h)
    tm = Tonemapper("durand00", "reference", effects=OFF)
    direct = tm.process(img)
    p0 = dd.FrameParams(**{**tm.last.params, "tint": tuple(tm.last.params["tint"])})
    be = Tonemapper("durand00", "opencl", effects=OFF).backend
    op = tm.op
    from ocl_tonemap.models.photometry import photopic_luminance, scotopic_luminance
    rgb = img.astype(np.float64)
    Y, Ys = photopic_luminance(rgb), scotopic_luminance(rgb)
    n = w * h
    mf = cl.mem_flags
    bufs = [cl.Buffer(rt.context, mf.READ_WRITE, n * 12) for _ in range(2)] + \
        [cl.Buffer(rt.context, mf.READ_WRITE, n * 4) for _ in range(2)]
    cl.enqueue_copy(rt.queue, bufs[0], img.reshape(-1, 3))
    cl.enqueue_copy(rt.queue, bufs[2], Y.astype(np.float32).ravel())
    cl.enqueue_copy(rt.queue, bufs[3], Ys.astype(np.float32).ravel())
    rows = []
    t_direct = None
    for entries in (0, 500, 2000, 8000):
        p = dd.FrameParams(**{**p0.as_dict(), "lut": entries, "tint": p0.tint})

        call = op.kernel_call(p)

        def run():
            be.run_pointwise(call, bufs[0], bufs[2], bufs[3], bufs[1], n)
            rt.queue.finish()
        t = timeit(run, reps)
        t_direct = t_direct or t
        out = np.empty((h, w, 3), np.float32)
        cl.enqueue_copy(rt.queue, out, bufs[1])
        ref = dd.map_reference(rgb, Y, Ys, p)
        ok = direct > 1e-4
        rel = np.abs(out[ok] - direct[ok]) / direct[ok]
        rel_ref = np.abs(ref[ok] - direct[ok]) / direct[ok]
        bound = 10 ** (0.5 * dd.LUT_DECADES / (entries - 1)) - 1 if entries else 0.0
        rows.append(("direct" if not entries else str(entries), f"{t * 1e3:.2f}",
                     f"{t / t_direct:.2f}", f"{rel_ref.max():.2%}", f"{rel.max():.2%}",
                     f"{np.mean(rel):.3%}", f"{bound:.2%}"))
    return table(("table entries", "kernel ms", "vs direct", "max rel err (float64 LUT)",
                  "max rel err (device)", "mean rel err (device)", "half-step bound"), rows)


def bench_flare(sizes, reps):
    """exact (float64 FFT) against the fast method: float64 on the host, the host-driven
    pyramid with the device's blur (streamed frames), and whole on the device (the
    default: backends/opencl/flare.py), per Gaussians/octave and PYRAMID_MIN_SIGMA."""
    from ocl_tonemap.backends.opencl import OpenCLBackend
    from ocl_tonemap.effects import flare as flare_fx
    rt = get_runtime()
    dev = DeviceBlur(rt)
    whole = OpenCLBackend().flare_device()
    rows = []
    for w, h in sizes:
        img = night_street_lamps(w, h).astype(np.float64)
        img32 = img.astype(np.float32)
        L = 0.3
        t_e = timeit(lambda: flx.apply_flare(img, L, L, 50.0, "exact"), 1)
        exact, info = flx.apply_flare(img, L, L, 50.0, "exact")
        rows.append((f"{w}x{h}", "exact (float64 FFT)", "-", "-", f"{t_e * 1e3:.0f}", "1.0x",
                     "0", "0", "0"))
        for po in (1, 2):
            for ms in (1.0, 1.5, 2.0):
                for where in ("float64 host", "host pyramid, device blur", "whole on device"):
                    if where != "whole on device" and (po, ms) != (1, fl.PYRAMID_MIN_SIGMA):
                        continue
                    old = fl.PYRAMID_MIN_SIGMA
                    fl.PYRAMID_MIN_SIGMA = ms
                    try:
                        fl.fit_gaussians((h, w), 50.0 / w, po)     # fit cached, as per shot
                        if where == "whole on device":
                            fx = EffectSettings(flare="on", flare_method="fast",
                                                flare_per_octave=po, fov_deg=50.0)

                            def go():
                                return flare_fx.run(fx, img32, L, L, device=whole)[0]
                        else:
                            blur = None if where == "float64 host" else \
                                (lambda im, t: dev.blur(im, t))

                            def go():
                                return flx.apply_flare(img, L, L, 50.0, "fast", per_octave=po,
                                                       blur=blur)[0]
                        t = timeit(go, reps)
                        fast = np.asarray(go(), np.float64)
                    finally:
                        fl.PYRAMID_MIN_SIGMA = old
                    rel = np.abs(fast - exact) / np.maximum(exact, 1e-12)
                    rows.append((f"{w}x{h}", f"fast, {where}", po, f"{ms:g}",
                                 f"{t * 1e3:.0f}", f"{t_e / t:.1f}x", f"{np.median(rel):.2%}",
                                 f"{np.percentile(rel, 99):.2%}", f"{rel.max():.1%}"))
        rows.append((f"{w}x{h}", f"({info['sources']} source px, pupil "
                     f"{info['pupil_mm']:.1f} mm; default: whole on device, 1/octave, "
                     f"{fl.PYRAMID_MIN_SIGMA:g} px)", "", "", "", "", "", "", ""))
    return table(("size", "method", "Gaussians/octave", "min coarse sigma px", "ms/frame",
                  "exact / this", "median rel err", "99th pct", "max"), rows)


def bench_acuity(sizes, reps):
    rt = get_runtime()
    dev = DeviceBlur(rt)
    rows = []
    for w, h in sizes:
        img = np.random.default_rng(0).random((h, w, 3)).astype(np.float32)
        for sigma in (1.0, 4.0):
            taps = gaussian_taps(sigma)
            t_d = timeit(lambda: dev.blur(img, taps, EDGE_CLAMP), reps)
            t_r = timeit(lambda: blur_reference(img, taps, EDGE_CLAMP), 1)
            err = float(np.max(np.abs(dev.blur(img, taps, EDGE_CLAMP)
                                      - blur_reference(img, taps, EDGE_CLAMP))))
            rows.append((f"{w}x{h}", f"{sigma:g}", f"{t_d * 1e3:.1f}", f"{t_r * 1e3:.0f}",
                         f"{t_r / t_d:.1f}x", f"{err:.1e}"))
    return table(("size", "sigma px", "device ms", "float64 ms", "float64 / device",
                  "max abs err"), rows)


def bench_frame(sizes, reps):
    rows = []
    for w, h in sizes:
        img = night_street_lamps(w, h) * np.float32(0.002)     # moonless: acuity matters at 50 deg
        for label, fxs in (("effects off", OFF),
                           ("auto (flare + acuity + chromatic)",
                            EffectSettings.for_operator("durand00"))):
            tm = Tonemapper("durand00", "opencl", effects=fxs)
            tm.process(img)
            t = timeit(lambda: tm.process(img, dt=1 / 30), reps)
            ran = ",".join(k for k, v in tm.last.effects.items() if v.get("ran")) or "none"
            rows.append((f"{w}x{h}", label, ran, f"{t * 1e3:.0f}"))
    return table(("size", "effects", "ran", "ms/frame"), rows)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="small sizes only")
    add_out_args(ap)
    a = ap.parse_args()
    rt = get_runtime()
    reps = 3 if a.quick else 5
    big = [(640, 360)] if a.quick else [(640, 360), (1920, 1080)]
    flare_sizes = [(320, 180)] if a.quick else [(640, 360), (1280, 720)]
    parts = [
        "# durand00 and effects benchmark\n",
        f"Device: {describe_device(rt.device)}; host: {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs. Command: `python -m benchmarks.bench_durand"
        f"{' --quick' if a.quick else ''}`. Median of {reps} runs after a warm-up.\n",
        "## 1. durand00 per frame (effects off)\n", bench_operator(big, reps),
        "\n## 2. Look-up tables (Sec. 5), per-pixel kernel at "
        f"{big[-1][0]}x{big[-1][1]}\n", bench_lut(*big[-1], reps),
        "\n## 3. Flares (Sec. 6): fast vs exact, error in cd/m^2 against exact\n",
        bench_flare(flare_sizes, reps),
        "\n## 4. Loss-of-acuity blur (Sec. 7), separable, clamped edges\n",
        bench_acuity(big, reps),
        "\n## 5. Whole durand00 frame, effects off vs auto (night street x 0.002, fov 50)\n",
        bench_frame(big, reps),
    ]
    text = "\n".join(parts) + "\n"
    with open(out_path(a, "durand00.md"), "w") as fh:
        fh.write(text)
    print(text)


if __name__ == "__main__":
    main()
