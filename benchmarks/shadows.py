"""What is seen stays seen (issue 57): does any operator, with its defaults, map the
shadows an adapted observer sees to black? One command:

    python -m benchmarks.shadows [--out-dir DIR] [--photos DIR] [--operators a,b]

The ten Poly Haven photographs of the viser wheel (benchmarks/lib/photos.py), each at a
daylight, interior, dusk and night level (its log-average put at 5000, 30, 1 and 0.01
cd/m^2: ``--luminance-scale auto:LEVEL``), through ``ocl-tonemap run`` to an 8-bit PNG
with every operator's defaults (the product as a user runs it). Per photograph, level
and operator:
- crushed: the share of the pixels within 1.5 log10 units below the log-average (or
  above) that come out exactly black (all three codes 0), which should be 0;
- black: the share of all pixels exactly black (the scene's own black may be);
- codes: the distinct 8-bit luma codes of the scene's darkest tenth.
Then the time course: each photograph at dusk, the eye adapted to 100x that first
(``simulate --preadapt``), after 600 s (adapted: it may not crush then) and 0.5 s.
Writes ``shadows.md``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

from benchmarks.lib import photos as ph
from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import write_markdown

OPERATORS = ("pattanaik00", "durand00", "ledda04", "kirk11")
LEVELS = (("daylight", 5000.0), ("interior", 30.0), ("dusk", 1.0), ("night", 0.01))
#: Seen: within this many log10 units below the log-average.
SEEN_DECADES = 1.5


def _read(path: str) -> np.ndarray:
    import OpenImageIO as oiio
    return oiio.ImageBuf(path).get_pixels(oiio.UINT8)[..., :3]


def _scene_luminance(path: str) -> np.ndarray:
    import OpenImageIO as oiio
    from ocl_tonemap.models.photometry import Y_WEIGHTS
    return oiio.ImageBuf(path).get_pixels(oiio.FLOAT)[..., :3] @ Y_WEIGHTS


def measures(Y: np.ndarray, codes: np.ndarray) -> dict:
    """crushed, black and the darkest tenth's distinct luma codes of one output."""
    logavg = float(np.exp(np.mean(np.log(np.maximum(Y, 1e-12)))))
    zero = codes.max(axis=2) == 0
    seen = Y >= logavg / 10 ** SEEN_DECADES
    dark = Y <= np.percentile(Y, 10)
    luma = np.round(codes.astype(np.float64) @ (0.2126, 0.7152, 0.0722))
    return {"crushed": float((zero & seen).sum() / max(seen.sum(), 1)),
            "black": float(zero.mean()), "codes": int(len(np.unique(luma[dark])))}


def _run(args) -> None:
    r = subprocess.run([sys.executable, "-m", "ocl_tonemap", *map(str, args), "-q"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, args))}: {r.stderr.strip()[-400:]}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_out_args(ap, "shadows.md")
    ap.add_argument("--photos", help="the photographs' folder (default: the cache)")
    ap.add_argument("--operators", default=",".join(OPERATORS))
    a = ap.parse_args(argv)
    ops = [o for o in a.operators.split(",") if o]
    paths = [p for p in ph.fetch_photos(a.photos) if p.suffix == ".hdr"]
    rows, worst, course = [], {}, []
    with tempfile.TemporaryDirectory() as d:
        for p in paths:
            Y = _scene_luminance(str(p))
            for level, L in LEVELS:
                cells = []
                for op in ops:
                    out = os.path.join(d, "o.png")
                    _run(["run", p, out, "--operator", op, "--luminance-scale", f"auto:{L:g}"])
                    m = measures(Y, _read(out))
                    w = worst.setdefault((op, level), [0.0, 10 ** 9])
                    w[0], w[1] = max(w[0], m["crushed"]), min(w[1], m["codes"])
                    cells.append(f"{m['crushed']:.2%} / {m['black']:.2%} / {m['codes']}")
                rows.append(f"| {p.stem} | {level} | " + " | ".join(cells) + " |")
            for op in ops:
                out = os.path.join(d, "s.png")
                _run(["simulate", p, out, "--operator", op, "--luminance-scale", "auto:1",
                      "--preadapt", "100", "--at", "0.5,600"])
                got = [measures(Y, _read(os.path.join(d, f"s_t{t}s.png")))
                       for t in ("0000p5", "0600p0")]   # simulate's names: 0.5 s, 600 s
                course.append(f"| {p.stem} | {op} | {got[0]['crushed']:.2%} | "
                              f"{got[1]['crushed']:.2%} | {got[1]['codes']} |")
    head = "| photograph | level | " + " | ".join(ops) + " |"
    lines = ["# What is seen stays seen: shadows on the display", "",
             f"`python -m benchmarks.shadows` ({len(paths)} Poly Haven photographs of "
             f"{ph.WHEEL}, each at four levels, `ocl-tonemap run` to 8-bit PNG with each "
             "operator's defaults). Cells: crushed (pixels within 1.5 log10 units below the "
             "log-average, or above, that come out exactly black) / black (all pixels "
             "exactly black) / the darkest tenth's distinct luma codes.", "",
             "Worst over the photographs (crushed, fewest codes):", "",
             "| operator | " + " | ".join(lv for lv, _ in LEVELS) + " |",
             "|---|" + "---|" * len(LEVELS),
             *(f"| {op} | " + " | ".join(f"{worst[(op, lv)][0]:.2%}, {worst[(op, lv)][1]}"
                                         for lv, _ in LEVELS) + " |" for op in ops),
             "", head, "|---|---|" + "---|" * len(ops), *rows, "",
             "## After a step into the dark", "",
             "Each photograph at dusk (1 cd/m^2), the eye adapted to 100 cd/m^2 before "
             "(`simulate --preadapt 100`): crushed 0.5 s and 600 s after, and the darkest "
             "tenth's codes at 600 s.", "",
             "| photograph | operator | crushed at 0.5 s | at 600 s | codes at 600 s |",
             "|---|---|---|---|---|", *course]
    out = out_path(a, "shadows.md")
    write_markdown(out, lines, [])
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
