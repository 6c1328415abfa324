"""Appearance benchmark: what a person sees from each operator, on real HDR photographs.

One command:  python -m benchmarks.appearance [--quick] [--operators a,b]
                  [--images a,b] [--levels L,L|all] [--effects-off] [--size W]
                  [--out-dir DIR] [--out SHEETS] [--results DIR] [--photos DIR]

Real photographs: twelve Poly Haven HDRIs (CC0): ten from the PyPI wheel
viser==0.2.23 (six of photos.PHOTOS, and EXTRA_PHOTOS here: a city, a forest, a
studio, a warehouse) and a sunrise and a tungsten-lit interior from Debian's
blender-data (benchmarks/lib/photos.py; fetched once, cached in
~/.cache/ocl-tonemap/photos or $OCLTM_PHOTOS), resized to W pixels wide; plus
three small generated scenes (benchmarks/lib/scenes.py). The photographs are
360-degree equirectangular panoramas and are rendered at that true angle,
``Tonemapper(op, fov_deg=360)`` (the flare's and acuity's field of view); the
generated scenes keep their own (the default). Each image is
calibrated so that its log-average photopic luminance is L cd/m^2, L in 1e-3,
0.1, 10, 1000 (``--levels all``: 1e-3 ... 1e4), and shown to a fresh observer,
steady-state adapted to the still, of every operator with its defaults,
``Tonemapper(op)`` (``--effects-off``: every effect off, the former setting;
SDR sRGB display, 1.0 = 100 cd/m^2). The reference is the plain OCIO rendering
of the same scene exposure-matched (log-average -> 0.18 of display white, no
tone curve). Light sources (scene luminance > 30x the log-average) are left out
of every measure.

Writes (OUT: --out-dir, default ./benchmark-results; the committed tables:
--out-dir benchmarks/results; the rule: benchmarks/lib/outdir.py):
  RESULTS/appearance.md     metric tables (worst case over images), targets,
                            a table per photo for the sunset, sunrise, tungsten
  RESULTS/appearance.json   the raw numbers
  SHEETS/<image>.png        contact sheet per image (rows: reference +
                            operators, columns: levels)
  SHEETS/readme_sheet.png   4 photos at their natural levels x operators
(RESULTS: --results, default OUT; SHEETS: --out, default OUT/appearance/.)
Metrics: benchmarks/lib/appearance_metrics.py. Issue 67's table (section 7): per
operator and level the worst photograph's clipping (any channel at 255, <= 3%) and
saturation ratio (coloured mid-tones, s_out / s_scene, 0.5-1.6 at 30 and 5000 cd/m^2);
its report levels: --levels 0.01,1,30,5000 (night, dusk, interior, daylight).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import sys
import time
import warnings

import numpy as np

from benchmarks.lib import appearance_metrics as am
from benchmarks.lib import photos as ph
from benchmarks.lib import scenes
from benchmarks.lib.outdir import DEFAULT_DIR, add_out_args, repo_relative
from benchmarks.lib.photos import load_photo

HERE = os.path.dirname(os.path.abspath(__file__))

#: The levels of the report (scene log-average, cd/m^2); ``--levels all``: ALL_LEVELS.
LEVELS = [1e-3, 0.1, 10.0, 1e3]
ALL_LEVELS = [1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0, 1e3, 1e4]
#: Photographs of the viser wheel beyond ``photos.PHOTOS`` (issue 67: a city, a forest, a
#: studio, a warehouse): stem -> (what it shows, natural level cd/m^2). With them the set
#: covers city, park, forest, interior, night, studio, sunrise and sunset.
EXTRA_PHOTOS = {
    "potsdamer_platz_1k": ("city, daylight", 5000.0),
    "forest_slope_1k": ("forest by day", 5000.0),
    "studio_small_03_1k": ("studio", 30.0),
    "empty_warehouse_01_1k": ("warehouse interior", 30.0),
}
ALL_PHOTOS = {**ph.PHOTOS, **EXTRA_PHOTOS}
#: The photographs are 360-degree equirectangular panoramas: rendered at their true
#: angle (the flare's and acuity's field of view); generated scenes keep their own.
PHOTO_FOV_DEG = 360.0
DEFAULT_IMAGES = [n[:-3] if n.endswith("_1k") else n for n in ALL_PHOTOS] + list(scenes.SCENES)
QUICK_IMAGES = ["rooitou_park", "st_fagans_interior", "dikhololo_night", "venice_sunset",
                "blender_interior", "patches"]
#: README sheet: (photo, level cd/m^2, label)
README_SHEET = [("rooitou_park", 5000.0, "daylight"), ("st_fagans_interior", 30.0, "interior"),
                ("kiara_1_dawn", 1.0, "dusk"), ("dikhololo_night", 0.01, "night")]
LOCAL_OPS = ("ledda04", "kirk11")
DISPLAY = "sRGB - Display"
REF = "OCIO (exposure-matched)"

CLIP_TARGET, HUE_TARGET, REV_TARGET, RHO_TARGET = 0.02, 5.0, 0.01, 0.9
HUE_MIN_LEVEL, SCOTOPIC_MAX_LEVEL = 100.0, 0.01
#: Colour as shown: magenta excess <= 1% (all levels); warm turned cool < 5% at
#: >= 10 cd/m^2; median hue difference to the input <= 15 degrees at >= 100 cd/m^2.
MAGENTA_TARGET, WARMCOOL_TARGET, SHIFT_TARGET = 0.01, 0.05, 15.0
WARMCOOL_MIN_LEVEL, SHIFT_MIN_LEVEL = 10.0, 100.0
SOURCE_FACTOR = 30.0                 # light sources: scene Y > 30 x log-average, left out
#: Issue 67: any channel at 255 <= 3%; saturation ratio on coloured mid-tones 0.5-1.6 at
#: these levels (daylight 5000, interior 30; dusk 1 and night 0.01 reported, lower there).
CLIPANY_TARGET, SAT_RANGE, SAT_LEVELS = 0.03, (0.5, 1.6), (30.0, 5000.0)
#: The issue's photographs (sunset, sunrise, tungsten light): a table each.
ISSUE_PHOTOS = ("venice_sunset", "blender_sunrise", "blender_interior")
VISIBLE_TOL = math.log10(1.01)      # a reversal of > 1% contrast (about a JND) is "visible"
TILE_W = 256


def short(name: str) -> str:
    return name[:-3] if name.endswith("_1k") else name


def lvl(L: float) -> str:
    return f"{L:g}"


# --- images ----------------------------------------------------------------------

def log_average(rgb) -> float:
    try:
        from ocl_tonemap.colour.calibration import log_average as la
        v = la(rgb)
    except ImportError:
        Y = am.luminance(rgb)
        Y = Y[Y > 0]
        v = float(np.exp(np.mean(np.log(Y)))) if Y.size else None
    if not v:
        raise ValueError("image has no light")
    return float(v)


def resolve_images(names, photo_paths, size):
    """name -> dict(rgb, kind, natural, source)."""
    by_stem = {short(p.stem): p for p in photo_paths}
    out = {}
    for n in names:
        n = short(n.strip())
        if not n:
            continue
        if n in scenes.SCENES:
            fn, what, nat = scenes.SCENES[n]
            w = max(64, size // 2)
            out[n] = dict(rgb=fn(w, w // 2), kind=what, natural=nat, source="generated")
        elif n in by_stem:
            stem = by_stem[n].stem
            what, nat = ALL_PHOTOS.get(stem, ("photograph", None))
            out[n] = dict(rgb=load_photo(by_stem[n], size), kind="photo: " + what, natural=nat,
                          source=ph.source_of(stem))
        else:
            raise ValueError(f"unknown image {n!r}; photos: "
                             f"{', '.join(sorted(by_stem))}; scenes: {', '.join(scenes.SCENES)}")
    return out


# --- running -----------------------------------------------------------------------

class Runner:
    """Runs the operators: ``Tonemapper(op)`` (the operator's defaults: backend,
    display sRGB, effects), or with ``effects_off`` the former setting
    (``backend="opencl"``, sRGB display, ``EffectSettings()``: every effect off)."""

    def __init__(self, effects_off: bool = False):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            from ocl_tonemap import Tonemapper
            from ocl_tonemap.colour import ColourPipeline, load_config
            from ocl_tonemap.models.display import display_for
            from ocl_tonemap.effects import EffectSettings
        self.Tonemapper, self.display_for, self.EffectSettings = Tonemapper, display_for, EffectSettings
        self.cp = ColourPipeline(load_config("ocl-tonemap"), DISPLAY)
        self.times: dict[str, list[float]] = {}
        self.effects_off = effects_off
        self.effects_seen: dict[str, dict] = {}
        self.gains = None        # the last run's von Kries gains (None: it did not run)

    def make(self, op: str, fov_deg: float | None = None):
        kw = {} if fov_deg is None else {"fov_deg": fov_deg}
        if self.effects_off:
            return self.Tonemapper(op, backend="opencl", display=self.display_for(DISPLAY),
                                   effects=self.EffectSettings(), **kw)
        return self.Tonemapper(op, **kw)

    def call(self, op: str) -> str:
        return (f"Tonemapper({op}, backend='opencl', display=sRGB, effects=EffectSettings())"
                if self.effects_off else f"Tonemapper({op})")

    def tonemap(self, op: str, rgb_cd: np.ndarray, fov_deg: float | None = None):
        """(display-linear output or None, error text or None); ``fov_deg``: the image's
        angular width (photographs: 360), else the default."""
        try:
            tm = self.make(op, fov_deg)
            if op not in self.effects_seen:
                s = tm.effects.s
                self.effects_seen[op] = {
                    k: getattr(s, k) for k in ("flare", "acuity", "chromatic_adaptation",
                                               "purkinje")}
                self.effects_seen[op]["backend"] = type(tm.backend).__name__
            t = time.perf_counter()
            out = tm.process(rgb_cd, luminance_scale=1.0)
            self.times.setdefault(op, []).append(time.perf_counter() - t)
            ca = (tm.last.effects or {}).get("chromatic_adaptation") or {}
            self.gains = np.asarray(ca["gains"], np.float32) if ca.get("ran") else None
            out = np.asarray(out, np.float32)[..., :3]
            if out.shape != rgb_cd.shape or not np.all(np.isfinite(out)):
                return None, f"bad output (shape {out.shape}, finite {np.isfinite(out).all()})"
            return out, None
        except Exception as e:  # noqa: BLE001 -- record and go on
            return None, f"{type(e).__name__}: {e}".splitlines()[0][:200]

    def tile(self, display_linear) -> np.ndarray:
        """What the display shows: clipped to white, downsized to TILE_W, OCIO-encoded."""
        a = np.clip(np.asarray(display_linear, np.float32), 0.0, 1.0)
        h, w = a.shape[:2]
        if w > TILE_W:
            import OpenImageIO as oiio
            th = max(1, int(round(h * TILE_W / w)))
            buf = oiio.ImageBuf(oiio.ImageSpec(w, h, 3, oiio.FLOAT))
            buf.set_pixels(oiio.ROI(0, w, 0, h, 0, 1, 0, 3), np.ascontiguousarray(a))
            buf = oiio.ImageBufAlgo.resize(buf, filtername="box",
                                           roi=oiio.ROI(0, TILE_W, 0, th, 0, 1, 0, 3))
            a = np.asarray(buf.get_pixels(oiio.FLOAT), np.float32)
        return np.clip(self.cp.encode(np.ascontiguousarray(a, np.float32)), 0.0, 1.0)


def provenance() -> str:
    """Which operator code was measured: git HEAD, the modified files under
    ocl_tonemap/ and kernels/ (read-only git calls), and a hash of their contents."""
    import hashlib
    import subprocess
    root = os.path.join(HERE, "..")

    def git(*args):
        try:
            r = subprocess.run(["git", "--no-optional-locks", *args], cwd=root,
                               capture_output=True, text=True, timeout=30)
            return r.stdout.rstrip() if r.returncode == 0 else None
        except (OSError, subprocess.TimeoutExpired):
            return None
    head = git("rev-parse", "--short", "HEAD") or "unknown"
    dirty = git("status", "--porcelain", "--", "ocl_tonemap", "kernels")
    h = hashlib.sha256()
    for sub in ("ocl_tonemap", "kernels"):
        for dp, _, fs in sorted(os.walk(os.path.join(root, sub))):
            for f in sorted(fs):
                if f.endswith((".py", ".cl", ".h")):
                    with open(os.path.join(dp, f), "rb") as fh:
                        h.update(f.encode() + b"\0" + fh.read())
    mods = [ln[3:] for ln in (dirty or "").splitlines() if ln.strip()]
    return (f"git {head}" + (f" + uncommitted changes in {', '.join(mods)}" if mods else "")
            + f"; ocl_tonemap/ + kernels/ sources sha256 {h.hexdigest()[:12]}")


def run_image(R: Runner, name: str, info: dict, ops, levels):
    base = info["rgb"]
    la0 = log_average(base)
    ref = base * np.float32(0.18 / la0)                 # exposure-matched, display-linear
    keep = ~am.light_source_mask(am.luminance(base), la0, SOURCE_FACTOR)   # same at every level
    fov = None if info["source"] == "generated" else PHOTO_FOV_DEG       # panoramas: 360°
    res = {"ref": {"clip": am.clip_fraction(ref, am.luminance(base) / la0, 1.0),
                   "magenta_hue_preserving": am.magenta_share(am.hue_preserving_render(base),
                                                              keep),
                   "sources": float(1.0 - keep.mean())}, "ops": {}}
    tiles = {REF: [R.tile(ref)] * len(levels)}
    for op in ops:
        outs, per = [], {}
        tiles[op] = []
        for L in levels:
            rgb_cd = np.ascontiguousarray(base * np.float32(L / la0))
            sY = am.luminance(rgb_cd)
            out, err = R.tonemap(op, rgb_cd, fov)
            outs.append(out)
            m = {"level": L}
            if err:
                m["error"] = err
                tiles[op].append(None)
            else:
                oY = am.luminance(out)
                m["mean_Y"] = float(oY[keep].mean()) if keep.any() else float(oY.mean())
                m["clip"] = am.clip_fraction(out, sY, L, source_factor=SOURCE_FACTOR)
                m["clip_any"] = am.clip_fraction(out, sY, L, source_factor=SOURCE_FACTOR,
                                                 channels="any")
                m["sat_ratio"] = am.saturation_ratio(out, rgb_cd, L,
                                                     source_factor=SOURCE_FACTOR)["ratio"]
                # the same against the scene under the observer's own von Kries gains:
                # the colours of the objects, not the cast that the eye discounts
                adapted = rgb_cd if R.gains is None else rgb_cd * R.gains
                m["sat_ratio_adapted"] = am.saturation_ratio(
                    out, adapted, L, source_factor=SOURCE_FACTOR)["ratio"]
                mg = am.magenta_excess(out, base, keep)
                m["magenta"], m["magenta_share"] = mg["excess"], mg["share"]
                wc = am.warm_to_cool(out, base, keep)
                m["warm_cool"], m["warm_cool_of_warm"] = wc["share"], wc["of_warm"]
                m["hue_shift_deg"] = am.hue_shift_deg(out, base, keep)
                g = am.gradient_reversal(sY, oY)
                m["reversal"] = g["all"]
                m["reversal_by_scale"] = {str(k): v for k, v in g.items() if k != "all"}
                m["reversal_visible"] = am.gradient_reversal(sY, oY, out_tol=VISIBLE_TOL)["all"]
                m["spearman"] = am.spearman(sY, oY)
                # the same against the luminance a person at this level orders by
                # (CIE 191 mesopic: V' at night, V by day): Purkinje is not an artefact
                sM = am.mesopic_luminance(rgb_cd)
                m["reversal_mesopic"] = am.gradient_reversal(sM, oY)["all"]
                m["spearman_mesopic"] = am.spearman(sM, oY)
                if L >= HUE_MIN_LEVEL:
                    m["hue_deg"] = am.hue_difference_deg(out, ref, mask=~am.light_source_mask(sY, L))
                tiles[op].append(R.tile(out))
            per[lvl(L)] = m
        means, inc = am.brightness_means(outs, mask=keep)
        day = next((o for o in reversed(outs) if o is not None), None)
        day_L = next((L for L, o in zip(reversed(levels), reversed(outs)) if o is not None), None)
        for L, out in zip(levels, outs):
            if L <= SCOTOPIC_MAX_LEVEL and out is not None and day is not None and day_L > L:
                per[lvl(L)]["scotopic"] = am.scotopic_colour(out, day, base)
                per[lvl(L)]["scotopic"]["day_level"] = day_L
        res["ops"][op] = {"levels": per, "brightness_means": means, "brightness_increasing": inc}
        print(f"  {name:20s} {op:12s} " + " ".join(
            "ERR" if "error" in per[lvl(L)] else
            f"{per[lvl(L)]['clip']:5.1%}/{per[lvl(L)]['magenta']:+5.1%}" for L in levels)
            + f"  bright-order {'ok' if inc else 'NO'}", flush=True)
    return res, tiles


# --- pictures ------------------------------------------------------------------------

def _show(ax, img, text=None, text_colour="white", shape=None):
    if img is None:
        ax.imshow(np.full(tuple(shape or (128, TILE_W)) + (3,), 0.5))
        ax.text(0.5, 0.5, "error", ha="center", va="center", transform=ax.transAxes,
                fontsize=11, color="red")
    else:
        ax.imshow(img, interpolation="nearest")
    if text:
        ax.text(0.02, 0.04, text, transform=ax.transAxes, fontsize=7, color=text_colour,
                va="bottom", ha="left",
                bbox=dict(boxstyle="square,pad=0.15", fc=(0, 0, 0, 0.55), ec="none"))
    ax.set_xticks([])
    ax.set_yticks([])
    for s in ax.spines.values():
        s.set_visible(False)


def _figure(nrows, ncols, tile_h, tile_w=TILE_W, left=1.25, top=0.75, dpi=100):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    tw, th = tile_w / dpi, tile_h / dpi
    gap = 0.06
    W = left + ncols * (tw + gap) + 0.1
    H = top + nrows * (th + 0.22) + 0.1
    fig, axes = plt.subplots(nrows, ncols, figsize=(W, H), dpi=dpi, squeeze=False)
    fig.subplots_adjust(left=left / W, right=1 - 0.1 / W, top=1 - top / H, bottom=0.1 / H,
                        wspace=gap / tw, hspace=0.22 / th)
    return plt, fig, axes


def _tile_label(m, L):
    """Two lines of a contact-sheet tile (clip, reversal, hue to OCIO; magenta excess,
    warm turned cool, hue to the input where they have targets) and whether the
    tile misses a target."""
    bad = m["clip"] >= CLIP_TARGET or m["reversal"] >= REV_TARGET
    top = f"clip {m['clip']:.1%}  rev {m['reversal']:.1%}"
    if "hue_deg" in m and np.isfinite(m["hue_deg"]):
        top += f"  dh {m['hue_deg']:.0f}°"
        bad = bad or m["hue_deg"] >= HUE_TARGET
    low = f"mag {m['magenta']:+.1%}"
    bad = bad or m["magenta"] > MAGENTA_TARGET
    if L >= WARMCOOL_MIN_LEVEL:
        low += f"  w>c {m['warm_cool']:.1%}"
        bad = bad or m["warm_cool"] >= WARMCOOL_TARGET
    if L >= SHIFT_MIN_LEVEL and np.isfinite(m["hue_shift_deg"]):
        low += f"  dh-in {m['hue_shift_deg']:.0f}°"
        bad = bad or m["hue_shift_deg"] > SHIFT_TARGET
    return top + "\n" + low, bad


def contact_sheet(path, name, info, tiles, res, ops, levels, effects="effects off"):
    rows = [REF] + list(ops)
    t0 = tiles[REF][0]
    th = int(round(TILE_W * t0.shape[0] / t0.shape[1]))
    plt, fig, axes = _figure(len(rows), len(levels), th, top=0.95)
    for i, r in enumerate(rows):
        for j, L in enumerate(levels):
            ax = axes[i][j]
            text, col = None, "white"
            if r != REF:
                m = res["ops"][r]["levels"][lvl(L)]
                if "error" not in m:
                    text, bad = _tile_label(m, L)
                    col = "#ff8080" if bad else "white"
            _show(ax, tiles[r][j], text, col, t0.shape[:2])
            if i == 0:
                ax.set_title(f"{lvl(L)} cd/m²", fontsize=11)
            if j == 0:
                ax.set_ylabel(r if r != REF else "OCIO\nexposure-\nmatched", fontsize=11,
                              rotation=0, ha="right", va="center", labelpad=8)
    nat = info.get("natural")
    fig.suptitle(f"{name} ({info['kind']}; natural level ~{lvl(nat)} cd/m²)" if nat else name,
                 fontsize=13, x=0.5, y=1 - 0.12 / fig.get_figheight())
    fig.text(0.5, 1 - 0.34 / fig.get_figheight(),
             "scene log-average luminance; sRGB display, white 100 cd/m², steady-state observer, "
             f"{effects};\nred labels miss a target (clip >= 2%, reversal >= 1%, "
             "hue to OCIO >= 5°, magenta excess > 1%, warm>cool >= 5%, hue to input > 15°)",
             ha="center", va="top", fontsize=8.5)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def readme_sheet(path, R: Runner, photos_rgb: dict, ops):
    cols = [(n, L, lab) for n, L, lab in README_SHEET if n in photos_rgb]
    tiles = {}
    for n, L, _ in cols:
        base = photos_rgb[n]
        rgb_cd = np.ascontiguousarray(base * np.float32(L / log_average(base)))
        for op in ops:
            out, _ = R.tonemap(op, rgb_cd, PHOTO_FOV_DEG)
            tiles[(op, n)] = None if out is None else R.tile(out)
    t0 = next((t for t in tiles.values() if t is not None), np.zeros((128, TILE_W, 3)))
    th = int(round(TILE_W * t0.shape[0] / t0.shape[1]))
    plt, fig, axes = _figure(len(ops), len(cols), th, left=1.1, top=0.55)
    for i, op in enumerate(ops):
        for j, (n, L, lab) in enumerate(cols):
            ax = axes[i][j]
            _show(ax, tiles[(op, n)], shape=t0.shape[:2])
            if i == 0:
                ax.set_title(f"{lab}: {n.replace('_', ' ')}\n{lvl(L)} cd/m²", fontsize=10)
            if j == 0:
                ax.set_ylabel(op, fontsize=11, rotation=0, ha="right", va="center", labelpad=8)
    fig.savefig(path, dpi=100)
    plt.close(fig)


# --- report ----------------------------------------------------------------------------

def md_table(head, rows):
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    return "\n".join(out + ["| " + " | ".join(str(c) for c in r) + " |" for r in rows])


def worst(results, op, L, key, pick=max, fmt="{:.1%}", sub=None):
    """Worst value over images and the image it comes from, as a cell."""
    vals = []
    for name, r in results.items():
        m = r["ops"].get(op, {}).get("levels", {}).get(lvl(L))
        if m is None:
            continue
        if "error" in m:
            return "error", None
        v = m.get(key) if sub is None else (m.get(key) or {}).get(sub)
        if v is not None and np.isfinite(v):
            vals.append((v, name))
    if not vals:
        return "-", None
    v, n = pick(vals)
    return (f"{fmt.format(v)} ({n})" if v != 0 else fmt.format(v)), v


def report(results, images, ops, levels, meta) -> tuple[str, dict]:
    L_hue = [L for L in levels if L >= HUE_MIN_LEVEL]
    L_sco = [L for L in levels if L <= SCOTOPIC_MAX_LEVEL]
    L_wc = [L for L in levels if L >= WARMCOOL_MIN_LEVEL]
    L_sh = [L for L in levels if L >= SHIFT_MIN_LEVEL]
    verdict = {op: {} for op in ops}
    parts = [
        "# Appearance benchmark",
        "",
        f"Command: `{meta['command']}`. Run time {meta['run_time_s']:.0f} s "
        f"({meta['date']}). Machine: {meta['machine']}; OpenCL: {meta['opencl']}.",
        "",
        f"Code measured: {meta['code']}.",
        "",
        "Each image is calibrated so that its log-average photopic luminance is the level "
        "(cd/m²), and shown to a fresh observer of each operator, steady-state adapted to "
        f"the still (`{meta['call']}`; {meta['effects']}). Output: "
        "display-linear Rec.709, 1.0 = display white 100 cd/m². Reference: the plain OCIO "
        "rendering of the scene exposure-matched (log-average -> 0.18 of white, no tone "
        "curve). Metrics: `benchmarks/lib/appearance_metrics.py`. Contact sheets: "
        f"`{meta['sheets_dir']}/<image>.png` (rows: reference + operators, columns: levels).",
        "",
        "**Tables give the worst case over the images** (the image in brackets).",
        "",
        "## Images",
        "",
        md_table(("image", "what", "size", "natural level cd/m²", "source"),
                 [(n, i["kind"], f"{i['rgb'].shape[1]}x{i['rgb'].shape[0]}",
                   lvl(i["natural"]) if i.get("natural") else "-", i["source"])
                  for n, i in images.items()]),
        "",
    ]

    def fails(op, key, bad, levels_):
        fl = []
        for L in levels_:
            for name, r in results.items():
                m = r["ops"][op]["levels"].get(lvl(L), {})
                if "error" in m or bad(m):
                    fl.append(lvl(L))
                    break
        return fl

    # targets
    rows = []
    for op in ops:
        def cell(fl):
            return "PASS" if not fl else "FAIL at " + ", ".join(fl)
        br = [short(n) for n, r in results.items() if not r["ops"][op]["brightness_increasing"]]
        v = {
            "brightness": "PASS" if not br else "FAIL (" + ", ".join(br) + ")",
            "clip": cell(fails(op, "clip", lambda m: m["clip"] >= CLIP_TARGET, levels)),
            "hue": cell(fails(op, "hue", lambda m: np.isfinite(m.get("hue_deg", np.nan))
                              and m["hue_deg"] >= HUE_TARGET, L_hue)) if L_hue else "-",
            "desat": cell(fails(op, "desat", lambda m: "scotopic" in m
                                and not m["scotopic"]["chroma_lower"], L_sco)) if L_sco else "-",
            "bluehue": cell(fails(op, "bluehue", lambda m: "scotopic" in m
                                  and np.isfinite(m["scotopic"]["neutral_hue"])
                                  and not m["scotopic"]["neutral_blue"], L_sco)) if L_sco else "-",
            "rev": cell(fails(op, "rev", lambda m: m["reversal"] >= REV_TARGET, levels)),
            "rev_mes": cell(fails(op, "rev_mes", lambda m: m["reversal_mesopic"] >= REV_TARGET,
                                  levels)),
            "rho": (cell(fails(op, "rho", lambda m: m["spearman"] < RHO_TARGET, levels))
                    if op in LOCAL_OPS else "n/a (global)"),
            "rho_mes": (cell(fails(op, "rho_mes", lambda m: m["spearman_mesopic"] < RHO_TARGET,
                                   levels)) if op in LOCAL_OPS else "n/a (global)"),
            "magenta": cell(fails(op, "magenta", lambda m: m["magenta"] > MAGENTA_TARGET, levels)),
            "warm_cool": cell(fails(op, "warm_cool", lambda m: m["warm_cool"] >= WARMCOOL_TARGET,
                                    L_wc)) if L_wc else "-",
            "hue_shift": cell(fails(op, "hue_shift", lambda m: np.isfinite(m["hue_shift_deg"])
                                    and m["hue_shift_deg"] > SHIFT_TARGET, L_sh)) if L_sh else "-",
        }
        verdict[op] = v
        rows.append([op] + list(v.values()))
    parts += ["## Targets", "",
              "A target fails at a level when any image misses it there.", "",
              md_table(("operator", "brightness rises with level (all images)",
                        f"clipping < {CLIP_TARGET:.0%} (light sources excluded)",
                        f"photopic hue < {HUE_TARGET:g}° (levels >= {HUE_MIN_LEVEL:g})",
                        f"scotopic: less chroma than at {lvl(levels[-1])} (levels <= "
                        f"{SCOTOPIC_MAX_LEVEL:g})",
                        "scotopic: neutrals tinted 180-300° (blue)",
                        f"gradient reversal < {REV_TARGET:.0%} (photopic Y)",
                        f"gradient reversal < {REV_TARGET:.0%} (mesopic Y, CIE 191)",
                        f"Spearman >= {RHO_TARGET} (local ops; photopic Y)",
                        f"Spearman >= {RHO_TARGET} (local ops; mesopic Y)",
                        f"magenta excess <= {MAGENTA_TARGET:.0%}",
                        f"warm turned cool < {WARMCOOL_TARGET:.0%} (levels >= "
                        f"{WARMCOOL_MIN_LEVEL:g})",
                        f"hue to the input <= {SHIFT_TARGET:g}° (levels >= {SHIFT_MIN_LEVEL:g})"),
                       rows), "",
              "The artefact targets are given twice: against photopic luminance Y (the "
              "brief's literal metric) and against the CIE 191:2010 mesopic luminance of "
              "the scene at its level (scotopic V' at night, V by day; m from the frame's "
              "log-averages). At night a person orders surfaces by V' -- reds darken, blues "
              "lighten (the Purkinje shift the papers model) -- so a faithful operator "
              "*must* reorder some photopic luminances there; the mesopic columns count only "
              "what no observer would see (halos, noise).", ""]

    head = ["operator"] + [f"{lvl(L)}" for L in levels]
    # 1 brightness
    names = list(results)
    parts += ["## 1. Brightness order", "",
              "Does the mean output luminance (light sources excluded) strictly increase with "
              "the scene level? (per image; the means are in the per-image detail)", "",
              md_table(["operator"] + names,
                       [[op] + [_order_cell(results[n]["ops"][op], levels)
                                for n in names] for op in ops]), "",
              "Median over images of the mean output luminance (cd/m² on the display = 100 x Y):", "",
              md_table(head, [[op] + [
                  _fmt_cd(statistics.median([r["ops"][op]["brightness_means"][k] for r in results.values()]))
                  for k in range(len(levels))] for op in ops]), ""]
    # 2 clipping
    parts += ["## 2. Clipping", "",
              "Share of pixels whose three 8-bit sRGB code values are >= 0.999 of 255 (255: "
              "display-linear >= 0.9956), light sources (scene "
              f"luminance > 30x the log-average) excluded; worst image. Target < {CLIP_TARGET:.0%}. "
              "(The exposure-matched reference clips "
              + ", ".join(f"{short(n)} {r['ref']['clip']:.1%}" for n, r in results.items()) + ".)",
              "", md_table(head, [[op] + [_mark(*worst(results, op, L, "clip"), CLIP_TARGET)
                                          for L in levels] for op in ops]), "",
              "The same counting a pixel when any one channel is at 255 (saturated colours "
              "included; the former definition); worst image:", "",
              md_table(head, [[op] + [worst(results, op, L, "clip_any")[0] for L in levels]
                              for op in ops]), ""]
    # 3 hue
    if L_hue:
        hh = ["operator"] + [lvl(L) for L in L_hue]
        parts += ["## 3. Photopic hue", "",
                  "Median |CIELAB hue difference| (degrees) to the exposure-matched OCIO rendering "
                  "over pixels with reference C*ab > 10, light sources excluded (both images "
                  "normalised to log-average Y 0.18; the output before the display clips it); "
                  f"worst image. Target < {HUE_TARGET:g}°.", "",
                  md_table(hh, [[op] + [_mark(*worst(results, op, L, "hue_deg", fmt="{:.1f}°"),
                                              HUE_TARGET) for L in L_hue] for op in ops]), ""]
    # 4 scotopic
    if L_sco:
        def ratio_cell(op, L):
            vals = []
            for n, r in results.items():
                s = r["ops"][op]["levels"][lvl(L)].get("scotopic")
                if s:
                    vals.append((s["chroma"] / s["chroma_day"] if s["chroma_day"] > 0 else np.inf, n,
                                 s["chroma"], s["chroma_day"], s["chroma_scene"]))
            if not vals:
                return "-"
            v, n, c, cd, cs = max(vals)
            t = f"{v:.2f} ({c:.1f}/{cd:.1f}, scene {cs:.1f}, {n})"
            return f"**{t}**" if v >= 1 else t

        def hue_cell(op, L):
            hs = []
            for n, r in results.items():
                s = r["ops"][op]["levels"][lvl(L)].get("scotopic")
                if s and np.isfinite(s["neutral_hue"]):
                    hs.append((s["neutral_hue"], n, s["neutral_blue"]))
            if not hs:
                return "- (no tinted neutrals)"
            inn = sum(1 for h in hs if h[2])
            t = ", ".join(f"{n} {h:.0f}" for h, n, _ in hs)
            return f"{inn}/{len(hs)} in range: {t}" if inn == len(hs) else f"**{inn}/{len(hs)}** in range: {t}"

        parts += ["## 4. Scotopic colour", "",
                  f"Chroma: median C*ab of the output at the level / at {lvl(levels[-1])} cd/m² "
                  "(same operator and image, both normalised to log-average Y 0.18); worst "
                  "(largest) ratio over images, with the two chromas and the scene's own; "
                  "expect < 1. (A day output that clips to white has little chroma itself.)", "",
                  md_table(["operator"] + [lvl(L) for L in L_sco],
                           [[op] + [ratio_cell(op, L) for L in L_sco] for op in ops]), "",
                  "Hue of the scene's near-neutral pixels (scene C* < 5) where the output has "
                  "C* > 2 (reported when those are >= 1% of the image): circular median hue "
                  "angle per image; expected 180-300° (blue-green to blue).", "",
                  md_table(["operator"] + [lvl(L) for L in L_sco],
                           [[op] + [hue_cell(op, L) for L in L_sco] for op in ops]), "",
                  "Share of pixels pushed toward magenta (output hue 300-30° with C* > 5 where the "
                  "scene's was not); worst image.", "",
                  md_table(["operator"] + [lvl(L) for L in L_sco],
                           [[op] + [worst(results, op, L, "scotopic", sub="magenta_share")[0]
                                    for L in L_sco] for op in ops]), ""]
    # 5 artefacts
    parts += ["## 5. Artefacts", "",
              "Gradient reversal: among horizontal/vertical pixel pairs 1, 4 and 16 px apart whose "
              "scene log10 luminance differs by > 0.05, the share whose output difference has the "
              f"opposite sign (by > 0.001 decades); worst image. Target < {REV_TARGET:.0%}.", "",
              md_table(head, [[op] + [_mark(*worst(results, op, L, "reversal", fmt="{:.2%}"),
                                            REV_TARGET) for L in levels] for op in ops]), "",
              "The same counting only reversals of more than 1% contrast in the output "
              "(about a just-noticeable difference):", "",
              md_table(head, [[op] + [_mark(*worst(results, op, L, "reversal_visible",
                                                   fmt="{:.2%}"), REV_TARGET)
                                      for L in levels] for op in ops]), "",
              "Gradient reversal against the scene's CIE 191 mesopic luminance (what an "
              "observer at the level orders by); worst image:", "",
              md_table(head, [[op] + [_mark(*worst(results, op, L, "reversal_mesopic",
                                                   fmt="{:.2%}"), REV_TARGET)
                                      for L in levels] for op in ops]), "",
              "Spearman against the mesopic luminance; worst image:", "",
              md_table(head, [[op] + [_mark(*worst(results, op, L, "spearman_mesopic", pick=min,
                                                   fmt="{:.3f}"), RHO_TARGET, low=True)
                                      if op in LOCAL_OPS else
                                      worst(results, op, L, "spearman_mesopic", pick=min,
                                            fmt="{:.3f}")[0]
                                      for L in levels] for op in ops]), "",
              "Spearman rank correlation of scene and output luminance; worst (lowest) image. "
              f"Target >= {RHO_TARGET} for the local operators ({', '.join(LOCAL_OPS)}).", "",
              md_table(head, [[op] + [_mark(*worst(results, op, L, "spearman", pick=min,
                                                   fmt="{:.3f}"), RHO_TARGET, low=True)
                                      if op in LOCAL_OPS else
                                      worst(results, op, L, "spearman", pick=min, fmt="{:.3f}")[0]
                                      for L in levels] for op in ops]), ""]
    # 6 colour as shown
    parts += ["## 6. Colour as shown", "",
              "The output as the display shows it (clipped to 0..1), CIELAB relative to display "
              "white; light sources (scene luminance > 30x the log-average) left out. "
              "Definitions: `benchmarks/lib/appearance_metrics.py` section 6.", "",
              "Magenta excess: share of pixels with CIELAB hue 290-350° and C*ab > 15, minus the "
              "same share in a hue-preserving rendering of the photograph (log-average scaled to "
              "0.18, Y/(1+Y) on luminance, RGB ratios kept); worst image. Target <= "
              f"{MAGENTA_TARGET:.0%}. (CIELAB puts saturated deep blue in that hue range too: "
              "the Rec.709 blue primary is at 306°.)", "",
              md_table(head, [[op] + [_mark(*worst(results, op, L, "magenta", fmt="{:+.1%}"),
                                            MAGENTA_TARGET + 1e-12) for L in levels]
                              for op in ops]), "",
              "Warm turned cool: share of pixels with scene R > 1.3 B shown with B > 1.15 R; "
              f"worst image. Target < {WARMCOOL_TARGET:.0%} at levels >= {WARMCOOL_MIN_LEVEL:g} "
              "(lower levels for information: the Purkinje shift and night tint are blue on "
              "purpose).", "",
              md_table(head, [[op] + [_mark(*worst(results, op, L, "warm_cool"),
                                            WARMCOOL_TARGET) if L >= WARMCOOL_MIN_LEVEL
                                      else worst(results, op, L, "warm_cool")[0]
                                      for L in levels] for op in ops]), "",
              "Hue to the input: median |CIELAB hue difference| between the output and the "
              "scene scaled by its 99th luminance percentile, over pixels with input C*ab > 8 "
              f"and output C*ab > 4; worst image. Target <= {SHIFT_TARGET:g}° at levels >= "
              f"{SHIFT_MIN_LEVEL:g}.", "",
              md_table(head, [[op] + [_mark(*worst(results, op, L, "hue_shift_deg",
                                                   fmt="{:.1f}°"), SHIFT_TARGET + 1e-9)
                                      if L >= SHIFT_MIN_LEVEL else
                                      worst(results, op, L, "hue_shift_deg", fmt="{:.1f}°")[0]
                                      for L in levels] for op in ops]), ""]
    parts += _issue67_section(results, images, ops, levels)
    issue = [n for n in ISSUE_PHOTOS if n in results]
    if issue:
        parts += ["## The sunset, the sunrise and the tungsten interior", "",
                  "Per photograph, operator and level: clip (three channels at 255) / magenta "
                  "excess / warm turned cool / hue to the input; **bold** misses its target "
                  "(warm turned cool from "
                  f"{WARMCOOL_MIN_LEVEL:g}, hue from {SHIFT_MIN_LEVEL:g} cd/m²). Last column: "
                  "does the brightness rise with the level.", ""]
        for n in issue:
            r, info = results[n], images[n]
            parts += [f"### {n}: {info['kind']} (natural level ~{lvl(info['natural'])} cd/m²)"
                      if info.get("natural") else f"### {n}", "",
                      f"Source: {info['source']}. Light sources: {r['ref']['sources']:.1%} of the "
                      f"pixels; the hue-preserving rendering's own magenta share: "
                      f"{r['ref']['magenta_hue_preserving']:.1%}.", "",
                      md_table(head + ["brightness rises"],
                               [[op] + [_colour_cell(r["ops"][op]["levels"][lvl(L)], L)
                                        for L in levels]
                                + ["yes" if r["ops"][op]["brightness_increasing"] else "**no**"]
                                for op in ops]), ""]
    # timing
    t_rows = []
    for op in ops:
        ts = meta["times"].get(op, [])
        if ts:
            t_rows.append((op, len(ts), f"{statistics.median(ts) * 1e3:.0f}", f"{max(ts) * 1e3:.0f}",
                           f"{sum(ts):.1f}"))
    parts += ["## Timing", "",
              f"Benchmark run time {meta['run_time_s']:.0f} s in all (photos "
              f"{meta['photo_size']}, scenes {meta['scene_size']}; the time per frame includes "
              "the first-frame set-up of a fresh observer).", "",
              md_table(("operator", "frames", "median ms/frame", "max ms/frame", "total s"), t_rows),
              ""]
    # detail
    parts += ["## Per-image detail", ""]
    for n, r in results.items():
        parts += [f"<details><summary>{n}</summary>", "",
                  "Cells: clip / gradient reversal / Spearman / hue° to OCIO (levels >= 100) / "
                  "magenta excess, warm turned cool, hue to the input / scotopic "
                  "chroma ratio, neutral hue, magenta share (levels <= 0.01); last column: mean "
                  "output luminance per level (cd/m², light sources excluded).", ""]
        rows = []
        for op in ops:
            o = r["ops"][op]
            cells = []
            for L in levels:
                m = o["levels"][lvl(L)]
                if "error" in m:
                    cells.append("error: " + m["error"].replace("|", "/"))
                    continue
                c = f"{m['clip']:.1%} / {m['reversal']:.2%} / {m['spearman']:.3f}"
                if "hue_deg" in m:
                    c += f" / {m['hue_deg']:.1f}°"
                c += (f" / mag {m['magenta']:+.1%}, w>c {m['warm_cool']:.1%}, "
                      f"dh-in {m['hue_shift_deg']:.0f}°")
                s = m.get("scotopic")
                if s:
                    ratio = s["chroma"] / s["chroma_day"] if s["chroma_day"] > 0 else float("inf")
                    c += (f" / x{ratio:.2f}, {s['neutral_hue']:.0f}°, {s['magenta_share']:.1%}")
                cells.append(c)
            means = ", ".join(_fmt_cd(v) for v in o["brightness_means"])
            rows.append([op] + cells + [means + (" (rises)" if o["brightness_increasing"]
                                                 else " (**not increasing**)")])
        parts += [md_table(head + ["mean output cd/m²"], rows), "", "</details>", ""]
    return "\n".join(parts), verdict


def _issue67_section(results, images, ops, levels) -> list[str]:
    """Issue 67's table: per operator and level, the worst photograph's clipping (any
    channel at 255) and the lowest and highest saturation ratio, against the targets."""
    photos = {n: r for n, r in results.items() if images[n]["source"] != "generated"}
    if not photos:
        return []

    def vals(op, L, key):
        v = [(r["ops"][op]["levels"][lvl(L)].get(key), n) for n, r in photos.items()]
        return [(x, n) for x, n in v if x is not None and np.isfinite(x)]

    def b(text, bad):
        return f"**{text}**" if bad else text
    rows = []
    for op in ops:
        for L in levels:
            cl, sr = vals(op, L, "clip_any"), vals(op, L, "sat_ratio_adapted")
            raw = vals(op, L, "sat_ratio")
            if any("error" in r["ops"][op]["levels"][lvl(L)] for r in photos.values()):
                rows.append([op, lvl(L), "error", "-", "-", "-", "-"])
                continue
            rcell = (f"{min(raw)[0]:.2f} ({min(raw)[1]}) .. {max(raw)[0]:.2f} ({max(raw)[1]})"
                     if raw else "-")
            c = max(cl) if cl else None
            ccell = ("-" if c is None else "0.0%" if c[0] == 0 else
                     b(f"{c[0]:.2%} ({c[1]})", c[0] > CLIPANY_TARGET))
            on = L in SAT_LEVELS
            if sr:
                lo, hi = min(sr), max(sr)
                scell = (b(f"{lo[0]:.2f} ({lo[1]})", on and lo[0] < SAT_RANGE[0]) + " .. "
                         + b(f"{hi[0]:.2f} ({hi[1]})", on and hi[0] > SAT_RANGE[1]))
                med = f"{statistics.median(v for v, _ in sr):.2f}"
                ok = (c is None or c[0] <= CLIPANY_TARGET) and (
                    not on or (lo[0] >= SAT_RANGE[0] and hi[0] <= SAT_RANGE[1]))
            else:
                scell, med, ok = "-", "-", c is None or c[0] <= CLIPANY_TARGET
            rows.append([op, lvl(L), ccell, scell, med, rcell,
                         "PASS" if ok else "FAIL"])
    return ["## 7. Clipping (any channel) and saturation kept, photographs (issue 67)", "",
            f"Over the {len(photos)} photographs only (rendered at their true angle, "
            f"`fov_deg={PHOTO_FOV_DEG:g}`: 360-degree panoramas), light sources (scene Y > "
            f"{SOURCE_FACTOR:g}x the log-average) left out. **Clipping**: share of pixels "
            "with any channel at 8-bit code 255, worst photograph; target <= "
            f"{CLIPANY_TARGET:.0%}. **Saturation ratio**: median over coloured mid-tones "
            "(scene luminance 0.25-4x the log-average, scene s = 1 - min/max of linear RGB > "
            "0.15, output not clipped) of s_out / s_scene, s on linear light of the output and "
            "of the scene (a hue-preserving rendering at the same exposure: 1; "
            "`appearance_metrics.saturation_ratio`), the scene taken under the run's own "
            "von Kries gains (its chromatic adaptation's record): the objects' colours as the "
            "adapted observer sees them, not the illuminant's cast, which the eye discounts "
            "(docs/models.md, *Saturation*); lowest and highest photograph and the "
            "median over them; beside it the same against the scene as it is (the cast "
            "counted as colour: a bluish studio's 0.4x is its cast discounted), reported "
            f"only; target {SAT_RANGE[0]:g}-{SAT_RANGE[1]:g} at "
            + " and ".join(f"{lvl(L)}" for L in SAT_LEVELS) + " cd/m² (interior, daylight); "
            "other levels (dusk 1, night 0.01) reported only: lower there, as the rods take "
            "over (the verdict there is the clipping's). **Bold** misses its target.", "",
            md_table(("operator", "level cd/m²", f"clip any channel (<= {CLIPANY_TARGET:.0%})",
                      "saturation ratio lowest .. highest", "median",
                      "against the unadapted scene", "verdict"), rows), ""]


def _colour_cell(m, L):
    """clip / magenta excess / warm turned cool / hue to the input, misses in bold."""
    if "error" in m:
        return "error: " + m["error"].replace("|", "/")

    def b(text, bad):
        return f"**{text}**" if bad else text
    h = m["hue_shift_deg"]
    return " / ".join([
        b(f"{m['clip']:.1%}", m["clip"] >= CLIP_TARGET),
        b(f"{m['magenta']:+.1%}", m["magenta"] > MAGENTA_TARGET),
        b(f"{m['warm_cool']:.1%}", L >= WARMCOOL_MIN_LEVEL and m["warm_cool"] >= WARMCOOL_TARGET),
        "-" if not np.isfinite(h) else b(f"{h:.0f}°", L >= SHIFT_MIN_LEVEL and h > SHIFT_TARGET)])


def _order_cell(o, levels):
    """'yes', or where the mean output luminance drops (by > 0.1%) or stays flat
    (does not rise, drops by <= 0.1%)."""
    if o["brightness_increasing"]:
        return "yes"
    m, bad = o["brightness_means"], []
    for k in range(1, len(m)):
        if not (np.isfinite(m[k]) and np.isfinite(m[k - 1])):
            bad.append(f"error {lvl(levels[k - 1])}→{lvl(levels[k])}")
        elif m[k] < m[k - 1] * (1 - 1e-3):
            bad.append(f"drops {lvl(levels[k - 1])}→{lvl(levels[k])}")
        elif m[k] <= m[k - 1]:
            bad.append(f"flat {lvl(levels[k - 1])}→{lvl(levels[k])}")
    return "**NO**: " + ", ".join(bad)


def _fmt_cd(Y):
    return "nan" if not np.isfinite(Y) else f"{100 * Y:.3g}"


def _mark(cell, v, target, low=False):
    if v is None:
        return cell
    bad = v < target if low else v >= target
    return f"**{cell}**" if bad else cell


def _json_safe(o):
    if isinstance(o, dict):
        return {str(k): _json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_json_safe(v) for v in o]
    if isinstance(o, (np.floating, float)):
        return float(o) if math.isfinite(o) else None
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


# --- main ------------------------------------------------------------------------------

def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="6 images (the sunset and the tungsten interior among them), 256 px")
    ap.add_argument("--levels", help="comma list of scene log-averages in cd/m^2, or 'all' "
                    f"({', '.join(lvl(L) for L in ALL_LEVELS)}); default "
                    f"{', '.join(lvl(L) for L in LEVELS)}")
    ap.add_argument("--effects-off", action="store_true",
                    help="every effect off (the former setting: Tonemapper(op, "
                    "backend='opencl', display=sRGB, effects=EffectSettings())); default: "
                    "the operator's defaults, Tonemapper(op)")
    ap.add_argument("--operators", help="comma list (default: every operator in the registry)")
    ap.add_argument("--images", help="comma list of photos (rooitou_park, blender_sunrise, "
                    "...) and scenes (tunnel, patches, lamp)")
    ap.add_argument("--size", type=int, help="photo width in pixels (default 512, --quick 256)")
    add_out_args(ap)
    ap.add_argument("--out", metavar="SHEETS", help="folder of the contact sheets "
                    "(default: OUT-DIR/appearance)")
    ap.add_argument("--results", metavar="DIR", help="folder of appearance.md / "
                    "appearance.json (default: OUT-DIR)")
    ap.add_argument("--photos", help="photo cache folder (default $OCLTM_PHOTOS or "
                    "~/.cache/ocl-tonemap/photos)")
    ap.add_argument("--no-readme-sheet", action="store_true")
    a = ap.parse_args(argv)
    base = a.out_dir or DEFAULT_DIR
    a.results = a.results or base
    a.out = a.out or os.path.join(base, "appearance")
    t0 = time.perf_counter()
    warnings.filterwarnings("ignore", module="colour")
    code = provenance()

    from ocl_tonemap.operators import registry
    REGISTRY = registry()
    ops = [o.strip() for o in a.operators.split(",")] if a.operators else list(REGISTRY)
    bad = [o for o in ops if o not in REGISTRY]
    if bad:
        print(f"appearance ERROR: unknown operator(s) {', '.join(bad)}; available: "
              f"{', '.join(REGISTRY)}", file=sys.stderr)
        return 2
    try:
        levels = (ALL_LEVELS if a.levels == "all" else
                  sorted(float(x) for x in a.levels.split(",")) if a.levels else LEVELS)
    except ValueError:
        print(f"appearance ERROR: bad --levels {a.levels!r}", file=sys.stderr)
        return 2
    size = a.size or (256 if a.quick else 512)
    names = [short(n.strip()) for n in (a.images.split(",") if a.images else
                                        (QUICK_IMAGES if a.quick else DEFAULT_IMAGES))]
    photo_stems = {short(k): k for k in ALL_PHOTOS}
    want = {photo_stems[n] for n in names if n in photo_stems}
    if not a.no_readme_sheet:
        want |= {photo_stems[n] for n, _, _ in README_SHEET}
    try:
        paths = ph.fetch_photos(a.photos, names=sorted(want))
    except ph.PhotoFetchError as e:
        print(f"appearance ERROR: {e}", file=sys.stderr)
        return 2
    try:
        images = resolve_images(names, paths, size)
    except (ValueError, RuntimeError) as e:
        print(f"appearance ERROR: {e}", file=sys.stderr)
        return 2
    os.makedirs(a.out, exist_ok=True)
    os.makedirs(a.results, exist_ok=True)

    from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime
    try:
        opencl = describe_device(get_runtime().device)
    except Exception as e:  # noqa: BLE001
        print(f"appearance ERROR: no OpenCL device: {e}", file=sys.stderr)
        return 2
    R = Runner(effects_off=a.effects_off)
    print(f"appearance: {len(images)} images x {len(ops)} operators x {len(levels)} levels; "
          f"OpenCL {opencl}", flush=True)
    print(f"  {'image':20s} {'operator':12s} clipping at " + " ".join(f"{lvl(L):>5s}" for L in levels))
    results, sheets = {}, []
    for n, info in images.items():
        res, tiles = run_image(R, n, info, ops, levels)
        results[n] = res
        p = os.path.join(a.out, f"{n}.png")
        contact_sheet(p, n, info, tiles, res, ops, levels,
                      "effects off" if a.effects_off else "operator defaults")
        sheets.append(p)
    if not a.no_readme_sheet:
        photos_rgb = {n: (images[n]["rgb"] if n in images else None) for n, _, _ in README_SHEET}
        by_stem = {short(p.stem): p for p in paths}
        for n in photos_rgb:
            if photos_rgb[n] is None and n in by_stem:
                photos_rgb[n] = load_photo(by_stem[n], size)
        photos_rgb = {k: v for k, v in photos_rgb.items() if v is not None}
        p = os.path.join(a.out, "readme_sheet.png")
        readme_sheet(p, R, photos_rgb, ops)
        sheets.append(p)

    run_time = time.perf_counter() - t0
    cmd = "python -m benchmarks.appearance" + ("" if not argv and len(sys.argv) <= 1
                                               else " " + " ".join(argv if argv else sys.argv[1:]))
    scene_sizes = {f"{i['rgb'].shape[1]}x{i['rgb'].shape[0]}" for i in images.values()
                   if i["source"] == "generated"}
    photo_sizes = {f"{i['rgb'].shape[1]}x{i['rgb'].shape[0]}" for i in images.values()
                   if i["source"] != "generated"}
    meta = {
        "command": cmd, "date": time.strftime("%Y-%m-%d %H:%M"),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
                   f"{platform.system()} {platform.release()}, Python {platform.python_version()}",
        "opencl": opencl, "code": code, "run_time_s": run_time, "times": R.times,
        "call": R.call("op"),
        "effects": ("every effect off" if a.effects_off else "the operator's default effects: "
                    + "; ".join(f"{op} " + ", ".join(f"{k} {v}" for k, v in e.items())
                                for op, e in R.effects_seen.items())),
        "sheets_dir": repo_relative(a.out),
        "photo_size": ", ".join(sorted(photo_sizes)) or "-",
        "scene_size": ", ".join(sorted(scene_sizes)) or "-",
    }
    md, verdict = report(results, images, ops, levels, meta)
    md_path = os.path.join(a.results, "appearance.md")
    with open(md_path, "w") as fh:
        fh.write(md + "\n")
    js = {"meta": {k: v for k, v in meta.items() if k != "times"},
          "timing_s": R.times, "levels": levels, "operators": ops,
          "images": {n: {"kind": i["kind"], "natural_level": i.get("natural"),
                         "source": i["source"], "size": list(i["rgb"].shape[:2])}
                     for n, i in images.items()},
          "targets": {"clip": CLIP_TARGET, "hue_deg": HUE_TARGET, "reversal": REV_TARGET,
                      "spearman_local": RHO_TARGET, "magenta": MAGENTA_TARGET,
                      "warm_cool": WARMCOOL_TARGET, "warm_cool_min_level": WARMCOOL_MIN_LEVEL,
                      "hue_shift_deg": SHIFT_TARGET, "hue_shift_min_level": SHIFT_MIN_LEVEL,
                      "clip_any_photos": CLIPANY_TARGET, "sat_ratio": list(SAT_RANGE),
                      "sat_ratio_levels": list(SAT_LEVELS)},
          "verdict": verdict, "results": results}
    js_path = os.path.join(a.results, "appearance.json")
    with open(js_path, "w") as fh:
        json.dump(_json_safe(js), fh, indent=1)
    print(f"\nappearance: {run_time:.0f} s; wrote {md_path}, {js_path} and "
          f"{len(sheets)} sheets in {a.out}")
    for op, v in verdict.items():
        print(f"  {op:12s} " + "; ".join(f"{k}: {x}" for k, x in v.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
