"""Speed against accuracy of the quality tiers (``--quality draft|balanced|reference``)
and of every speed/accuracy knob they are made of.

One command:  python -m benchmarks.speed_accuracy [--quick] [--out-dir DIR | --out FILE]
Writes speed_accuracy.md and, beside it, the Pareto plot speed_accuracy.png into DIR
(default ./benchmark-results; the committed ones: --out-dir benchmarks/results) and
prints the tables as it goes.

1. Knob sweep (what the tiers are chosen from). For each operator and scene, at
   640x360 and 1920x1080: the three tiers, and every value of each knob the
   operator has, one at a time from ``balanced`` (ledda04/kirk11: ``bilateral``
   exact|fast, ``bilateral_sampling`` 1|1.5|2|3; durand00: ``lut`` 0|256|1024|4096,
   effect ``flare_method`` fast|exact and ``flare_per_octave`` 1|2 (durand00's flare
   is on ``auto``: it runs on the scenes with light sources); every operator: the
   display encoding, device table | OCIO). Each: ms/frame (tone mapping + display
   encoding, the median of repeated frames after a warm-up, the rule of
   ``benchmarks.lib.timing.timeit``), MPix/s, and Delta E ITP (ITU-R BT.2124) against the
   ``reference`` tier's output of the same frame: median, 99th percentile, max.
   Scenes: the Poly Haven photographs of ``benchmarks/lib/photos.py`` (centre-cropped to
   16:9, resized with OIIO) calibrated to a log-average of 5000 (daylight), 30
   (interior), 1 (dusk) and 0.01 cd/m^2 (night), and a frame of the built-in tunnel
   drive with the exit and the sodium lamps in view. The observer is in the steady
   state: a fresh Tonemapper is fully adapted to its first frame.
   Delta E ITP is taken in absolute display light: the tier's display code values
   (its own encoding: OCIO's CPU processor or the baked device table), clipped to
   [0, 1] as an integer file holds them, decoded with OCIO's inverse of the same
   display/view, turned into cd/m^2 by the display model (``DisplaySpec.from_signal``:
   1.0 = white, plus the display's black), BT.709 -> BT.2020, ICtCp (colour-science,
   absolute cd/m^2 into the ST 2084 inverse EOTF).
2. Tiers table: operator x tier x size (+3840x2160): ms/frame, MPix/s, Delta E
   median/p99/max (worst scene), PASS/FAIL for "balanced p99 <= 1, draft p99 <= 3 on
   every scene".
3. Roofline: the device's buffer-copy bandwidth (bench_pattanaik's method,
   ``benchmarks.lib.timing.copy_bandwidth``) and each kernel of one 1080p frame per
   operator, timed on an OpenCL profiling queue, against the time its buffers would
   take at that bandwidth.
4. Whole command over 60 frames (not with --quick): the tunnel sample at 640x360 and
   1920x1080 through ``ocl-tonemap run`` to 8-bit PNG, against OIIO read + PNG write
   alone and the pfstools/pfstmo chains (pattanaik00, durand02) and pfstools' own
   read + write.
5. The Pareto plot: ms/frame at 1080p against the worst scene's p99 Delta E.

The float64 reference of the bilateral operators (ledda04, kirk11) costs O(sigma^2)
per pixel with sigma = 2% of the frame width: it is estimated from a 320x180 probe
and, where all scenes would take more than --ref-budget seconds, replaced by the
OpenCL backend with the exact filter (float32; the same tier otherwise), and where
even that is too slow, by the exact filter on a band of rows through the middle of
the frame (the rest through a fine grid), the errors measured on that band.
Machines are noisy: compare ratios, not absolute times.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import warnings
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from benchmarks.lib.outdir import add_out_args, out_path
from benchmarks.lib.report import fmt_de, fmt_ms
from benchmarks.lib.photos import load_photo
from benchmarks.lib.scenes import tunnel
from benchmarks.lib.timing import table

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

OPERATORS = ("pattanaik00", "durand00", "ledda04", "kirk11")
BILATERAL_OPS = ("ledda04", "kirk11")
SIZES = ((640, 360), (1920, 1080), (3840, 2160))
SWEEP_MAX_PIXELS = 1920 * 1080          # the knob sweep runs up to 1080p; larger: tiers only
#: (name, Poly Haven stem, log-average cd/m^2); the tunnel frame is rendered in cd/m^2.
SCENES = (("daylight", "rooitou_park_1k", 5000.0), ("interior", "st_fagans_interior_1k", 30.0),
          ("dusk", "kiara_1_dawn_1k", 1.0), ("night", "dikhololo_night_1k", 0.01),
          ("tunnel", None, None))
QUICK_SCENES = ("night", "tunnel")
TUNNEL_SECONDS, TUNNEL_T = 8.0, 4.5     # 12.5 m before the tunnel exit... 27.5 m: exit in view
BOUNDS = {"balanced": 1.0, "draft": 3.0}
DT = 1.0 / 30.0
PROBE = (320, 180)
#: The band reference (and the exact knob on it) gets 1/BAND_SHARE of --ref-budget.
BAND_SHARE = 3.0
#: A timed configuration stops repeating frames past this many seconds per scene.
REP_BUDGET_S = 4.0


def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# --- scenes -------------------------------------------------------------------------------

class Scenes:
    def __init__(self, names):
        from benchmarks.lib.photos import PhotoFetchError, fetch_photos
        self.names, self.paths, self.note = list(names), {}, ""
        stems = [s for n, s, _ in SCENES if n in self.names and s]
        if stems:
            try:
                self.paths = {p.stem: p for p in fetch_photos(names=stems)}
            except PhotoFetchError as e:
                self.note = f"photographs unavailable ({str(e).splitlines()[0]}): tunnel only"
                log("WARNING " + self.note)
                self.names = [n for n in self.names if n == "tunnel"]
        self._cache: dict = {}

    def get(self, name: str, w: int, h: int) -> np.ndarray:
        """The scene in cd/m^2 (working RGB, luminance scale 1)."""
        key = (name, w, h)
        if key not in self._cache:
            from ocl_tonemap.colour.calibration import log_average
            stem, level = next((s, L) for n, s, L in SCENES if n == name)
            if stem is None:
                img = tunnel(w, h, t=TUNNEL_T, seconds=TUNNEL_SECONDS)
            else:
                img = load_photo(self.paths[stem], w, h)
                img = np.ascontiguousarray(img * np.float32(level / log_average(img)))
            self._cache = {k: v for k, v in self._cache.items() if k[1:] in ((w, h), PROBE)}
            self._cache[key] = img
        return self._cache[key]

    def describe(self) -> list[str]:
        from benchmarks.lib.photos import WHEEL
        from ocl_tonemap.colour.calibration import log_average
        out = []
        for n, stem, level in SCENES:
            if n not in self.names:
                continue
            if stem is None:
                img = self.get(n, 640, 360)
                out.append(f"`{n}`: the built-in tunnel drive (`sample.render_frame`, t = "
                           f"{TUNNEL_T} s of {TUNNEL_SECONDS:g} s: inside, exit and sodium lamps "
                           f"in view), absolute cd/m^2, log-average {log_average(img):.3g} cd/m^2, "
                           f"peak {img.max():.0f}")
            else:
                out.append(f"`{n}`: Poly Haven `{stem}.hdr` (CC0, via {WHEEL}), log-average "
                           f"{level:g} cd/m^2")
        return out


# --- colour: encoding, decoding, Delta E ITP ---------------------------------------------

class Colour:
    """The CLI's default colour set-up ($OCIO, else ocio://default; the config's default
    display and its un-tone-mapped view), both display encodings, and the decode to
    absolute display light for Delta E ITP."""

    def __init__(self):
        import PyOpenColorIO as ocio
        from ocl_tonemap import colour
        from ocl_tonemap.models.display import display_for
        self.source = colour.resolve_config_source(None)
        cfg = colour.load_config(None)
        self.cp = {m: colour.ColourPipeline(cfg) for m in ("ocio", "table", "auto")}
        self.notes = {m: cp.set_display_encode(m, "opencl") for m, cp in self.cp.items()}
        self.auto = "table" if self.cp["auto"].device_table is not None else "ocio"
        cp = self.cp["ocio"]
        self.display_name, self.view = cp.display, cp.view
        self.primaries = cp.display_primaries()
        self.display = display_for(cp.display)
        self._inv = cfg.getProcessor(cp.working, cp.display, cp.view,
                                     ocio.TRANSFORM_DIR_INVERSE).getDefaultCPUProcessor()

    def resolve(self, mode: str, backend: str) -> str:
        if mode == "auto":
            return self.auto if backend == "opencl" else "ocio"
        return mode

    def encoder(self, mode: str):
        """Display-linear -> code values: OCIO's CPU processor or the device table."""
        return self.cp["ocio"].encode if mode == "ocio" else self.cp["table"].encode_fast

    def ictcp(self, code: np.ndarray, rows=None) -> np.ndarray:
        """ICtCp of what the display shows for ``code`` (rows [a, b) only, when given)."""
        c = code[..., :3] if rows is None else code[rows[0]:rows[1], :, :3]
        c = np.ascontiguousarray(np.clip(c, 0.0, 1.0), np.float32)
        self._inv.applyRGB(c)
        return self.ictcp_cd(self.display.from_signal(c))

    def ictcp_cd(self, rgb709_cd) -> np.ndarray:
        """ICtCp of display light (cd/m^2, BT.709): the package's ``models/ictcp.py``,
        the measure the mechanism plan bounds (equal to colour-science's, tested)."""
        from ocl_tonemap.models.ictcp import rgb709_to_ictcp
        return rgb709_to_ictcp(rgb709_cd)

    def sanity(self) -> dict:
        """Delta E ITP of a 1% step of a grey at 100 cd/m^2, and of one 8-bit / 10-bit code
        step of a mid-grey code value of this display."""
        from ocl_tonemap.models.ictcp import delta_e_itp
        g = lambda L: self.ictcp_cd(np.array([[L, L, L]], np.float64))  # noqa: E731
        one_pct = float(delta_e_itp(g(100.0), g(101.0))[0])
        steps = {}
        for bits in (8, 10):
            n = 2 ** bits - 1
            c = np.full((1, 2, 3), 128 / 255, np.float32)
            c[0, 1] += 1.0 / n
            I = self.ictcp(c)
            steps[bits] = float(delta_e_itp(I[0, 0], I[0, 1]))
        return {"one_pct_100cd": one_pct, "code_step": steps}


def colour_science():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    return colour


def delta_e(I, I_ref) -> tuple[float, float, float]:
    from ocl_tonemap.models.ictcp import delta_e_itp
    d = delta_e_itp(I, I_ref).ravel()
    d = d[np.isfinite(d)]
    return float(np.median(d)), float(np.percentile(d, 99)), float(d.max())


# --- configurations -----------------------------------------------------------------------

@dataclass(frozen=True)
class Config:
    """One point of the sweep: a tier, or ``balanced`` with one knob changed."""

    knob: str                 # "tier" or the knob's name
    value: str
    quality: str = "balanced"
    options: tuple = ()
    effects: tuple = ()
    encode: str | None = None  # None: the tier's display_encode
    backend: str | None = None

    @property
    def label(self) -> str:
        return self.value if self.knob == "tier" else f"{self.knob}={self.value}"


def knob_configs(op: str) -> list[Config]:
    from ocl_tonemap.effects import EffectSettings
    from ocl_tonemap.operators import get_operator
    names = {o.name for o in get_operator(op).options}
    out = [Config("tier", t, t) for t in ("draft", "balanced", "reference")]
    if "lut" in names:
        out += [Config("lut", str(n), options=(("lut", n),)) for n in (0, 256, 1024, 4096)]
    if "bilateral" in names:
        out += [Config("bilateral", m, options=(("bilateral", m),)) for m in ("exact", "fast")]
    if "bilateral_sampling" in names:
        out += [Config("bilateral_sampling", q, options=(("bilateral_sampling", q),))
                for q in ("1", "1.5", "2", "3")]
    if EffectSettings.for_operator(op).flare != "off":
        out += [Config("flare_method", m, effects=(("flare_method", m),)) for m in ("fast", "exact")]
        out += [Config("flare_per_octave", str(n), effects=(("flare_per_octave", n),))
                for n in (1, 2)]
    out += [Config("display_encode", m, encode=m) for m in ("table", "ocio")]
    return out


def tier_of(cfg: Config):
    from ocl_tonemap.backends.quality import QUALITY_TIERS
    return QUALITY_TIERS[cfg.quality]


def effects_of(op: str, cfg: Config):
    from ocl_tonemap.effects import EffectSettings
    return EffectSettings.for_operator(op, **{**dict(tier_of(cfg).effects), **dict(cfg.effects)})


def backend_of(cfg: Config) -> str:
    return cfg.backend or tier_of(cfg).backend


def resolved_key(op: str, cfg: Config, w: int, h: int, col: Colour) -> tuple[str, str | None]:
    """(key, bilateral method): what the configuration computes, with defaults filled in
    and ``auto`` resolved (equal keys: the same work; the sweep runs one of them)."""
    from ocl_tonemap.models.bilateral import BilateralSpec
    from ocl_tonemap.operators import get_operator
    declared = {o.name: o for o in get_operator(op).options}
    given = {**tier_of(cfg).options_for(declared), **dict(cfg.options)}
    full = {n: given.get(n, o.default) for n, o in declared.items()}
    backend = backend_of(cfg)
    if "bilateral" in full:
        spec = BilateralSpec.parse(full["bilateral"] or "auto", full.get("bilateral_sampling"))
        method = spec.method
        if backend == "reference":
            method = "exact"
        elif method == "auto":
            sigma = full.get("sigma_spatial") or max(0.02 * max(w, h), 0.5)
            method = bilateral_choose(spec, sigma, w, h)
        full["bilateral"] = method
        full["bilateral_sampling"] = None if method == "exact" else (spec.q_s, spec.q_r)
    method = full.get("bilateral")
    eff = effects_of(op, cfg).as_dict()
    if eff["flare"] == "off":
        for k in ("flare_method", "flare_per_octave", "flare_threshold"):
            eff.pop(k)
    elif eff["flare_method"] == "exact":
        eff.pop("flare_per_octave")
    enc = col.resolve(cfg.encode or tier_of(cfg).display_encode, backend)
    return repr((backend, sorted(full.items(), key=str), sorted(eff.items()), enc)), method


def bilateral_choose(spec, sigma, w, h) -> str:
    try:
        from ocl_tonemap.backends.opencl.bilateral import DeviceBilateral
        from ocl_tonemap.backends.opencl.runtime import get_runtime
        return DeviceBilateral(get_runtime()).choose(spec, sigma, w, h)
    except Exception:  # noqa: BLE001 -- the rule without the memory check
        return "exact" if sigma <= spec.AUTO_EXACT_SIGMA else "fast"


def make_tonemapper(op: str, cfg: Config, col: Colour):
    from ocl_tonemap.pipeline import Tonemapper
    tm = Tonemapper(op, backend=backend_of(cfg), quality=cfg.quality,
                    options=dict(cfg.options) or None, effects=effects_of(op, cfg))
    tm.set_display_primaries(col.primaries)        # as the CLI does
    return tm


@contextmanager
def exact_band(y0: int, y1: int, q: float = 4.0):
    """The device's exact bilateral filter on rows [y0, y1) only; the other rows of a
    whole-frame call through the grid at q_s = q_r = ``q`` (for the frame's global
    statistics). Only for the reference at sizes where the brute force is unaffordable;
    errors are then measured on rows [y0, y1) (in process, nothing on disk changes)."""
    import pyopencl as cl
    from ocl_tonemap.backends.opencl import bilateral as B
    orig = B.DeviceBilateral.exact

    def exact(self, v_buf, out_buf, width, rows_in, in_y0, out_y0, rows_out, sigma_s, rk):
        if in_y0 != 0 or out_y0 != 0 or rows_in != rows_out:
            raise RuntimeError("exact_band: the frame is processed in bands")
        a, b = max(0, y0), min(rows_out, y1)
        self.fast(v_buf, out_buf, width, rows_out, sigma_s, rk, q, q)
        if a < b:
            tmp = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, (b - a) * width * 4)
            orig(self, v_buf, tmp, width, rows_in, in_y0, a, b - a, sigma_s, rk)
            cl.enqueue_copy(self.rt.queue, out_buf, tmp, dst_offset=a * width * 4,
                            byte_count=(b - a) * width * 4)
    B.DeviceBilateral.exact = exact
    try:
        yield
    finally:
        B.DeviceBilateral.exact = orig


@dataclass
class Run:
    """One configuration on one scene."""

    code: np.ndarray | None = None     # display code values of the steady-state frame
    t: float | None = None             # seconds per frame (process + encode)
    first: float | None = None
    reps: int = 0
    flare_ran: bool = False
    error: str | None = None


def run_config(op: str, cfg: Config, img: np.ndarray, col: Colour, reps: int,
               band=None, time_it: bool = True) -> Run:
    """The steady-state frame (the first, fresh observer: also the warm-up), then up
    to ``reps`` more frames timed (median), as ``timing.timeit``."""
    r = Run()
    try:
        mode = col.resolve(cfg.encode or tier_of(cfg).display_encode, backend_of(cfg))
        enc = col.encoder(mode)
        with (exact_band(*band) if band is not None else _null()):
            tm = make_tonemapper(op, cfg, col)
            t0 = time.perf_counter()
            r.code = enc(tm.process(img, dt=DT))
            r.first = time.perf_counter() - t0
            fl = (tm.last.effects or {}).get("flare") or {}
            r.flare_ran = bool(fl.get("ran"))
            if time_it:
                n = reps if r.first * reps <= REP_BUDGET_S else int(REP_BUDGET_S // r.first)
                ts = []
                for _ in range(n):
                    t0 = time.perf_counter()
                    enc(tm.process(img, dt=DT))
                    ts.append(time.perf_counter() - t0)
                r.reps = len(ts)
                r.t = statistics.median(ts) if ts else r.first
    except Exception as e:  # noqa: BLE001 -- one row fails, the benchmark goes on
        r.error = f"{type(e).__name__}: {str(e).splitlines()[0][:160]}" if str(e) else type(e).__name__
        log(f"    ERROR {op} {cfg.label}: {r.error}")
    return r


@contextmanager
def _null():
    yield


# --- the reference ---------------------------------------------------------------------------

@dataclass
class RefPlan:
    kind: str                 # float64 | opencl-exact | band | none
    est_s: float              # estimated seconds per scene of the float64 reference tier
    est_ocl_s: float | None   # ... of the OpenCL one (exact filter, reference knobs)
    band: tuple | None = None

    def describe(self, h: int) -> str:
        if self.kind == "float64":
            return "float64 reference tier"
        if self.kind == "opencl-exact":
            return "OpenCL backend with the reference tier's knobs (exact bilateral, float32)"
        if self.kind == "none":
            return "none (unaffordable: ΔE not measured)"
        a, b = self.band
        return f"OpenCL exact bilateral on rows {a}-{b - 1} ({b - a} of {h}; the rest grid q=4)"


def taps(op: str, w: int, h: int) -> float:
    from ocl_tonemap.models.bilateral import spatial_radius
    if op not in BILATERAL_OPS:
        return 1.0
    return (2 * spatial_radius(max(0.02 * max(w, h), 0.5)) + 1) ** 2


#: Cost of a reference frame of the global operators against pixels (the exact flare's FFT
#: and the caches make it grow faster than the pixel count: durand00 x4.8 from 1080p to
#: 4K); the bilateral operators' cost is pixels x taps.
PIXEL_EXPONENT = 1.2


class RefPlanner:
    """The reference's cost per scene, estimated from the last size where it ran (mean
    over the scenes) or from one 320x180 frame of the darkest scene (rods on: both filters
    of ledda04), scaled by pixels^1.2 x bilateral taps; and the choice it makes."""

    def __init__(self, scenes: Scenes, col: Colour, budget_s: float):
        self.scenes, self.col, self.budget = scenes, col, budget_s
        self._probe: dict = {}
        self.measured: dict = {}      # (op, kind) -> (w, h, seconds per scene)

    def probe(self, op: str) -> tuple[float, float]:
        if op not in self._probe:
            name = "night" if "night" in self.scenes.names else self.scenes.names[0]
            img = self.scenes.get(name, *PROBE)
            t64 = run_config(op, Config("tier", "reference", "reference"), img, self.col, 0,
                             time_it=False).first
            ocl = Config("tier", "reference", "reference", backend="opencl")
            run_config(op, ocl, img, self.col, 0, time_it=False)        # compile
            tcl = run_config(op, ocl, img, self.col, 0, time_it=False).first
            self._probe[op] = (t64 or math.inf, tcl or math.inf)
            log(f"  probe {op} 320x180 ({name}): float64 reference {t64:.2f} s, OpenCL "
                f"reference {tcl:.2f} s")
        return self._probe[op]

    def estimate(self, op: str, kind: str, w: int, h: int) -> float:
        base = self.measured.get((op, kind))
        if base is None:
            t64, tcl = self.probe(op)
            base = (*PROBE, t64 if kind == "float64" else tcl)
        bw, bh, t = base
        e = 1.0 if op in BILATERAL_OPS else PIXEL_EXPONENT
        return t * ((w * h) / (bw * bh)) ** e * taps(op, w, h) / taps(op, bw, bh)

    def record(self, op: str, plan: "RefPlan", w: int, h: int, times: list) -> None:
        if plan.kind in ("float64", "opencl-exact") and times:
            self.measured[(op, "float64" if plan.kind == "float64" else "opencl")] = \
                (w, h, statistics.fmean(times))

    def plan(self, op: str, w: int, h: int, n_scenes: int, runs: int = 2) -> RefPlan:
        est64, estcl = self.estimate(op, "float64", w, h), self.estimate(op, "opencl", w, h)
        if est64 * n_scenes <= self.budget:
            return RefPlan("float64", est64, estcl)
        if estcl * n_scenes <= self.budget:
            return RefPlan("opencl-exact", est64, estcl)
        if op not in BILATERAL_OPS:
            return RefPlan("none", est64, estcl)
        # the band, in a third of the budget: the reference and the exact knob (``runs``)
        # each run once per scene on it
        rows = int(h * self.budget / BAND_SHARE / (runs * estcl * n_scenes))
        rows = max(8, min(h, rows - rows % 4))
        a = (h - rows) // 2
        return RefPlan("band", est64, estcl, (a, a + rows))

    def config(self, plan: RefPlan) -> Config:
        return Config("tier", "reference", "reference",
                      backend=None if plan.kind == "float64" else "opencl")


# --- the sweep -------------------------------------------------------------------------------

@dataclass
class Row:
    """One configuration over the scenes at one size."""

    op: str
    size: tuple
    cfg: Config
    same_as: str | None = None
    t: dict = field(default_factory=dict)        # scene -> s/frame
    de: dict = field(default_factory=dict)       # scene -> (median, p99, max)
    flare: list = field(default_factory=list)    # scenes where flare ran
    est_t: float | None = None                   # estimated s/frame (not timed)
    errors: list = field(default_factory=list)
    reps: list = field(default_factory=list)

    @property
    def mean_t(self):
        return statistics.fmean(self.t.values()) if self.t else self.est_t

    def worst(self, i: int):
        return max(v[i] for v in self.de.values()) if self.de else None


def sweep(op: str, size: tuple, cfgs: list[Config], scenes: Scenes, col: Colour,
          planner: RefPlanner, reps: int) -> tuple[list[Row], RefPlan]:
    w, h = size
    names = scenes.names
    has_exact = any(c.options == (("bilateral", "exact"),) for c in cfgs)
    plan = planner.plan(op, w, h, len(names), 2 if has_exact else 1)
    log(f"== {op} {w}x{h}: reference = {plan.describe(h)} (est. per scene: float64 "
        f"{plan.est_s:.3g} s, OpenCL {plan.est_ocl_s:.3g} s)")
    band = plan.band
    rows_cmp = band if band else None
    keys, methods, rows, first_of = {}, {}, [], {}
    for cfg in cfgs:
        row = Row(op, size, cfg)
        key, methods[id(row)] = resolved_key(op, cfg, w, h, col)
        if key in first_of:
            row.same_as = first_of[key].cfg.label
        else:
            first_of[key] = row
        keys[id(row)] = key
        rows.append(row)
    ref_cfg = planner.config(plan)
    is_ref_tier = plan.kind == "float64"
    ref_times = []
    for name in names:
        img = scenes.get(name, w, h)
        t0 = time.perf_counter()
        I_ref, ref = None, None
        if plan.kind != "none":
            ref = run_config(op, ref_cfg, img, col, reps if is_ref_tier else 0, band=band,
                             time_it=is_ref_tier)
            if ref.error:
                log(f"  {name}: reference failed: {ref.error}")
            else:
                I_ref = col.ictcp(ref.code, rows_cmp)
                ref_times.append(ref.first)
            log(f"  {name}: reference {time.perf_counter() - t0:.1f} s")
        for row in rows:
            if row.same_as is not None:
                continue
            cfg = row.cfg
            if cfg.knob == "tier" and cfg.value == "reference":
                if is_ref_tier and ref is not None:
                    r = ref
                else:                        # not run: the float64 is the estimate
                    row.est_t = plan.est_s
                    continue
            elif band is not None and backend_of(cfg) == "opencl" and \
                    methods[id(row)] == "exact":
                # the brute force at this size: once, on the band; time estimated
                r = run_config(op, cfg, img, col, 0, band=band, time_it=False)
                row.est_t = plan.est_ocl_s
                r.t = None
            else:
                r = run_config(op, cfg, img, col, reps)
            if r.error:
                row.errors.append(f"{name}: {r.error}")
                continue
            if r.t is not None:
                row.t[name] = r.t
                row.reps.append(r.reps)
            if r.flare_ran:
                row.flare.append(name)
            if I_ref is not None:
                row.de[name] = delta_e(col.ictcp(r.code, rows_cmp), I_ref)
            r.code = None
        del ref
    planner.record(op, plan, w, h, ref_times)
    for row in rows:                                  # the duplicates take their twin's values
        if row.same_as is not None:
            twin = first_of[keys[id(row)]]
            row.t, row.de, row.flare, row.est_t = twin.t, twin.de, twin.flare, twin.est_t
            row.errors, row.reps = twin.errors, twin.reps
    for row in rows:
        log(f"  {row.cfg.label:28s} {fmt_ms(row.mean_t):>8s} ms  p99 {fmt_de(row.worst(1)):>6s}  "
            f"max {fmt_de(row.worst(2)):>6s}" + (f"  (= {row.same_as})" if row.same_as else ""))
    return rows, plan


# --- roofline (in a child process: the profiling queue must exist before the runtime) ---------

def roofline_child(w: int, h: int, ops: list[str], frames: int) -> dict:
    os.environ["OCLTM_PROFILE"] = "1"         # the runtime's own profiling switch, where it has one
    import pyopencl as cl
    from ocl_tonemap.backends.opencl import runtime as R
    from ocl_tonemap.pipeline import Tonemapper
    from ocl_tonemap.operators import get_operator
    from benchmarks.lib.timing import copy_bandwidth
    rt = R.get_runtime()
    hook = "OCLTM_PROFILE=1 (runtime profiling queue)"
    if not (rt.queue.properties & cl.command_queue_properties.PROFILING_ENABLE):
        rt.queue = cl.CommandQueue(rt.context,
                                   properties=cl.command_queue_properties.PROFILING_ENABLE)
        hook = "a profiling queue put on the runtime by the benchmark"
    records: list = []
    orig_kernel = R.Runtime.kernel

    class Rec:
        def __init__(self, k, name):
            self._k, self.name = k, name

        def __call__(self, *args, **kw):
            ev = self._k(*args, **kw)
            nbytes = sum(a.size for a in args[3:] if isinstance(a, cl.MemoryObject))
            records.append((self.name, ev, nbytes))
            return ev

        def __getattr__(self, a):
            return getattr(self._k, a)

    def kernel(self, file, name, defines=()):
        return Rec(orig_kernel(self, file, name, defines), name)
    R.Runtime.kernel = kernel
    copies: list = []                     # (direction, bytes) of every enqueue_copy
    orig_copy = cl.enqueue_copy

    def enqueue_copy(queue, dest, src, **kw):
        up, down = isinstance(dest, cl.MemoryObject), isinstance(src, cl.MemoryObject)
        host = src if up and not down else dest
        nbytes = kw.get("byte_count") or getattr(host, "nbytes", 0)
        copies.append(("device" if up and down else "up" if up else "down", int(nbytes)))
        return orig_copy(queue, dest, src, **kw)
    cl.enqueue_copy = enqueue_copy
    from ocl_tonemap.colour import ColourPipeline, load_config
    cp = ColourPipeline(load_config("ocl-tonemap"), "sRGB - Display")
    cp.set_display_encode("auto", "opencl")
    bw = copy_bandwidth(rt, w * h * 16)
    img = tunnel(w, h, t=TUNNEL_T, seconds=TUNNEL_SECONDS)
    out = {"bandwidth": bw, "hook": hook, "device": R.describe_device(rt.device), "ops": {}}
    for op in ops:
        stages = {}
        for s in get_operator(op).stages:
            for k in (s.kernel.split(":", 1)[1] if ":" in s.kernel else "").split("|"):
                if k:
                    stages[k] = (s.name, s.kind)
        tm = Tonemapper(op)
        # as the run does for an 8-bit PNG: the display table on the operator's output
        tm.output_encoding = cp.device_output_encoding(True, rt)
        tm.process(img)
        rt.queue.finish()
        records.clear()
        copies.clear()
        t0 = time.perf_counter()
        for _ in range(frames):
            tm.process(img, dt=DT)
        rt.queue.finish()
        wall = (time.perf_counter() - t0) / frames
        plane = w * h * 4                  # one float plane of the frame
        full = {d: sum(1 for dd, b in copies if dd == d and b >= plane // 2) / frames
                for d in ("up", "down", "device")}
        passes = sum(1 for _, _, b in records if b >= plane) / frames
        per = {}
        for name, ev, nbytes in records:
            ev.wait()
            ms = (ev.profile.end - ev.profile.start) * 1e-6
            t, c, b = per.get(name, (0.0, 0, 0))
            per[name] = (t + ms, c + 1, b + nbytes)
        if hasattr(R, "kernel_times"):
            R.kernel_times(reset=True)
        rows = []
        for name, (ms, c, b) in sorted(per.items(), key=lambda kv: -kv[1][0]):
            st = next((v for k, v in stages.items() if name == k or
                       (k.endswith("*") and name.startswith(k[:-1])) or
                       name.rstrip("4") == k.rstrip("4")), ("", ""))
            rows.append({"kernel": name, "stage": st[0], "kind": st[1], "ms": ms / frames,
                         "launches": c / frames, "bytes": b / frames})
        out["ops"][op] = {"wall_ms": wall * 1e3, "kernels": rows, "copies": full,
                          "passes": passes, "encoded": bool(tm.last_output_encoded)}
    R.Runtime.kernel = orig_kernel
    cl.enqueue_copy = orig_copy
    return out


def roofline(w: int, h: int, ops: list[str], frames: int) -> dict | None:
    cmd = [sys.executable, "-m", "benchmarks.speed_accuracy", "--roofline-child", f"{w}x{h}",
           "--operators", ",".join(ops), "--repeat", str(frames)]
    r = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if r.returncode != 0:
        log("roofline child failed:\n" + r.stderr[-2000:])
        return None
    return json.loads(r.stdout.strip().splitlines()[-1])


PER_PIXEL = ("pointwise", "state", "colour")


def roofline_md(rf: dict, w: int, h: int) -> list[str]:
    bw = rf["bandwidth"]
    lines = [f"## 3. Roofline ({w}x{h}, the tunnel frame, `balanced`)", "",
             f"Device buffer-to-buffer copy bandwidth (read + write, as in bench_pattanaik.py): "
             f"**{bw / 1e9:.1f} GB/s**. Kernel times: {rf['hook']}, per frame, averaged over "
             "the timed frames. `bytes`: the sizes of the buffers a kernel is given (each read "
             "or written once: a streaming kernel's traffic); `roofline ms` = bytes / copy "
             "bandwidth; `fraction` = roofline / kernel time (1 = as fast as a copy of its "
             "data). Meaningful for the per-pixel kernels (stages of kind pointwise, state, "
             "colour: each pixel's data read and written once); the grid and reduction "
             "kernels touch their buffers in other patterns.", ""]
    rows = []
    for op, d in rf["ops"].items():
        tot = sum(k["ms"] for k in d["kernels"])
        for k in d["kernels"]:
            if k["ms"] < 0.02 * tot and k["kind"] not in PER_PIXEL:
                continue
            roof = k["bytes"] / bw * 1e3
            rows.append((op, k["kernel"], f"{k['stage']} ({k['kind']})" if k["stage"] else "",
                         f"{k['launches']:.0f}", f"{k['ms']:.2f}", f"{k['bytes'] / 2**20:.1f} MiB",
                         f"{roof:.2f}", f"{roof / k['ms']:.2f}" if k["ms"] > 0 else "—"))
        rows.append((op, "**all kernels**", "", "", f"{tot:.1f}", "", "",
                     f"wall {d['wall_ms']:.0f} ms/frame"))
    lines.append(table(("operator", "kernel", "stage", "launches", "kernel ms", "bytes",
                        "roofline ms", "fraction"), rows))
    lines += ["", "Kernels under 2% of an operator's device time are left out (per-pixel "
              "ones always shown). `all kernels` is the device time of the operator and its "
              "effects; the rest of the wall time is transfers, host work and launch overhead. "
              "Each frame is mapped as the run maps it for an 8-bit PNG: the display table "
              "runs on the operator's output (`Tonemapper.output_encoding`), timed in the wall "
              "time and the transfers, not in the kernel rows.", "",
              "Full-resolution passes and crossings per frame: `kernel passes` counts the "
              "launches given at least one float plane of the frame (w x h x 4 bytes) in "
              "buffers (an upper bound: the flare gives its full-size scratch to the blurs "
              "of every pyramid level); `up` / `down` / `on device` count the copies of at least half a "
              "plane (an 8-bit RGB frame is three quarters of one; the flare's halo ring "
              "level, a quarter or less, is not counted) to the device, back to the host, "
              "and within the device.", ""]
    rows = [(op, f"{d.get('passes', 0):.0f}", f"{d['copies']['up']:.0f}",
             f"{d['copies']['down']:.0f}", f"{d['copies']['device']:.0f}",
             "yes" if d.get("encoded") else "no")
            for op, d in rf["ops"].items() if "copies" in d]
    if rows:
        lines += [table(("operator", "kernel passes", "up", "down", "on device",
                         "encoded on the device"), rows), ""]
    return lines


# --- whole command -----------------------------------------------------------------------------

RW_CODE = r"""
import sys, OpenImageIO as oiio
oiio.attribute("threads", 1)
level, filt, outp, ins = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4:]
for i, p in enumerate(ins):
    src = oiio.ImageBuf(p)
    px = src.get_pixels(oiio.FLOAT)
    h, w, c = px.shape
    spec = oiio.ImageSpec(w, h, c, oiio.UINT8)
    spec.attribute("png:compressionLevel", level)
    spec.attribute("png:filter", filt)
    out = oiio.ImageOutput.create(outp % (i + 1))
    if not (out.open(outp % (i + 1), spec) and out.write_image(px) and out.close()):
        sys.exit(out.geterror())
"""

#: (operator, --quality, --model) of the whole-command runs: the defaults (--model auto:
#: the mechanisms the frame needs, glare of the tunnel's sun included) and, like for like
#: with pfstmo (the operator alone), --model none.
CMD_RUNS = (("pattanaik00", "draft", "auto"), ("pattanaik00", "balanced", "auto"),
            ("pattanaik00", "balanced", "none"), ("durand00", "draft", "auto"),
            ("durand00", "balanced", "auto"), ("durand00", "balanced", "none"),
            ("ledda04", "balanced", "auto"), ("ledda04", "balanced", "none"))


def sample_sequence(w: int, h: int) -> tuple[str, list[int]]:
    """The 60-frame tunnel sample (30 fps, 2 s), rendered once into a cache folder."""
    from ocl_tonemap.io.patterns import frame_path
    from ocl_tonemap.io.sample import write_tunnel_sequence
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    d = os.path.join(base, "ocl-tonemap", "speed_accuracy", f"tunnel_{w}x{h}_60")
    pattern = os.path.join(d, "tunnel.####.exr")
    frames = list(range(1, 61))
    if not all(os.path.exists(frame_path(pattern, f)) for f in frames):
        log(f"  rendering the 60-frame tunnel sample at {w}x{h} into {d} ...")
        shutil.rmtree(d, ignore_errors=True)
        pattern, frames = write_tunnel_sequence(d, w, h, 30.0, 2.0)
    return pattern, frames


def ensure_pfstools() -> str | None:
    """None when the pfstools chains can run, else why not."""
    need = ("pfsin", "pfsout", "pfsclamp", "pfsgamma", "pfstmo_pattanaik00", "pfstmo_durand02")
    if all(shutil.which(p) for p in need):
        return None
    if shutil.which("apt-get"):
        log("pfstools/pfstmo missing: trying apt-get install -y --no-install-recommends "
            "pfstools pfstmo ...")
        r = subprocess.run(["apt-get", "install", "-y", "--no-install-recommends", "pfstools",
                            "pfstmo"], capture_output=True, text=True)
        if r.returncode != 0:
            tail = ((r.stderr or r.stdout or "").strip().splitlines() or ["?"])[-1]
            log(f"apt-get install failed (it needs root and the package lists): {tail}")
    missing = [p for p in need if not shutil.which(p)]
    return f"not installed ({', '.join(missing)})" if missing else None


#: GNU time: runs the command from a small process, so that a child's peak resident set
#: does not start at this benchmark's own size (a fork copies the parent's high-water mark).
GNU_TIME = "/usr/bin/time"


def timed(cmd, repeat: int, cwd: str, shell: bool = False):
    """(median wall s, error or "", peak RSS MiB or None) of a command run ``repeat``
    times. The peak is GNU time's %M: the largest resident set of the command's
    processes (for a pipeline, its largest stage), the largest over the repeats; None
    where GNU time is not installed."""
    import tempfile as _tf
    ts, peak = [], None
    argv = ["/bin/bash", "-c", cmd] if shell else list(cmd)
    for _ in range(repeat):
        with _tf.NamedTemporaryFile("r", suffix=".rss") as rss:
            run = ([GNU_TIME, "-f", "%M", "-o", rss.name] + argv) if os.path.exists(GNU_TIME) \
                else argv
            t0 = time.perf_counter()
            r = subprocess.run(run, cwd=cwd, capture_output=True, text=True)
            ts.append(time.perf_counter() - t0)
            if r.returncode != 0:
                err = (r.stderr or r.stdout).strip().splitlines()[-1:] or ["failed"]
                return None, f"exit {r.returncode}: {err[0][:120]}", None
            got = rss.read().strip().splitlines()
            if got and got[-1].isdigit():
                peak = max(peak or 0.0, int(got[-1]) / 1024.0)
    return statistics.median(ts), "", peak


def whole_command(sizes, repeat: int) -> list[str]:
    from ocl_tonemap.io.imageio import PNG_FILTER, PNG_FILTERS, PNG_LEVEL
    cli = os.path.join(os.path.dirname(sys.executable), "ocl-tonemap")
    cli = [cli] if os.path.exists(cli) else [sys.executable, "-m", "ocl_tonemap"]
    pfs_missing = ensure_pfstools()
    lines = ["## 4. Whole command: the tunnel sample, 60 frames (30 fps EXR) -> 8-bit PNG", "",
             f"Wall time of the whole command (median of {repeat}), process start-up included; "
             f"peak RSS: the largest resident set of its processes (GNU time's %M; a "
             f"pipeline's largest stage). "
             f"Ours: `{' '.join(os.path.basename(c) for c in cli)} run IN.####.exr "
             f"OUT.####.png --operator X --quality Q --model M -q` (its default OCIO display encoding and "
             f"PNG zlib level {PNG_LEVEL}, row filter {PNG_FILTER}). Read + write only: a Python "
             f"loop in one process, OIIO with one thread: read each EXR, write an 8-bit PNG "
             f"through OIIO's ImageOutput at zlib level {PNG_LEVEL}, filter {PNG_FILTER} (what "
             f"the CLI's writer sets, `imageio.PNG_LEVEL`, `PNG_FILTER`). pfstools: "
             "`pfsin IN.%04d.exr --frames 1:60 | pfstmo_pattanaik00 -t --fps 30 | pfsclamp | "
             "pfsgamma -g 2.2 | pfsout OUT.%04d.png`, the same with `pfstmo_durand02` "
             "(a bilateral operator: ledda04's peer), and `pfsin | pfsout` alone (pfsout writes "
             "PNG through ImageMagick at its default compression). Each of our runs is made "
             "once on one frame before the timings (kernel binaries built and cached).", ""]
    rows, checks = [], []
    # One untimed frame of each run first: a fresh machine's first run builds every
    # kernel (pyopencl then keeps the binaries on disk; ~2.4 s on the H100 machine, where
    # the 640x360 rows had paid it), which is not the per-frame cost being measured.
    pattern, frames = sample_sequence(*sizes[0])
    with tempfile.TemporaryDirectory(prefix="ocltm-sa-") as out:
        for op, q, m in CMD_RUNS:
            subprocess.run(cli + ["run", pattern, os.path.join(out, "warm.####.png"), "--frames",
                                  f"{frames[0]}-{frames[0]}", "--operator", op, "--quality", q,
                                  "--model", m, "-q"], capture_output=True)
    for w, h in sizes:
        pattern, frames = sample_sequence(w, h)
        src = os.path.dirname(pattern)
        n = len(frames)
        with tempfile.TemporaryDirectory(prefix="ocltm-sa-") as out:
            res = {}
            cmd = cli + ["run", pattern, os.path.join(out, "startup.####.png"), "--frames",
                         f"{frames[0]}-{frames[0]}", "-q"]
            res["startup"] = timed(cmd, repeat, out)
            log(f"  {w}x{h} ours, one frame (start-up): {res['startup'][0]}")
            for op, q, m in CMD_RUNS:
                cmd = cli + ["run", pattern, os.path.join(out, f"{op}_{q}_{m}.####.png"),
                             "--operator", op, "--quality", q, "--model", m, "-q"]
                res[(op, q, m)] = timed(cmd, repeat, out)
                log(f"  {w}x{h} ours {op} {q} {m}: {res[(op, q, m)][0]}")
            ins = [os.path.join(src, f"tunnel.{f:04d}.exr") for f in frames]
            res["rw"] = timed([sys.executable, "-c", RW_CODE, str(PNG_LEVEL),
                               str(PNG_FILTERS[PNG_FILTER]), os.path.join(out, "rw.%04d.png")]
                              + ins, repeat, out)
            log(f"  {w}x{h} OIIO read+write: {res['rw'][0]}")
            pin = f"pfsin {shlex.quote(os.path.join(src, 'tunnel.%04d.exr'))} --frames 1:{n}"
            chains = {"pfs_pattanaik00": f"{pin} | pfstmo_pattanaik00 -t --fps 30 | pfsclamp | "
                                         f"pfsgamma -g 2.2 | pfsout p.%04d.png",
                      "pfs_durand02": f"{pin} | pfstmo_durand02 | pfsclamp | pfsgamma -g 2.2 | "
                                      f"pfsout d.%04d.png",
                      "pfs_rw": f"{pin} | pfsout rw_pfs.%04d.png"}
            for k, c in chains.items():
                if pfs_missing:
                    res[k] = (None, pfs_missing, None)
                else:
                    res[k] = timed("set -o pipefail; " + c, repeat, out, shell=True)
                log(f"  {w}x{h} {k}: {res[k][0]}")
        t_rw, t_pp, t_pd = res["rw"][0], res["pfs_pattanaik00"][0], res["pfs_durand02"][0]

        def cell(key):
            t, err, peak = res[key]
            return (f"{t:.2f}", f"{t / n * 1e3:.0f}", f"{n / t:.1f}",
                    "—" if peak is None else f"{peak:.0f}") if t else (err or "—", "", "", "")
        for op, q, m in CMD_RUNS:
            t = res[(op, q, m)][0]
            vs_pp = f"{t_pp / t:.1f}x" if t and t_pp else "—"
            vs_pd = f"{t_pd / t:.1f}x" if t and t_pd else "—"
            vs_rw = f"{t_rw / t:.0%}" if t and t_rw else "—"
            rows.append((f"{w}x{h}", f"ours {op} --quality {q} --model {m}", *cell((op, q, m)),
                         vs_pp, vs_pd, vs_rw))
            if not t or m != "none":          # the targets: like for like (the operator alone)
                continue
            if op in ("pattanaik00", "durand00"):
                if t_pp:
                    checks.append((f"{w}x{h}", f"{op} {q}", ">= 3x faster than the "
                                   "pfstmo_pattanaik00 chain", f"{t_pp / t:.1f}x",
                                   "PASS" if t_pp / t >= 3 else "FAIL"))
                if t_rw:
                    checks.append((f"{w}x{h}", f"{op} {q}", ">= 80% of read+write throughput",
                                   f"{t_rw / t:.0%}", "PASS" if t_rw / t >= 0.8 else "FAIL"))
            if op == "ledda04" and t_pd and (w, h) == (1920, 1080):
                checks.append((f"{w}x{h}", f"{op} {q}", ">= 5x faster than the pfstmo_durand02 "
                               "chain", f"{t_pd / t:.1f}x", "PASS" if t_pd / t >= 5 else "FAIL"))
        t1 = res["startup"][0]
        rows.append((f"{w}x{h}", "ours pattanaik00 balanced, 1 frame (start-up)",
                     f"{t1:.2f}" if t1 else res["startup"][1], "", "",
                     f"{res['startup'][2]:.0f}" if t1 and res["startup"][2] else "", "", "",
                     ""))
        for key, label in (("rw", "OIIO read + PNG write only (1 thread)"),
                           ("pfs_pattanaik00", "pfstools + pfstmo_pattanaik00 -t"),
                           ("pfs_durand02", "pfstools + pfstmo_durand02"),
                           ("pfs_rw", "pfsin \\| pfsout only")):
            rows.append((f"{w}x{h}", label, *cell(key), "", "", ""))
    lines.append(table(("size", "command", "wall s", "ms/frame", "frames/s", "peak RSS MiB",
                        "speed vs pfstmo_pattanaik00", "speed vs pfstmo_durand02",
                        "of read+write throughput"), rows))
    lines += ["", "Targets (printed, not enforced):", ""]
    lines.append(table(("size", "run", "target", "measured", "result"), checks) if checks
                 else "no target could be evaluated")
    for c in checks:
        log(f"  target {c[0]} {c[1]}: {c[2]}: {c[3]} {c[4]}")
    return lines + [""]


# --- report --------------------------------------------------------------------------------------

def pareto(points):
    """Indices of the points no other point beats in both time and error."""
    out = []
    for i, (t, e) in enumerate(points):
        if not any((t2 <= t and e2 <= e and (t2 < t or e2 < e)) for j, (t2, e2) in
                   enumerate(points) if j != i):
            out.append(i)
    return out


def plot(path: str, rows: list[Row], size) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    colours = dict(zip(OPERATORS, ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    markers = {"tier": "*", "display_encode": "s", "lut": "D", "bilateral": "o",
               "bilateral_sampling": "^", "flare_method": "v", "flare_per_octave": "P"}
    fig, ax = plt.subplots(figsize=(10, 6.5))
    floor = 1e-4
    for op in OPERATORS:
        pts = [(r.mean_t, r.worst(1), r) for r in rows if r.op == op and r.mean_t
               and r.worst(1) is not None and r.same_as is None]
        if not pts:
            continue
        for t, e, r in pts:
            big, est = r.cfg.knob == "tier", not r.t
            c = colours.get(op, "k")
            ax.scatter(t * 1e3, max(e, floor), marker=markers.get(r.cfg.knob, "o"),
                       s=160 if big else 40, facecolors="none" if est else c,
                       edgecolors="k" if big else c, zorder=3)
            near_tier = not big and any(
                q.cfg.knob == "tier" and abs(math.log(t2 / t)) < 0.05 and
                abs(math.log(max(e2, floor) / max(e, floor))) < 0.05 for t2, e2, q in pts)
            if not near_tier:
                ax.annotate(f"{op} {r.cfg.value}" if big else r.cfg.label,
                            (t * 1e3, max(e, floor)), fontsize=8 if big else 6,
                            xytext=(5, 4) if big else (4, -9), textcoords="offset points",
                            color=c, weight="bold" if big else "normal")
        front = sorted((pts[i] for i in pareto([(t, e) for t, e, _ in pts])), key=lambda p: p[0])
        ax.plot([p[0] * 1e3 for p in front], [max(p[1], floor) for p in front], "-",
                color=colours.get(op, "k"), alpha=0.5, lw=1.2, label=f"{op} (Pareto front)")
    for y, txt in ((1.0, "balanced bound (p99 ≤ 1)"), (3.0, "draft bound (p99 ≤ 3)")):
        ax.axhline(y, color="0.3", ls="--", lw=0.9)
        ax.text(0.01, y * 1.08, txt, transform=ax.get_yaxis_transform(), fontsize=8,
                color="0.3")
    for k, m in markers.items():
        ax.scatter([], [], marker=m, color="0.5", label=k)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(f"ms / frame at {size[0]}x{size[1]} (tone mapping + display encoding; log)")
    ax.set_ylabel(f"worst scene's p99 ΔE ITP vs the reference tier (log; < {floor} drawn at {floor})")
    ax.set_title("Speed against accuracy: quality tiers (stars) and single knobs from "
                 "balanced\n(hollow: time estimated, not measured)", fontsize=11)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=7, loc="upper right", ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def tier_rows(all_rows: list[Row], ops, sizes) -> tuple[list, list, list]:
    rows, verdict, notes = [], [], []
    for op in ops:
        for size in sizes:
            for tier in ("draft", "balanced", "reference"):
                r = next((x for x in all_rows if x.op == op and x.size == size and
                          x.cfg.knob == "tier" and x.cfg.value == tier), None)
                if r is None:
                    continue
                w, h = size
                t = r.mean_t
                est = "~" if (not r.t and r.est_t) else ""
                res = "ref"
                if tier in BOUNDS:
                    p = r.worst(1)
                    res = "—" if p is None else ("PASS" if p <= BOUNDS[tier] else "FAIL")
                    if p is not None:
                        verdict.append((op, tier, f"{w}x{h}", res, p))
                rows.append((op, tier, f"{w}x{h}", (est + fmt_ms(t)) if t else "—",
                             f"{w * h / t / 1e6:.1f}" if t else "—",
                             fmt_de(r.worst(0)), fmt_de(r.worst(1)), fmt_de(r.worst(2)), res,
                             "; ".join(r.errors)[:80]))
    return rows, verdict, notes


def diagnose(all_rows: list[Row], verdict) -> list[str]:
    """For each failing tier: the single knobs (from balanced) that exceed the bound,
    and those that bring it under."""
    out = []
    for op, tier, size, res, p in verdict:
        if res != "FAIL":
            continue
        bound = BOUNDS[tier]
        knobs = [r for r in all_rows if r.op == op and f"{r.size[0]}x{r.size[1]}" == size
                 and r.cfg.knob != "tier" and r.worst(1) is not None]
        if tier == "draft":
            from ocl_tonemap.backends.quality import QUALITY_TIERS
            t = QUALITY_TIERS["draft"]
            mine = {f"{k}={v}" for k, v in t.operator_options} | \
                {f"{k}={v}" for k, v in t.effects} | {f"display_encode={t.display_encode}"}
            bad = [r for r in knobs if r.cfg.label in mine and r.worst(1) > bound]
            why = ", ".join(f"`{r.cfg.label}` alone gives p99 {fmt_de(r.worst(1))}" for r in bad) \
                or "no single knob of the tier exceeds the bound alone: their errors add up"
        else:
            fix = [r for r in knobs if r.worst(1) <= bound]
            why = ("switching " + ", ".join(f"`{r.cfg.label}` (p99 {fmt_de(r.worst(1))}, "
                                             f"{fmt_ms(r.mean_t)} ms)" for r in fix)
                   + " brings it under the bound") if fix else \
                "no single knob brings it under the bound"
        tr = next(r for r in all_rows if r.op == op and f"{r.size[0]}x{r.size[1]}" == size
                  and r.cfg.knob == "tier" and r.cfg.value == tier)
        scn = ", ".join(f"{k} {fmt_de(v[1])}" for k, v in tr.de.items() if v[1] > bound)
        out.append(f"- **{op} {tier} at {size} FAILS** (p99 over the bound on: {scn}): {why}.")
    return out


def knob_md(rows: list[Row], op: str, size, plan: RefPlan, scenes) -> list[str]:
    w, h = size
    lines = [f"### {op}, {w}x{h}", "",
             f"Reference: {plan.describe(h)}; estimated per scene: float64 reference tier "
             f"{plan.est_s:.3g} s, OpenCL with the reference knobs {plan.est_ocl_s:.3g} s.", ""]
    out = []
    for r in rows:
        t = r.mean_t
        est = "~" if (not r.t and r.est_t) else ""
        per = "/".join(fmt_de(r.de[s][1]) if s in r.de else "—" for s in scenes)
        note = []
        if r.same_as:
            note.append(f"= {r.same_as}")
        if r.cfg.knob.startswith("flare"):
            note.append(f"flare ran on: {', '.join(r.flare) or 'none'}")
        if r.errors:
            note.append("; ".join(r.errors)[:100])
        out.append((r.cfg.knob, r.cfg.value, (est + fmt_ms(t)) if t else "—",
                    f"{w * h / t / 1e6:.1f}" if t else "—", fmt_de(r.worst(0)),
                    fmt_de(r.worst(1)), fmt_de(r.worst(2)), per, "; ".join(note)))
    lines.append(table(("knob", "value", "ms/frame", "MPix/s", "ΔE median", "ΔE p99",
                        "ΔE max", "p99 per scene (" + "/".join(scenes) + ")", "note"), out))
    return lines + [""]


# --- main ----------------------------------------------------------------------------------------

def parse_sizes(text: str) -> list[tuple]:
    out = []
    for part in text.split(","):
        w, _, h = part.strip().lower().partition("x")
        out.append((int(w), int(h)))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="640x360 only, 2 scenes, no "
                    "whole-command section, fewer repetitions (< 4 minutes)")
    ap.add_argument("--sizes", help="WxH,... (default 640x360,1920x1080,3840x2160; the knob "
                    "sweep runs at sizes up to 1920x1080, larger sizes get the tiers only)")
    ap.add_argument("--operators", help="comma list (default all four)")
    ap.add_argument("--scenes", help="comma list of " + ", ".join(n for n, _, _ in SCENES))
    ap.add_argument("--repeat", type=int, default=1, help="whole-command repetitions (median)")
    ap.add_argument("--reps", type=int, help="timed frames per configuration and scene "
                    "(default 3, --quick 2; 1 at 4K)")
    ap.add_argument("--ref-budget", type=float, help="seconds the reference may take for all "
                    "scenes at one size and operator before a cheaper reference is used "
                    "(default 180, --quick 45)")
    ap.add_argument("--no-commands", action="store_true", help="skip the whole-command section")
    ap.add_argument("--sections", default="tiers,roofline,commands",
                    help="comma list of the sections to run: tiers (the knob sweep, tiers "
                    "and Pareto plot), roofline, commands (default all; a long run can be "
                    "split over several commands, each with its own --out)")
    add_out_args(ap, "speed_accuracy.md")
    ap.add_argument("--roofline-child", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    ops = [o.strip() for o in (a.operators or ",".join(OPERATORS)).split(",") if o.strip()]
    warnings.simplefilter("ignore")
    if a.roofline_child:
        (w, h), = parse_sizes(a.roofline_child)
        print(json.dumps(roofline_child(w, h, ops, max(1, a.repeat))))
        return 0
    t_start = time.perf_counter()
    sizes = parse_sizes(a.sizes) if a.sizes else ([SIZES[0]] if a.quick else list(SIZES))
    scene_names = [s.strip() for s in a.scenes.split(",")] if a.scenes else \
        (list(QUICK_SCENES) if a.quick else [n for n, _, _ in SCENES])
    reps = a.reps or (2 if a.quick else 3)
    budget = a.ref_budget if a.ref_budget is not None else (45.0 if a.quick else 180.0)
    sections = {x.strip() for x in a.sections.split(",") if x.strip()}
    bad = sections - {"tiers", "roofline", "commands"}
    if bad:
        ap.error(f"--sections: unknown {', '.join(sorted(bad))}")

    from ocl_tonemap.backends.opencl.runtime import describe_device, get_runtime
    rt = get_runtime()
    col = Colour()
    scenes = Scenes(scene_names)
    planner = RefPlanner(scenes, col, budget)
    sweep_sizes = [s for s in sizes if s[0] * s[1] <= SWEEP_MAX_PIXELS]
    tier_only = [s for s in sizes if s[0] * s[1] > SWEEP_MAX_PIXELS]
    run_sizes = (sweep_sizes, tier_only) if "tiers" in sections else ([], [])
    all_rows, plans, knob_sections = [], {}, []
    for size in run_sizes[0]:
        for op in ops:
            rows, plan = sweep(op, size, knob_configs(op), scenes, col, planner, reps)
            all_rows += rows
            plans[(op, size)] = plan
            knob_sections += knob_md(rows, op, size, plan, scenes.names)
    for size in run_sizes[1]:
        for op in ops:
            cfgs = [Config("tier", t, t) for t in ("draft", "balanced", "reference")]
            rows, plan = sweep(op, size, cfgs, scenes, col, planner, 1)
            all_rows += rows
            plans[(op, size)] = plan
    t_sweep = time.perf_counter() - t_start

    # -- roofline
    rsize = (1920, 1080) if (1920, 1080) in sizes else max(sweep_sizes or sizes,
                                                            key=lambda s: s[0] * s[1])
    rf = None
    if "roofline" in sections:
        log(f"== roofline at {rsize[0]}x{rsize[1]}")
        rf = roofline(*rsize, ops, 2 if a.quick else 3)

    # -- whole command
    cmd_lines = []
    if not (a.quick or a.no_commands) and "commands" in sections:
        log("== whole command, 60 frames")
        cmd_sizes = [s for s in ((640, 360), (1920, 1080)) if s in sizes] or [(640, 360)]
        cmd_lines = whole_command(cmd_sizes, max(1, a.repeat))

    # -- report
    psize = (1920, 1080) if any(r.size == (1920, 1080) for r in all_rows) else \
        max(sweep_sizes or sizes, key=lambda s: s[0] * s[1])
    out = out_path(a, "speed_accuracy.md")
    png = os.path.splitext(out)[0] + ".png"
    prows = [r for r in all_rows if r.size == psize]
    if prows:
        plot(png, prows, psize)
    trows, verdict, _ = tier_rows(all_rows, ops, sizes)
    sanity = col.sanity()
    cmdline = "python -m benchmarks.speed_accuracy" + "".join(
        " " + shlex.quote(x) for x in (argv if argv is not None else sys.argv[1:]))
    lines = ["# Speed against accuracy: the quality tiers and their knobs", "",
             f"- device: {describe_device(rt.device)}",
             f"- host: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
             f"Python {platform.python_version()}, NumPy {np.__version__}, colour-science "
             f"{colour_science().__version__}",
             f"- date: {datetime.datetime.now().astimezone().isoformat(timespec='seconds')}",
             f"- command: `{cmdline}`",
             f"- took {(time.perf_counter() - t_start) / 60:.1f} min (sweep and tiers "
             f"{t_sweep / 60:.1f} min)",
             "- **machines are noisy: compare ratios, not absolute times.** The CPU device is "
             "shared with the host: PoCL's threads on every core.", ""]
    lines += ["## Method", "",
              f"- Scenes ({len(scenes.names)}): " + "; ".join(scenes.describe()) + "."
              + (f" {scenes.note}." if scenes.note else ""),
              "- Photographs are centre-cropped to 16:9 and resized with OIIO (box filter "
              "down, triangle up: 3840x2160 and 1920x1080 are upsampled from 910x512, smooth), "
              "then scaled to the log-average.",
              "- Steady state: each configuration gets a fresh `Tonemapper`, fully adapted to "
              "its first frame (the default without `preadapt`); that frame's output is "
              "compared. The same frame is then processed again (dt = 1/30 s; the state does "
              "not move) and timed.",
              f"- ms/frame = `Tonemapper.process` + the display encoding of the tier (the "
              f"device table: `ColourPipeline.encode_fast`; OCIO: `encode`), the median of "
              f"{reps} frames after the warm-up frame (fewer where a frame takes over "
              f"{REP_BUDGET_S / reps:.1f} s; 1 at sizes above 1080p), averaged over the scenes. "
              "File I/O is in section 4.",
              f"- Colour: OCIO config `{col.source}`, display `{col.display_name}`, view "
              f"`{col.view}` (the CLI's defaults). `auto` resolves to **{col.auto}**: "
              f"{col.notes['auto']}.",
              "- ΔE ITP (ITU-R BT.2124, `colour.delta_E(method='ITP')`): code values clipped "
              "to [0, 1] (what an 8-bit file holds; not quantised) -> OCIO inverse display/view "
              "-> display-linear BT.709 -> cd/m^2 with the display model "
              f"(`DisplaySpec.from_signal`: 1.0 -> white {col.display.white_cd:g} cd/m^2, "
              f"black {col.display.black_cd:g} cd/m^2 added as the display shows it) -> "
              "BT.2020 -> ICtCp (`ocl_tonemap/models/ictcp.py`, BT.2100 PQ on absolute "
              "cd/m^2 / 10000; equal to colour-science's `RGB_to_ICtCp`, tested; the "
              "same measure the mechanism plan bounds). Sanity check: a grey at 100 cd/m^2 against 101 cd/m^2 (1%) "
              f"gives ΔE ITP **{sanity['one_pct_100cd']:.2f}** (order 1, as a JND should); "
              f"one 8-bit code step of code value 128/255 gives {sanity['code_step'][8]:.2f}, "
              f"one 10-bit step {sanity['code_step'][10]:.2f}.",
              "- Reference per operator and size: the float64 `reference` tier where its "
              f"estimated time for all scenes is under {budget:g} s (`--ref-budget`; the "
              "estimate scales the mean time per scene at the last size where it ran, else one "
              "320x180 frame of the darkest scene, by pixels x bilateral taps (global "
              f"operators: pixels^{PIXEL_EXPONENT}, the exact flare's FFT)); else the OpenCL "
              "backend with the reference tier's knobs (exact bilateral, lut 0, exact flare, "
              "OCIO; float32); else, for ledda04/kirk11, that with the exact filter on a band "
              "of rows through the middle of the frame, the other rows through the grid at "
              "q_s = q_r = 4 (they only feed the frame's global log-averages and base-layer "
              f"statistics), in 1/{BAND_SHARE:g} of the budget, and ΔE measured on the band; "
              "else none (ΔE `—`). `~` times are estimates, not measured (the float64 tier's "
              "and the exact filter's where they were not run on whole frames). The line "
              "`Reference:` above each knob table says which.", ""]
    if all_rows:
        lines += ["## 1. Tiers", "",
                  "Worst scene for each ΔE statistic. Rule: `balanced` p99 ≤ 1 and `draft` p99 ≤ 3 "
                  "on every scene. The reference row's ΔE is against itself where it is the "
                  "float64 tier, against the OpenCL exact reference otherwise.", ""]
        lines.append(table(("operator", "tier", "size", "ms/frame", "MPix/s", "ΔE median",
                            "ΔE p99", "ΔE max", "rule", "errors"), trows))
        lines.append("")
        for (op, size), plan in plans.items():
            if plan.kind != "float64":
                lines.append(f"- {op} {size[0]}x{size[1]}: reference = {plan.describe(size[1])} "
                             f"(float64 would take ~{plan.est_s:.0f} s per scene).")
        lines.append("")
        diag = diagnose(all_rows, verdict)
        n_fail = sum(1 for v in verdict if v[3] == "FAIL")
        lines += [f"**{len(verdict) - n_fail} of {len(verdict)} tier checks pass.**", ""] + diag + [""]
        # Pareto list
        lines += [f"## 2. Pareto-optimal settings at {psize[0]}x{psize[1]}", "",
                  f"![speed/accuracy]({os.path.basename(png)})", "",
                  "Per operator, the settings no other setting beats in both ms/frame and worst "
                  "p99 ΔE (duplicates of another setting left out):", ""]
        for op in ops:
            pts = [r for r in prows if r.op == op and r.mean_t and r.worst(1) is not None
                   and r.same_as is None]
            front = sorted((pts[i] for i in pareto([(r.mean_t, r.worst(1)) for r in pts])),
                           key=lambda r: r.mean_t)
            if front:
                lines.append(f"- {op}: " + " → ".join(
                    f"`{r.cfg.label}` ({fmt_ms(r.mean_t)} ms, p99 {fmt_de(r.worst(1))})"
                    for r in front))
        lines += ["", "## Knob sweep", "",
                  "One knob changed from `balanced` at a time (`= X`: resolves to the same work as "
                  "row X, its numbers repeated). Knobs an operator lacks are not listed.", ""]
        lines += knob_sections
    else:
        lines += ["## 1. Tiers", "", "Not run (--sections).", ""]
    if rf:
        lines += roofline_md(rf, *rsize)
    else:
        why = ("The profiling run failed (see the log)." if "roofline" in sections
               else "Not run (--sections).")
        lines += ["## 3. Roofline", "", why, ""]
    if cmd_lines:
        lines += cmd_lines
    else:
        why = ("Not run (--sections)." if "commands" not in sections
               else "Skipped (--quick or --no-commands)." if a.quick or a.no_commands
               else "No results (see the log).")
        lines += ["## 4. Whole command", "", why, ""]
    text = "\n".join(lines) + "\n"
    tmp = out + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(text)
    os.replace(tmp, out)
    print(text)
    log(f"wrote {out}" + (f" and {png}" if prows else "")
        + f" in {(time.perf_counter() - t_start) / 60:.1f} min")
    return 0


if __name__ == "__main__":
    sys.exit(main())
