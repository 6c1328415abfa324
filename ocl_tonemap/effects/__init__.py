"""Effects any operator can use, each in a declared slot of the frame's data flow.

=======================  =========  ==============================================
effect                   slot       module
=======================  =========  ==============================================
``flare``                scene      ``effects/flare.py`` (Spencer et al. 1995)
``purkinje``             scene      ``effects/purkinje.py`` (Kirk & O'Brien 2011)
``chromatic_adaptation`` receptor   ``effects/chromatic.py`` (Durand & Dorsey 2000, Eq. 6)
``acuity``               display    ``effects/acuity.py`` (Shaler 1937, D&D Sec. 7)
=======================  =========  ==============================================

*scene* effects change the scene (cd/m^2) the operator maps: the optical ones (the
flare, plugins) before it is metered, the Purkinje shift after the state step
(``stages.py`` says why); *receptor* effects act on the cone signals (the schedule
places them, see ``chromatic.py``); *display* effects change the display-linear
output.

Frames streamed in row bands (``Tonemapper.process_stream``, ``--max-memory``)
get every built-in effect: the scene effects make each band from the rows
around it after a metering pass over the unchanged frame (flare: the fast
method's pyramid cut where its image fits the budget, ``flare.BandedFlare``;
Purkinje and chromatic gains: pointwise), acuity blurs the display bands on
their way out (``acuity.BandedAcuity``); the values are the whole frame's
(flare ``exact`` streams as ``fast``). Effect plugins see whole frames.

Each takes ``on | off | auto``. ``auto`` leaves the choice to the frame's
mechanism plan (``ocl_tonemap/mechanisms/``): flare, acuity and the Purkinje
shift are skipped where their predicted effect, summed over what is skipped,
stays within one JND (Delta E ITP) of running them, and blended in or out over a
tenth of a second; chromatic adaptation applies its degree of adaptation. The
defaults come from ``--model`` (:data:`MODEL_DEFAULTS`): ``auto`` (every effect
the operator can take on ``auto``), ``full`` (all ``on``), ``none`` (the operator
alone). Which effects ran, and with what, is returned per frame for the metadata.

:data:`REGISTRY` lists them; a separately installed package may add effects in
the ``ocl_tonemap.effects`` entry-point group (a module or object with ``NAME``,
``SLOT`` in scene | display, ``HELP`` and ``run(rgb, levels) -> (rgb or None,
info)``), run when enabled through ``Tonemapper(plugin_effects=[NAME, ...])``.
"""

from __future__ import annotations

import functools

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from ..models import spencer1995 as fl
from ..models.convolution import EDGE_CLAMP
from ..models.durand2000 import parse_illuminant
from . import acuity as _acuity
from . import chromatic as _chromatic
from . import flare as _flare
from . import purkinje as _purkinje

MODES = ("on", "off", "auto")
#: --model -> the mode of every effect the operator can take (a mode given wins).
MODEL_DEFAULTS = {"auto": "auto", "full": "on", "none": "off"}
#: The effects, by EffectSettings field.
EFFECT_FIELDS = ("flare", "acuity", "chromatic_adaptation", "purkinje")
SLOTS = ("scene", "receptor", "display")
#: Default angular width of the image, degrees (the paper's 50-degree example, Sec. 8).
DEFAULT_FOV = 50.0
#: name -> module of the built-in effects (each with NAME, SLOT, NEEDS, HELP, run).
REGISTRY = {m.NAME: m for m in (_flare, _acuity, _chromatic, _purkinje)}


def plugin_effects() -> dict:
    """Effects installed by other packages (entry-point group ``ocl_tonemap.effects``)."""
    from importlib.metadata import entry_points
    out = {}
    for ep in entry_points(group="ocl_tonemap.effects"):
        eff = ep.load()
        if getattr(eff, "SLOT", None) not in ("scene", "display"):
            raise ValueError(f"effect plugin {ep.name}: SLOT must be scene or display")
        out[ep.name] = eff
    return out


@dataclass(frozen=True)
class EffectSettings:
    """Switches and parameters of the effects (CLI: --flare, --acuity,
    --chromatic-adaptation, --fov, --illuminant, --flare-method ...)."""

    flare: str = "off"
    acuity: str = "off"
    chromatic_adaptation: str = "off"
    purkinje: str = "off"
    fov_deg: float = DEFAULT_FOV
    flare_method: str = "fast"
    flare_threshold: float = fl.DEFAULT_THRESHOLD
    flare_per_octave: int = 1
    illuminant: str | None = None
    #: The papers' literal forms (``--mode paper``): complete chromatic adaptation to
    #: the frame's grey world (Eq. 6), Shaler's table indexed by L_waR itself.
    paper: bool = False

    def __post_init__(self):
        for k in EFFECT_FIELDS:
            if getattr(self, k) not in MODES:
                raise ValueError(f"--{k.replace('_', '-')} must be on, off or auto "
                                 f"(got {getattr(self, k)!r})")
        if not (0 < self.fov_deg <= 360):
            raise ValueError(f"--fov must be above 0 and at most 360 degrees (a fisheye's "
                             f"width; got {self.fov_deg})")
        if self.flare_method not in ("fast", "exact"):
            raise ValueError(f"--flare-method must be fast or exact (got {self.flare_method!r})")
        if not (self.flare_threshold > 0 and math.isfinite(self.flare_threshold)):
            raise ValueError("--flare-threshold must be a positive number")
        if self.flare_per_octave not in (1, 2, 3, 4):
            raise ValueError("--flare-sampling (Gaussians per octave) must be 1..4")
        if self.illuminant is not None:
            parse_illuminant(self.illuminant)

    @classmethod
    def for_operator(cls, operator: str, model: str = "auto", paper: bool = False,
                     **given) -> "EffectSettings":
        """Defaults of ``--model`` (:data:`MODEL_DEFAULTS`) for the effects the operator
        can take (kirk11 models the Purkinje shift itself); ``paper`` (``--mode
        paper``): the paper's operator alone, effects off, complete chromatic
        adaptation when asked for. A value given wins."""
        from ..operators import get_operator
        if model not in MODEL_DEFAULTS:
            raise ValueError(f"--model must be one of {', '.join(MODEL_DEFAULTS)} (got {model!r})")
        mode = "off" if paper else MODEL_DEFAULTS[model]
        takes = [k for k in EFFECT_FIELDS if k not in get_operator(operator).own_effects]
        base = replace(cls(), **{k: mode for k in takes},
                       paper=paper)
        return replace(base, **{k: v for k, v in given.items() if v is not None})

    @property
    def any(self) -> bool:
        return any(getattr(self, k) != "off" for k in EFFECT_FIELDS)

    def as_dict(self) -> dict:
        return asdict(self)




class Effects:
    """The effects of one observer: settings, the backend's device helpers, and the
    effects' state (kept in ``AdaptationState.extra``)."""

    STATE_KEY = _chromatic.STATE_KEY

    @functools.cached_property
    def _device_blur(self):
        """The backend's device blur (flare, acuity) or None, made on first use: its
        program build is ~40 ms of a start on PoCL, for runs that may never blur. Its
        band size is the backend's when the effects were made (a streamed frame narrows
        the backend's own bands later: the blur keeps its whole-frame passes)."""
        return self.backend.device_blur(self._blur_pixels)

    @property
    def _blur(self):
        """``blur(img, taps, edge)`` on the device, or None (the effects' NumPy path)."""
        dev = self._device_blur
        return None if dev is None else dev.blur

    def __init__(self, settings: EffectSettings, backend, plugins=()):
        self.s = self.settings = settings
        #: This frame's plan weights of the gated effects (field -> 0..1) and the
        #: scene analysis's illuminant estimate (rgb, CCT, confidence), set by
        #: :meth:`begin_frame`.
        self.weights: dict = {}
        self.estimate = None
        self.backend = backend
        self._blur_pixels = backend.max_band_pixels
        self.user_illuminant = parse_illuminant(settings.illuminant) if settings.illuminant else None
        self._purkinje_dev = None
        self._flare_dev = None
        #: What the run has said once (warnings not repeated per frame).
        self.said: set = set()
        found = plugin_effects() if plugins else {}
        missing = [p for p in plugins if p not in found]
        if missing:
            raise ValueError(f"no effect plugin {', '.join(missing)} (installed: "
                             f"{', '.join(sorted(found)) or 'none'})")
        self.plugins = [found[p] for p in plugins]

    def begin_frame(self, weights: dict | None, estimate=None) -> None:
        """This frame's plan: ``weights`` (mechanism -> 0..1, ``mechanisms.planner``)
        switch the gated effects on ``auto`` on or off for the frame and blend them
        in; ``estimate``: the analysis's (illuminant rgb, CCT, confidence)."""
        from ..mechanisms.planner import GATED
        self.estimate = estimate
        if not weights:
            self.s, self.weights = self.settings, {}
            return
        modes, self.weights = {}, {}
        for mech, field in GATED.items():
            if getattr(self.settings, field) == "auto":
                w = float(weights.get(mech, 0.0))
                modes[field] = "on" if w > 0.0 else "off"
                self.weights[field] = w
        self.s = replace(self.settings, **modes)

    def weight(self, field: str) -> float:
        return self.weights.get(field, 1.0)

    def slot_plugins(self, slot: str):
        return [p for p in self.plugins if p.SLOT == slot]

    def flare(self, rgb: np.ndarray, G_rod: float, G_cone: float, lim: float):
        """(new rgb or None, info) for one frame in cd/m^2 (``rgb`` may be a device image
        where :meth:`flare_on_device`: the new one is then one too); ``lim``: the
        frame's source limit (``flare.source_limit``)."""
        self._make_flare_device()
        new, info = _flare.run(self.s, rgb, G_rod, G_cone, lim, self._blur, self._flare_dev)
        if self._flare_dev is not None:
            self._flare_dev.discard()         # start()'s passes, where the plan skipped it
        w = self.weight("flare")
        if new is not None and w < 1.0:       # blended in or out (the plan's ramp)
            old = np.asarray(rgb, np.float32)[..., :3]
            new = (old + w * (np.asarray(new, np.float32) - old)).astype(np.float32)
            info["weight"] = w
        return new, info

    def start_flare(self, rgb, G_rod: float, G_cone: float, max_Y: float | None,
                    lim: float) -> None:
        """Before the frame is planned: the first passes of its flare on the device,
        where the frame has a source (``max_Y`` above the source limit ``lim``) and the
        flare may run (on, or ``auto`` for the plan to decide): the device makes them
        while the host plans. :meth:`flare` goes on from them, or drops them."""
        self._make_flare_device()
        if self._flare_dev is not None and max_Y is not None and max_Y > lim:
            _flare.start_on_device(self.settings, rgb, G_rod, G_cone, lim, self._flare_dev)

    def drop_started(self) -> None:
        """Drop :meth:`start_flare`'s passes a frame left (one that failed before its
        flare): the next frame starts afresh."""
        if self._flare_dev is not None:
            self._flare_dev.discard()

    def _make_flare_device(self) -> None:
        if self.s.flare != "off" and self.s.flare_method == "fast" and \
                self._flare_dev is None:
            self._flare_dev = self.backend.flare_device()

    def flare_on_device(self, h: int, w: int) -> bool:
        """Whether this frame's flare runs whole on the device (the fast method, a device
        that holds the frame): its working frame can stay there."""
        self._make_flare_device()
        return self._flare_dev is not None and self._flare_dev.fits(h, w)

    def purkinje_advance(self, G_rod: float, G_cone: float, extra: dict | None, dt: float,
                         fresh: bool, preadapt) -> dict:
        """The Purkinje shift's time course over one frame (``purkinje.advance``): its
        record, ``ran`` where :meth:`purkinje_shift` is to make the frame's pixels."""
        skipped = self._purkinje_skipped()          # the plan's: its levels still advance
        return _purkinje.advance(self.settings if skipped else self.s, G_rod, G_cone, extra,
                                 dt, fresh, preadapt, self.weight("purkinje"), skipped)

    def purkinje_shift(self, rgb, info: dict):
        """(shifted rgb, info) of a frame whose :meth:`purkinje_advance` ran (on the
        device, in place, where ``rgb`` is a device image)."""
        self._make_purkinje_device()
        return _purkinje.shift(rgb, info, self._purkinje_dev)

    def purkinje_on_device(self) -> bool:
        """Whether the Purkinje shift runs on the device (then in place on a device
        image: the working frame can stay there)."""
        if self.settings.purkinje == "off":
            return False
        if self._purkinje_dev is None:
            self._purkinje_dev = self.backend.purkinje_device()
        return self._purkinje_dev is not None

    def _purkinje_skipped(self) -> bool:
        return self.settings.purkinje != "off" and self.s.purkinje == "off"

    def _make_purkinje_device(self) -> None:
        if self.s.purkinje != "off" and self._purkinje_dev is None:
            self._purkinje_dev = self.backend.purkinje_device()

    def illuminant_goal(self, frame_hint, estimate_fn):
        """(normalised rgb, source): user value > frame metadata > estimate (the
        scene analysis's bounded one; with ``paper``, the paper's: the backend's
        grey world ``estimate_fn``)."""
        est = estimate_fn
        if self.estimate is not None and not self.s.paper:
            est = lambda: self.estimate[0]                 # noqa: E731
        return _chromatic.illuminant_goal(self.user_illuminant, frame_hint, est)

    def chromatic(self, extra: dict, goal, source: str, dt: float, fresh: bool,
                  preadapted: bool, L_A: float | None = None):
        """Advance the illuminant state; returns (gains or None, info). ``L_A``: the
        adapting luminance (cd/m^2) of the degree of adaptation (an estimate comes
        with its confidence applied: ``mechanisms.analysis``)."""
        return _chromatic.run(self.s, extra, goal, source, dt, fresh, preadapted, L_A)

    def acuity(self, img: np.ndarray, G_rod: float):
        out, info = _acuity.run(self.s, img, G_rod, self._blur)
        w = self.weight("acuity")
        if info.get("ran") and w < 1.0:
            out = (img + w * (np.asarray(out, np.float32) - img)).astype(np.float32)
            info["weight"] = w
        return out, info

    def acuity_encoding(self, encoding, G_rod: float, h: int, w: int):
        """(``encoding`` with the acuity blur on the device before it, the frame's acuity
        record) where the backend can blur the frame where the operator leaves it
        (``backend.acuity_encoding``), else (None, None): the blur of :meth:`acuity`
        with the plan's weight, in float32 on the device."""
        make = getattr(self.backend, "acuity_encoding", None)
        plan = _acuity.blur_plan(self.s, G_rod, w, self.weight("acuity"))
        if make is None or plan is None or self._device_blur is None:
            return None, None
        taps, t, info = plan
        enc = make(encoding, h, w, taps, t, self._device_blur)
        return (None, None) if enc is None else (enc, info)

    def acuity_needed(self, G_rod: float, width: int) -> bool:
        return _acuity.needed(self.s, G_rod, width)

    def acuity_report(self, G_rod: float, width: int) -> dict:
        """The acuity record of a frame left unblurred (``acuity_needed`` False)."""
        return _acuity.report(self.s, G_rod, width)

    # -- frames in row bands (Tonemapper.process_stream) -------------------------------
    def flare_stream(self, shape, G_rod: float, G_cone: float, lim: float, rgb_rows,
                     max_pixels: int, max_Y: float | None = None,
                     block_pixels: int | None = None):
        """(:class:`~.flare.BandedFlare` or None, info); see :func:`.flare.stream`."""
        return _flare.stream(self.s, shape, G_rod, G_cone, lim, rgb_rows, max_pixels,
                             self._blur, max_Y, block_pixels, self.weight("flare"))

    def purkinje_banded(self, info: dict, height: int):
        """A :class:`~.purkinje.BandedPurkinje` for a frame whose shift ran, else None."""
        if not info.get("ran"):
            return None
        self._make_purkinje_device()
        return _purkinje.BandedPurkinje(info, self._purkinje_dev, height)

    def acuity_stream(self, sink, G_rod: float, shape, block_pixels: int | None = None):
        """(sink, info): ``sink`` behind a :class:`~.acuity.BandedAcuity` when it blurs."""
        dev = self._device_blur
        pas = None if dev is None else \
            (lambda im, taps, axis: dev.blur_axis(im, taps, EDGE_CLAMP, axis))
        return _acuity.stream(self.s, sink, G_rod, shape, pas, block_pixels,
                              self.weight("acuity"))
