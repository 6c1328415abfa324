"""Outputs of every operator on the benchmark scenes, saved or compared.

A refactoring must not change what a user sees. This renders short sequences
(three frames whose level changes, so the time course runs) of the generated
appearance scenes and, when cached, real photographs, through every operator in
both modes, on both backends, and with the effects on, through the public API
only (``Tonemapper``), and either saves them or compares them with a saved set:

    python -m benchmarks.equivalence --save /tmp/before     # on the old tree
    python -m benchmarks.equivalence --compare /tmp/before  # on the new tree

``--compare`` prints the largest absolute difference per case and exits 1 when
any exceeds ``--tol`` (default 1e-6, display-linear units).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np


def scenes(size=(96, 64)):
    from benchmarks.lib import scenes as sc
    w, h = size
    out = {"tunnel": sc.tunnel(w, h), "patches": sc.patches(w, h), "lamp": sc.lamp(w, h)}
    try:
        from benchmarks.lib.photos import cached_photos
        import OpenImageIO as oiio
        for p in cached_photos()[:2]:
            buf = oiio.ImageBufAlgo.resize(oiio.ImageBuf(str(p)), roi=oiio.ROI(0, w, 0, h, 0, 1, 0, 3))
            a = np.asarray(buf.get_pixels(oiio.FLOAT))[..., :3]
            out[p.stem] = a / max(float(np.exp(np.mean(np.log(np.maximum(a.mean(-1), 1e-6))))), 1e-6)
    except Exception as exc:  # noqa: BLE001 -- photos are optional
        print(f"(no photographs: {exc})")
    return out


#: (operator, options, effects keywords)
CASES = [
    ("pattanaik00", {}, {}), ("pattanaik00", {"mode": "paper"}, {}),
    ("durand00", {}, {}), ("durand00", {"mode": "paper"}, {}), ("durand00", {"lut": 2000}, {}),
    ("durand00", {}, {"flare": "on", "acuity": "on", "chromatic_adaptation": "on"}),
    ("ledda04", {}, {}), ("ledda04", {"mode": "paper"}, {}),
    ("ledda04", {"bilateral": "exact"}, {}),
    ("kirk11", {}, {}), ("kirk11", {"mode": "paper"}, {}),
    ("pattanaik00", {}, {"purkinje": "on", "flare": "on"}),
    ("ledda04", {}, {"chromatic_adaptation": "on", "acuity": "on"}),
]
LEVELS = (0.05, 50.0, 3000.0)      # cd/m^2 log-average of frames 1-3
TIMES = (0.0, 0.5, 30.5)


def render(backends=("opencl", "reference")) -> dict:
    from ocl_tonemap import Tonemapper
    from ocl_tonemap.effects import EffectSettings
    res = {}
    for sname, img in scenes().items():
        for backend in backends:
            for i, (op, opts, fx) in enumerate(CASES):
                if backend == "reference" and sname not in ("tunnel", "lamp"):
                    continue
                eff = EffectSettings.for_operator(op, **fx) if fx else None
                tm = Tonemapper(op, backend=backend, options=opts or None, effects=eff)
                for j, (lv, t) in enumerate(zip(LEVELS, TIMES)):
                    out = tm.process(img, time_s=t, luminance_scale=lv)
                    res[f"{sname}|{backend}|{i}:{op}{opts}{fx}|{j}"] = np.asarray(out, np.float32)
    from ocl_tonemap.io.sample import spectral_patches
    lam, spec, _ = spectral_patches("A", 0.05)
    spec = np.repeat(np.repeat(spec.reshape(4, 6, -1), 4, axis=0), 4, axis=1).astype(np.float32)
    for backend in backends:
        tm = Tonemapper("kirk11", backend=backend)
        res[f"spectral|{backend}|kirk11"] = tm.process(spec, luminance_scale=1.0, wavelengths=lam)
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--save", metavar="DIR")
    g.add_argument("--compare", metavar="DIR")
    ap.add_argument("--tol", type=float, default=1e-6)
    a = ap.parse_args(argv)
    res = render()
    if a.save:
        Path(a.save).mkdir(parents=True, exist_ok=True)
        np.savez_compressed(Path(a.save) / "outputs.npz", **res)
        print(f"saved {len(res)} outputs to {a.save}/outputs.npz")
        return 0
    ref = np.load(Path(a.compare) / "outputs.npz")
    worst, bad = 0.0, []
    for k in ref.files:
        if k not in res:
            bad.append(f"missing {k}")
            continue
        d = float(np.max(np.abs(res[k].astype(np.float64) - ref[k]))) if res[k].shape == ref[k].shape \
            else float("inf")
        worst = max(worst, d)
        if d > a.tol:
            bad.append(f"{k}: max |diff| {d:.3g}")
    print(f"{len(ref.files)} outputs compared; largest difference {worst:.3g} (tolerance {a.tol:g})")
    for b in bad:
        print("  " + b)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
