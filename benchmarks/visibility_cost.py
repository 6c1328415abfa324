"""What ``--visibility`` costs a run (issue 48: at most 25 % of a frame at 1080p): one command.

    python -m benchmarks.visibility_cost [--out-dir DIR] [--runs 3] [--size 1920x1080]

The built-in tunnel drive (2 s at 10 fps, 20 frames, flare and all defaults) through
``ocl-tonemap run`` with each operator's defaults, without and with ``--visibility``
(and with ``--visibility-view`` too), interleaved runs, the median of each: the
whole command's wall time, the cost per frame and its share of the frame's own time,
and the peak memory (GNU time %M). Writes ``visibility_cost.md``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import write_markdown

OPERATORS = ("pattanaik00", "durand00", "ledda04", "kirk11")
FRAMES = 20


def _timed(cmd) -> tuple[float, float]:
    t0 = time.perf_counter()
    r = subprocess.run(["/usr/bin/time", "-f", "%M", *cmd], stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: {r.stderr[-2000:]}")
    return dt, int(r.stderr.strip().splitlines()[-1]) / 1024.0


def _stages(size: str, frames: int = 8) -> list:
    """Where a frame's visibility goes, in this process (the median of ``frames``): the
    planes on the device (``Backend.visibility``, a 1080p tunnel frame, pattanaik00's
    observer; ledda04's per-pixel one needs its schedule's state and is in the table
    above), the write of the half and float EXR with its read-back, the view's pixels
    and its PNG."""
    import numpy as np
    from ocl_tonemap.backends.base import VisibilityRequest
    from ocl_tonemap.backends.opencl import OpenCLBackend
    from ocl_tonemap.job.visibility_out import view_pixels, write_view, write_visibility
    from ocl_tonemap.models.visibility_map import Geometry, recipe
    from ocl_tonemap.operators import get_operator
    from ocl_tonemap.io.sample import render_frame
    from ocl_tonemap.effects.visibility import Viewing
    w, h = (int(v) for v in size.split("x"))
    pix = render_frame(1.0, w, h, 8.0, ss=1).astype(np.float16)
    be = OpenCLBackend()
    op = get_operator("pattanaik00")({})
    obs = op.observer_preadapted(1000.0, None)
    view = Viewing()
    r = recipe(Geometry(h, w, 50.0), view.size_arcmin, view.age)
    shown = (np.clip(np.asarray(pix[..., :3], np.float32) / 5000.0, 0, 1) * 255).astype(np.uint8)
    t: dict = {}

    def timed(name, fn):
        t0 = time.perf_counter()
        out = fn()
        t.setdefault(name, []).append(1e3 * (time.perf_counter() - t0))
        return out
    with tempfile.TemporaryDirectory() as d:
        for _ in range(frames):
            for kind, dt in (("half", np.float16), ("float", np.float32)):
                req = VisibilityRequest(pix, 1.0, r, view, op, lambda: obs, None, None, dt)
                P = timed(f"planes on the device ({kind})", lambda: be.visibility(req))
                timed(f"EXR write + read-back ({kind}, {P.data.nbytes / 2**20:.0f} MiB)",
                      lambda: write_visibility(os.path.join(d, "v.exr"), P, None, view,
                                               "pattanaik00", 50.0))
            v = timed("view's pixels (device)", lambda: view_pixels(be, P, shown, True))
            timed("view's PNG (level 1, sub)", lambda: write_view(os.path.join(d, "w.png"),
                                                                  v, None))
    return ["| stage, a frame | ms (median) |", "|---|---|",
            *(f"| {k} | {statistics.median(v):.1f} |" for k, v in t.items())]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_out_args(ap, "visibility_cost.md")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--size", default="1920x1080")
    a = ap.parse_args(argv)
    exe = [sys.executable, "-m", "ocl_tonemap"]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        subprocess.run(exe + ["sample", os.path.join(d, "s"), "--size", a.size, "--seconds",
                              "2", "--fps", "10"], check=True, stdout=subprocess.DEVNULL)
        src = os.path.join(d, "s", "tunnel.####.exr")
        for op in OPERATORS:
            base = exe + ["run", src, os.path.join(d, "o", "d.####.png"), "--operator", op,
                          "--no-checkpoint", "-q"]
            kinds = {"run": base,
                     "--visibility": base + ["--visibility", os.path.join(d, "o", "v.####.exr")],
                     "+ --visibility-view": base + [
                         "--visibility", os.path.join(d, "o", "v.####.exr"),
                         "--visibility-view", os.path.join(d, "o", "w.####.png")]}
            got = {k: [] for k in kinds}
            _timed(base)                                   # warm: kernels, caches
            for _ in range(a.runs):
                for k, cmd in kinds.items():
                    got[k].append(_timed(cmd))
            med = {k: (statistics.median(t for t, _ in v), max(m for _, m in v))
                   for k, v in got.items()}
            t0 = med["run"][0]
            for k in kinds:
                t, m = med[k]
                extra = (t - t0) / FRAMES
                rows.append(f"| {op} | {k} | {t:.2f} | {1e3 * t / FRAMES:.0f} | "
                            f"{'' if k == 'run' else f'{1e3 * extra:+.0f}'} | "
                            f"{'' if k == 'run' else f'{100 * (t - t0) / t0:+.0f} %'} | "
                            f"{m:.0f} |")
    lines = ["# What --visibility costs a run", "",
             f"`python -m benchmarks.visibility_cost` ({a.size}, the built-in tunnel drive, "
             f"{FRAMES} frames, each operator's defaults; median of {a.runs} interleaved "
             "runs of the whole command; peak: the largest resident set).", "",
             "| operator | run | s | ms / frame | ms / frame more | share of the run | "
             "peak MiB |", "|---|---|---|---|---|---|---|", *rows, "",
             "The planes are made on the OpenCL device from the luminance the frame's "
             "colour stage kept there (grids, the veil's cells, one kernel a pixel; a CPU "
             "device's veil by the host's FFT), come down as half floats and are written "
             "uncompressed on the writer thread: docs/models.md, \"Visibility maps\".", "",
             *_stages(a.size)]
    out = out_path(a, "visibility_cost.md")
    write_markdown(out, lines, [])
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
