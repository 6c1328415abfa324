"""The Python API: :class:`Tonemapper`, a thin façade over one observer
(``observer.py``) and its per-frame graph (``frame.py``, ``banded.py``)."""

from __future__ import annotations

import numpy as np

from .alpha import restore_alpha, straight_colour
from ..backends.quality import quality_tier
from ..backends.select import make_backend
from ..effects import EffectSettings, Effects
from ..mechanisms import MechanismPlan
from ..models import cie203
from ..models.display import DisplaySpec, display_for
from ..models.metering import MeteringSpec
from ..models.photometry import Y_WEIGHTS
from ..base.quantities import RUN
from ..operators import get_operator
from ..operators.base import Frame
from .state import AdaptationState

from .banded import run_banded
from .frame import FrameGraph, spectral_frame
from .observer import Observer
from .results import FrameInfo, FrameResult, check_scale, rgb_pixels


def _behind_media(preadapt, gain: float):
    """A pre-adaptation (L cd/m^2, seconds) as the light behind the ocular media."""
    if preadapt is None or gain == 1.0:
        return preadapt
    return (float(preadapt[0]) * gain, *tuple(preadapt)[1:])


def _declared(**given) -> tuple:
    """The API's keywords that the run declares (``quantities.RUN``), checked in its
    words; None: not given."""
    return tuple(None if v is None else RUN[k].check(v, k) for k, v in given.items())


class Tonemapper:
    """Time-dependent tone mapping of frames for one observer.

    Parameters
    ----------
    operator : registry name (``pattanaik00``; ``operators.registry()`` lists them).
    backend : ``"opencl"``, ``"reference"`` (float64 NumPy) or ``"auto"``; default
        (None): the quality tier's, with OpenCL falling back to the reference backend
        with a warning where no OpenCL device works (``backends.select``).
    metering : metering spec string or :class:`MeteringSpec` (``logmean``).
    display : the display observer (:class:`DisplaySpec`); SDR 100 cd/m^2 by default.
    preadapt : ``(L_cd, seconds_or_None)`` initial adaptation; default: fully
        adapted to the first frame.
    state : an :class:`AdaptationState` to resume from.
    device : OpenCL device spec (see ``backends.opencl.runtime.choose_device``).
    max_band_pixels : process larger frames in row bands (device memory).
    options : operator options (the operator's ``options`` specs; e.g. durand00:
        ``tint``, ``lut``; ledda04: ``sigma_spatial``, ``local_strength`` ...).
    effects : :class:`~ocl_tonemap.effects.EffectSettings`; default: ``model``'s.
    quality : ``draft``, ``balanced`` (default) or ``reference``: the defaults of every
        speed/accuracy knob (``backends/quality.py``); what is given here wins.
    model : ``auto`` (default): each frame gets the mechanisms it needs, within one
        JND of ``full`` (``mechanisms/``); ``full``: every effect the operator can
        take, on; ``none``: the operator alone. Used where ``effects`` is not given.
    **effect_options : any effect's switch or option, over ``effects`` (``flare="off"``,
        ``fov_deg=40``; an installed effect's too: ``effects.registry()``).
    """

    def __init__(self, operator: str = "pattanaik00", backend: str | None = None,
                 metering: str | MeteringSpec | None = "logmean",
                 display: DisplaySpec | None = None,
                 preadapt: tuple[float, float | None] | None = None,
                 state: AdaptationState | None = None, device: str | None = None,
                 max_band_pixels: int | None = None, options: dict | None = None,
                 effects: EffectSettings | None = None, quality: str | None = None,
                 model: str = "auto", **effect_options):
        self.operator_name = operator
        op_cls = get_operator(operator)
        preadapt, max_band_pixels = _declared(preadapt=preadapt, max_band_pixels=max_band_pixels)
        tier = quality_tier(quality)
        self.quality, self.model = tier.name, model
        backend = backend or ("auto" if tier.backend == "opencl" and device is None
                              else tier.backend)
        options = {**tier.options_for(o.name for o in op_cls.options), **(options or {})}
        if effects is None:
            effects = EffectSettings.for_operator(operator, model,
                                                  paper=options.get("mode") == "paper",
                                                  **{**dict(tier.effects), **effect_options})
        elif effect_options:
            effects = effects.replace(**effect_options)
        for name in op_cls.own_effects:
            if getattr(effects, name) != "off":
                raise ValueError(f"{operator} models the {name} effect itself; leave "
                                 f"--{name.replace('_', '-')} off")
        #: The ocular media's scene-to-retina factor (``cie203.media_gain``): every
        #: frame's luminance scale and the pre-adaptation take it.
        self.media_gain = cie203.media_gain(effects.age)
        preadapt = _behind_media(preadapt, self.media_gain)
        self.backend = make_backend(backend, device, max_band_pixels)
        self.metering = metering if isinstance(metering, MeteringSpec) else MeteringSpec.parse(metering)
        self.display = display or display_for("sRGB - Display")
        self.op = op_cls(options, self.display, preadapt)
        self.options = dict(self.op.options)
        self.schedule = self.backend.schedule(self.op)
        self.observer = Observer(operator, self.op, self.schedule, state, preadapt)
        fx = Effects(effects, self.backend)
        self.graph = FrameGraph(self.op, self.schedule, self.backend, fx,
                                MechanismPlan(self.op, effects, self.display, self.metering,
                                              self.backend), self.metering, self.observer)
        #: The record of the last frame, and its output (for the API's callers; the
        #: job takes :class:`FrameResult` values from :meth:`process_frame`).
        self.last: FrameInfo | None = None
        self.last_output: np.ndarray | None = None
        self.last_alpha = None

    # -- the observer ---------------------------------------------------------------------
    effects = property(lambda self: self.graph.effects)
    plan = property(lambda self: self.graph.plan)
    preadapt = property(lambda self: self.observer.preadapt)
    adapted = property(lambda self: self.observer.adapted,
                       doc="Whether the observer has seen a frame (or was given a state).")
    display_primaries = property(lambda self: self.graph.primaries)
    frame_plan = property(lambda self: self.graph.record, doc="The last frame's plan record "
                          "(``ocltm:plan``), with ``flare_metered``: the flare's weight in "
                          "the frame that was metered (None where no pixel was a source).")

    @property
    def state(self) -> AdaptationState:
        """A copy of the adaptation state (serialisable; with the per-pixel planes of
        operators that keep them)."""
        return self.observer.state()

    @state.setter
    def state(self, value: AdaptationState) -> None:
        self.observer.set_state(value)

    def scalar_state(self) -> AdaptationState:
        return self.observer.scalar_state()

    def remember(self, key: str, value) -> None:
        self.observer.remember(key, value)

    def reset_adaptation(self, preadapt=None) -> None:
        """A scene cut (``--cuts``): the observer starts again fully adapted to the next
        frame, as at the start of a shot (``preadapt``: this one, ``--stills``)."""
        self.observer.reset(_behind_media(preadapt, self.media_gain))

    def frame_clock(self, dt, time_s):
        return self.observer.clock(dt, time_s)

    def set_field_of_view(self, fov_deg: float) -> None:
        """The image's width in degrees for the spatial effects, from the next frame on
        (``--stills``: each Radiance picture's own VIEW)."""
        s = self.effects.settings
        if float(fov_deg) != s.fov_deg:
            self.effects.set_settings(s.replace(fov_deg=float(fov_deg)))
            self.graph.plan = MechanismPlan(self.op, self.effects.settings, self.display,
                                            self.metering, self.backend)

    def set_display_primaries(self, D) -> None:
        """Display linear RGB -> working RGB (3x3), for operators that solve for display
        values (kirk11, Eq. 14)."""
        self.graph.primaries = None if D is None else np.asarray(D, np.float64)

    # -- the three phases (a shot split over machines, ``shot/``) ------------------------
    def measure(self, frame: Frame):
        return self.graph.measure(frame)

    def integrate(self, stats, time_s: float, frame_number: int | None = None, dt: float = 0.0,
                  fresh: bool = False, illuminant=None, eff: dict | None = None):
        """Advance the observer over one frame's statistics; (params, receptor gains)."""
        return self.graph.integrate(stats, time_s, frame_number, dt, fresh, illuminant,
                                    {} if eff is None else eff)

    def apply(self, frame: Frame, stats, params=None, gains=None, sink=None, encoding=None):
        return self.graph.apply(frame, stats, params, gains, sink, encoding)

    def advance_plan(self, predicted: dict, G_cone: float, dt: float, fresh: bool, sig=None):
        return self.graph.advance_plan(predicted, G_cone, dt, fresh, sig)

    def freeze_mapping(self, stats, params, gains) -> None:
        """Make (stats, params, gains) of :meth:`integrate` the last mapping without
        mapping pixels (the shot's export pass)."""
        self.graph.frozen = (stats, params, gains)

    def last_mapping(self):
        """(operator, frame scalars, receptor gains or None) of the last frame mapped
        (``colour/export.py`` samples it for an OCIO export)."""
        if self.graph.frozen is None:
            raise ValueError("no frame has been mapped yet")
        _, params, gains = self.graph.frozen
        return self.op, params, gains

    # -- frames ---------------------------------------------------------------------------
    def process(self, frame, dt: float | None = None, time_s: float | None = None,
                frame_number: int | None = None, luminance_scale: float = 1.0,
                illuminant=None, wavelengths=None, premultiplied: bool = True,
                measure_only: bool = False) -> np.ndarray:
        """Tone map one working-space frame (H x W x 3 or 4, float; H x W or H x W x 1:
        luminance in, luminance out; integers normalised as OIIO does). ``frame *
        luminance_scale`` must be cd/m^2; time advances by ``dt`` seconds, or to the
        absolute ``time_s`` (a fresh observer's first frame needs neither). Returns
        display-linear float32 of the same shape; a 4th channel is alpha
        (``premultiplied``: the colour is divided by it for the operator, multiplied
        after). ``illuminant``: the frame's own (working RGB, EXR ``adoptedNeutral``).
        ``wavelengths``: the frame is spectral radiance sampled there (nm; kirk11).
        ``measure_only``: its :class:`FrameStats`, the state untouched (``shot/``).
        A ``pyopencl.array.Array`` frame (H x W x 3 float32 on the backend's context,
        ``backend.device_runtime()``) stays on the device: the output is a new device
        array, and neither crosses to the host."""
        res = self.process_frame(frame, dt, time_s, frame_number, luminance_scale, illuminant,
                                 wavelengths, premultiplied, measure_only=measure_only)
        return res if measure_only else res.output

    def process_frame(self, frame, dt: float | None = None, time_s: float | None = None,
                      frame_number: int | None = None, luminance_scale: float = 1.0,
                      illuminant=None, wavelengths=None, premultiplied: bool = True,
                      encoding=None, measure_only: bool = False, weights: dict | None = None):
        """:meth:`process`, as a :class:`FrameResult` (``measure_only``: :class:`FrameStats`).
        ``encoding``: a display encoding on the device for a frame written encoded (RGB
        in, no alpha, no display effect on display-linear pixels: code values back,
        ``encoded``). ``weights``: the plan's weights instead of the frame's own (a
        shot's integrate pass measuring a frame as the serial run weighs it)."""
        img = None if isinstance(frame, np.ndarray) else self.backend.device_image(frame)
        check_scale(luminance_scale)
        luminance_scale = luminance_scale * self.media_gain      # what reaches the retina
        if img is not None:
            if wavelengths is not None:
                raise ValueError("a spectral frame comes as a host array (wavelengths=...)")
            res = self.graph.run_device(img, dt, time_s, frame_number, luminance_scale,
                                        illuminant, encoding, measure_only, weights)
            return res if measure_only else self._remember(res)
        if wavelengths is not None:
            fr = spectral_frame(self.op, self.operator_name, self.effects, frame, wavelengths,
                                luminance_scale, self.graph.primaries)
            res = self.graph.run(fr, dt, time_s, frame_number, None, encoding, measure_only)
            return res if measure_only else self._remember(res)
        pix, grey = rgb_pixels(frame)
        if grey is not None or pix.shape[2] != 3:
            encoding = None                           # code values only for RGB in and out
        if not (pix.dtype == np.float16 and pix.shape[2] == 3 and self.backend.half_input):
            pix = np.ascontiguousarray(pix, np.float32)   # (half RGB: up as it is stored)
        alpha = None
        if pix.shape[2] == 4:
            pix, alpha = straight_colour(pix, premultiplied)
        res = self.graph.run(Frame(pix, luminance_scale, None, self.graph.primaries), dt,
                             time_s, frame_number, illuminant, encoding, measure_only, weights)
        if measure_only:
            return res
        if pix.shape[2] == 4:                         # premultiplied again where it was
            res.output = restore_alpha(res.output, alpha) if alpha is not None else \
                np.concatenate([res.output, pix[..., 3:4]], axis=2)
        res.alpha = alpha
        if grey is not None:                          # luminance in, luminance out
            y = (np.asarray(res.output[..., :3], np.float64) @ Y_WEIGHTS).astype(np.float32)
            res.output = y if grey == "2d" else y[..., None]
        return self._remember(res)

    def _remember(self, res: FrameResult) -> FrameResult:
        self.last, self.last_output, self.last_alpha = res.info, res.output, res.alpha
        return res

    def can_stream(self) -> str | None:
        """Why frames cannot be streamed in bands (None: they can)."""
        if not self.schedule.streams:
            return f"the {self.backend.name} backend works on whole frames for {self.operator_name}"
        return self.effects.stream_blocker()

    def process_stream(self, source, sink, dt: float | None = None, time_s: float | None = None,
                       frame_number: int | None = None, luminance_scale: float = 1.0,
                       illuminant=None, measure_only: bool = False, start=None,
                       weights: dict | None = None):
        """One frame in row bands, never whole in memory: ``source[y0:y1]`` gives
        working-space bands (``source.shape`` is (H, W, C)); ``sink(y0, band)`` receives
        the display-linear bands in order; ``start(info)`` gets the frame's
        :class:`FrameInfo` before the first band (a writer's metadata). Returns it
        (``measure_only``: the :class:`FrameStats`). ``weights``: as :meth:`process_frame`'s."""
        why = self.can_stream()
        if why:
            raise ValueError(f"cannot stream this frame: {why}")
        self.last_output = self.last_alpha = None

        def begin(info):              # ``last`` is this frame's before the first band
            self.last = info
            if start is not None:
                start(info)
        check_scale(luminance_scale)
        return run_banded(self.graph, source, sink, dt, time_s, frame_number,
                          luminance_scale * self.media_gain, illuminant, measure_only, begin,
                          weights)
