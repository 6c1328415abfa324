"""The before/after sheet of issue 57 (benchmarks/results/shadows_before_after.jpg):
pattanaik00's defaults on three photographs before the shadow toe (Sec. 4.3's clip) and
after, each also lifted x6 in display-linear with the pixels an adapted observer sees
(within 1.5 log10 units of the log-average) that came out exactly black in red; a row
per photograph and level (benchmarks.shadows' four). One command, given two folders of
``ocl-tonemap run PHOTO.hdr DIR/PHOTO_LEVEL.png --luminance-scale auto:L`` outputs (the
before from a checkout of 694b239, the commit before the toe):

    python -m benchmarks.shadows_sheet BEFORE_DIR AFTER_DIR [--out FILE]
"""

from __future__ import annotations

import argparse
import os
import sys

import numpy as np

from benchmarks.lib import photos as ph
from benchmarks.shadows import LEVELS, SEEN_DECADES, _read, _scene_luminance

NAMES = ("potsdamer_platz_1k", "venice_sunset_1k", "st_fagans_interior_1k")


def _lift(codes: np.ndarray) -> np.ndarray:
    """8-bit sRGB-ish codes x6 in display-linear, re-encoded (the shadows made visible)."""
    return np.clip((codes / 255.0) ** 2.2 * 6.0, 0.0, 1.0) ** (1 / 2.2)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--photos", help="the photographs' folder (default: the cache)")
    ap.add_argument("--out", default="shadows_before_after.jpg")
    a = ap.parse_args(argv)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    hdr = {p.stem: p for p in ph.fetch_photos(a.photos)}
    rows = [(n, lv, L) for n in NAMES for lv, L in LEVELS]
    fig, ax = plt.subplots(len(rows), 4, figsize=(16, 2.2 * len(rows) + 0.6))
    for i, (n, lv, L) in enumerate(rows):
        Y = _scene_luminance(str(hdr[n]))
        seen = Y >= np.exp(np.mean(np.log(np.maximum(Y, 1e-12)))) / 10 ** SEEN_DECADES
        for j, (tag, d) in enumerate((("before (Sec. 4.3 clip)", a.before),
                                      ("after (toe)", a.after))):
            c = _read(os.path.join(d, f"{n}_{lv}.png")).astype(np.float64)
            crushed = (c.max(axis=2) == 0) & seen
            ax[i, j].imshow(c / 255.0)
            ax[i, j].set_title(f"{n} at {lv} ({L:g} cd/m^2): {tag}", fontsize=8)
            lifted = _lift(c)
            lifted[crushed] = (1.0, 0.0, 0.0)
            ax[i, j + 2].imshow(lifted)
            ax[i, j + 2].set_title(f"{tag}, x6 lifted; red: seen but black "
                                   f"({crushed.sum() / max(seen.sum(), 1):.2%})", fontsize=8)
    for x in ax.ravel():
        x.axis("off")
    fig.suptitle("pattanaik00 defaults, before/after issue 57 (benchmarks/results/shadows.md)",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.3 / fig.get_figheight()))
    fig.savefig(a.out, dpi=60, **({"pil_kwargs": {"quality": 85}} if a.out.endswith(".jpg") else {}))
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
