"""A contact sheet of Radiance renderings through Radiance's ``pcond -h`` and through
each operator with its defaults, for docs/radiance.md.

One command (Radiance from PyPI: ``pip install "ocl-tonemap[radiance]"``):
    python -m benchmarks.radiance_sheet [--out-dir DIR | --out FILE]

Writes radiance_pcond.jpg into DIR (default ./benchmark-results); docs/radiance.md's
sheet is refreshed with ``--out docs/sheets/radiance_pcond.jpg``.

Three scenes rendered here with ``rpict`` (no files needed): a room lit by one warm
lamp (interior), a road at night with sodium-coloured luminaires every 30 m, and a
tunnel portal at noon under a sunny sky (gensky). Rows: the scenes; columns: ``pcond
-h`` (its display values encoded with gamma 2.2, as Radiance's ``ra_tiff`` and
``ximage`` show them), then pattanaik00, ledda04, durand00 and kirk11 (8-bit sRGB PNG,
the bundled config), each run as a user runs it: ``ocl-tonemap run scene.hdr out.png``.
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
from benchmarks.lib.report import join, radiance_env, write_image

OPERATORS = ("pattanaik00", "ledda04", "durand00", "kirk11")
SIZE = (480, 270)

ROOM = """void plastic wallpaint
0
0
5 0.6 0.58 0.55 0 0
void plastic floorwood
0
0
5 0.25 0.15 0.08 0 0
void plastic redcloth
0
0
5 0.45 0.05 0.04 0 0
void plastic bluebook
0
0
5 0.04 0.08 0.4 0 0
void light lampbright
0
0
3 4000 3200 2200
!genbox wallpaint room 5 4 3 -i
!genbox floorwood floor 5 4 0.01 | xform -t 0 0 0.001
!genbox redcloth table 1.2 0.8 0.75 | xform -t 2 1.5 0
!genbox bluebook book 0.3 0.2 0.05 | xform -t 2.3 1.8 0.75
lampbright sphere bulb
0
0
4 2.5 2 2.6 0.06
"""

ROAD = """void plastic asphalt
0
0
5 0.07 0.07 0.07 0 0
void plastic verge
0
0
5 0.05 0.09 0.04 0 0
void plastic marking
0
0
5 0.6 0.6 0.6 0 0
void plastic poles
0
0
5 0.3 0.3 0.3 0 0
void light sodium
0
0
3 9000 5000 1200
asphalt polygon road
0
0
12 -4 -10 0  4 -10 0  4 400 0  -4 400 0
verge polygon vleft
0
0
12 -60 -10 0  -4 -10 0  -4 400 0  -60 400 0
verge polygon vright
0
0
12 4 -10 0  60 -10 0  60 400 0  4 400 0
""" + "".join(f"""!genbox poles pole{k} 0.15 0.15 8 | xform -t 4.5 {30 * k + 5} 0
sodium sphere lamp{k}
0
0
4 3.8 {30 * k + 5} 8 0.12
!genbox marking dash{k} 0.12 3 0.002 | xform -t -0.06 {30 * k + 15} 0
""" for k in range(10))

PORTAL_TAIL = """
skyfunc glow skyglow
0
0
4 0.9 0.95 1.1 0
skyglow source sky
0
0
4 0 0 1 180
void plastic ground
0
0
5 0.12 0.15 0.08 0 0
void plastic asphalt
0
0
5 0.08 0.08 0.08 0 0
void plastic concrete
0
0
5 0.45 0.43 0.4 0 0
ground polygon field
0
0
12 -300 -20 0  300 -20 0  300 600 0  -300 600 0
asphalt polygon road
0
0
12 -4 -20 0.01  4 -20 0.01  4 260 0.01  -4 260 0.01
!genbox concrete facL 20 1 14 | xform -t -25 60 0
!genbox concrete facR 20 1 14 | xform -t 5 60 0
!genbox concrete facT 10 1 8 | xform -t -5 60 6
!genbox concrete wallL 1 200 6 | xform -t -6 61 0
!genbox concrete wallR 1 200 6 | xform -t 5 61 0
!genbox concrete roof 12 200 1 | xform -t -6 61 6
!genbox concrete hill 60 220 14 | xform -t -30 61 7
"""

VIEWS = {
    "room": ["-vtv", "-vp", "0.3", "0.3", "1.6", "-vd", "1", "0.8", "-0.25", "-vu", "0", "0",
             "1", "-vh", "70", "-vv", "43", "-ab", "1", "-ad", "512", "-as", "0", "-aa", "0.2"],
    "road": ["-vtv", "-vp", "0", "0", "1.5", "-vd", "0", "1", "-0.02", "-vu", "0", "0", "1",
             "-vh", "60", "-vv", "36", "-ab", "0"],
    "portal": ["-vtv", "-vp", "0", "0", "1.5", "-vd", "0", "1", "0.02", "-vu", "0", "0", "1",
               "-vh", "60", "-vv", "36", "-ab", "1", "-ad", "256", "-as", "0", "-aa", "0.2"],
}


def render(d: str, env: dict) -> dict:
    """The three scenes as Radiance pictures (rpict's headers: absolute, VIEW)."""
    sky = subprocess.run(["gensky", "6", "21", "11", "+s", "-a", "45", "-o", "0", "-m", "0"],
                         capture_output=True, text=True, env=env, check=True).stdout
    out = {}
    for name, text in (("room", ROOM), ("road", ROAD), ("portal", sky + PORTAL_TAIL)):
        with open(os.path.join(d, f"{name}.rad"), "w") as fh:
            fh.write(text)
        with open(os.path.join(d, f"{name}.oct"), "wb") as fh:
            subprocess.run(["oconv", f"{name}.rad"], stdout=fh, cwd=d, env=env, check=True)
        out[name] = os.path.join(d, f"{name}.hdr")
        with open(out[name], "wb") as fh:
            subprocess.run(["rpict", *VIEWS[name], "-x", str(SIZE[0]), "-y", str(SIZE[1]),
                            f"{name}.oct"], stdout=fh, stderr=subprocess.DEVNULL, cwd=d,
                           env=env, check=True)
    return out


def main(argv=None) -> int:
    import OpenImageIO as oiio
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_out_args(ap, "radiance_pcond.jpg")
    a = ap.parse_args(argv)
    env = radiance_env()[1]
    d = tempfile.mkdtemp(prefix="ocltm_sheet_")
    try:
        pics = render(d, env)
        rows = []
        for name, hdr in pics.items():
            cells = []
            pc = os.path.join(d, f"{name}_pcond.hdr")
            with open(pc, "wb") as fh:
                subprocess.run(["pcond", "-h", hdr], stdout=fh, env=env, check=True)
            v = oiio.ImageBuf(pc).get_pixels(oiio.FLOAT)[..., :3]
            cells.append(np.clip(np.clip(v, 0, 1) ** (1 / 2.2) * 255 + 0.5, 0, 255).astype(np.uint8))
            for op in OPERATORS:
                png = os.path.join(d, f"{name}_{op}.png")
                subprocess.run([sys.executable, "-m", "ocl_tonemap", "run", hdr, png,
                                "--operator", op, "-q"], check=True)
                cells.append(oiio.ImageBuf(png).get_pixels(oiio.UINT8)[..., :3])
            rows.append(join(cells))
            print(f"{name}: done", flush=True)
        out = out_path(a, "radiance_pcond.jpg")
        print(f"wrote {write_image(out, join(rows, axis=0), Compression='jpeg:88')}")
    finally:
        shutil.rmtree(d, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
