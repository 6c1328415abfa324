"""The run of one observer over a sequence of frames.

Data flows one way per frame:
    pixels (working space) x luminance scale -> cd/m^2 (bad-value policy)
    -> optical effects (flare) -> **measure** (metering, local levels)
    -> **integrate** (advance the adaptation state and the effects' time courses)
    -> seen effects (Purkinje shift) -> **apply** (per-pixel operator)
    -> display effects -> display-linear (1.0 = display unit).
The three phases can be called separately (:meth:`Tonemapper.measure`,
:meth:`~Tonemapper.integrate`, :meth:`~Tonemapper.apply`); :meth:`Tonemapper.process`
chains them. The operator says what each phase computes (``operators/``), the
backend's schedule how (``backends/``). OCIO display encoding and file I/O wrap
this in ``sequence.py`` / the CLI; :class:`Tonemapper` is the Python API for a
compositing pipeline step.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from .alpha import restore_alpha, straight_colour
from .backends import make_backend
from .backends.plan import quality_tier
from .effects import EffectSettings, Effects
from .effects.stages import metered_weight, optical_effects, seen_effects
from .mechanisms import MechanismPlan
from .models import spencer1995 as fl
from .models.display import DisplaySpec, display_for
from .models.metering import MeteringSpec
from .models.photometry import RepairCounts, Y_WEIGHTS
from .operators import get_operator
from .operators.base import Frame, FrameStats, ModelOperator
from .state import AUTO_SCALE_KEY, AdaptationState
from .streaming import (STREAM_EFFECT_BANDS, SceneBands, WorkingRows, alpha_sink,
                        stream_flare, stream_seen)

log = logging.getLogger("ocl_tonemap")


@dataclass
class FrameInfo:
    """What happened on one frame (also written to the output's metadata)."""

    frame: int | None
    time_s: float
    dt: float
    G_rod: float
    G_cone: float
    repairs: RepairCounts
    state: AdaptationState
    params: dict = field(default_factory=dict)
    effects: dict = field(default_factory=dict)
    #: The frame's mechanism plan: weights (mechanism -> 0..1), predictions, analysis.
    plan: dict = field(default_factory=dict)


@dataclass
class FrameResult:
    """One mapped frame, as a value (:meth:`Tonemapper.process_frame`)."""

    output: np.ndarray         # display-linear float32 (H x W x 3 or 4), or code values
    alpha: tuple | None        # (alpha, empty mask, premultiplied?) of an RGBA frame
    info: FrameInfo
    encoded: bool = False      # ``output`` holds code values of the frame's ``encoding``


def as_float_pixels(frame) -> np.ndarray:
    """Pixels as float32, integers normalised as OIIO does (unsigned: 0..max -> 0..1,
    signed: -max..max -> -1..1); booleans, complex and non-numeric arrays refused."""
    a = np.asarray(frame)
    if a.dtype == bool or not (np.issubdtype(a.dtype, np.number)) or \
            np.issubdtype(a.dtype, np.complexfloating):
        raise ValueError(f"frame pixels must be real numbers (got dtype {a.dtype})")
    if np.issubdtype(a.dtype, np.integer):
        return (a.astype(np.float64) / float(np.iinfo(a.dtype).max)).astype(np.float32)
    return a


class Tonemapper:
    """Time-dependent tone mapping of frames for one observer.

    Parameters
    ----------
    operator : registry name (``pattanaik00``; ``operators.registry()`` lists them).
    backend : ``"opencl"``, ``"reference"`` (float64 NumPy) or ``"auto"``; default
        (None): the quality tier's, with OpenCL falling back to the reference backend
        with a warning where no OpenCL device works (``backends.resolve_backend``).
    metering : metering spec string or :class:`MeteringSpec` (``logmean``).
    display : the display observer (:class:`DisplaySpec`); SDR 100 cd/m^2 by default.
    preadapt : ``(L_cd, seconds_or_None)`` initial adaptation; default: fully
        adapted to the first frame.
    state : an :class:`AdaptationState` to resume from.
    device : OpenCL device spec (see ``backends.opencl.runtime.choose_device``).
    max_band_pixels : process larger frames in row bands (device memory).
    options : operator options (the operator's ``options`` specs; e.g. durand00:
        ``tint``, ``lut``; ledda04: ``sigma_spatial``, ``local_strength`` ...).
    effects : :class:`~ocl_tonemap.effects.EffectSettings` (flare, acuity, chromatic
        adaptation, Purkinje); default: the operator's defaults.
    plugin_effects : names of installed effect plugins to run (entry points).
    quality : ``draft``, ``balanced`` (default) or ``reference``: the defaults of every
        speed/accuracy knob (``backends/plan.py`` ``QUALITY_TIERS``); the backend,
        options and effects given here win over the tier's.
    model : ``auto`` (default): each frame gets the mechanisms it needs, within one
        JND of ``full`` (``mechanisms/``); ``full``: every effect the operator can
        take, on; ``none``: the operator alone. Used where ``effects`` is not given.
    """

    def __init__(self, operator: str = "pattanaik00", backend: str | None = None,
                 metering: str | MeteringSpec | None = "logmean",
                 display: DisplaySpec | None = None,
                 preadapt: tuple[float, float | None] | None = None,
                 state: AdaptationState | None = None, device: str | None = None,
                 max_band_pixels: int | None = None, options: dict | None = None,
                 effects: EffectSettings | None = None, plugin_effects=(),
                 quality: str | None = None, model: str = "auto"):
        self.operator_name = operator
        op_cls = get_operator(operator)
        tier = quality_tier(quality)
        self.quality = tier.name
        backend = backend or ("auto" if tier.backend == "opencl" and device is None
                              else tier.backend)
        options = {**tier.options_for(o.name for o in op_cls.options), **(options or {})}
        self.model = model
        if effects is None:
            effects = EffectSettings.for_operator(operator, model,
                                                  paper=options.get("mode") == "paper",
                                                  **dict(tier.effects))
        self.backend = make_backend(backend, device, max_band_pixels)
        self.metering = metering if isinstance(metering, MeteringSpec) else MeteringSpec.parse(metering)
        self.display = display or display_for("sRGB - Display")
        self.preadapt = preadapt
        if preadapt is not None:
            L, s = preadapt
            if not (L >= 0 and math.isfinite(L)) or (s is not None and not (s >= 0 and math.isfinite(s))):
                raise ValueError(f"bad pre-adaptation {preadapt}: need L >= 0 cd/m^2 and seconds >= 0")
        self._state = state.copy() if state is not None else AdaptationState(operator)
        if self._state.operator != operator:
            raise ValueError(f"state belongs to operator {self._state.operator!r}, not {operator!r}")
        self.op = op_cls(options, self.display, preadapt)
        self.options = dict(self.op.options)
        self.schedule = self.backend.schedule(self.op)
        self.schedule_set_pixels(self._state.pixels)
        self._state.pixels = None             # the schedule holds them now
        self.effects = Effects(effects, self.backend, tuple(plugin_effects))
        self.plan = MechanismPlan(self.op, self.effects.settings, self.display, self.metering,
                                  self.backend)
        if "spectral" in self.op.inputs and self.effects.s.purkinje != "off":
            raise ValueError(f"{operator} models the Purkinje shift itself; leave --purkinje off")
        self.display_primaries = None
        #: The record of the last frame, and its output (for the API's callers; the
        #: job takes :class:`FrameResult` values from :meth:`process_frame`).
        self.last: FrameInfo | None = None
        self.last_output: np.ndarray | None = None
        self.last_alpha = None
        self._frame_plan: dict = {}          # this frame's plan record (FrameInfo.plan)
        self._measure_only = False
        self.front_door = None           # the ImageBuf API's run setup, by its settings (job/imagebuf.py)

    # -- state -----------------------------------------------------------------
    def schedule_set_pixels(self, pixels) -> None:
        self.schedule.set_pixel_state(pixels)

    @property
    def state(self) -> AdaptationState:
        """A copy of the current adaptation state (serialisable; with the per-pixel
        planes of operators that keep them)."""
        st = self._state.copy()
        if self.op.state.planes:
            st.pixels = self.schedule.pixel_state()
        return st

    @state.setter
    def state(self, value: AdaptationState) -> None:
        if value.operator != self.operator_name:
            raise ValueError(f"state belongs to operator {value.operator!r}")
        self._state = value.copy()
        self.schedule_set_pixels(self._state.pixels)
        self._state.pixels = None

    def reset_adaptation(self, preadapt=None) -> None:
        """A scene cut (``--cuts``): the observer starts again fully adapted to the
        next frame, as at the start of a shot (no pre-adaptation; ``preadapt``: this
        one, ``--stills``), with no memory of the last shot (operator and effect
        state); the time and the run's calibration constant are kept."""
        keep = {k: v for k, v in self._state.extra.items() if k == AUTO_SCALE_KEY}
        self.preadapt = preadapt
        self.op.preadapt = preadapt
        self.state = AdaptationState(self.operator_name, time_s=self._state.time_s,
                                     frame=self._state.frame, extra=keep)

    @property
    def adapted(self) -> bool:
        """Whether the observer has seen a frame (or was given a state)."""
        return bool(self._state.values)

    def scalar_state(self) -> AdaptationState:
        """A copy of the state without the per-pixel planes (cheap)."""
        st = self._state.copy()
        st.pixels = None
        return st

    def remember(self, key: str, value) -> None:
        """Keep a JSON-able run value in the state's ``extra`` (saved and resumed)."""
        self._state.extra[key] = value

    def set_field_of_view(self, fov_deg: float) -> None:
        """The image's width in degrees for the spatial effects (flare, acuity), from
        the next frame on (``--stills``: each Radiance picture's own VIEW)."""
        from dataclasses import replace
        s = self.effects.settings
        if float(fov_deg) == s.fov_deg:
            return
        self.effects.settings = self.effects.s = replace(s, fov_deg=float(fov_deg))
        self.plan = MechanismPlan(self.op, self.effects.settings, self.display, self.metering,
                                  self.backend)

    def set_display_primaries(self, D) -> None:
        """Display linear RGB -> working RGB (3x3), for operators that solve for
        display values (kirk11, Eq. 14)."""
        self.display_primaries = None if D is None else np.asarray(D, np.float64)

    # -- the three phases -----------------------------------------------------------
    def measure(self, frame: Frame) -> FrameStats:
        """Per-frame statistics of ``frame`` (metering, the illuminant, local levels): of
        the frame as it reaches the eye, before any effect; the effects change what
        the observer sees, not the light it adapts to (docs/models.md, "Effects
        after metering"), so a frame's statistics never depend on the state."""
        s = self.effects.settings
        return self.schedule.measure(frame, self.metering,
                                     s.chromatic_adaptation != "off" and self._grey_world())

    def _grey_world(self) -> bool:
        """Whether chromatic adaptation takes the backend's grey-world sums (the paper's
        estimate, or no scene analysis); else the analysis's bounded estimate."""
        return self.effects.s.paper or not self.plan.active

    def _own_chroma(self) -> bool:
        """Chromatic adaptation on the scene's colours (schedules without receptor gains)."""
        return not self.schedule.receptor_gains and \
            self.effects.settings.chromatic_adaptation != "off"

    def _scene_stats(self, stats: FrameStats, levels) -> None:
        """``stats`` completed from the frame's scene pass (``levels``; None where no
        effect or plan runs): the goals of the frame before its optical effects (the
        Purkinje shift's receptor levels follow them) and the illuminant estimate
        (the analysis's bounded one, else the grey world)."""
        if levels is None:
            return
        stats.scene_goal = (float(levels.goal[0]), float(levels.goal[1]))
        est = self.effects.estimate
        if est is not None and not self.effects.s.paper:
            stats.illuminant = lambda e=np.asarray(est[0], np.float64): e
        elif stats.illuminant is None:
            stats.illuminant = levels.illuminant

    def advance_plan(self, predicted: dict, G_cone: float, dt: float, fresh: bool,
                     sig: list | None = None) -> dict:
        """Advance the mechanism plan over a frame's stored predictions and signature
        (the shot's integrate pass; a serial run does it in the frame): the weights,
        also handed to the effects for the frame's :meth:`integrate`."""
        weights = self.plan.advance(self._state.extra, predicted, G_cone, dt, fresh, sig)[0]
        self.effects.begin_frame(weights)
        return weights

    def integrate(self, stats: FrameStats, time_s: float, frame_number: int | None = None,
                  dt: float = 0.0, fresh: bool = False, illuminant=None, eff: dict | None = None):
        """Advance the observer over one frame's statistics: the operator's state, then
        the effects' (chromatic adaptation, the Purkinje shift's receptor levels; their
        records into ``eff``). Returns (params, receptor gains)."""
        params = self._advance_operator(stats, time_s, frame_number, dt, fresh)
        return params, self._advance_effects(stats, dt, fresh, illuminant,
                                             {} if eff is None else eff)

    def _advance_operator(self, stats, time_s, frame_number, dt, fresh):
        st = self._state
        self.schedule.integrate(st, stats, dt, fresh)
        st.time_s, st.frame = float(time_s), frame_number
        return self.op.params(st, stats) if self.schedule.receptor_gains else None

    def _advance_effects(self, stats, dt, fresh, illuminant, eff: dict):
        """The effects' time courses over the frame, toward its scene goals: returns the
        chromatic gains for the schedule's cone signals (receptor gains; the scene's
        gains of the other schedules stay in ``eff["chromatic_adaptation"]``)."""
        fx, st = self.effects, self._state
        # the shift's receptor levels follow the frame before its optical effects
        G_rod, G_cone = stats.scene_goal or (stats.G_rod, stats.G_cone)
        eff["purkinje"] = fx.purkinje_advance(G_rod, G_cone, st.extra, dt, fresh, self.preadapt)
        if fx.s.chromatic_adaptation == "off" or not (self.schedule.receptor_gains
                                                      or stats.scene_goal is not None):
            return None
        goal, src = fx.illuminant_goal(illuminant, stats.illuminant)
        # the adapting luminance: the metered frame's on the cone signals; the frame's
        # own metering where the gains go on the scene (local operators' levels differ)
        L_A = stats.G_cone if self.schedule.receptor_gains else G_cone
        gains, eff["chromatic_adaptation"] = fx.chromatic(
            st.extra, goal, src, dt, fresh, self.preadapt is not None, L_A)
        return gains if self.schedule.receptor_gains else None

    def apply(self, frame: Frame, stats: FrameStats, params=None, gains=None, sink=None,
              encoding=None):
        """The per-pixel mapping of ``frame`` under the current state (``encoding``: see
        :meth:`process_frame`)."""
        return self.schedule.apply(frame, self._state, stats, params, gains, sink, encoding)

    # -- frames ----------------------------------------------------------------
    def process(self, frame: np.ndarray, dt: float | None = None, time_s: float | None = None,
                frame_number: int | None = None, luminance_scale: float = 1.0,
                illuminant=None, wavelengths=None, premultiplied: bool = True,
                measure_only: bool = False) -> np.ndarray:
        """Tone map one working-space frame (H x W x 3 or 4, float).

        ``frame * luminance_scale`` must be cd/m^2. Time advances by ``dt``
        seconds, or to the absolute ``time_s``; the first frame of a fresh
        observer needs neither. Returns display-linear float32 of the same
        shape (H x W or H x W x 1 in: the output's luminance); a 4th channel is
        alpha. Integer pixels are normalised as OIIO does (uint8 255 -> 1.0). ``premultiplied`` (OIIO's and OpenEXR's
        convention): the colour is divided by alpha before tone mapping (the
        operators are not linear) and multiplied again after; pixels with zero
        alpha and zero colour stay zero either way. Non-finite alpha is 0.
        ``illuminant``: the frame's own illuminant (working RGB, e.g. from EXR
        ``adoptedNeutral``) for chromatic adaptation, below a user value.
        ``wavelengths``: the frame is spectral radiance (H x W x N, W sr^-1 m^-2
        nm^-1 times ``luminance_scale`` / 683 ... see models/lmsr.py) sampled at these
        wavelengths (nm); operators that take spectral input (kirk11) only.
        ``measure_only``: the frame's :class:`FrameStats` as the run would measure them
        (of the frame as it is: the effects come after the metering), the state
        untouched: the measure pass of a shot split over machines (``shot/``).
        """
        res = self.process_frame(frame, dt, time_s, frame_number, luminance_scale, illuminant,
                                 wavelengths, premultiplied, measure_only=measure_only)
        return res if measure_only else res.output

    def process_frame(self, frame: np.ndarray, dt: float | None = None,
                      time_s: float | None = None, frame_number: int | None = None,
                      luminance_scale: float = 1.0, illuminant=None, wavelengths=None,
                      premultiplied: bool = True, encoding=None, measure_only: bool = False,
                      weights: dict | None = None):
        """:meth:`process`, returning the frame as a :class:`FrameResult` (with
        ``measure_only``: its :class:`FrameStats`). ``encoding``: a display encoding on
        the device (``ColourPipeline.device_output_encoding``) for a frame the caller
        writes encoded; a frame that allows it (RGB in, no alpha, no display-slot
        effect at work, a schedule that brings its output back through the backend)
        comes back as display code values straight from the device (``encoded``).
        ``weights``: the plan's weights of the gated effects instead of the frame's
        own (a shot's integrate pass measuring a frame as the serial run weighs it)."""
        if wavelengths is not None:
            return self._process_spectral(frame, dt, time_s, frame_number, luminance_scale,
                                          wavelengths, measure_only, encoding)
        pix = as_float_pixels(frame)
        grey = None                                   # the input's own grey layout
        if pix.ndim == 2:
            pix, grey = pix[..., None], "2d"
        if pix.ndim != 3 or pix.shape[2] not in (1, 3, 4) or pix.shape[0] < 1 or pix.shape[1] < 1:
            raise ValueError(f"frame must be H x W (luminance), H x W x 1, 3 or 4 "
                             f"(got shape {np.shape(frame)})")
        if pix.shape[2] == 1:
            pix, grey = np.repeat(pix, 3, axis=2), grey or "1"
        if grey is not None or pix.shape[2] != 3:
            encoding = None                           # code values only for RGB in and out
        res = self._process_rgb(pix, dt, time_s, frame_number, luminance_scale, illuminant,
                                premultiplied, measure_only, encoding, weights)
        if measure_only:
            return res
        if grey is not None:                          # luminance in, luminance out
            y = (np.asarray(res.output[..., :3], np.float64) @ Y_WEIGHTS).astype(np.float32)
            res.output = y if grey == "2d" else y[..., None]
        return self._remember(res)

    def _remember(self, res: FrameResult) -> FrameResult:
        self.last, self.last_output, self.last_alpha = res.info, res.output, res.alpha
        return res

    def _process_rgb(self, pix, dt, time_s, frame_number, luminance_scale, illuminant,
                     premultiplied, measure_only=False, encoding=None, weights=None):
        self._check_scale(luminance_scale)
        pix = np.ascontiguousarray(pix, np.float32)
        alpha = None
        if pix.shape[2] == 4:
            pix, alpha = straight_colour(pix, premultiplied)
        res = self._run_frame(Frame(pix, luminance_scale, None, self.display_primaries), dt,
                              time_s, frame_number, illuminant, encoding, measure_only, weights)
        if measure_only:
            return res
        if pix.shape[2] == 4 and alpha is not None:   # premultiplied again where it was
            res.output = restore_alpha(res.output, alpha)
        elif pix.shape[2] == 4:
            res.output = np.concatenate([res.output, pix[..., 3:4]], axis=2)
        res.alpha = alpha
        return res

    @staticmethod
    def _check_scale(scale) -> None:
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"luminance scale must be a positive finite number (got {scale})")

    def _begin_frame(self, measure_only: bool, scene: bool = True) -> bool:
        """A frame starts: the effects forget the last frame's plan (``scene`` False: a
        spectral frame, scene effects left out); returns whether the last frame's
        predictions were reused (the flare's early start waits for this one's)."""
        reused = bool(self._frame_plan.get("reused", False))
        self.effects.drop_started()
        self.effects.begin_frame(None if scene else {"acuity": 1.0})
        self._frame_plan = {}
        self._measure_only = measure_only
        return reused

    def _run_frame(self, frame: Frame, dt, time_s, frame_number, illuminant, encoding=None,
                   measure_only: bool = False, weights: dict | None = None):
        """One whole frame: the optical effects (flare, scene plugins) -> measure ->
        integrate (the observer and the effects' time courses) -> the effects of what
        the observer makes of the light (Purkinje shift, chromatic gains on the scene)
        -> apply -> display effects, and its record (``measure_only``: its statistics,
        the state untouched; ``weights``: the plan's weights of its gated effects
        instead of the frame's own, for a shot's integrate pass)."""
        rgb_in = frame.wavelengths is None
        if measure_only:
            step_dt, fresh = 0.0, True
        else:
            time_s, step_dt, fresh = self.frame_clock(dt, time_s)
        reused = self._begin_frame(measure_only, rgb_in)
        fx = self.effects
        eff: dict = {}
        levels = self._working(frame) if rgb_in else None
        metered = frame
        if levels is not None:
            lim = self._source_limit(levels)
            if levels.rgb is not None and not isinstance(levels.rgb, np.ndarray):
                h, w = frame.shape[:2]       # the device starts the flare while the host plans
                self.plan.sources_ahead(h, w, *levels.goal, fresh or not reused)
                fx.start_flare(levels.rgb, *levels.goal, levels.max_Y, lim)
            self._begin_plan(levels, frame, step_dt, fresh, weights)
            metered, self._frame_plan["flare_metered"] = optical_effects(
                fx, frame, levels, lim, eff, self.display_primaries)
        stats = self.measure(metered)
        self._scene_stats(stats, levels)
        if measure_only:
            return stats
        params = self._advance_operator(stats, time_s, frame_number, step_dt, fresh)
        gains = self._advance_effects(stats, step_dt, fresh, illuminant, eff)
        work = metered if levels is None else seen_effects(
            fx, metered, frame, levels, eff, self._own_chroma(), self.display_primaries)
        blurred = None
        if encoding is not None and (not self.schedule.encodes_output
                                     or fx.slot_plugins("display")):
            encoding = None              # display-linear first: something works on it
        elif encoding is not None and fx.acuity_needed(stats.G_rod, stats.width):
            # the blur on the device before the encoding, or display-linear first
            encoding, blurred = fx.acuity_encoding(encoding, stats.G_rod, stats.height,
                                                   stats.width)
        out = self.apply(work, stats, params, gains, encoding=encoding)
        stats.handle = None              # the resident frame: its pixels are spent now
        self._frozen = (stats, params, gains)
        if blurred is not None:
            eff["acuity"] = blurred
        elif encoding is not None:       # code values: no display-slot effect was at work
            eff["acuity"] = fx.acuity_report(stats.G_rod, stats.width)
        else:
            out, eff["acuity"] = fx.acuity(out, stats.G_rod)
            for plugin in fx.slot_plugins("display"):
                new, eff[plugin.NAME] = plugin.run(out, {"G_rod": stats.G_rod,
                                                         "G_cone": stats.G_cone})
                out = out if new is None else np.asarray(new, np.float32)
        repairs = levels.repairs if metered is not frame else stats.repairs
        info = FrameInfo(frame_number, float(time_s), step_dt, stats.G_rod, stats.G_cone,
                         repairs, self._state.copy(), self.schedule.summary(stats, params),
                         eff, self._frame_plan)
        return FrameResult(out, None, info, encoding is not None)

    def _working(self, frame: Frame):
        """The frame's colour stage and metering for the plan and the effects (the
        backend's :class:`~ocl_tonemap.backends.base.Levels`), or None where neither
        runs. The working frame stays on the device where an effect runs there (the
        flare whole, else the Purkinje shift): one upload, no round trip."""
        fx = self.effects
        if not self.plan.active and not fx.slot_plugins("scene"):
            return None
        pix = frame.pixels
        h, w = pix.shape[:2]
        flare_dev = fx.settings.flare != "off" and fx.flare_on_device(h, w)
        on_dev = pix.shape[2] == 3 and (flare_dev or (fx.settings.flare == "off"
                                                      and fx.purkinje_on_device()))
        return self.backend.working(pix, frame.scale, self.metering,
                                    self._own_chroma() and self._grey_world(), on_device=on_dev,
                                    proxy_stride=self.plan.proxy_stride(h, w))

    def _source_limit(self, levels) -> float:
        """The frame's flare source limit (``models/spencer1995.py`` source_limit): the
        paper's test, and beyond the display's white for an observer adapted to the
        frame (``MechanismPlan.flare_limit``: the flare changes the light that is
        metered, so its sources cannot depend on the state); inf where it cannot run."""
        if self.effects.settings.flare == "off":
            return math.inf
        return self.plan.flare_limit(*levels.goal)

    def freeze_mapping(self, stats, params, gains) -> None:
        """Make (``stats``, ``params``, ``gains``) of :meth:`integrate` the last mapping
        without mapping pixels (the shot's export pass, ``shot/passes.export``)."""
        self._frozen = (stats, params, gains)

    def last_mapping(self):
        """(operator, frame scalars, receptor gains or None) of the last frame mapped:
        its per-pixel mapping, frozen (``colour/export.py`` samples it for an OCIO
        export; spatial and scene-slot effects are not part of it)."""
        if getattr(self, "_frozen", None) is None:
            raise ValueError("no frame has been mapped yet")
        _, params, gains = self._frozen
        return self.op, params, gains

    def _begin_plan(self, levels, frame: Frame, dt: float, fresh: bool,
                    weights: dict | None = None) -> None:
        """The frame's mechanism plan (``mechanisms/``) from its scene pass
        (``levels``), handed to the effects; the weights advance in the state's
        ``extra`` (not in a measure-only pass). Its record: ``_frame_plan``.
        ``weights``: the gated effects' weights to use instead (a shot's integrate
        pass measuring a frame again as the serial run's plan weighs it)."""
        if levels is None:
            return
        h, w = frame.shape[:2]
        pix = frame.pixels
        plan = self.plan.frame(levels, lambda a, b: pix[a:b], h, w, frame.scale,
                               None if self._measure_only else self._state.extra, dt, fresh)
        self.effects.begin_frame(weights if weights is not None else plan.get("weights"),
                                 plan.get("estimate"))
        self._frame_plan = plan.get("record", {})

    @property
    def frame_plan(self) -> dict:
        """The last frame's plan record (``ocltm:plan``): weights, predictions, analysis,
        and ``flare_metered``, the flare's weight in the frame that was metered (None
        where no pixel could be a source)."""
        return self._frame_plan

    def frame_clock(self, dt, time_s):
        """(time of this frame, step since the last one, fresh observer?): the one rule
        of every entry (RGB, spectral, streamed): ``time_s``, else the last frame's time
        plus ``dt``; a fresh observer's first frame needs neither."""
        st = self._state
        fresh = not st.values
        if time_s is None:
            if fresh:
                time_s = 0.0 if st.time_s is None else st.time_s
            elif dt is None:
                raise ValueError("give dt (seconds since the last frame) or time_s")
            else:
                time_s = (st.time_s or 0.0) + dt
        step_dt = 0.0 if (fresh or st.time_s is None) else time_s - st.time_s
        if not math.isfinite(step_dt) or step_dt < 0:
            raise ValueError(f"time goes backwards or is not finite: last frame at {st.time_s} s, "
                             f"this one at {time_s} s")
        return time_s, step_dt, fresh

    def can_stream(self) -> str | None:
        """Why frames cannot be streamed in bands (None: they can): operators whose
        schedule streams; every built-in effect streams (flare, Purkinje and
        chromatic adaptation wrap the band source, acuity the sink), effect
        plugins see whole frames."""
        if not self.schedule.streams:
            return f"the {self.backend.name} backend works on whole frames for {self.operator_name}"
        if self.effects.plugins:
            return "effect plugins need the whole frame"
        return None

    def process_stream(self, source, sink, dt: float | None = None,
                       time_s: float | None = None, frame_number: int | None = None,
                       luminance_scale: float = 1.0, illuminant=None,
                       measure_only: bool = False, start=None,
                       weights: dict | None = None) -> FrameInfo | FrameStats:
        """One frame in row bands, never whole in memory: ``source[y0:y1]`` gives
        working-space bands (straight colour), ``source.shape`` is (H, W, C);
        ``sink(y0, band)`` receives the display-linear bands (3 channels) in order
        after the state has advanced; ``start(info)``, when given, gets the frame's
        :class:`FrameInfo` before the first band comes (a writer's metadata). Returns
        the :class:`FrameInfo` (``measure_only``: the :class:`FrameStats`). Operators
        that stream (:meth:`can_stream`).

        The same flow as a whole frame, band by band: the flare made from the
        source's rows around each band (``streaming.SceneBands``, ``effects/flare.py``
        ``BandedFlare``) before the metering pass, the Purkinje shift and chromatic
        gains on the scene after the state step, on the bands' way to the operator,
        and the acuity blur on the display bands on their way to ``sink``
        (``effects/acuity.py`` ``BandedAcuity``). A source with ``alpha(y0)``
        (``job/stream.py``) is read again at a band whose alpha it no longer holds
        when the sink gets it. The Purkinje shift's gamut fallbacks are known once
        the bands are made: in the returned record, not in ``start``'s. ``weights``:
        as :meth:`_run_frame`'s."""
        why = self.can_stream()
        if why:
            raise ValueError(f"cannot stream this frame: {why}")
        self._check_scale(luminance_scale)
        if measure_only:
            step_dt, fresh = 0.0, True
        else:
            time_s, step_dt, fresh = self.frame_clock(dt, time_s)
        self._begin_frame(measure_only)
        self.last_output = self.last_alpha = None
        h, w = source.shape[:2]
        frame = metered = Frame(source, luminance_scale, None, self.display_primaries)
        eff: dict = {}
        levels, sweep, band_px = None, [], self._band_pixels(h, w)
        if self.plan.active:          # the source's levels and proxy: nothing kept
            levels = self.backend.scene_levels(source, luminance_scale, self.metering,
                                               self._own_chroma() and self._grey_world(),
                                               self.plan.proxy_stride(h, w))
            lim = self._source_limit(levels)
            self._begin_plan(levels, frame, step_dt, fresh, weights)
            rows = WorkingRows(self.backend, source, luminance_scale,
                               max(1, band_px // max(w, 1)))
            self._frame_plan["flare_metered"] = metered_weight(self.effects, levels.max_Y, lim)
            flare, sweep = stream_flare(self.effects, rows, levels, lim, eff, band_px)
            if flare is not None:
                metered = Frame(SceneBands(rows, flare), 1.0, None, self.display_primaries)
        stats = self.measure(metered)
        for finish in sweep:          # what the measure pass's sweep added up
            finish()
        self._scene_stats(stats, levels)
        if measure_only:
            return stats
        params = self._advance_operator(stats, time_s, frame_number, step_dt, fresh)
        gains = self._advance_effects(stats, step_dt, fresh, illuminant, eff)
        work, after = metered, []
        if levels is not None:
            work, after = stream_seen(self.effects, metered, levels, eff, self._own_chroma(),
                                      self.display_primaries)
        out, eff["acuity"] = self.effects.acuity_stream(
            alpha_sink(source, sink), stats.G_rod, (h, w), STREAM_EFFECT_BANDS * band_px)
        self.last = info = FrameInfo(frame_number, float(time_s), step_dt, stats.G_rod,
                                     stats.G_cone, levels.repairs if metered is not frame
                                     else stats.repairs, self._state.copy(),
                                     self.schedule.summary(stats, params, work), eff,
                                     self._frame_plan)
        if start is not None:
            start(info)
        self.apply(work, stats, params, gains, out)
        if not getattr(out, "done", True):     # a BandedAcuity sink counts its rows
            raise RuntimeError(f"the schedule sent rows up to {out.got} of {h}")
        for finish in after:          # what the bands' sweep added up
            finish()
        return info

    def _band_pixels(self, h: int, w: int) -> int:
        return int(self.backend.max_band_pixels or h * w)

    def _process_spectral(self, frame, dt, time_s, frame_number, scale, wavelengths,
                          measure_only=False, encoding=None):
        if "spectral" not in self.op.inputs:
            from .operators import registry
            which = [n for n, c in registry().items() if "spectral" in c.inputs]
            raise ValueError(f"operator {self.operator_name} takes RGB frames; spectral "
                             f"input needs --operator {' or '.join(which)}")
        fx = self.effects.settings
        if "on" in (fx.flare, fx.chromatic_adaptation, fx.purkinje):
            raise ValueError("flare, chromatic adaptation and the Purkinje effect need RGB "
                             "input; switch them off for spectral frames")
        # on auto they are left out of spectral frames; acuity (display slot) runs
        pix = np.ascontiguousarray(frame, np.float32)
        lam = np.asarray(wavelengths, np.float64)
        if pix.ndim != 3 or pix.shape[2] != len(lam) or len(lam) < 2:
            raise ValueError(f"spectral frame must be H x W x {len(lam)} (got {pix.shape})")
        self._check_scale(scale)
        res = self._run_frame(Frame(pix, scale, lam, self.display_primaries), dt, time_s,
                              frame_number, None, encoding, measure_only)
        return res if measure_only else self._remember(res)

    def process_imagebuf(self, buf, dt: float | None = None, time_s: float | None = None,
                         luminance_scale=None, colorconfig: str | None = None,
                         iscolorspace: str | None = None, encode: bool = False,
                         unpremult: bool | None = None, frame_number: int | None = None,
                         channels: list[str] | None = None):
        """ImageBuf in, ImageBuf out: the same front door as the command line.

        The input's colourspace (``oiio:ColorSpace``, EXR ``chromaticities``, else
        scene-linear Rec.709; ``iscolorspace`` overrides), its calibration
        (``luminance_scale`` S or ``"auto:LEVEL"`` > ``whiteLuminance`` > EXIF
        exposure > ...; see ``calibration.py``) and its alpha
        (``oiio:UnassociatedAlpha``; ``unpremult`` overrides) are read as the CLI
        reads them, with the OCIO config ``colorconfig`` (> $OCIO > ocio://default).
        The result is float display-linear light in the display's linear
        colourspace (``encode``: display code values), tagged and carrying the same
        ``ocltm:*`` attributes as the CLI's outputs."""
        from .job.imagebuf import process_imagebuf
        return process_imagebuf(self, buf, dt, time_s, luminance_scale, colorconfig,
                                iscolorspace, encode, unpremult, frame_number, channels)
