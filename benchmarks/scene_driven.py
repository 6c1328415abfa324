"""Scene-driven modelling: ``--model auto`` (the per-frame mechanism plan) against
``--model full`` (every effect on), per operator, scene and size.

One command:
    python -m benchmarks.scene_driven [--quick] [--sizes 640x360,1920x1080]
        [--operators pattanaik00,ledda04,durand00,kirk11] [--out-dir DIR | --out FILE]
Writes the Markdown report scene_driven.md and a .json of the raw numbers beside it
into DIR (default ./benchmark-results; the committed ones: --out-dir benchmarks/results).

The set:

* generated scenes (``benchmarks/lib/scenes.py``, made at the size under test) at
  natural log-average levels: daylight (``sky_sun``, 5000 cd/m^2), interior
  (``patches``, ``log_noise``: 30), dusk (``sky_gradient``, ``lamp``: 1), night
  (``night_street_lamps``, ``night_street_windows``: 0.01), the tunnel (a frame of
  the built-in drive at t = 1.2 s, the approach in sun, in its own cd/m^2);
* the photographs of ``benchmarks/lib/photos.py`` (:data:`PHOTOS`, the
  blender_sunrise and blender_interior entries included) at their natural levels,
  centre-cropped to 16:9 and resized by ``load_photo`` (box down, triangle up);
* two sequences at 30 fps (dt = 1/30 s), both models run over the whole sequence
  and compared frame by frame: a day-to-night fade (one scene, its log-average
  going from 1e4 to 1e-3 cd/m^2 geometrically) and the tunnel drive across the
  entrance (``ocl_tonemap.io.sample.render_frame``; 2x2 supersampled up to 640x360,
  1x1 above: the 1080p frames cost 3 s each otherwise).

Per operator x scene x size (stills): a fresh ``Tonemapper`` per model (backend
default: OpenCL here), one warm-up frame each (kernel builds; the observer fully
adapted to it), then 3 timed ``process_frame`` calls per model (dt = 1/30, the state
does not move on a still), auto and full alternating; the median wall time each;
the p99 Delta E ITP (BT.2124, ``mechanisms.predict.frame_delta_e``) between the
two outputs of the last frame; the plan's weights, targets and predictions; the
effects that ran (``info.effects[..]["ran"]``) under each model; and the host wall
time spent in the plan (``MechanismPlan.frame``: analysis and predictions) and in
each effect's call (flare, Purkinje, acuity; instance wrappers, nothing in the
package changed; a device effect's kernels may be counted in the later stage that
waits for them).

Targets (the issue): p99 Delta E ITP <= 1 between auto and full on every frame of
the set, every operator; in daylight auto leaves at least two mechanisms out
(plan weight 0); at night acuity and the Purkinje shift are in (plan weight > 0);
the time saved per operator reported, and where auto skips a mechanism that full
runs, auto must be faster. The fade: each weight switches at most once and never
moves by more than 0.5 between frames. Machines are noisy: compare ratios.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import shlex
import statistics
import subprocess
import sys
import time
from collections import defaultdict

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import fmt_de, fmt_ms
from benchmarks.lib import photos as ph
from benchmarks.lib import scenes
from benchmarks.lib.timing import table

HERE = os.path.dirname(os.path.abspath(__file__))
MODELS = ("auto", "full")
REPS = 3
DT = 1.0 / 30.0
DE_TARGET = 1.0
MAX_STEP = 0.5
DAY_MIN_OUT = 2
#: Natural log-average levels, cd/m^2 (README "Calibration and colour").
LEVELS = {"daylight": 5000.0, "interior": 30.0, "dusk": 1.0, "night": 0.01}
GATED = ("flare", "purkinje", "acuity")
#: effect name in info.effects -> plan mechanism
EFFECT_MECH = {"flare": "flare", "purkinje": "purkinje", "acuity": "acuity",
               "chromatic_adaptation": "chromatic-adaptation"}


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --- the scenes -------------------------------------------------------------------------

def tunnel_frame(w: int, h: int, t: float, seconds: float = 8.0) -> np.ndarray:
    """A frame of the tunnel drive, cd/m^2 (``scenes.tunnel``; 1x1 samples above
    640x360, where the 2x2 supersampled ray cast takes seconds a frame)."""
    if w * h <= 640 * 360:
        return scenes.tunnel(w, h, t, seconds)
    from ocl_tonemap.io.sample import render_frame
    return render_frame(t, w, h, seconds, ss=1).astype(np.float32)


#: Generated stills: name -> (class, function (w, h) -> rgb, level or None (as made), what)
GENERATED = {
    "daylight_sky_sun": ("daylight", scenes.sky_sun, LEVELS["daylight"],
                         "sky gradient, sun disc, textured ground"),
    "interior_patches": ("interior", scenes.patches, LEVELS["interior"],
                         "ColorChecker patches x log-normal texture"),
    "interior_log_noise": ("interior", scenes.log_noise, LEVELS["interior"],
                           "white noise over 9 decades"),
    "dusk_sky_gradient": ("dusk", scenes.sky_gradient, LEVELS["dusk"],
                          "five decades bright sky to dark ground"),
    "dusk_lamp": ("dusk", scenes.lamp, LEVELS["dusk"], "bright lamp on a dark wall"),
    "night_street_lamps": ("night", scenes.night_street_lamps, LEVELS["night"],
                           "street lamps, traffic lights, headlights"),
    "night_street_windows": ("night", scenes.night_street_windows, LEVELS["night"],
                             "dark street, lit windows, lamps"),
    "tunnel_approach": ("tunnel", lambda w, h: tunnel_frame(w, h, 1.2), None,
                        "tunnel drive t=1.2 s: sunlit road, dark mouth (own cd/m^2)"),
}
QUICK_GENERATED = ("daylight_sky_sun", "interior_patches", "dusk_sky_gradient",
                   "night_street_lamps", "night_street_windows", "tunnel_approach")
QUICK_PHOTOS = ("rooitou_park_1k", "blender_interior", "dikhololo_night_1k")


def class_of(what: str, L: float) -> str:
    """A photograph's class from its description in PHOTOS (else its level)."""
    for word, cls in (("night", "night"), ("sunrise", "sunrise"), ("sunset", "dusk"),
                      ("dawn", "dusk"), ("interior", "interior"), ("daylight", "daylight")):
        if word in what:
            return cls
    return "daylight" if L >= 1000 else "night" if L <= 0.1 else \
        "interior" if L >= 20 else "dusk"


def log_average(rgb) -> float:
    from ocl_tonemap.colour.calibration import log_average as la
    v = la(rgb)
    if not v:
        raise ValueError("image has no light")
    return float(v)


def at_level(rgb: np.ndarray, L: float | None) -> np.ndarray:
    if L is None:
        return np.ascontiguousarray(rgb, np.float32)
    return np.ascontiguousarray(rgb * np.float32(L / log_average(rgb)), np.float32)


class Stills:
    """The stills of the run: name -> dict(kind, cls, level, source, make(w, h))."""

    def __init__(self, quick: bool, photo_dir=None, only=None):
        self.items = {}
        gen = QUICK_GENERATED if quick else tuple(GENERATED)
        for n in gen:
            cls, fn, L, what = GENERATED[n]
            self.items[n] = dict(cls=cls, level=L, kind=what, source="generated",
                                 make=(lambda w, h, fn=fn, L=L: at_level(fn(w, h), L)))
        want = QUICK_PHOTOS if quick else tuple(ph.PHOTOS)
        self.note = ""
        try:
            paths = {p.stem: p for p in ph.fetch_photos(photo_dir, names=list(want))}
        except ph.PhotoFetchError as e:
            self.note = f"photographs left out: {e}"
            log("photos: " + self.note)
            paths = {}
        for stem in want:
            if stem not in paths:
                continue
            what, L = ph.PHOTOS[stem]
            self.items[stem] = dict(
                cls=class_of(what, L), level=L, kind="photo: " + what, source=ph.source_of(stem),
                make=(lambda w, h, p=paths[stem], L=L: at_level(ph.load_photo(p, w, h), L)))
        if only:
            self.items = {k: v for k, v in self.items.items() if k in only}


# --- measuring --------------------------------------------------------------------------

class Clock:
    """Host wall time spent in some methods of one Tonemapper (instance wrappers)."""

    def __init__(self, tm):
        self.t = defaultdict(float)
        self._wrap(tm.plan, "frame", "plan")
        for k in GATED:
            self._wrap(tm.effects, k, k)

    def _wrap(self, obj, name, key):
        f = getattr(obj, name)

        def g(*a, **kw):
            t0 = time.perf_counter()
            try:
                return f(*a, **kw)
            finally:
                self.t[key] += time.perf_counter() - t0
        setattr(obj, name, g)

    def take(self) -> dict:
        out = {k: round(v, 6) for k, v in self.t.items()}
        self.t.clear()
        return out


def make_tm(op: str, model: str):
    from ocl_tonemap.pipeline import Tonemapper
    tm = Tonemapper(op, model=model)
    return tm, Clock(tm)


def ran_effects(info) -> list[str]:
    return [EFFECT_MECH.get(k, k) for k, v in (info.effects or {}).items()
            if isinstance(v, dict) and v.get("ran")]


def frame_record(res, t: float, parts: dict, analysis: bool = False) -> dict:
    plan = res.info.plan or {}
    rec = {"t": t, "parts": parts, "ran": ran_effects(res.info),
           "weights": dict(plan.get("weights") or {}), "target": dict(plan.get("target") or {}),
           "predicted": dict(plan.get("predicted_dE_p99") or {}),
           "G_rod": float(res.info.G_rod), "G_cone": float(res.info.G_cone)}
    pk = (res.info.effects or {}).get("purkinje") or {}
    if "A_rod" in pk:            # the shift's own receptor levels (its time course)
        rec["purkinje"] = {k: float(pk[k]) for k in ("A_rod", "rod_gain", "rod_sensitivity")
                           if k in pk}
    if analysis and plan.get("analysis"):
        rec["analysis"] = plan["analysis"]
    return rec


def skipped(weights: dict) -> list[str]:
    return [m for m, w in weights.items() if w == 0.0]


def run_still(op: str, img: np.ndarray, reps: int = REPS) -> dict:
    from ocl_tonemap.mechanisms.predict import frame_delta_e
    tms = {m: make_tm(op, m) for m in MODELS}
    first = {}
    cold = {}
    for m, (tm, clock) in tms.items():       # warm-up: kernel builds, the observer adapts
        r = tm.process_frame(img, dt=DT)
        first[m] = r.output
        cold[m] = clock.take().get("plan", 0.0)   # the first frame's plan: made, not reused
    times = {m: [] for m in MODELS}
    parts = {m: [] for m in MODELS}
    last = {}
    for i in range(reps):
        for m in (MODELS if i % 2 == 0 else MODELS[::-1]):
            tm, clock = tms[m]
            t0 = time.perf_counter()
            r = tm.process_frame(img, dt=DT)
            times[m].append(time.perf_counter() - t0)
            parts[m].append(clock.take())
            last[m] = r
    display = tms["auto"][0].display
    de = frame_delta_e(last["auto"].output, last["full"].output, display)
    de_first = frame_delta_e(first["auto"], first["full"], display)
    rec = {"de_p99": de, "de_p99_first_frame": de_first}
    for m in MODELS:
        fr = frame_record(last[m], statistics.median(times[m]),
                          {k: statistics.median(p.get(k, 0.0) for p in parts[m])
                           for k in ("plan",) + GATED}, analysis=(m == "auto"))
        fr["times"] = times[m]
        fr["plan_first"] = cold[m]
        rec[m] = fr
    rec["ratio"] = rec["auto"]["t"] / rec["full"]["t"]
    return rec


def run_sequence(op: str, frames, dt: float = DT) -> dict:
    """Both models over the frames (a callable i -> rgb, and a count), timed frame by
    frame, auto and full alternating first; per frame the p99 Delta E and the plan."""
    from ocl_tonemap.mechanisms.predict import frame_delta_e
    get, n = frames
    f0 = get(0)
    for m in MODELS:                                     # warm-up on a throwaway observer
        make_tm(op, m)[0].process_frame(f0, dt=dt)
    tms = {m: make_tm(op, m) for m in MODELS}
    out = {"de_p99": [], "auto": [], "full": []}
    for i in range(n):
        img = f0 if i == 0 else get(i)
        res = {}
        for m in (MODELS if i % 2 == 0 else MODELS[::-1]):
            tm, clock = tms[m]
            t0 = time.perf_counter()
            res[m] = tm.process_frame(img, dt=dt)
            t = time.perf_counter() - t0
            out[m].append(frame_record(res[m], t, clock.take()))
        out["de_p99"].append(frame_delta_e(res["auto"].output, res["full"].output,
                                           tms["auto"][0].display))
    return out


#: Weight changes below this are rounding (the plan keeps 6 decimals).
W_TOL = 1e-4


def switches(ws) -> int:
    """How many times a weight starts moving in a new direction (a ramp 0 -> 1 over
    several frames is one switch; on and off again is two)."""
    n, last = 0, 0
    for a, b in zip(ws, ws[1:]):
        d = (b > a + W_TOL) - (b < a - W_TOL)
        if d and d != last:
            n, last = n + 1, d
    return n


def weight_track(frames: list[dict]) -> dict:
    """mechanism -> {switches, max_step, changes [(frame, weight)], first, last}."""
    mechs = sorted({m for f in frames for m in f["weights"]},
                   key=lambda m: (GATED + ("rods", "chromatic-adaptation", "local",
                                           "temporal")).index(m)
                   if m in GATED + ("rods", "chromatic-adaptation", "local", "temporal") else 99)
    out = {}
    for m in mechs:
        ws = [float(f["weights"].get(m, float("nan"))) for f in frames]
        steps = [abs(b - a) for a, b in zip(ws, ws[1:]) if math.isfinite(a) and math.isfinite(b)]
        out[m] = {"switches": switches(ws), "max_step": max(steps, default=0.0),
                  "changes": [(i, ws[i]) for i in range(1, len(ws))
                              if abs(ws[i] - ws[i - 1]) > W_TOL],
                  "first": ws[0] if ws else None, "last": ws[-1] if ws else None}
    return out


# --- sequences --------------------------------------------------------------------------

def fade_frames(base: np.ndarray, n: int, L0: float = 1e4, L1: float = 1e-3):
    la = log_average(base)
    levels = [L0 * (L1 / L0) ** (i / max(1, n - 1)) for i in range(n)]
    return (lambda i: np.ascontiguousarray(base * np.float32(levels[i] / la), np.float32), n), \
        levels


def tunnel_frames(w: int, h: int, n: int, t0: float):
    cache = {}

    def get(i):
        if i not in cache:
            cache[i] = tunnel_frame(w, h, t0 + i * DT)
        return cache[i]
    return (get, n), cache


# --- report -----------------------------------------------------------------------------

def fmt_level(L) -> str:
    return "as made" if L is None else f"{L:g}"


def short_mech(ms) -> str:
    ab = {"flare": "flare", "purkinje": "Purkinje", "acuity": "acuity",
          "chromatic-adaptation": "chroma"}
    return ", ".join(ab.get(m, m) for m in ms) or "—"


def git(*args) -> str | None:
    try:
        r = subprocess.run(["git", "--no-optional-locks", *args], cwd=os.path.join(HERE, ".."),
                           capture_output=True, text=True, timeout=30)
        return r.stdout.strip() if r.returncode == 0 else None
    except (OSError, subprocess.TimeoutExpired):
        return None


def provenance() -> str:
    head = git("rev-parse", "--short", "HEAD") or "unknown"
    branch = git("rev-parse", "--abbrev-ref", "HEAD") or "?"
    dirty = git("status", "--porcelain", "--", "ocl_tonemap", "kernels") or ""
    mods = [ln[3:] for ln in dirty.splitlines() if ln.strip()]
    return f"git {head} (branch {branch})" + \
        (f" + uncommitted changes in {', '.join(mods)}" if mods else "; ocl_tonemap/ clean")


def still_targets(op: str, size: str, name: str, item: dict, rec: dict) -> dict:
    """The per-still checks: Delta E, daylight out, night in, time shows the skip."""
    a, f = rec["auto"], rec["full"]
    out = {"de": rec["de_p99"] <= DE_TARGET}
    if item["cls"] == "daylight":
        out["day_out"] = len(skipped(a["weights"])) >= DAY_MIN_OUT
    if item["cls"] == "night":
        out["night_in"] = all(a["weights"].get(m, 0.0) > 0 for m in ("acuity", "purkinje"))
    saved = [m for m in GATED if m in f["ran"] and m not in a["ran"]]
    if saved:
        out["time_shows"] = rec["ratio"] < 1.0
    return out


def why(key: str, r: dict) -> str:
    """A failed still check in words."""
    a, f = r["auto"], r["full"]
    if key == "de":
        out = skipped(a["weights"])
        return (f"p99 {r['de_p99']:.2f}; out {short_mech(out)}, predicted "
                f"{sum(a['predicted'].get(m, 0.0) for m in out):.2f}")
    if key == "day_out":
        return (f"out: {short_mech(skipped(a['weights']))}; offered to the plan: "
                f"{short_mech(a['predicted'])}")
    if key == "night_in":
        return "; ".join(f"{m} out (predicted {a['predicted'].get(m, 0.0):.2g}; full "
                         f"{'runs' if m in f['ran'] else 'does not run'} it)"
                         for m in ("acuity", "purkinje") if a["weights"].get(m, 0.0) <= 0)
    if key == "time_shows":
        saved = [m for m in GATED if m in f["ran"] and m not in a["ran"]]
        return (f"auto/full {r['ratio']:.2f}; skips {short_mech(saved)} worth "
                f"{sum(f['parts'].get(m, 0.0) for m in saved) * 1e3:.1f} ms, plan "
                f"{a['parts'].get('plan', 0.0) * 1e3:.1f} ms")
    return ""


def summarise(results: dict, ops, sizes) -> dict:
    """Per operator (and size): totals, worst Delta E, target verdicts with where."""
    summ = {}
    for op in ops:
        rows = {}
        for size in sizes + ["all"]:
            sz = sizes if size == "all" else [size]
            st = [(s, n, r) for s in sz for n, r in results["stills"].get(op, {}).get(s, {}).items()]
            sq = [(s, n, r) for s in sz for n, r in results["sequences"].get(op, {}).get(s, {}).items()]
            ta = sum(r["auto"]["t"] for _, _, r in st)
            tf = sum(r["full"]["t"] for _, _, r in st)
            qa = sum(x["t"] for _, _, r in sq for x in r["auto"])
            qf = sum(x["t"] for _, _, r in sq for x in r["full"])
            worst = (-1.0, None)
            for s, n, r in st:
                worst = max(worst, (r["de_p99"], f"{n} @ {s}"))
            for s, n, r in sq:
                i = int(np.argmax(r["de_p99"]))
                worst = max(worst, (r["de_p99"][i], f"{n} frame {i} @ {s}"))
            fails = defaultdict(list)
            checked = defaultdict(int)
            for s, n, r in st:
                for k, ok in r["targets"].items():
                    checked[k] += 1
                    if not ok:
                        fails[k].append(f"{n} @ {s} ({why(k, r)})")
            for s, n, r in sq:
                checked["de"] += 1
                bad = [i for i, d in enumerate(r["de_p99"]) if d > DE_TARGET]
                if bad:
                    fails["de"].append(f"{n} @ {s} frames {bad[0]}..{bad[-1]} ({len(bad)})")
                if n == "fade":
                    checked["fade_smooth"] += 1
                    badw = [f"{m}: {t['switches']} switches, max step {t['max_step']:.2f}"
                            for m, t in r["track"].items()
                            if t["switches"] > 1 or t["max_step"] > MAX_STEP + 1e-9]
                    if badw:
                        fails["fade_smooth"].append(f"@ {s}: " + "; ".join(badw))
            plan_a = [r["auto"]["parts"].get("plan", 0.0) for _, _, r in st]
            plan_f = [r["full"]["parts"].get("plan", 0.0) for _, _, r in st]
            plan_1 = [r["auto"].get("plan_first", 0.0) for _, _, r in st]
            plan_q = [x["parts"].get("plan", 0.0) for _, _, r in sq for x in r["auto"][1:]]
            rows[size] = {"plan_auto_ms": 1e3 * statistics.median(plan_a) if plan_a else None,
                          "plan_first_ms": 1e3 * statistics.median(plan_1) if plan_1 else None,
                          "plan_seq_ms": 1e3 * statistics.median(plan_q) if plan_q else None,
                          "plan_full_ms": 1e3 * statistics.median(plan_f) if plan_f else None,
                          "stills_auto_s": ta, "stills_full_s": tf,
                          "stills_ratio": ta / tf if tf else None,
                          "seq_auto_s": qa, "seq_full_s": qf, "seq_ratio": qa / qf if qf else None,
                          "total_ratio": (ta + qa) / (tf + qf) if tf + qf else None,
                          "worst_de": worst[0], "worst_de_where": worst[1],
                          "checked": dict(checked), "fails": {k: v for k, v in fails.items()}}
        summ[op] = rows
    return summ


TARGET_NAMES = {"de": "p99 ΔE ≤ 1 every frame", "day_out": "daylight: ≥ 2 out",
                "night_in": "night: acuity + Purkinje in",
                "time_shows": "skip shows in time", "fade_smooth": "fade: ≤ 1 switch, step ≤ 0.5"}

CHECK_SHORT = {"de": "ΔE > 1", "day_out": "< 2 out", "night_in": "acuity/Purkinje out",
               "time_shows": "skip not faster", "fade_smooth": "weights jump"}


def verdict(row: dict, key: str) -> str:
    n = row["checked"].get(key, 0)
    if not n:
        return "n/a"
    bad = row["fails"].get(key, [])
    return "PASS" if not bad else f"FAIL {len(bad)}/{n}"


def report(results: dict, meta: dict, stills: Stills, ops, sizes) -> str:
    summ = results["summary"]
    L = ["# Scene-driven modelling: `--model auto` against `--model full`", "",
         f"- device: {meta['device']}",
         f"- host: {meta['host']}",
         f"- date: {meta['date']}",
         f"- code: {meta['commit']}",
         f"- command: `{meta['command']}`"
         + (f" (this report re-rendered from the .json by {meta['rendered_by']})"
            if meta.get("rendered_by") else ""),
         f"- took {meta['minutes']:.1f} min",
         "- **machines are noisy (2 CPU cores shared by the host and PoCL's threads): compare "
         "the ratios auto/full, not absolute times.**", ""]
    L += ["## Summary", "",
          "Time: the sum over the stills of each one's median ms/frame, and over the "
          "sequences of every frame's time. ΔE: p99 ΔE ITP between the two models' "
          "outputs (BT.2124, the display's light), the worst frame of the set.", ""]
    rows = []
    for op in ops:
        for size in sizes + (["all"] if len(sizes) > 1 else []):
            r = summ[op][size]
            rows.append((f"**{op}**" if size == sizes[0] else "", size,
                         f"{r['stills_auto_s']:.2f}", f"{r['stills_full_s']:.2f}",
                         f"{r['stills_ratio']:.3f}" if r["stills_ratio"] else "—",
                         f"{r['seq_auto_s']:.1f}", f"{r['seq_full_s']:.1f}",
                         f"{r['seq_ratio']:.3f}" if r["seq_ratio"] else "—",
                         fmt_de(r["worst_de"]), r["worst_de_where"] or "—",
                         "—" if r.get("plan_auto_ms") is None else
                         f"{r.get('plan_first_ms') or 0:.1f} / {r['plan_auto_ms']:.1f} / "
                         f"{r.get('plan_seq_ms') or 0:.1f} / {r['plan_full_ms']:.1f}"))
    L += [table(("operator", "size", "stills auto s", "stills full s", "auto/full",
                 "sequences auto s", "sequences full s", "auto/full", "worst p99 ΔE", "where",
                 "plan ms/frame auto: first / held / moving; full"), rows), ""]
    L += ["*plan ms/frame*: host time in `MechanismPlan.frame`, medians: auto on a still's "
          "first frame (analysis and predictions made), on its timed frames (the same frame "
          "held: the predictions reused, `planner.reusable`), on the sequences' frames "
          "(moving: made again wherever the frame's signature moved); full: the analysis "
          "only, which it makes too. The price auto pays for what it may skip.", ""]
    L += ["### Targets", ""]
    rows = []
    for op in ops:
        r = summ[op]["all" if len(sizes) > 1 else sizes[0]]
        rows.append((op,) + tuple(verdict(r, k) for k in TARGET_NAMES))
    L += [table(("operator",) + tuple(TARGET_NAMES.values()), rows), ""]
    fl = []
    for op in ops:
        r = summ[op]["all" if len(sizes) > 1 else sizes[0]]
        for k, where in r["fails"].items():
            fl.append(f"- {op}, {TARGET_NAMES[k]}: " + "; ".join(where))
    L += (["Failures:", ""] + fl + [""]) if fl else ["Every target passes.", ""]
    L += ["Checks: *daylight* stills (sky_sun, the daylight photograph) count the plan's "
          "weights at 0; *night* stills (the two night streets and the night photograph) "
          "need weight > 0 for acuity and the Purkinje shift (kirk11 models the shift "
          "itself: its weight is always 1); *skip shows in time*: on every still where "
          "auto skips a gated mechanism (flare, Purkinje, acuity) that full runs "
          "(`info.effects[..]['ran']`), auto's median time must be below full's.", ""]

    # per-size stills tables
    L += ["## Stills", "",
          "Columns: median ms/frame of 3 (auto, full); p99 ΔE ITP between their outputs; "
          "*out*: the plan's mechanisms at weight 0 under auto; *ran*: the effects that ran "
          "(`info.effects`); *pred*: the plan's predicted p99 ΔE of what it skipped (sum, "
          "before the ×3 safety factor); *plan ms*: host time in `MechanismPlan.frame` "
          "(auto: analysis + predictions; full: analysis only); *skip saves*: full's host "
          "time in the effects auto skipped (device work of an effect can be counted later, "
          "in the stage that waits for it).", ""]
    for size in sizes:
        L += [f"### {size}", ""]
        for op in ops:
            rs = results["stills"].get(op, {}).get(size, {})
            rows = []
            for n, r in rs.items():
                it = stills.items[n]
                a, f = r["auto"], r["full"]
                out = skipped(a["weights"])
                pred = sum(a["predicted"].get(m, 0.0) for m in out)
                saves = sum(f["parts"].get(m, 0.0) for m in GATED
                            if m in f["ran"] and m not in a["ran"])
                flag = ", ".join(CHECK_SHORT[k] for k, ok in r["targets"].items() if not ok)
                rows.append((n, it["cls"], fmt_level(it["level"]), fmt_ms(a["t"]),
                             fmt_ms(f["t"]), f"{r['ratio']:.2f}", fmt_de(r["de_p99"]),
                             short_mech(out), short_mech(a["ran"]), short_mech(f["ran"]),
                             fmt_de(pred), f"{a['parts'].get('plan', 0) * 1e3:.1f} / "
                             f"{f['parts'].get('plan', 0) * 1e3:.1f}", fmt_ms(saves), flag or "ok"))
            if rows:
                L += [f"**{op}**", "",
                      table(("scene", "class", "level cd/m²", "auto ms", "full ms", "auto/full",
                             "p99 ΔE", "out (auto)", "ran (auto)", "ran (full)", "pred ΔE",
                             "plan ms auto/full", "skip saves ms", "fails"), rows), ""]

    # sequences
    L += ["## Sequences", ""]
    seqm = results["meta"]["sequences"]
    L += [f"- **fade**: {seqm['fade']['scene']} ({seqm['fade']['what']}), {seqm['fade']['frames']} "
          f"frames at 30 fps, log-average {seqm['fade']['from']:g} → {seqm['fade']['to']:g} "
          "cd/m² geometrically; both models from a fresh observer (adapted to the first "
          "frame), dt = 1/30 s.",
          f"- **tunnel**: the built-in drive ({seqm['tunnel']['seconds']:g} s, entrance at "
          f"{0.3 * seqm['tunnel']['seconds']:.1f} s), {seqm['tunnel']['frames']} frames at 30 fps "
          f"from t = {seqm['tunnel']['t0']:g} s, cd/m² as rendered.",
          "- *switches*: how often a weight starts to move in a new direction (a ramp 0 → 1 "
          "is one); *max step*: its largest change between frames.", ""]
    rows = []
    for op in ops:
        for size in sizes:
            for n, r in results["sequences"].get(op, {}).get(size, {}).items():
                ta = sum(x["t"] for x in r["auto"])
                tf = sum(x["t"] for x in r["full"])
                i = int(np.argmax(r["de_p99"]))
                tr = r["track"]
                sw = ", ".join(f"{short_mech([m])} {t['switches']}/{t['max_step']:.2f}"
                               for m, t in tr.items() if m in GATED)
                nout = [len(skipped(x["weights"])) for x in r["auto"]]
                rows.append((op, size, n, f"{ta:.2f}", f"{tf:.2f}", f"{ta / tf:.3f}",
                             fmt_de(r["de_p99"][i]), str(i),
                             str(sum(d > DE_TARGET for d in r["de_p99"])), sw,
                             f"{np.mean(nout):.2f}"))
    L += [table(("operator", "size", "sequence", "auto s", "full s", "auto/full",
                 "worst p99 ΔE", "at frame", "frames > 1", "switches / max step",
                 "mean # out"), rows), ""]
    rows = []
    for op in ops:
        for size in sizes:
            for n, r in results["sequences"].get(op, {}).get(size, {}).items():
                bad = [i for i, d in enumerate(r["de_p99"]) if d > DE_TARGET]
                if not bad:
                    continue
                i = int(np.argmax(r["de_p99"]))
                a, f = r["auto"][i], r["full"][i]
                pa, pf = a.get("purkinje", {}), f.get("purkinje", {})

                def pk(p, k):
                    return f"{p[k]:.3g}" if k in p else "—"
                rows.append((op, size, n, f"{bad[0]}–{bad[-1]} ({len(bad)})", str(i),
                             fmt_de(r["de_p99"][i]),
                             ", ".join(f"{short_mech([m])} {w:.2f}" for m, w in a["weights"].items()
                                       if m in GATED),
                             f"{sum(a['predicted'].get(m, 0.0) * (1 - a['weights'].get(m, 1.0)) for m in GATED):.2f}",
                             f"{pk(pa, 'A_rod')} / {pk(pf, 'A_rod')}",
                             f"{pk(pa, 'rod_gain')} / {pk(pf, 'rod_gain')}",
                             f"{pk(pa, 'rod_sensitivity')} / {pk(pf, 'rod_sensitivity')}"))
    if rows:
        L += ["### Sequence frames over 1 JND", "",
              "At the worst frame: auto's gated weights, the predicted ΔE of what it leaves "
              "out (Σ prediction × (1 − weight)), and the Purkinje shift's own receptor "
              "state (`info.effects['purkinje']`: adapted rod level A_rod cd/m², rod gain, "
              "rods' sensitivity), auto / full.", "",
              table(("operator", "size", "sequence", "frames > 1", "worst", "p99 ΔE",
                     "auto weights", "pred. left out", "A_rod", "rod gain", "rod sens."),
                    rows), ""]
    L += ["### Fade: the plan's weights over time", "",
          "Each gated mechanism's weight under auto: its value on frame 0, then each change "
          "as `frame:weight`; the level is the frame's scene log-average (cd/m²).", ""]
    for size in sizes:
        for op in ops:
            r = results["sequences"].get(op, {}).get(size, {}).get("fade")
            if not r:
                continue
            lv = seqm["fade"]["levels"][size]
            parts = []
            for m, t in r["track"].items():
                if m not in GATED:
                    continue
                ch = " ".join(f"{i}:{w:.2g}" for i, w in t["changes"]) or "no change"
                span = ""
                if t["changes"]:
                    i0, i1 = t["changes"][0][0], t["changes"][-1][0]
                    span = f" ({lv[i0]:.3g} → {lv[i1]:.3g} cd/m²)"
                parts.append(f"{short_mech([m])} {t['first']:.2g} → {ch}{span}")
            de = r["de_p99"]
            parts.append(f"ΔE p99 max {fmt_de(max(de))} (frame {int(np.argmax(de))}), "
                         f"median {fmt_de(float(np.median(de)))}")
            L += [f"- {op} @ {size}: " + "; ".join(parts)]
    L += [""]
    L += ["## Scenes", "",
          table(("scene", "class", "level cd/m²", "what", "source"),
                [(n, it["cls"], fmt_level(it["level"]), it["kind"], it["source"])
                 for n, it in stills.items.items()]), ""]
    if stills.note:
        L += [f"Note: {stills.note}", ""]
    L += ["Generated scenes are made at the size under test (their functions take w, h); "
          "photographs are centre-cropped to 16:9 and resized by `load_photo` (box filter "
          "down, triangle up: 1920x1080 is upsampled from 910x512). Levels: the scene "
          "(or photograph) scaled so its log-average luminance is the level. Raw numbers: "
          f"`{os.path.basename(meta['json'])}`.", ""]
    return "\n".join(L)


# --- main -------------------------------------------------------------------------------

def parse_sizes(text: str) -> list[str]:
    out = []
    for s in text.split(","):
        s = s.strip().lower()
        if s:
            w, h = (int(x) for x in s.split("x"))
            out.append(f"{w}x{h}")
    return out


def wh(size: str) -> tuple[int, int]:
    w, h = size.split("x")
    return int(w), int(h)


def jsonable(o):
    if isinstance(o, dict):
        return {str(k): jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [jsonable(v) for v in o]
    if isinstance(o, np.integer):
        return o.item()
    if isinstance(o, (float, np.floating)):
        return float(f"{float(o):.5g}") if math.isfinite(o) else None   # 5 digits: enough
    return o


class _Stored:
    """The stills of a stored run (``--render``): their descriptions only."""

    def __init__(self, scenes_meta: dict, note: str = ""):
        self.items, self.note = scenes_meta, note


def render(json_path: str, out: str) -> int:
    with open(json_path) as f:
        results = json.load(f)
    meta = results["meta"]
    ops, sizes = meta["operators"], meta["sizes"]
    results["summary"] = summarise(results, ops, sizes)
    meta = dict(meta, json=json_path, rendered_by=provenance())
    md = report(results, meta, _Stored(meta["scenes"], meta.get("note", "")), ops, sizes)
    with open(out, "w") as f:
        f.write(md + "\n")
    log(f"wrote {out}")
    return 0


def main(argv=None) -> int:
    from ocl_tonemap.operators import registry
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="640x360 only, fewer scenes and shorter sequences (a check)")
    ap.add_argument("--sizes", help="comma list WxH (default 640x360,1920x1080; --quick 640x360)")
    ap.add_argument("--operators", help="comma list (default: all)")
    ap.add_argument("--scenes", help="comma list of stills to run (default: the set)")
    ap.add_argument("--sequences", default="fade,tunnel",
                    help="comma list of fade, tunnel (or 'none')")
    ap.add_argument("--fade-scene", default="interior_patches",
                    help="the still the fade runs (a generated scene or photo stem)")
    ap.add_argument("--fade-frames", type=int, help="default 90 (--quick 45)")
    ap.add_argument("--tunnel-frames", type=int, help="default 60 (--quick 30)")
    ap.add_argument("--photos", help="photo cache folder (default $OCLTM_PHOTOS or "
                    "~/.cache/ocl-tonemap/photos)")
    add_out_args(ap, "scene_driven.md")
    ap.add_argument("--render", metavar="JSON",
                    help="only write the report again from a run's .json (to --out, else "
                    "scene_driven.md in --out-dir)")
    a = ap.parse_args(argv)
    out = out_path(a, "scene_driven.md")
    if a.render:
        return render(a.render, out)
    t_start = time.perf_counter()
    sizes = parse_sizes(a.sizes) if a.sizes else (["640x360"] if a.quick else
                                                  ["640x360", "1920x1080"])
    ops = [o.strip() for o in a.operators.split(",")] if a.operators else list(registry())
    bad = [o for o in ops if o not in registry()]
    if bad:
        ap.error(f"unknown operator(s) {', '.join(bad)}; known: {', '.join(registry())}")
    seqs = [s.strip() for s in a.sequences.split(",") if s.strip() and s.strip() != "none"]
    only = [s.strip() for s in a.scenes.split(",")] if a.scenes else None
    stills = Stills(a.quick, a.photos, only)
    fade_n = a.fade_frames or (45 if a.quick else 90)
    tunnel_n = a.tunnel_frames or (30 if a.quick else 60)
    tunnel_seconds, tunnel_t0 = 8.0, 2.4 - 0.4 * tunnel_n * DT   # entrance at 40% of the span

    from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime
    rt = get_runtime()
    fade_item = stills.items.get(a.fade_scene)
    if fade_item is None and "fade" in seqs:
        full = Stills(False, a.photos)
        fade_item = full.items.get(a.fade_scene)
        if fade_item is None:
            ap.error(f"--fade-scene {a.fade_scene}: not a scene of the set")
    results = {"stills": {}, "sequences": {}, "meta": {"sequences": {
        "fade": {"scene": a.fade_scene, "what": fade_item["kind"] if fade_item else None,
                 "frames": fade_n, "from": 1e4, "to": 1e-3, "levels": {}},
        "tunnel": {"seconds": tunnel_seconds, "t0": tunnel_t0, "frames": tunnel_n}}}}

    for size in sizes:
        w, h = wh(size)
        log(f"== {size}: making {len(stills.items)} stills")
        imgs = {n: it["make"](w, h) for n, it in stills.items.items()}
        for op in ops:
            for n, img in imgs.items():
                rec = run_still(op, img)
                rec["targets"] = still_targets(op, size, n, stills.items[n], rec)
                results["stills"].setdefault(op, {}).setdefault(size, {})[n] = rec
                log(f"{op:12s} {size:9s} {n:24s} auto {fmt_ms(rec['auto']['t']):>5s} ms  "
                    f"full {fmt_ms(rec['full']['t']):>5s} ms  ratio {rec['ratio']:.2f}  "
                    f"dE {fmt_de(rec['de_p99']):>6s}  out {short_mech(skipped(rec['auto']['weights']))}"
                    f"  ran {short_mech(rec['auto']['ran'])} | full {short_mech(rec['full']['ran'])}")
        del imgs
        if "fade" in seqs:
            base = fade_item["make"](w, h)
            frames, levels = fade_frames(base, fade_n)
            results["meta"]["sequences"]["fade"]["levels"][size] = levels
            for op in ops:
                r = run_sequence(op, frames)
                r["track"] = weight_track(r["auto"])
                results["sequences"].setdefault(op, {}).setdefault(size, {})["fade"] = r
                log(f"{op:12s} {size:9s} fade: worst dE {fmt_de(max(r['de_p99']))}, "
                    + ", ".join(f"{m} {t['switches']} sw / step {t['max_step']:.2f}"
                                for m, t in r["track"].items() if m in GATED))
        if "tunnel" in seqs:
            log(f"== {size}: rendering {tunnel_n} tunnel frames")
            frames, cache = tunnel_frames(w, h, tunnel_n, tunnel_t0)
            for i in range(tunnel_n):
                frames[0](i)
            for op in ops:
                r = run_sequence(op, frames)
                r["track"] = weight_track(r["auto"])
                results["sequences"].setdefault(op, {}).setdefault(size, {})["tunnel"] = r
                log(f"{op:12s} {size:9s} tunnel: worst dE {fmt_de(max(r['de_p99']))}, "
                    f"auto {sum(x['t'] for x in r['auto']):.2f} s, "
                    f"full {sum(x['t'] for x in r['full']):.2f} s")
            cache.clear()

    results["summary"] = summarise(results, ops, sizes)
    cmdline = "python -m benchmarks.scene_driven" + "".join(
        " " + shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))
    json_path = os.path.splitext(out)[0] + ".json"
    meta = {"device": describe_device(rt.device),
            "host": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
                    f"Python {platform.python_version()}, NumPy {np.__version__}",
            "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
            "commit": provenance(), "command": cmdline,
            "minutes": (time.perf_counter() - t_start) / 60, "json": json_path,
            "sizes": sizes, "operators": ops, "note": stills.note,
            "scenes": {n: {k: v for k, v in it.items() if k != "make"}
                       for n, it in stills.items.items()}}
    results["meta"].update(meta)
    md = report(results, meta, stills, ops, sizes)
    with open(out, "w") as f:
        f.write(md + "\n")
    with open(json_path, "w") as f:
        json.dump(jsonable(results), f, separators=(",", ":"))
    log(f"wrote {out} and {json_path}")
    print(md.split("## Stills")[0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
