"""How close an OCIO export (``run --ocio-export``) comes to the run, and what it costs:
each exported frame read back through the written config by OCIO and compared with
the frame's own mapping, per lattice size.

One command:
    python -m benchmarks.ocio_export_lut [--sizes 17,33,49,65] [--out-dir DIR | --out FILE]

Writes ocio_export_lut.md into DIR (default ./benchmark-results; the committed one:
``--out-dir benchmarks/results``).

Scenes: the tunnel sample (320x180, 9 frames across the drive, the adaptation running
through them), and real HDR photographs (480 wide; ``benchmarks/lib/photos.py``) at
daylight, interior, dusk and night levels (log-mean luminance 3000, 100, 3, 0.03
cd/m^2), each level a frame of a sequence 2 s apart. Operators pattanaik00 and
durand00 at their defaults with the spatial effects off (--flare off --acuity off:
the per-pixel effects, chromatic adaptation and the Purkinje shift, stay on), the
bundled config's sRGB display.

Sizes 17 to 65 fixed, and ``auto`` (the default: 33, else 49, else 65 where a frame
is beyond the bound). Reported per scene, operator and lattice size: the worst frame's p99 and max error in
8-bit codes (the issue's bound: p99 <= 1, max <= 3), max in 10-bit codes and the p99
in half-float steps, the frames within the bound, the time per frame to build the
lattices (including choosing stage B by measuring both), to write the CLF and to read
it back through OCIO, and the CLF's size per frame.
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import write_markdown

LEVELS = (3000.0, 100.0, 3.0, 0.03)
PHOTOS = ("venice_sunset_1k.hdr", "blender_interior.exr", "potsdamer_platz_1k.hdr",
          "dikhololo_night_1k.hdr")


def scenes(photo_names):
    from ocl_tonemap.models.photometry import Y_WEIGHTS
    from ocl_tonemap.io.sample import render_frame
    yield "tunnel (9 frames)", 1.0, [np.ascontiguousarray(render_frame(float(t), 320, 180, 8.0)
                                                          [..., :3], np.float32)
                                     for t in range(9)]
    from benchmarks.lib.photos import fetch_photos, load_photo
    paths = {p.name: p for p in fetch_photos()}
    for name in photo_names:
        if name not in paths:
            continue
        img = load_photo(paths[name], 480).astype(np.float32)[..., :3]
        lm = float(np.exp(np.mean(np.log(np.maximum(img @ Y_WEIGHTS, 1e-9)))))
        yield (f"{name.split('_1k')[0].split('.')[0]} (4 levels)", 2.0,
               [np.ascontiguousarray(img * (L / lm), np.float32) for L in LEVELS])


def export_scene(op: str, frames, dt: float, size: int) -> dict:
    from ocl_tonemap.colour import ColourPipeline
    from ocl_tonemap.colour.export import OcioExport
    from ocl_tonemap.effects import EffectSettings
    from ocl_tonemap.pipeline import Tonemapper
    cp = ColourPipeline("ocl-tonemap")
    fx = EffectSettings(chromatic_adaptation="auto", purkinje="auto")
    tm = Tonemapper(op, model="auto", backend="reference", effects=fx)
    folder = tempfile.mkdtemp(prefix="ocltm_export_")
    try:
        ex = OcioExport(folder, cp, tm, 1, size)
        recs = []
        for k, img in enumerate(frames):
            r = tm.process_frame(img, dt=None if k == 0 else dt)
            recs.append(ex.add_frame(k + 1, img, 1.0, r.info.effects))
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return {"p99": max(r["p99_8bit"] for r in recs), "max": max(r["max_8bit"] for r in recs),
            "max10": max(r["max_10bit"] for r in recs),
            "half": max(r["p99_half_steps"] for r in recs),
            "within": sum(r["within_bound"] for r in recs), "n": len(recs),
            "build": np.mean([r["ms_build"] for r in recs]),
            "write": np.mean([r["ms_write"] for r in recs]),
            "verify": np.mean([r["ms_verify"] for r in recs]),
            "mb": np.mean([r["bytes"] for r in recs]) / 1e6,
            "b_rgb": sum("rgb" in r["stage_b"] for r in recs),
            "lattices": ",".join(str(r["lattice"]) for r in recs),
            "a_matrix": sum(r["stage_a"] == "matrix" for r in recs)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="17,33,49,65,auto")
    ap.add_argument("--operators", default="pattanaik00,durand00")
    ap.add_argument("--photos", default=",".join(PHOTOS))
    add_out_args(ap, "ocio_export_lut.md")
    a = ap.parse_args(argv)
    sizes = [s if s == "auto" else int(s) for s in a.sizes.split(",")]
    rows = []
    t0 = time.perf_counter()
    for name, dt, frames in scenes([p for p in a.photos.split(",") if p]):
        for op in a.operators.split(","):
            for n in sizes:
                s = export_scene(op, frames, dt, n)
                ok = "PASS" if s["within"] == s["n"] else f"{s['within']}/{s['n']}"
                rows.append((name, op, n if n == "auto" else f"{n}^3", f"{s['p99']:.2f}", f"{s['max']:.2f}", ok,
                             f"{s['max10']:.1f}", f"{s['half']:.1f}",
                             f"{s['a_matrix']}/{s['n']}", f"{s['b_rgb']}/{s['n']}",
                             f"{s['build']:.0f}", f"{s['write']:.0f}", f"{s['verify']:.0f}",
                             f"{s['mb']:.1f}", s["lattices"] if n == "auto" else ""))
                print(" | ".join(rows[-1]), flush=True)
    L = ["# OCIO export: each frame's CLF replayed by OCIO against the run", "",
         "- command `python -m benchmarks.ocio_export_lut`; "
         f"{time.perf_counter() - t0:.0f} s on this machine (2-core host, OCIO "
         f"{__import__('PyOpenColorIO').__version__} CPU processor)",
         "- operators at their defaults, --flare off --acuity off (chromatic adaptation "
         "and the Purkinje shift on `auto`), the bundled config's sRGB display; the "
         "reference: the frame's own float64 mapping through OCIO's display transform",
         "- bound (issue 32): p99 <= 1 and max <= 3 8-bit codes on every frame; "
         "'within': frames within it",
         "- stage A 'matrix': frames whose operator stage is linear (exact); stage B "
         "'rgb': frames where the RGB lattice measured better than the log-opponent one",
         "", "| scene | operator | lattice | worst p99 (8-bit) | worst max (8-bit) | within | "
         "max (10-bit) | p99 (half steps) | A matrix | B rgb | ms build | ms write | "
         "ms read-back | MB/frame | auto: each frame's lattice |", "|" + "---|" * 15]
    write_markdown(out_path(a, "ocio_export_lut.md"), L, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
