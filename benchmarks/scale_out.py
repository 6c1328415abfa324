"""A shot on many workers: the serial run against measure -> integrate -> apply.

One command:  python -m benchmarks.scale_out [--sizes 320x180:60,1920x1080:30]
              [--operators pattanaik00,durand00,ledda04,kirk11] [--workers 1,2]
              [--rounds 2] [--out-dir DIR | --out FILE]
Writes scale_out.md (and scale_out.json beside it) into DIR (default
./benchmark-results; the committed ones: --out-dir benchmarks/results).

The shot: the built-in tunnel drive at each size (EXR half, cd/m^2, 30 fps; cached
in $TMPDIR between runs), every command the real command line to 8-bit PNG with
the defaults. Per operator and size:

* **passes by hand**: ``run`` (serial), then ``measure``, ``integrate``, ``apply``
  one after the other on this machine, each a whole command (its process start
  included); their sum against the serial run, and whether every output frame
  equals the serial run's (decoded pixels);
* **per process**: the start of a one-frame ``run`` (imports, OpenCL context,
  kernels from the cache, OCIO): what each pass pays once, whatever its frames;
* **per frame** of each pass: (pass - process start) / frames;
* **Dask**: ``run --scheduler dask --workers W`` (a LocalCluster of W processes,
  PoCL with cores/W threads each), its passes and per-task overhead (the run's
  summary line);
* **projection**: the wall time of an N-frame shot on K workers from the per-frame
  costs measured here, T_K = start + N (measure + apply) / K + N integrate (+ the
  tasks' set-up), against N serial frames on one worker: the speedup Amdahl's law
  allows with integrate serial.

Each timing is the least of ``--rounds`` rounds (configurations interleaved within
a round): this machine is noisy; compare ratios, not seconds.
"""

from __future__ import annotations

import argparse
import json
import math
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

OPERATORS = ("pattanaik00", "durand00", "ledda04", "kirk11")
#: The projection's shots and worker counts.
PROJECT_FRAMES = 10_000
PROJECT_WORKERS = (1, 2, 8, 50)
#: Apply and measure tasks per worker in the projection (the Dask default: four).
TASKS_PER_WORKER = 4


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


def dask_summary(text: str) -> tuple[dict, dict]:
    """(passes {name: s}, tasks {pass: {tasks, setup_s, dask_s}}) from the summary line
    ``wrote N frame(s) in T s (start a s, measure b s, ...; measure tasks 8: 0.03 s
    set-up + 0.01 s Dask a task; ...)``."""
    line = [ln for ln in text.splitlines() if ln.startswith("wrote ")][-1]
    inner = line[line.index("s (") + 3:].rstrip(")")
    head, _, rest = inner.partition(";")
    passes = {k: float(v) for k, v in re.findall(r"(\w+) ([\d.]+) s", head)}
    tasks = {m.group(1): {"tasks": int(m.group(2)), "setup_s": float(m.group(3)),
                          "dask_s": float(m.group(4))}
             for m in re.finditer(r"(\w+) tasks (\d+): ([\d.]+) s set-up \+ ([\d.]+) s Dask",
                                  rest)}
    return passes, tasks


def measure_operator(op: str, pattern: str, n: int, work: Path, rounds: int,
                     workers: list[int]) -> dict:
    """The timings of one operator at one size (least of ``rounds``)."""
    frames = list(range(1, n + 1))
    base = ["--operator", op, "-q"]
    best: dict = {}
    ident = {}
    dask = {w: None for w in workers}

    def keep(key, t):
        best[key] = min(best.get(key, math.inf), t)
    for r in range(rounds):
        shutil.rmtree(work, ignore_errors=True)
        (work / "serial").mkdir(parents=True)
        keep("start", run(_cli() + ["run", pattern, str(work / "one" / "o.####.png"),
                                    "--frames", "1-1", "--no-checkpoint"] + base)[0])
        keep("serial", run(_cli() + ["run", pattern, str(work / "serial" / "o.####.png"),
                                     "--no-checkpoint"] + base)[0])
        split = work / "split" / "o.####.png"
        for p in ("measure", "integrate", "apply"):
            keep(p, run(_cli() + [p, pattern, str(split)] + base)[0])
        if r == 0:
            ident["split"] = same_outputs(work / "serial", split.parent, frames)
            store = ShotStore(str(split.parent / "o.png.shot")).bytes_per_frame()
            best["store"] = store
        for w in workers:
            d = work / f"dask{w}" / "o.####.png"
            t, text = run(_cli() + ["run", pattern, str(d), "--no-checkpoint", "--operator", op,
                                    "--scheduler", "dask", "--workers", str(w)])
            passes, tasks = dask_summary(text)
            if dask[w] is None or t < dask[w]["seconds"]:
                dask[w] = {"seconds": t, "passes": passes, "tasks": tasks}
            if r == 0:
                ident[f"dask{w}"] = same_outputs(work / "serial", d.parent, frames)
    shutil.rmtree(work, ignore_errors=True)
    return {"best": best, "identical": ident, "dask": dask}


def per_frame(best: dict, n: int) -> dict:
    """Seconds per frame of the serial run and each pass (less one process start)."""
    s0 = best["start"]
    return {k: max(0.0, best[k] - s0) / n for k in ("serial", "measure", "integrate", "apply")}


def projection(pf: dict, start: float, task_setup: float, frames: int, k: int) -> float:
    """Speedup on ``k`` workers of a ``frames``-frame shot: N serial frames against
    3 process starts + N (measure + apply) / k + N integrate + the tasks' set-up
    (``TASKS_PER_WORKER`` a worker and pass, each ``task_setup``)."""
    t_k = (3 * start + frames * (pf["measure"] + pf["apply"]) / k + frames * pf["integrate"]
           + 2 * TASKS_PER_WORKER * task_setup)
    return (start + frames * pf["serial"]) / max(t_k, 1e-9)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="320x180:60,1920x1080:30",
                    help="WxH:FRAMES, comma separated")
    ap.add_argument("--operators", default=",".join(OPERATORS))
    ap.add_argument("--workers", default="1,2", help="Dask worker counts")
    ap.add_argument("--rounds", type=int, default=2)
    add_out_args(ap, "scale_out.md")
    a = ap.parse_args(argv)
    root = Path(tempfile.gettempdir()) / "ocltm-scale-out"
    root.mkdir(exist_ok=True)
    workers = [int(x) for x in a.workers.split(",") if x]
    rows = []
    for spec in a.sizes.split(","):
        size, _, nf = spec.partition(":")
        w, h = (int(v) for v in size.split("x"))
        n = int(nf or 60)
        pattern = make_shot(root, w, h, n)
        for op in a.operators.split(","):
            got = measure_operator(op, pattern, n, root / f"run_{op}", a.rounds, workers)
            b = got["best"]
            row = {"operator": op, "size": f"{w}x{h}", "frames": n, **got,
                   "per_frame": per_frame(b, n)}
            rows.append(row)
            split = b["measure"] + b["integrate"] + b["apply"]
            print(f"{op} {w}x{h} x{n}: serial {b['serial']:.2f} s, passes {b['measure']:.2f} + "
                  f"{b['integrate']:.2f} + {b['apply']:.2f} = {split / b['serial']:.2f}x, "
                  + ", ".join(f"dask{k} {v['seconds'] / b['serial']:.2f}x"
                              for k, v in got["dask"].items())
                  + f"; identical {got['identical']}", flush=True)
    write_report(Path(out_path(a, "scale_out.md")), rows, a)


def _device() -> str:
    import pyopencl as cl
    try:
        dev = cl.get_platforms()[0].get_devices()[0]
        return f"{dev.name.strip()} ({cl.get_platforms()[0].name})"
    except Exception:  # noqa: BLE001
        return "?"


def write_report(path: Path, rows: list, a) -> None:
    ms = lambda s: f"{1000 * s:.0f}"                           # noqa: E731
    lines = [
        "# A shot on many workers: the serial run against measure -> integrate -> apply",
        "",
        f"`python -m benchmarks.scale_out --sizes {a.sizes} --workers {a.workers} "
        f"--rounds {a.rounds}` on {platform.node()}: {os.cpu_count()} cores, {_device()}, "
        f"Python {platform.python_version()}; {time.strftime('%Y-%m-%d')}. The tunnel "
        "drive, EXR -> 8-bit PNG with the defaults, the whole command line each time; "
        "each figure the least of the rounds (a noisy machine: compare ratios).",
        "",
        "## Passes by hand on one machine",
        "",
        "| operator | size x frames | serial s | measure s | integrate s | apply s | "
        "passes / serial | process start s | frames = serial |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        b = r["best"]
        split = b["measure"] + b["integrate"] + b["apply"]
        lines.append(f"| {r['operator']} | {r['size']} x {r['frames']} | {b['serial']:.2f} | "
                     f"{b['measure']:.2f} | {b['integrate']:.2f} | {b['apply']:.2f} | "
                     f"**{split / b['serial']:.2f}x** | {b['start']:.2f} | "
                     f"{'yes' if r['identical'].get('split') else 'NO'} |")
    lines += ["", "## Per frame (ms; each pass less one process start)", "",
              "| operator | size | serial | measure | integrate | apply | "
              "integrate / apply | (measure + integrate + apply) / serial | "
              "store a frame: stats / states |",
              "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        pf, st = r["per_frame"], r["best"].get("store") or {}

        def size(v):
            return "-" if v is None else (f"{v / 2**20:.1f} MiB" if v > 2**20 else
                                          f"{v / 1024:.1f} KiB")
        lines.append(f"| {r['operator']} | {r['size']} | {ms(pf['serial'])} | "
                     f"{ms(pf['measure'])} | {ms(pf['integrate'])} | {ms(pf['apply'])} | "
                     f"{pf['integrate'] / max(pf['apply'], 1e-9):.0%} | "
                     f"{(pf['measure'] + pf['integrate'] + pf['apply']) / max(pf['serial'], 1e-9):.2f}x | "
                     f"{size(st.get('stats'))} / {size(st.get('states'))} |")
    lines += ["", "## Dask on this machine (`run --scheduler dask --workers W`)", "",
              "| operator | size x frames | workers | wall s | vs serial | start s | "
              "measure s | integrate s | apply s | tasks a pass | set-up a task s "
              "(measure / apply) | Dask a task s | frames = serial |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b = r["best"]
        for wk, d in r["dask"].items():
            p, t = d["passes"], d["tasks"]
            lines.append(
                f"| {r['operator']} | {r['size']} x {r['frames']} | {wk} | {d['seconds']:.2f} | "
                f"**{d['seconds'] / b['serial']:.2f}x** | {p.get('start', 0):.2f} | "
                f"{p.get('measure', 0):.2f} | {p.get('integrate', 0):.2f} | "
                f"{p.get('apply', 0):.2f} | {t.get('measure', {}).get('tasks', '-')} | "
                f"{t.get('measure', {}).get('setup_s', 0):.3f} / "
                f"{t.get('apply', {}).get('setup_s', 0):.3f} | "
                f"{t.get('apply', {}).get('dask_s', 0):.3f} | "
                f"{'yes' if r['identical'].get(f'dask{wk}') else 'NO'} |")
    lines += ["", f"## Projected: a {PROJECT_FRAMES}-frame shot on K workers like this "
              "machine's", "",
              "From the per-frame costs above (each worker a machine like this one; "
              f"{TASKS_PER_WORKER} tasks a worker and pass, each paying the measured "
              "set-up): speedup against one serial run of the same frames. The ceiling is "
              "serial / integrate per frame (integrate runs once, in order).", "",
              "| operator | size | " + " | ".join(f"K={k}" for k in PROJECT_WORKERS)
              + " | ceiling |", "|---|---|" + "---|" * (len(PROJECT_WORKERS) + 1)]
    for r in rows:
        pf, b = r["per_frame"], r["best"]
        setup = max((d["tasks"].get("apply", {}).get("setup_s", 0.0)
                     for d in r["dask"].values()), default=0.0)
        sp = [projection(pf, b["start"], setup, PROJECT_FRAMES, k) for k in PROJECT_WORKERS]
        ceiling = pf["serial"] / pf["integrate"] if pf["integrate"] >= 1e-4 else None
        lines.append(f"| {r['operator']} | {r['size']} | " + " | ".join(f"{s:.1f}x" for s in sp)
                     + (f" | {ceiling:.0f}x |" if ceiling else
                        " | - (integrate < 0.1 ms a frame) |"))
    lines += ["", "docs/scale-out.md reads these numbers (what bounds each pass, a farm "
              "of GPU workers).", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    path.with_suffix(".json").write_text(json.dumps(rows, indent=2, default=str) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
