"""ocl-tonemap against Radiance's ``pcond -h`` (Ward Larson, Rushmeier & Piatko 1997),
the tool lighting designers use to show a rendering as a person would see it: whole
commands, time and peak memory, in the same run on the same machine.

One command (Radiance from PyPI: ``pip install "ocl-tonemap[radiance]"``; ~6 min):
    python -m benchmarks.radiance_peer [--out-dir DIR | --out FILE] [--repeat 3]

Writes radiance_peer.md into DIR (default ./benchmark-results; the committed one:
``--out-dir benchmarks/results``).

Work (a night photograph with lamps at 0.5 cd/m^2 log-average, written as Radiance
.hdr; ``benchmarks/lib/photos.py``):

* a 1080p still and a 4K still: one command each;
* 20 independent 1080p stills: ours one command with ``--stills``, pcond once per still;
* a 60-frame 1080p sequence: ours one command (the observer over time), pcond once
  per frame (it has no time course).

durand00 with its defaults (the issue's comparison) and pattanaik00, writing 8-bit PNG;
pcond writes its own .hdr. Peak memory: GNU time's maximum resident set size of the
command (the sum over pcond's processes is not taken: each is one frame). The bound of
issue 33: a whole-frame run peaks at most 4x the frame's float32 RGB plus 300 MiB.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import (compile_package, cpu_model, radiance_env, write_image,
                                   write_markdown)

PHOTO = "dikhololo_night_1k.hdr"
LEVEL = 0.5                     # cd/m^2, log-average


def _timed(cmd, env=None, stdout=None) -> tuple[float, float]:
    """(seconds, peak RSS MiB) of one command (GNU time %M)."""
    t0 = time.perf_counter()
    r = subprocess.run(["/usr/bin/time", "-f", "%M", *cmd], env=env, stdout=stdout,
                       stderr=subprocess.PIPE, text=True)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: {r.stderr[-2000:]}")
    return dt, int(r.stderr.strip().splitlines()[-1]) / 1024.0


def make_inputs(d: str) -> dict:
    """The night photograph at 1080p and 4K (Radiance units: 179 cd/m^2 per unit),
    20 stills and a 60-frame sequence (a slow pan across it)."""
    from benchmarks.lib.photos import fetch_photos, load_photo
    from ocl_tonemap.models.photometry import Y_WEIGHTS
    path = {p.name: p for p in fetch_photos()}[PHOTO]
    wide = load_photo(path, 2560, 1280).astype(np.float32)[..., :3]
    lm = float(np.exp(np.mean(np.log(np.maximum(wide @ Y_WEIGHTS, 1e-9)))))
    wide *= LEVEL / lm / 179.0
    out = {}
    for name, (w, h) in (("1080p", (1920, 1080)), ("4k", (3840, 2160))):
        img = load_photo(path, w, h).astype(np.float32)[..., :3] * (LEVEL / lm / 179.0)
        out[name] = os.path.join(d, f"night_{name}.hdr")
        write_image(out[name], img)
    os.makedirs(os.path.join(d, "seq"))
    for k in range(60):                     # a pan: 1920x1080 windows of the 2560x1280
        x0 = int(round(k * (2560 - 1920) / 59))
        write_image(os.path.join(d, "seq", f"f.{k + 1:04d}.hdr"), wide[100:1180, x0:x0 + 1920])
    out["seq"] = os.path.join(d, "seq", "f.####.hdr")
    os.makedirs(os.path.join(d, "stills"))
    for k in range(20):
        shutil.copy(os.path.join(d, "seq", f"f.{3 * k + 1:04d}.hdr"),
                    os.path.join(d, "stills", f"s.{k + 1:04d}.hdr"))
    out["stills"] = os.path.join(d, "stills", "s.####.hdr")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--operators", default="durand00,pattanaik00")
    add_out_args(ap, "radiance_peer.md")
    ap.add_argument("--repeat", type=int, default=3,
                    help="runs of each command, interleaved with the peer's (medians)")
    a = ap.parse_args(argv)
    tools = radiance_env()
    env = tools[1]
    compiled = compile_package()
    d = tempfile.mkdtemp(prefix="ocltm_peer_")
    rows = []
    try:
        inp = make_inputs(d)
        me = [sys.executable, "-m", "ocl_tonemap", "run"]
        pcond = os.path.join(tools[0], "pcond")

        def pcond_files(pattern, n):
            t = m = 0.0
            for k in range(1, n + 1):
                src = pattern.replace("####", f"{k:04d}")
                with open(os.path.join(d, "pc.hdr"), "wb") as fh:
                    dt, mm = _timed([pcond, "-h", src], env, fh)
                t, m = t + dt, max(m, mm)
            return t, m
        frame_mib = {"1080p": 1920 * 1080 * 12 / 2 ** 20, "4k": 3840 * 2160 * 12 / 2 ** 20}
        work = (("1080p still", inp["1080p"], [], 1, "1080p"),
                ("4K still", inp["4k"], [], 1, "4k"),
                ("20 independent 1080p stills", inp["stills"], ["--stills"], 20, "1080p"),
                ("60-frame 1080p sequence", inp["seq"], ["--fps", "24"], 60, "1080p"))
        ops = a.operators.split(",")
        for what, src, extra, n, size in work:
            peer, ours = [], {op: [] for op in ops}
            for _ in range(max(1, a.repeat)):      # interleaved: the machine's phases
                with open(os.devnull, "wb") as null:
                    peer.append(pcond_files(src, n) if n > 1 else
                                _timed([pcond, "-h", src], env, null))
                for op in ops:
                    outp = os.path.join(d, "o", op, "out.####.png" if n > 1 else "out.png")
                    shutil.rmtree(os.path.dirname(outp), ignore_errors=True)
                    ours[op].append(_timed(me + [src, outp, "--operator", op, "-q", *extra]))
            pt, pm = float(np.median([p[0] for p in peer])), max(p[1] for p in peer)
            bound = 4 * frame_mib[size] + 300
            for op in ops:
                t, m = float(np.median([r[0] for r in ours[op]])), max(r[1] for r in ours[op])
                rows.append((what, op, f"{t:.2f}", f"{pt:.2f}", f"{pt / t:.2f}x",
                             f"{m:.0f}", f"{pm:.0f}", f"{bound:.0f}",
                             "within" if m <= bound else "over"))
                print(" | ".join(rows[-1]), flush=True)
    finally:
        shutil.rmtree(d, ignore_errors=True)
    from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime
    try:
        opencl = describe_device(get_runtime().device)
    except Exception as e:  # noqa: BLE001 (the table still says what ran)
        opencl = f"no OpenCL device ({e})"
    L = ["# ocl-tonemap against Radiance's pcond -h", "",
         f"- command `python -m benchmarks.radiance_peer`; a night photograph with lamps "
         f"({PHOTO}) at {LEVEL} cd/m^2 log-average as Radiance .hdr; this machine "
         f"({os.cpu_count()} cores, {cpu_model()}; OpenCL: {opencl}); ours writes 8-bit PNG, "
         f"pcond -h its .hdr (one process per frame); {compiled}",
         f"- times: the median of {max(1, a.repeat)} runs each, ours and pcond's "
         "interleaved (this machine's speed drifts by tens of percent between minutes)",
         "- speed: pcond's time / ours (> 1: ours faster); peak: maximum resident set (GNU "
         "time, the largest of the runs), MiB; bound (issue 33): 4x the frame's float32 "
         "RGB + 300 MiB", "",
         "| work | operator (defaults) | ours s | pcond -h s | speed | ours peak | pcond peak "
         "| bound | memory |", "|---|---|---|---|---|---|---|---|---|"]
    write_markdown(out_path(a, "radiance_peer.md"), L, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
