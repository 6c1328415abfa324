"""A shot on many workers: the serial run against measure -> integrate -> apply on Dask.

One command:  python -m benchmarks.scale_out [--frames 600] [--size 1920x1080]
              [--operators pattanaik00,ledda04] [--workers 1,2] [--out-dir DIR | --out FILE]
Writes scale_out.md (and scale_out.json beside it) into DIR (default
./benchmark-results; the committed ones: --out-dir benchmarks/results).

The shot: the built-in tunnel drive, generated at the size asked (EXR half,
cd/m^2, 30 fps; cached in $TMPDIR between runs). Each configuration is the real
command line to 8-bit PNG (``ocl-tonemap run``; ``--scheduler dask --workers W``
starts a LocalCluster of W processes, PoCL with cores/W threads each). Reported:
wall time of the whole command, frames/s, the time of each pass (cluster start,
measure, integrate, apply), the statistics store per frame (stats and states),
and whether every output frame equals the serial run's (decoded pixels).
Ratios are against the serial run of the same operator in the same run of this
script (this machine is noisy: compare ratios, not seconds).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.scenes import exr_spec, tunnel
from ocl_tonemap.shot.store import ShotStore


def _cli() -> list[str]:
    exe = shutil.which("ocl-tonemap", path=os.path.dirname(sys.executable))
    return [exe] if exe else [sys.executable, "-m", "ocl_tonemap"]


def make_shot(root: Path, w: int, h: int, n: int) -> str:
    """The tunnel drive at w x h: rendered at a quarter of the size and resampled
    with OIIO (the sample's renderer takes ~4 s a 1080p frame), written as the built-in
    sample is (``sample.write_tunnel_sequence``: half, zip, cd/m^2, 30 fps)."""
    import OpenImageIO as oiio

    d = root / f"scene_{w}x{h}_{n}"
    pattern = str(d / "tunnel.####.exr")
    if not (d / "done").exists():
        shutil.rmtree(d, ignore_errors=True)
        d.mkdir(parents=True)
        t = time.perf_counter()
        rw, rh = max(1, w // 4), max(1, h // 4)
        for i in range(n):
            small = oiio.ImageBuf(oiio.ImageSpec(rw, rh, 3, oiio.FLOAT))
            small.set_pixels(oiio.ROI(0, rw, 0, rh, 0, 1, 0, 3),
                             tunnel(rw, rh, t=i / 30.0, seconds=n / 30.0))
            big = oiio.ImageBufAlgo.resample(small, roi=oiio.ROI(0, w, 0, h, 0, 1, 0, 3))
            out = oiio.ImageBuf(exr_spec(w, h, fps=30.0, compression="zip"))
            out.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, 3),
                           np.maximum(big.get_pixels(oiio.FLOAT), 0.0))
            if not out.write(str(d / f"tunnel.{i + 1:04d}.exr")):
                raise SystemExit(out.geterror())
        (d / "done").write_text("ok")
        print(f"shot written: {n} frames {w}x{h} in {time.perf_counter() - t:.0f} s", flush=True)
    return pattern


def run(argv: list[str]) -> tuple[float, str]:
    t = time.perf_counter()
    r = subprocess.run(argv, capture_output=True, text=True)
    dt = time.perf_counter() - t
    if r.returncode != 0:
        raise SystemExit(f"failed: {' '.join(argv)}\n{r.stderr}")
    return dt, r.stdout + r.stderr


def same_outputs(a: Path, b: Path, frames: list[int]) -> bool:
    import OpenImageIO as oiio
    for f in frames:
        pa = oiio.ImageBuf(str(a / f"o.{f:04d}.png")).get_pixels(oiio.UINT8)
        pb = oiio.ImageBuf(str(b / f"o.{f:04d}.png")).get_pixels(oiio.UINT8)
        if pa is None or pb is None or not np.array_equal(pa, pb):
            return False
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=600)
    ap.add_argument("--size", default="1920x1080")
    ap.add_argument("--operators", default="pattanaik00,ledda04")
    ap.add_argument("--workers", default="1,2")
    add_out_args(ap, "scale_out.md")
    ap.add_argument("--keep", action="store_true", help="keep the outputs and stores")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    n = a.frames
    root = Path(tempfile.gettempdir()) / "ocltm-scale-out"
    root.mkdir(exist_ok=True)
    pattern = make_shot(root, w, h, n)
    frames = list(range(1, n + 1))
    rows = []
    for op in a.operators.split(","):
        work = root / f"run_{op}"
        shutil.rmtree(work, ignore_errors=True)
        serial_dir = work / "serial"
        serial_dir.mkdir(parents=True)
        base = [pattern, "--operator", op, "-q", "--no-checkpoint"]
        t, _ = run(_cli() + ["run", pattern, str(serial_dir / "o.####.png")] + base[1:])
        rows.append({"operator": op, "config": "serial", "workers": 1, "seconds": t,
                     "fps": n / t, "passes": {}, "identical": True, "store": None})
        print(f"{op} serial: {t:.1f} s ({n / t:.2f} frames/s)", flush=True)
        for nw in (int(x) for x in a.workers.split(",")):
            d = work / f"dask{nw}"
            d.mkdir()
            t, text = run(_cli() + ["run", pattern, str(d / "o.####.png")] + base[1:-2]
                          + ["--scheduler", "dask", "--workers", str(nw)])
            passes = {k: float(v) for k, v in re.findall(r"(\w+) ([\d.]+) s", text.split("(")[-1])}
            store = d / "o.png.shot"
            row = {"operator": op, "config": f"dask, {nw} worker(s)", "workers": nw,
                   "seconds": t, "fps": n / t, "passes": passes,
                   "identical": same_outputs(serial_dir, d, frames),
                   "store": ShotStore(store).bytes_per_frame()}
            rows.append(row)
            print(f"{op} dask {nw}: {t:.1f} s {passes} identical={row['identical']} "
                  f"store/frame={row['store']}", flush=True)
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)
    write_report(Path(out_path(a, "scale_out.md")), rows, w, h, n)


def write_report(path: Path, rows: list, w: int, h: int, n: int) -> None:
    import pyopencl as cl
    try:
        dev = cl.get_platforms()[0].get_devices()[0]
        device = f"{dev.name.strip()} ({cl.get_platforms()[0].name})"
    except Exception:  # noqa: BLE001
        device = "?"
    serial = {r["operator"]: r["seconds"] for r in rows if r["config"] == "serial"}
    lines = [
        "# A shot on many workers: serial run vs measure -> integrate -> apply on Dask",
        "",
        f"`python -m benchmarks.scale_out --frames {n} --size {w}x{h}` on {platform.node()}: "
        f"{os.cpu_count()} cores, {device}, Python {platform.python_version()}; "
        f"{time.strftime('%Y-%m-%d')}. The tunnel drive, {n} frames {w}x{h} EXR -> "
        "8-bit PNG, the whole command line each time (LocalCluster start included).",
        "",
        "| operator | run | wall s | frames/s | vs serial | cluster start s | measure s | "
        "integrate s | apply s | stats / frame | states / frame | frames = serial |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        p, st = r["passes"], r["store"]

        def s(k):
            return f"{p[k]:.1f}" if k in p else "-"

        def size(b):
            return "-" if b is None else (f"{b / 2**20:.1f} MiB" if b > 2**20 else
                                          f"{b / 1024:.1f} KiB")
        lines.append(
            f"| {r['operator']} | {r['config']} | {r['seconds']:.1f} | {r['fps']:.2f} | "
            f"{serial[r['operator']] / r['seconds']:.2f}x | {s('start')} | {s('measure')} | "
            f"{s('integrate')} | {s('apply')} | {size(st and st['stats'])} | "
            f"{size(st and st['states'])} | {'yes' if r['identical'] else 'NO'} |")
    lines += ["", "Per frame (ms) of each pass, from the table: measure and apply are "
              "spread over the workers, integrate is serial.", "",
              "| operator | workers | measure ms/frame (per worker) | integrate ms/frame | "
              "apply ms/frame (per worker) |", "|---|---|---|---|---|"]
    for r in rows:
        p = r["passes"]
        if not p:
            continue
        wk = r["workers"]
        lines.append(f"| {r['operator']} | {wk} | {1000 * p['measure'] * wk / n:.0f} | "
                     f"{1000 * p['integrate'] / n:.1f} | {1000 * p['apply'] * wk / n:.0f} |")
    lines += ["", "The extrapolation to a 10 000-frame 4K shot on 50 GPU workers is in "
              "docs/scale-out.md.", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    path.with_suffix(".json").write_text(json.dumps(rows, indent=2) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
