"""The README's picture of the OCIO export: one frame of the tunnel sample as the run
writes it, the same frame replayed by oiiotool through the exported view, and their
difference (x 32, so that one 8-bit code shows as 32).

One command:
    python -m benchmarks.ocio_export_picture [--frame 2] [--out-dir DIR | --out FILE]

Writes ocio_export.png into DIR (default ./benchmark-results); the README's picture is
refreshed with ``--out docs/ocio_export.png``.

It runs the real commands: ``ocl-tonemap sample`` (640x360, 8 s at 1 fps), ``ocl-tonemap
run ... --flare off --acuity off --ocio-export``, ``oiiotool --frames ...
--ociodisplay:key=FRAME:value={FRAME_NUMBER}`` over the whole sequence, and prints each
frame's p99 and max difference in 8-bit codes.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import join, write_image


def _run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: {r.stderr or r.stdout}")
    return r.stdout


def main(argv=None) -> int:
    import OpenImageIO as oiio
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frame", type=int, default=2)
    ap.add_argument("--operator", default="pattanaik00")
    add_out_args(ap, "ocio_export.png")
    a = ap.parse_args(argv)
    oiiotool = shutil.which("oiiotool", path=os.path.dirname(sys.executable)) or "oiiotool"
    d = tempfile.mkdtemp(prefix="ocltm_pic_")
    try:
        me = [sys.executable, "-m", "ocl_tonemap"]
        _run(me + ["sample", f"{d}/s", "--size", "640x360", "--seconds", "8", "--fps", "1", "-q"])
        print(_run(me + ["run", f"{d}/s/tunnel.####.exr", f"{d}/o/o.####.png", "--operator",
                         a.operator, "--flare", "off", "--acuity", "off", "--ocio-export",
                         f"{d}/x"]).strip())
        cfg = f"{d}/x/ocl-tonemap_{a.operator}.ocio"
        _run([oiiotool, "--frames", "1-8", "--colorconfig", cfg, f"{d}/s/tunnel.#.exr",
              "--ociodisplay:from=scene_linear:key=FRAME:value={FRAME_NUMBER}",
              "sRGB - Display", f"{a.operator} observer", "-d", "uint8", "-o", f"{d}/r.#.png"])
        for n in range(1, 9):
            run = oiio.ImageBuf(f"{d}/o/o.{n:04d}.png").get_pixels(oiio.UINT8)[..., :3]
            rep = oiio.ImageBuf(f"{d}/r.{n:04d}.png").get_pixels(oiio.UINT8)[..., :3]
            diff = np.abs(run.astype(int) - rep.astype(int))
            print(f"frame {n}: p99 {np.percentile(diff, 99):.0f}, max {diff.max()} 8-bit codes")
            if n == a.frame:
                pic = join([run, rep, np.clip(diff * 32, 0, 255).astype(np.uint8)], gap=8)
        print(f"wrote {write_image(out_path(a, 'ocio_export.png'), pic)}")
    finally:
        shutil.rmtree(d, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
