"""Flare: light sources scattered in the eye (Spencer et al. 1995, as Durand & Dorsey
2000, Sec. 6 use it), added to the scene in cd/m^2 before tone mapping.

Slot: optical (its veil adapts the eye: before the metering). Needs: the frame's
adaptation levels and source limit; on the device, a blur. The model is
``models/spencer1995.py``; it is computed on the host by ``backends/flare_exec.py``,
whole on the device by ``backends/opencl/flare.py``; :class:`Flare` is the effect.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ..backends import flare_exec as fx
from ..backends.base import Later
from ..models import spencer1995 as fl
from ..models.convolution import EDGE_ZERO
from ..models.photometry import Y_WEIGHTS
from ..base.quantities import AGE, Quantity, Text, word_or
from ..base.resources import cached_json
from .base import Effect, EffectOption

log = logging.getLogger("ocl_tonemap")
#: Default angular width of the image, degrees (the paper's 50-degree example, Sec. 8).
DEFAULT_FOV = 50.0


def _check_method(v):
    if v not in ("fast", "exact"):
        raise ValueError(f"--flare-method must be fast or exact (got {v!r})")


#: The field of view, an option of the flare and of acuity (one option of both).
FOV_OPTION = EffectOption("fov_deg", "--fov", "angular width of the image (default: the "
                          "file's projection, a Radiance VIEW or an equirectangular "
                          "panorama's metadata, else 50; 360: a 2:1 panorama)",
                          metavar="DEGREES", value=DEFAULT_FOV,
                          decl=Quantity("angular width of the image", "degrees", 0.0, 360.0,
                                        above=True))

#: The observer's age: the flare's pupil (Watson & Yellott 2012) and glare (CIE 146's
#: equation at that age); the visibility threshold's age factor (Adrian 1989). Default
#: 25 years; ``spencer`` (spencer1995.LITERAL_AGE): the flare as Eq. 8 prints it with
#: Moon & Spencer's pupil, the threshold at 25 (docs/models.md, "Observer age").
AGE_OPTION = EffectOption("age", "--age", "observer's age: pupil, glare, threshold (default "
                          "25; spencer: the flare's Eq. 8 as printed)", metavar="YEARS",
                          value=fl.DEFAULT_AGE,
                          decl=Text("observer's age", f"{AGE.range_text()} or "
                                    f"{fl.LITERAL_AGE}", word_or(AGE, fl.LITERAL_AGE)))


def run(settings, rgb: np.ndarray, G_rod: float, G_cone: float, lim: float, blur=None,
        device=None):
    """(new rgb or None, info) for one frame in cd/m^2; ``lim``: the source limit
    (``models/spencer1995.py`` source_limit); ``blur(img, taps, edge)``: the device's blur for the
    host-driven pyramid; ``device``: the fast method made whole on the device
    (``backends/opencl/flare.py``), used where the frame fits it."""
    if settings.flare == "off":
        return None, {"ran": False}
    if not math.isfinite(lim):
        return None, {"ran": False, "reason": "no light sources", "source_limit_cd": lim}
    h, w = rgb.shape[:2]
    if device is not None and settings.flare_method == "fast" and device.fits(h, w):
        return _run_on_device(settings, rgb, G_rod, G_cone, lim, device)
    if settings.flare == "auto":
        Ymax = float(np.max(rgb.reshape(-1, 3) @ Y_WEIGHTS, initial=0.0))
        if not Ymax > lim:
            return None, {"ran": False, "reason": "no light sources", "source_limit_cd": lim}
    dev = None if blur is None else (lambda img, taps: blur(img, taps, EDGE_ZERO))
    out, info = fx.apply_flare(rgb, G_cone, G_rod, settings.fov_deg, settings.flare_method,
                               settings.flare_threshold, settings.flare_per_octave, dev, lim=lim,
                               age=settings.age)
    info["ran"] = info["sources"] > 0
    info["source_limit_cd"] = lim
    return out.astype(np.float32), info


def device_plan(settings, shape, G_rod: float, G_cone: float):
    """(pupil mm, fast plan) of a frame's flare on the device."""
    h, w = (int(v) for v in shape[:2])
    D = fl.observer_pupil(G_cone, G_rod, settings.fov_deg, (h, w), settings.age)
    plan = fl.fast_plan((h, w), settings.fov_deg / w, D, settings.flare_per_octave,
                        fit=stored_fit((h, w), settings.fov_deg / w, settings.flare_per_octave),
                        age=settings.age)
    return D, plan


def start_on_device(settings, rgb, G_rod: float, G_cone: float, lim: float, device) -> None:
    """The first passes of the frame's flare on the device, enqueued before the frame is
    planned (``DeviceFlare.start``): :func:`run` goes on from them."""
    if settings.flare != "off" and settings.flare_method == "fast" and math.isfinite(lim) \
            and device.fits(*rgb.shape[:2]):
        _, plan = device_plan(settings, rgb.shape, G_rod, G_cone)
        device.start(rgb, plan, lim)


def _run_on_device(settings, rgb, G_rod: float, G_cone: float, lim: float, device):
    """:func:`run` with the pyramid on the device: the same plan and info."""
    D, plan = device_plan(settings, rgb.shape, G_rod, G_cone)
    out, sources, S_sum, F_sum = device.apply(rgb, plan, lim)
    if sources == 0 and settings.flare == "auto":
        return None, {"ran": False, "reason": "no light sources", "source_limit_cd": lim}
    info = {"sources": sources, "pupil_mm": D,
            "weights": list(fl.flare_weights(D, settings.age)),
            "method": "fast", "threshold": settings.flare_threshold, "source_limit_cd": lim,
            "ran": sources > 0}
    if sources == 0:
        return None, info
    # the flared sums come down with the frame's next statistics (the metering's)
    info["energy_in_frame"] = Later(lambda: float(F_sum().sum() / max(S_sum.sum(), 1e-300)))
    return out, info


def stored_fit(shape, deg_per_px: float, per_octave: int) -> fl.GaussianFit:
    """:func:`~ocl_tonemap.models.spencer1995.fit_gaussians` for a frame size, kept in
    the user's cache (``resources.cached_json``): the fit is ~50 ms of every start of a
    run with flare, the same for every frame of that size and field of view."""
    h, w = (int(v) for v in shape)

    def compute():
        f = fl.fit_gaussians((h, w), float(deg_per_px), int(per_octave))
        return {"sigmas": list(f.sigmas), "l2_error": {k: float(v) for k, v in f.l2_error.items()},
                "weights": {k: np.asarray(v, np.float64).tolist() for k, v in f.weights.items()}}
    doc = cached_json("flare-fits", [h, w, float(deg_per_px).hex(), int(per_octave)], compute)
    return fl.GaussianFit(tuple(doc["sigmas"]),
                          {k: np.asarray(v, np.float64) for k, v in doc["weights"].items()},
                          dict(doc["l2_error"]))


#: Pixels of working rows made into the source part at a time (memory).
SOURCE_PART_PIXELS = 1 << 18


class BandedFlare:
    """The flare of a frame that is never whole in memory (``Tonemapper.process_stream``):
    :func:`~ocl_tonemap.backends.flare_exec.banded_fast` -- the fast method's pyramid
    cut at a level whose image fits the band budget, that level built from the
    source part band by band (one pass over the frame), the finer levels and the
    delta per band from the rows around it. The same arithmetic on every pixel as
    the whole frame's ``fast`` flare: equal to it bit for bit in
    tests/effects/test_stream_effects.py (device blurs; the float64 reference: 1e-12 of
    the largest flare). ``exact`` is not banded (its FFT spans the frame): streamed
    frames get the fast method (said in the info), whose error against ``exact``
    measured on frames with lamps inside them is in tests/effects/test_stream_effects.py.

    ``rgb_rows(a, b)``: rows [a, b) of the working frame (cd/m^2, float32);
    ``max_pixels``: the split level's image and the bands of the pass that builds
    it hold at most this many pixels; ``block_pixels``: flared rows are made this
    many pixels at a time (~100 bytes a pixel while they are made, 12 kept)."""

    def __init__(self, settings, shape, G_rod: float, G_cone: float, lim: float, rgb_rows,
                 max_pixels: int, blur=None, block_pixels: int | None = None):
        self.s, self.shape, self.lim = settings, tuple(shape[:2]), float(lim)
        self.rgb_rows = rgb_rows
        self.blur = None if blur is None else (lambda img, taps: blur(img, taps, EDGE_ZERO))
        h, w = self.shape
        self.D = fl.observer_pupil(G_cone, G_rod, settings.fov_deg, (h, w), settings.age)
        self.plan = fx.banded_fast((h, w), settings.fov_deg / w, self.D,
                                   settings.flare_per_octave, max_pixels, settings.age)
        self.max_rows = max(1, int(max_pixels) // max(w, 1))
        self.coarse = None
        self.sources = 0
        self.S_sum = 0.0
        self.F_sum, self._swept = 0.0, 0
        self.block_rows = max(1, int(block_pixels or max_pixels) // max(w, 1))
        self._out, self._c0 = np.zeros((0, w, 3), np.float32), 0
        self.weight = 1.0                           # the plan's weight (0..1]

    def _S(self, rgb):
        """The source part of working rows (float64), made a few rows at a time
        (source_part's temporaries on a few rows; the same values)."""
        out = np.empty(rgb.shape[:2] + (3,), np.float64)
        step = max(1, SOURCE_PART_PIXELS // max(1, rgb.shape[1]))
        for y in range(0, len(rgb), step):
            out[y:y + step] = fl.source_part(rgb[y:y + step, :, :3], 1.0, self.lim)
        return out

    def build(self) -> None:
        """One pass over the frame: its source part decimated to the split level
        in bands of that level's rows (each band from the source rows it is made
        of, a few rows of halo read twice), the sources counted once."""
        h, w = self.shape
        plan, L = self.plan, self.plan.split
        r0, r1 = plan.rows(L)
        step = max(1, self.max_rows // 2 ** L)
        level = np.empty((r1 - r0, plan.sizes[L][1] + 2 * fx.level_margin(L), 3), np.float64)
        counted = 0
        for c0 in range(r0, r1, step):
            c1 = min(r1, c0 + step)
            a0, a1 = plan.source_rows(L, c0, c1)[0]
            S = self._S(self.rgb_rows(a0, a1))
            new = S[max(0, counted - a0):]
            self.sources += int(np.count_nonzero(new.any(axis=-1)))
            self.S_sum += float(new.sum())
            counted = max(counted, a1)
            level[c0 - r0:c1 - r0] = fx.down_rows(plan, S, a0, c0, c1)
        if self.sources:
            self.coarse = fx.banded_coarse(plan, level, self.blur)

    def rows(self, y0: int, y1: int) -> np.ndarray:
        """Rows [y0, y1) of the flared frame (float32 working rgb, cd/m^2). Made
        ``block_rows`` at a time (the halo's share of the work falls as the block
        grows) and kept until a request leaves them."""
        c0, c1 = self._c0, self._c0 + len(self._out)
        if not (c0 <= y0 and y1 <= c1):
            b1 = min(self.shape[0], max(y1, y0 + self.block_rows))
            self._out = self._out[:0]
            self._out, self._c0 = self._make(y0, b1), y0
            c0 = y0
        return self._out[y0 - c0:y1 - c0]

    def _make(self, y0: int, y1: int) -> np.ndarray:
        got = {}

        def source_rows(a, b):
            got["rgb"], got["a"] = self.rgb_rows(a, b), a
            return self._S(got["rgb"])
        F, S = fx.banded_rows(self.plan, y0, y1, source_rows, self.coarse, self.blur)
        out = np.array(got["rgb"][y0 - got["a"]:y1 - got["a"], :, :3], np.float64)
        got.clear()
        if y0 <= self._swept < y1:                  # the first sweep: the energy kept
            self.F_sum += float(F[self._swept - y0:].sum())
            self._swept = y1
        if self.weight < 1.0:                       # the plan blends it in or out
            out += self.weight * (F - S)
        else:
            out -= S                                # rgb - S + F, as apply_flare
            out += F
        return out.astype(np.float32)

    def energy_in_frame(self) -> float | None:
        """F.sum / S.sum of the whole-frame flare, once a sweep has seen every row."""
        if self._swept < self.shape[0]:
            return None
        return float(self.F_sum / max(self.S_sum, 1e-300))


def stream(settings, shape, G_rod: float, G_cone: float, lim: float, rgb_rows,
           max_pixels: int, blur=None, max_Y: float | None = None,
           block_pixels: int | None = None, weight: float = 1.0):
    """(:class:`BandedFlare` or None, info) for a frame in row bands: the info of
    :func:`run` (``energy_in_frame`` once the frame has been swept: see
    :meth:`BandedFlare.energy_in_frame`). ``max_Y``: the frame's largest luminance
    where known (skips the pass that looks for sources on ``auto``)."""
    if settings.flare == "off":
        return None, {"ran": False}
    if not math.isfinite(lim) or (settings.flare == "auto" and max_Y is not None
                                  and max_Y <= lim * (1.0 - 1e-5)):
        return None, {"ran": False, "reason": "no light sources", "source_limit_cd": lim}
    bf = BandedFlare(settings, shape, G_rod, G_cone, lim, rgb_rows, max_pixels, blur,
                     block_pixels)
    bf.weight = float(weight)
    bf.build()
    if settings.flare == "auto" and bf.sources == 0:
        return None, {"ran": False, "reason": "no light sources", "source_limit_cd": lim}
    info = {"sources": bf.sources, "pupil_mm": bf.D,
            "weights": list(fl.flare_weights(bf.D, settings.age)),
            "method": "fast", "threshold": settings.flare_threshold, "source_limit_cd": lim,
            "ran": bf.sources > 0}
    if settings.flare_method != "fast":
        info["streamed"] = "the fast method (exact needs the whole frame)"
    if bf.sources == 0:
        return None, info
    return bf, info


class Flare(Effect):
    """The flare as an effect: whole frames on the host or, with the fast method and
    a device that holds the frame, whole on the device (its first passes started
    before the frame is planned, :meth:`start`); frames in bands through
    :class:`BandedFlare`. The plan's weight blends it in or out."""

    name = "flare"
    slot = "optical"
    help = "glare of light sources (Spencer et al. 1995)"
    gated = True
    blends = True
    capabilities = frozenset({"host", "device", "banded"})
    options = (
        FOV_OPTION,
        AGE_OPTION,
        EffectOption("flare_method", "--flare-method", "fast: Gaussians on a pyramid "
                     "(default); exact: FFT of the full PSF", choices=("fast", "exact"),
                     check=_check_method, value="fast"),
        EffectOption("flare_threshold", "--flare-threshold", "light sources are pixels "
                     "above this x the adaptation level (default 7)", metavar="X",
                     value=fl.DEFAULT_THRESHOLD,
                     decl=Quantity("flare source threshold", "x the adaptation level",
                                   0.0, 1e6, above=True)),
        EffectOption("flare_per_octave", "--flare-sampling", "fast flare: Gaussians per "
                     "octave (default 1)", metavar="N", value=1,
                     decl=Quantity("Gaussians per octave", "", 1, 4, integer=True)),
    )

    def __init__(self, fx):
        super().__init__(fx)
        self._dev = None                # the fast method whole on the device, made on use

    def _device(self):
        s = self.fx.s
        if s.flare != "off" and s.flare_method == "fast" and self._dev is None:
            self._dev = self.fx.backend.flare_device()
        return self._dev

    def host(self, ctx, rgb):
        """(new rgb or None, info) of a whole frame (``rgb`` a device image where
        :meth:`on_device`: the new one is then one too)."""
        dev = self._device()
        new, info = run(self.fx.s, rgb, ctx.G_rod, ctx.G_cone, ctx.lim, self.fx.blur, dev)
        if dev is not None:
            dev.discard()                     # start()'s passes, where the plan skipped it
        w = self.fx.weight(self.name)
        if new is not None and w < 1.0:       # blended in or out (the plan's ramp)
            old = np.asarray(rgb, np.float32)[..., :3]
            new = (old + w * (np.asarray(new, np.float32) - old)).astype(np.float32)
            info["weight"] = w
        return new, info

    device = host

    def start(self, ctx, rgb) -> None:
        """Before the frame is planned: its first passes on the device, where the frame
        has a source (``max_Y`` above the source limit) and the flare may run (on, or
        ``auto`` for the plan to decide): the device makes them while the host plans;
        :meth:`host` goes on from them, or drops them."""
        dev = self._device_for(self.fx.settings)
        if dev is not None and ctx.max_Y is not None and ctx.max_Y > ctx.lim:
            start_on_device(self.fx.settings, rgb, ctx.G_rod, ctx.G_cone, ctx.lim, dev)

    def _device_for(self, settings):
        if settings.flare != "off" and settings.flare_method == "fast" and self._dev is None:
            self._dev = self.fx.backend.flare_device()
        return self._dev

    def drop_started(self) -> None:
        """Drop :meth:`start`'s passes a frame left (one that failed before its flare)."""
        if self._dev is not None:
            self._dev.discard()

    def on_device(self, h: int, w: int) -> bool:
        """Whether this frame's flare runs whole on the device (the fast method, a device
        that holds the frame): its working frame can stay there."""
        dev = self._device()
        return dev is not None and dev.fits(h, w)

    def metered_weight(self, max_Y: float | None, lim: float) -> float | None:
        """Its weight in the frame that is metered (the plan's: ramps and hysteresis
        included), None where no pixel can be a source (then no weight changes the
        frame): what a shot's integrate pass checks its statistics by."""
        if self.asked == "off" or not (max_Y is None or max_Y > lim):
            return None
        return float(self.fx.weight(self.name)) if self.mode != "off" else 0.0

    def banded(self, ctx, rows, max_pixels: int, block_pixels: int):
        """The flare of a frame in row bands, before its metering pass: (a
        :class:`BandedFlare` or None, functions to call once the metering pass has
        swept the frame: the share of light kept in it). ``rows``: the working rows
        (``pipeline/banded.py`` ``WorkingRows``)."""
        fxr = self.fx
        flare, ctx.eff["flare"] = stream(fxr.s, (rows.h, rows.w), ctx.G_rod, ctx.G_cone,
                                         ctx.lim, rows.get, max_pixels, fxr.blur, ctx.max_Y,
                                         block_pixels, fxr.weight(self.name))
        if "streamed" in ctx.eff["flare"] and "streamed flare" not in fxr.said:
            fxr.said.add("streamed flare")
            log.warning("flare: streamed frames use --flare-method fast (the exact method's FFT "
                        "needs the whole frame)")
        if flare is None:
            return None, []

        def done(info=ctx.eff["flare"]):
            e = flare.energy_in_frame()
            if e is not None:
                info["energy_in_frame"] = e
        return flare, [done]
