"""Peak memory and time per frame on huge frames: whole-frame against streamed.

    python -m benchmarks.bench_memory [--size 12000x8000] [--also 16000x16000] [--cases a,b]
        [--out-dir DIR]

Writes memory.md into DIR (default ./benchmark-results; the committed one: --out-dir
benchmarks/results). Each run is a child ``ocl-tonemap run`` whose
peak resident set (ru_maxrss) is read after it exits; the frame is generated
once as a half-float EXR (the tunnel sample) in a temporary folder.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import tempfile
import time

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.scenes import exr_spec, tunnel
from benchmarks.lib.timing import child_peak, table



def make_frame(path: str, w: int, h: int) -> None:
    import OpenImageIO as oiio
    out = oiio.ImageOutput.create(path)
    assert out.open(path, exr_spec(w, h))
    tw, th = 1500, 1000                               # the sample, tiled across
    tile = tunnel(tw, th)
    reps = -(-w // tw)
    for y0 in range(0, h, th):                        # written in bands of the tile
        y1 = min(h, y0 + th)
        band = np.tile(tile[: y1 - y0], (1, reps, 1))[:, :w]
        assert out.write_scanlines(y0, y1, 0, np.ascontiguousarray(band))
    out.close()


def child(args: list[str]) -> tuple[float | None, float | None, int | None]:
    """(peak RSS MiB, seconds, return code) of one ocl-tonemap run."""
    return child_peak([sys.executable, "-m", "ocl_tonemap", *args])


#: (label, operator, extra arguments, also whole?): every operator and effect.
CASES = (
    ("pattanaik00", "pattanaik00", [], True),
    ("durand00", "durand00", ["--flare", "off", "--acuity", "off"], True),
    ("durand00 flare+acuity on", "durand00", ["--flare", "on", "--acuity", "on"], False),
    ("pattanaik00 purkinje on", "pattanaik00", ["--purkinje", "on"], False),
    ("ledda04 (+checkpoint)", "ledda04", ["--checkpoint-every", "1"], False),
    ("kirk11", "kirk11", [], False),
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", default="12000x8000")
    ap.add_argument("--also", default=None, help="a second, larger size (e.g. 16000x16000)")
    ap.add_argument("--budget", type=float, default=1024.0, help="--max-memory, MiB")
    ap.add_argument("--cases", default=None, help="labels of CASES to run, comma-separated "
                    "(default: all)")
    add_out_args(ap)
    a = ap.parse_args()
    cases = [c for c in CASES if a.cases is None or c[0] in a.cases.split(",")]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        for size in [s for s in (a.size, a.also) if s]:
            w, h = (int(v) for v in size.split("x"))
            src = os.path.join(d, f"f{w}.exr")
            t0 = time.perf_counter()
            make_frame(src, w, h)
            gen = time.perf_counter() - t0
            frame_mb = w * h * 12 / 2**20
            fits = frame_mb * 12 < 0.8 * os.sysconf("SC_PAGE_SIZE") * \
                os.sysconf("SC_PHYS_PAGES") / 2**20            # whole only where it fits
            for label, op, fx, whole in cases:
                modes = [("streamed", ["--max-memory", f"{a.budget:g}"])]
                if whole and fits:
                    modes.append(("whole", ["--max-memory", "1e9"]))
                for mode, extra in modes:
                    ck = [] if "--checkpoint-every" in fx else ["--no-checkpoint"]
                    rss, sec, rc = child(["run", src, os.path.join(d, "o.png"), "--operator",
                                          op, "-q", *ck, *fx, *extra])
                    rows.append((f"{w}x{h}", label, mode, f"{frame_mb:.0f}",
                                 f"{rss:.0f}" if rc == 0 else f"failed ({rc})",
                                 f"{rss / frame_mb:.2f}" if rc == 0 else "-",
                                 "-" if sec is None else f"{sec:.1f}"))
                    print(rows[-1], flush=True)
                    for x in os.listdir(d):                  # checkpoints of the last case
                        if x.startswith("o.png.state"):
                            os.remove(os.path.join(d, x))
            print(f"(generated {size} in {gen:.0f} s)", flush=True)
    out = out_path(a, "memory.md")
    with open(out, "w") as fh:
        fh.write("# Peak memory on huge frames\n\n")
        fh.write(f"Command: `python -m benchmarks.bench_memory --size {a.size}"
                 + (f" --also {a.also}" if a.also else "") + "`. Machine: "
                 f"{platform.machine()}, {os.cpu_count()} CPUs, PoCL. Peak resident set of the "
                 "whole `ocl-tonemap run` (PNG out), against the frame's size as float32 RGB. "
                 f"Streamed: `--max-memory {a.budget:g}`; whole: the budget lifted.\n\n")
        fh.write(table(("frame", "operator and effects", "path", "frame MiB (float32 RGB)", "peak RSS MiB",
                        "RSS / frame", "seconds"), rows))
        fh.write("\n\nThe bound in the README: streamed frames stay under 3x the frame plus "
                 "~300 MiB (the process itself is ~130 MiB).\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
