"""Benchmark of the bilateral filters (exact vs grid) and of the ledda04 operator.

One command:  python -m benchmarks.bench_bilateral [--quick] [--out-dir DIR | --out FILE]
Writes bilateral_ledda04.md into DIR (default ./benchmark-results; the committed one:
--out-dir benchmarks/results) and prints it.

Filters the photopic luminance of generated HDR scenes with Ledda's range
kernel (sigma_g = 0.15 I_s) at 640x360, 1920x1080 and 3840x2160 for several
spatial sigmas, and reports for the fast bilateral grid against the exact
brute force (both float32 OpenCL; the exact one is checked against float64 in
the tests):
* ms per filtered channel of each, and their ratio;
* PSNR of log10 I_A (peak = the log10 range of I_A over the whole frame) and
  the largest |error| in log10 I_A;
* PSNR of the operator's display-linear output (clipped to [0, 1], peak 1)
  when I_A comes from the grid instead of the exact filter.
The exact filter costs O(sigma_s^2) per pixel: where a full frame would take
more than EXACT_BUDGET_S, it runs on a band of rows through the middle of the
frame, its time is scaled to the full frame (marked "~"), and the errors are
measured on that band.
Then: the grid's sampling knob (q_s = q_r = q) at 1080p, and the whole
ledda04 operator per frame (OpenCL, and the float64 reference at 640x360).
Machines are noisy: compare the ratios, not the absolute times.
"""

from __future__ import annotations

import argparse
import math
import platform
import time

import numpy as np

from benchmarks.lib import scenes as sc
from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.timing import timeit
from ocl_tonemap.models import ledda2004 as L
from ocl_tonemap.backends.opencl.bilateral import DeviceBilateral
from ocl_tonemap.models.bilateral import LEDDA_RANGE, prepare_signal
from ocl_tonemap.pipeline import Tonemapper
from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime

SIZES = [(640, 360), (1920, 1080), (3840, 2160)]
EXACT_BUDGET_S = 6.0


def scene_tunnel(w, h):
    return sc.tunnel(w, h, t=3.0)


SCENES = {"night street": sc.night_street_windows, "sky + sun": sc.sky_sun,
          "tunnel (sample)": scene_tunnel, "noise (worst)": sc.log_noise}


def psnr(err, peak):
    rms = float(np.sqrt(np.mean(np.square(err))))
    return math.inf if rms == 0 else 20 * math.log10(peak / rms)


class Bench:
    def __init__(self, rt):
        import pyopencl as cl
        self.cl, self.rt, self.f = cl, rt, DeviceBilateral(rt)

    def upload(self, v):
        cl = self.cl
        v = np.ascontiguousarray(prepare_signal(v, LEDDA_RANGE), np.float32)
        mf = cl.mem_flags
        return (cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=v),
                cl.Buffer(self.rt.context, mf.READ_WRITE, v.nbytes))

    def exact(self, vb, ob, w, h, sigma, y0, rows):
        out = np.empty((rows, w), np.float32)

        def run():
            self.f.exact(vb, ob, w, h, 0, y0, rows, sigma, LEDDA_RANGE)
            self.cl.enqueue_copy(self.rt.queue, out, ob)
        return run, out

    def fast(self, vb, ob, w, h, sigma, q):
        out = np.empty((h, w), np.float32)

        def run():
            self.f.fast(vb, ob, w, h, sigma, LEDDA_RANGE, q, q)
            self.cl.enqueue_copy(self.rt.queue, out, ob)
        return run, out


def exact_rows(w, h, sigma, rate):
    """Rows the exact filter can do within the budget (rate: taps/s)."""
    taps = (2 * math.ceil(3 * sigma) + 1) ** 2
    rows = int(EXACT_BUDGET_S * rate / (taps * w))
    return h if rows >= h else max(8, min(rows, h))


def operator_psnr(img_band, Ic_ex, Ir_ex, Ic_fa, Ir_fa):
    """Display-linear output of the static operator from each pair of I_A maps."""
    rgb = np.asarray(img_band, np.float64)
    _, Ys = L.luminances(rgb)
    sd = L.display_sigma(Tonemapper("ledda04", "reference").display)
    outs = [L.map_reference(rgb, Ys, ic, L.sigma_of(ic, L.BETA_CONE), L.sigma_of(ir, L.BETA_ROD),
                            sd, 100.0) for ic, ir in ((Ic_ex, Ir_ex), (Ic_fa, Ir_fa))]
    return psnr(np.clip(outs[1], 0, 1) - np.clip(outs[0], 0, 1), 1.0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="640x360 only, fewer repetitions")
    add_out_args(ap, "bilateral_ledda04.md")
    a = ap.parse_args()
    rt = get_runtime()
    b = Bench(rt)
    sizes = SIZES[:1] if a.quick else SIZES
    reps = 1 if a.quick else 3
    lines = [f"# Bilateral filtering and ledda04 on {describe_device(rt.device)}", "",
             f"Host: {platform.processor() or platform.machine()}, Python {platform.python_version()}. "
             "Command: `python -m benchmarks.bench_bilateral`.", "",
             "## Exact vs fast (grid, q_s = q_r = 2, the default) per filtered channel", "",
             "| size | scene | sigma_s px | exact ms | grid ms | exact/grid | PSNR log10 I_A dB "
             "| max err log10 | PSNR output dB | rows compared |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    # calibrate the exact filter's tap rate on a small case
    v0 = scene_tunnel(320, 180)[..., 1]
    vb, ob = b.upload(v0)
    run, _ = b.exact(vb, ob, 320, 180, 6.0, 0, 180)
    rate = 180 * 320 * (2 * 18 + 1) ** 2 / timeit(run, 1)
    worst = math.inf
    for (w, h) in sizes:
        for sname, fn in SCENES.items():
            img = fn(w, h)
            Y, Ys = L.luminances(img)
            default_sigma = 0.02 * max(w, h)
            for sigma in (4.0, 8.0, 16.0, default_sigma):
                if sname != "tunnel (sample)" and sigma != default_sigma:
                    continue
                if sigma < 16 and w > 2000:
                    continue          # the grid at sigma_s/2 spacing is larger than the frame
                rows = exact_rows(w, h, sigma, rate)
                y0 = (h - rows) // 2
                maps = {}
                for ch, v in (("c", Y), ("r", Ys)):
                    vb, ob = b.upload(v)
                    run_e, out_e = b.exact(vb, ob, w, h, sigma, y0, rows)
                    te = timeit(run_e, 1 if rows < h or ch == "r" else reps) * h / rows
                    run_f, out_f = b.fast(vb, ob, w, h, sigma, 2.0)
                    tf = timeit(run_f, reps)
                    full = np.log10(out_f.astype(np.float64))
                    maps[ch] = (out_e.astype(np.float64), out_f[y0:y0 + rows].astype(np.float64),
                                te, tf, max(full.max() - full.min(), 1e-3))
                ex, fa, te, tf, _ = maps["c"]
                le, lf = np.log10(ex), np.log10(fa)
                p_log = psnr(lf - le, maps["c"][4])
                p_out = operator_psnr(img[y0:y0 + rows], ex, maps["r"][0], fa, maps["r"][1])
                if sname != "noise (worst)" and sigma == default_sigma:
                    worst = min(worst, p_log, p_out)
                mark = "" if rows == h else "~"
                lines.append(f"| {w}x{h} | {sname} | {sigma:.1f} | {mark}{te * 1e3:.0f} | "
                             f"{tf * 1e3:.1f} | {mark}{te / tf:.0f} | {p_log:.1f} | "
                             f"{np.abs(lf - le).max():.4f} | {p_out:.1f} | {rows}/{h} |")
                print(lines[-1], flush=True)
    lines += ["", f"Lowest PSNR over the natural scenes at the default sigma: **{worst:.1f} dB** "
              "(requirement: >= 45 dB).", ""]

    # the sampling knob at 1080p (or 640x360 quick), tunnel scene, default sigma
    w, h = sizes[-1] if a.quick else (1920, 1080)
    img = scene_tunnel(w, h)
    Y, _ = L.luminances(img)
    sigma = 0.02 * max(w, h)
    rows = exact_rows(w, h, sigma, rate)
    y0 = (h - rows) // 2
    vb, ob = b.upload(Y)
    run_e, out_e = b.exact(vb, ob, w, h, sigma, y0, rows)
    te = timeit(run_e, 1) * h / rows
    le = np.log10(out_e.astype(np.float64))
    run_f, out_f = b.fast(vb, ob, w, h, sigma, 4.0)
    run_f()
    full = np.log10(out_f.astype(np.float64))
    peak = full.max() - full.min()
    lines += [f"## Grid sampling knob ({w}x{h}, tunnel, sigma_s = {sigma:.1f} px; exact "
              f"{'~' if rows < h else ''}{te * 1e3:.0f} ms)", "",
              "| q_s = q_r | grid ms | exact/grid | PSNR log10 I_A dB | max err log10 |",
              "|---|---|---|---|---|"]
    for q in (1.0, 1.5, 2.0, 3.0, 4.0):
        run_f, out_f = b.fast(vb, ob, w, h, sigma, q)
        tf = timeit(run_f, reps)
        lf = np.log10(out_f[y0:y0 + rows].astype(np.float64))
        lines.append(f"| {q:g} | {tf * 1e3:.1f} | {te / tf:.0f} | "
                     f"{psnr(lf - le, peak):.1f} | {np.abs(lf - le).max():.4f} |")
        print(lines[-1], flush=True)

    # the whole operator
    lines += ["", "## ledda04 per frame (upload, colour, both filters, time step, mapping, "
              "download)", "",
              "Error: display-linear output vs the float64 reference (exact filter), "
              "max |d| / max(1, |ref|), at 640x360 where the reference runs.", "",
              "| size | bilateral | ms/frame | MPix/s | max err vs float64 |", "|---|---|---|---|---|"]
    w0, h0 = sizes[0]
    img0 = scene_tunnel(w0, h0)
    ref = Tonemapper("ledda04", "reference", options={"rods": "always"})
    t0 = time.perf_counter()
    ref_out = ref.process(img0, time_s=0).astype(np.float64)
    tr = time.perf_counter() - t0
    for (w, h) in sizes:
        img = scene_tunnel(w, h)
        for method in ("fast", "exact"):
            sigma = 0.02 * max(w, h)
            if method == "exact" and exact_rows(w, h, sigma, rate) < h:
                continue
            tm = Tonemapper("ledda04", "opencl", options={"bilateral": method, "rods": "always"})
            first = tm.process(img, time_s=0).astype(np.float64)
            err = "-"
            if (w, h) == (w0, h0):
                err = f"{np.max(np.abs(first - ref_out) / np.maximum(1.0, np.abs(ref_out))):.2e}"
            k = [0]

            def frame():
                k[0] += 1
                tm.process(img, time_s=k[0] / 24)
            t = timeit(frame, reps)
            lines.append(f"| {w}x{h} | {method} | {t * 1e3:.0f} | {w * h / t / 1e6:.1f} | {err} |")
            print(lines[-1], flush=True)
    lines.append(f"| {w0}x{h0} | float64 reference (exact) | {tr * 1e3:.0f} | "
                 f"{w0 * h0 / tr / 1e6:.2f} | 0 |")
    lines += ["", "`~`: exact time scaled from the rows compared (the brute force is linear in "
              "rows); errors measured on those rows.", ""]
    text = "\n".join(lines)
    with open(out_path(a, "bilateral_ledda04.md"), "w") as fh:
        fh.write(text)
    print(text)


if __name__ == "__main__":
    main()
