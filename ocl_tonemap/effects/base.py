"""The effect protocol: what an effect declares and what it can do, as
``operators/base.py`` is for operators.

An effect is a class with

* ``name``: its switch -- the :class:`~.settings.EffectSettings` field, the API
  keyword, the command-line flag (``--flare``) and, where ``gated``, the mechanism
  the frame's plan weighs (``mechanisms/``);
* ``slot``: where it sits in a frame's data flow (:data:`SLOTS`): ``optical``, the
  light that reaches the eye, before the metering (the flare); ``seen``, what the
  observer makes of that light, after the state step (the Purkinje shift,
  chromatic gains on the scene); ``display``, the display-linear output (acuity);
* ``options``: its parameters (:class:`EffectOption`): each an EffectSettings
  field, an API keyword and a flag, with its default and its check;
* ``gated``: the plan may skip it where its predicted effect (``predict``) is
  below one JND (``--model auto``);
* ``capabilities``: what it can work on, each one method -- ``host`` (a frame in
  host memory), ``device`` (a frame on the backend's device), ``banded`` (a frame
  in row bands, never whole); ``advance`` is its time course at the state step.

Built-in effects: ``flare.py``, ``purkinje.py``, ``chromatic.py``, ``acuity.py``;
a separately installed package adds one through the ``ocl_tonemap.effects`` entry
point group (``examples/night_noise_effect``), and gets its flag, keyword and gate
without a change here. ``runner.py`` runs a frame's effects slot by slot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from ..operators.base import Option

#: The slots of a frame's data flow, in order.
SLOTS = ("optical", "seen", "display")
#: An effect's switch: on, off, or ``auto`` (the frame's plan decides).
MODES = ("on", "off", "auto")
#: What an effect can work on (one method each).
CAPABILITIES = ("host", "device", "banded")


@dataclass(frozen=True)
class EffectOption(Option):
    """One parameter of an effect: ``name`` (the EffectSettings field and API keyword),
    ``flag``, ``help``, ``type``/``choices``/``metavar`` (the command line), ``check``
    (raises ValueError on a bad API value), ``value`` (its default setting). The
    command line's ``default`` stays None: a flag not given is not passed."""

    value: Any = None


def mode_option(name: str, help: str) -> EffectOption:
    """An effect's switch: ``--NAME on|off|auto``."""
    flag = "--" + name.replace("_", "-")

    def check(v):
        if v not in MODES:
            raise ValueError(f"{flag} must be on, off or auto (got {v!r})")
    return EffectOption(name, flag, help, choices=MODES, check=check, value="off")


@dataclass
class FrameContext:
    """What the effects of one frame are given: the frame's levels (the scene's
    metering goals before the optical effects; the metered frame's in the display
    slot), the flare's source limit and largest luminance (photopic, scotopic), the
    state step (``dt``, ``fresh``, the state's ``extra`` where time courses are kept,
    the run's pre-adaptation), the frame's number and time, and ``eff``, the frame's
    effect records (``ocltm:effects``), which each effect fills under its name."""

    G_rod: float
    G_cone: float
    eff: dict = field(default_factory=dict)
    lim: float = math.inf
    max_Y: float | None = None
    max_Ys: float | None = None
    dt: float = 0.0
    fresh: bool = True
    extra: dict | None = None
    preadapt: Any = None
    frame: int | None = None
    time_s: float = 0.0
    width: int = 0

    @property
    def levels(self) -> dict:
        return {"G_rod": self.G_rod, "G_cone": self.G_cone}


class Effect:
    """Base class of an effect (class attributes declare it; an instance runs it for
    one observer, ``fx`` being the run's :class:`~.runner.Effects`). The methods of
    its capabilities return ``(new frame or None, info)``; ``info["ran"]`` says
    whether it changed the frame. An effect that does not blend itself by the plan's
    weight (``blends`` False) is blended by the runner: old + w (new - old)."""

    name: str = ""
    slot: str = ""
    help: str = ""
    options: tuple = ()
    gated: bool = False
    #: The plan's name for it (``ocltm:plan``), where it is not ``name``.
    mechanism: str | None = None
    capabilities: frozenset = frozenset({"host"})
    #: It applies the plan's weight itself (else the runner blends its output).
    blends: bool = False

    def __init__(self, fx):
        self.fx = fx

    @classmethod
    def mechanism_name(cls) -> str:
        return cls.mechanism or cls.name

    @property
    def mode(self) -> str:
        """This frame's mode (the plan's choice applied to ``auto``)."""
        return getattr(self.fx.s, self.name)

    @property
    def asked(self) -> str:
        """The run's mode (on, off or auto)."""
        return getattr(self.fx.settings, self.name)

    @classmethod
    def predict(cls, an, response, settings) -> float:
        """Its predicted p99 Delta E ITP on a frame (``an``: the plan's analysis of it;
        ``response``: scene cd/m^2 -> ICtCp of the display light at the frame's levels,
        ``mechanisms.predict.DisplayResponse``). Gated effects only."""
        raise NotImplementedError

    def advance(self, ctx: FrameContext) -> None:
        """Its time course over the frame, at the state step (records into ``ctx.eff``)."""

    def host(self, ctx: FrameContext, rgb):
        return None, {"ran": False}

    def device(self, ctx: FrameContext, img):
        return self.host(ctx, img)

    def banded(self, ctx: FrameContext, *args, **kw):
        """A frame in row bands: optical ``(rows, max_pixels, block_pixels)`` -> (a band
        source with ``rows(y0, y1)`` or None, functions to call once the metering pass
        has swept it); seen ``(height)`` -> (``step(y0, rgb)`` or None, functions to
        call once the bands are made); display ``(sink, shape, block_pixels)`` ->
        (the sink with it in front, info). Effects with the ``banded`` capability."""
        raise NotImplementedError(f"effect {self.name} does not work on frames in bands")

    def start(self, ctx: FrameContext, rgb) -> None:
        """Optical effects: work the device can begin before the frame is planned."""

    def drop_started(self) -> None:
        """Drop what :meth:`start` began (a frame that failed before its effects)."""
