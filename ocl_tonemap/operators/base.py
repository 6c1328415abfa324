"""The operator protocol: what an operator computes, declared; how, left to the backends.

An operator is a class with

``name``, ``description``, ``citation``
    registry name (``--operator NAME``), one line for ``--help``, the paper;
``options``
    :class:`Option` specs: the command line (flags and ``--help``), the API
    keywords (``Tonemapper(options=...)``), validation and the output metadata are
    all generated from them;
``state``
    a :class:`StateSpec`: the scalar values and per-pixel planes it keeps between
    frames (``AdaptationState.values`` / ``.pixels``);
``stages``
    its per-frame :class:`Stage` list, each a pointwise, neighbourhood (with a
    halo), reduction (metering) or host-side state step, naming its float64
    reference in ``models/`` and its kernel in ``kernels/``;
``inputs``
    ``("rgb",)`` or ``("rgb", "spectral")``;

and the three phases of a frame, which a run chains frame by frame and which can
also be called separately (``Tonemapper.measure / integrate / apply``):

``measure``   per-frame statistics (metering sums, the illuminant, and for local
              operators the per-pixel adaptation inputs): :class:`FrameStats`;
``integrate`` advance the adaptation state over the statistics (host scalars, or
              per-pixel planes on the backend);
``apply``     the per-pixel mapping of the frame, given the state.

The phases run on a *schedule*: the backend's executor of the stage list
(``backends/``). A pointwise operator (colour, metering, state step, one
per-pixel map) needs no schedule of its own: it provides ``params`` (the frame's
scalars), ``map_reference`` (float64) and ``kernel_call`` (the kernel and its
packed parameters), and both backends run it. Operators with neighbourhood
stages or per-pixel state name a schedule per backend (``schedules``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from ..models.photometry import RepairCounts, neutral_scotopic_ratio
from .pigment import PIGMENT_KEY, PigmentCourse  # noqa: F401 (PIGMENT_KEY re-exported)

#: Kinds of stage.
STAGE_KINDS = ("colour", "reduction", "state", "pointwise", "neighbourhood")


@dataclass(frozen=True)
class Option:
    """One operator option: the API keyword ``name`` and the command-line ``flag``.

    ``default`` is the command line's default (a flag left at it is not passed);
    ``convert`` turns the flag's text into the API value; ``check`` validates an
    API value (raises ValueError). Several operators may declare the same flag:
    it is then one command-line option shared by them."""

    name: str
    flag: str
    help: str
    type: Callable | None = None
    default: Any = None
    choices: tuple | None = None
    metavar: str | None = None
    convert: Callable | None = None
    check: Callable | None = None
    decl: Any = None

    def __post_init__(self):
        """``decl`` (a ``quantities`` declaration: what the value is, its unit and
        range) makes the flag's parser and the API's check, in the same words."""
        if self.decl is None:
            return
        flag = self.flag or self.name
        if self.type is None:
            object.__setattr__(self, "type", self.decl.arg(flag))
        if self.check is None:
            object.__setattr__(self, "check", lambda v, d=self.decl, f=flag:
                               None if v is None else d.check(v, f))   # None: not given

    @property
    def help_text(self) -> str:
        """The flag's help with the declared range."""
        return self.decl.help(self.help) if self.decl is not None else self.help

    @property
    def dest(self) -> str:
        """The argparse destination (the API name for API-only options, flag None)."""
        return self.flag.lstrip("-").replace("-", "_") if self.flag else self.name


@dataclass(frozen=True)
class Stage:
    """One per-frame stage: what it computes (``reference``, a function in
    ``models/``), where its device code is (``kernel``, ``FILE.cl:NAME``), what
    kind of access it makes and, for neighbourhoods, its halo."""

    name: str
    kind: str
    what: str
    reference: str = ""
    kernel: str = ""
    halo: str = ""

    def __post_init__(self):
        if self.kind not in STAGE_KINDS:
            raise ValueError(f"stage {self.name}: kind must be one of {STAGE_KINDS}")


@dataclass(frozen=True)
class StateSpec:
    """What an operator keeps between frames: named scalars and per-pixel planes."""

    scalars: tuple[str, ...] = ()
    planes: tuple[str, ...] = ()


@dataclass
class FrameStats:
    """What ``measure`` found on one frame.

    G_rod, G_cone : the frame's adaptation goals (scotopic / photopic cd/m^2).
    repairs : bad values replaced (NaN, inf, negatives ...).
    illuminant : a function giving the frame's illuminant estimate (working RGB),
        computed on demand.
    values : operator-specific scalars (JSON-able).
    planes : per-pixel adaptation inputs (backend arrays or buffers).
    handle : the backend's resident frame (private to the schedule that made it).
    scene_goal : (G_rod, G_cone) of the run's ``--metering`` on the frame, where the
        effects need it (the operator's own goals may be local: ledda04, kirk11).
    scene_max_Y, scene_max_Ys, scene_repairs : the largest working luminance (photopic,
        scotopic) and the repair counts of that metering (before the optical effects),
        where it ran: with
        ``scene_goal``, what a shot's apply pass takes from the store instead of
        metering the frame again (issue 59).
    """

    width: int
    height: int
    G_rod: float
    G_cone: float
    repairs: RepairCounts = field(default_factory=RepairCounts)
    illuminant: Callable | None = None
    values: dict = field(default_factory=dict)
    planes: dict = field(default_factory=dict)
    handle: Any = None
    scene_goal: tuple | None = None
    scene_max_Y: float | None = None
    scene_repairs: RepairCounts | None = None
    scene_max_Ys: float | None = None


@dataclass
class Frame:
    """One frame as the schedules see it: ``pixels`` (H x W x C float32, or a band
    source whose row slices read the file), ``scale`` (cd/m^2 per pixel value),
    ``wavelengths`` (nm, spectral frames), the display primaries for operators that
    solve for display RGB."""

    pixels: Any
    scale: float
    wavelengths: np.ndarray | None = None
    display_primaries: np.ndarray | None = None

    @property
    def shape(self):
        return self.pixels.shape


class Operator(PigmentCourse):
    """Base class of the operators (see the module docstring)."""

    name = ""
    description = ""
    citation = ""
    options: tuple[Option, ...] = ()
    state = StateSpec()
    stages: tuple[Stage, ...] = ()
    inputs = ("rgb",)
    #: "frame": metered with the run's --metering spec; "local": adapts per pixel.
    metering = "frame"
    #: effects this operator models itself (not offered as an effect: kirk11's
    #: Purkinje shift).
    own_effects: tuple = ()
    #: backend name -> "module:Class" of the schedule running this operator; the
    #: pointwise schedules are used where none is named.
    schedules: dict = {}
    #: Why a frame's mapping is not one function of the pixel's RGB (what keeps it out
    #: of an OCIO export, ``colour/export.py``); None where it is.
    export_blocker: str | None = "its mapping is not declared per-pixel"

    def __init__(self, options: dict | None = None, display=None, preadapt=None):
        self.display = display
        self.preadapt = preadapt
        self.options = self.validate_options(options)

    # -- options -------------------------------------------------------------------
    @classmethod
    def validate_options(cls, options: dict | None) -> dict:
        """Options given (None dropped), unknown names refused, each checked."""
        given = {k: v for k, v in (options or {}).items() if v is not None}
        known = {o.name: o for o in cls.options}
        bad = [k for k in given if k not in known]
        if bad:
            raise ValueError(f"operator {cls.name} takes no option(s) {', '.join(sorted(bad))}"
                             + (f" (it takes {', '.join(known)})" if known else ""))
        for k, v in given.items():
            o = known[k]
            if o.choices is not None and o.type is None and v not in o.choices:
                raise ValueError(f"{o.flag} must be one of {', '.join(map(str, o.choices))} "
                                 f"(got {v!r})")
            if o.check is not None:
                checked = o.check(v)
                if o.decl is not None:            # the declared value (text parsed)
                    given[k] = checked
        return given

    def option(self, name: str, default=None):
        return self.options.get(name, default)

    # -- the phases ------------------------------------------------------------------
    def steady_state(self, stats: FrameStats) -> dict:
        """State values fully adapted to a frame."""
        raise NotImplementedError

    def preadapted(self, L_cd: float, seconds: float | None) -> dict:
        """State values after a neutral field of ``L_cd`` cd/m^2 (for ``seconds``)."""
        raise NotImplementedError

    def advance(self, values: dict, stats: FrameStats, dt: float) -> dict:
        """State values advanced by ``dt`` seconds toward the frame's goals."""
        raise NotImplementedError

    def integrate(self, state, stats: FrameStats, dt: float, fresh: bool) -> None:
        """Advance ``state`` (an AdaptationState) over one frame's statistics: the
        scalar time course of the host scheduler. Operators with per-pixel state
        do it on their schedule. In the default mode of an operator with the
        shared pigment course, the goals it adapts to carry the equivalent
        backgrounds of the pigment still bleached."""
        if self.uses_pigment():
            stats = self.pigment_goals(state, stats, dt, fresh)
        if fresh:
            state.values = (self.preadapted(*self.preadapt) if self.preadapt is not None
                            else self.steady_state(stats))
        else:
            state.values = self.advance(state.values, stats, dt)

    def params(self, state, stats: FrameStats):
        """The frame's scalars for the per-pixel stage (an object with ``as_dict``)."""
        raise NotImplementedError

    def summary(self, params, stats: FrameStats | None = None) -> dict:
        """What to record per frame (metadata, plots): the frame's scalars ``params``;
        operators whose schedules work them out per pixel read ``stats.values``."""
        return params.as_dict() if hasattr(params, "as_dict") else {}

    # -- per-pixel stage of pointwise operators --------------------------------------------
    def map_reference(self, rgb: np.ndarray, Y: np.ndarray, Ys: np.ndarray, params) -> np.ndarray:
        """Float64: scene cd/m^2 (rgb, photopic Y, scotopic Y') -> display-linear RGB."""
        raise NotImplementedError

    def kernel_call(self, params) -> "KernelCall | None":
        """The device per-pixel stage: kernel and packed scalars (None: no kernel;
        the OpenCL backend then runs ``map_reference`` on the host)."""
        return None

    # -- display model helpers --------------------------------------------------------------
    def white_luminance_at(self, G_rod: float, G_cone: float, lo: float = 0.0) -> float | None:
        """Where an observer adapted to a frame's levels runs out of display: the
        luminance (cd/m^2, >= ``lo``) of a uniform neutral region that its map shows at
        the display's white or beyond (:func:`white_luminance`); None where the
        operator has no model of it (the mechanism plan then takes pattanaik00's)."""
        return None

    def plot_curves(self, state, Ls: np.ndarray):
        """Display-linear output of neutral greys ``Ls`` (cd/m^2) under ``state``, or
        None for operators with no single curve (local adaptation)."""
        L = np.asarray(Ls, np.float64)
        p = self.params(state, None)
        rgb = np.repeat(L[:, None], 3, axis=1)
        return self.map_reference(rgb, L, L * neutral_scotopic_ratio(), p)


    # -- the observer, for visibility (ocl_tonemap/effects/visibility.py) ----------------------------
    # A uniform neutral field seen over time, in the operator's own state, and the gain
    # of its response for a small increment: the transient threshold follows the
    # operator's time course (models/adrian1989.transient_factor).
    def observer_preadapted(self, L_cd: float, seconds: float | None) -> dict:
        """Observer state after a neutral field of ``L_cd`` cd/m^2 (for ``seconds``;
        None: fully adapted)."""
        raise NotImplementedError(f"{self.name} has no observer model")

    def observer_advance(self, obs: dict, L_cd: float, dt: float) -> dict:
        """Observer state after ``dt`` s more of a neutral field of ``L_cd``."""
        raise NotImplementedError(f"{self.name} has no observer model")

    def observer_slope(self, obs: dict, L_b):
        """dR/dln L of the operator's response at background(s) ``L_b`` under ``obs``."""
        raise NotImplementedError(f"{self.name} has no observer model")

    def observer_level(self, obs: dict):
        """The eye's (cone) adaptation luminance of ``obs``, cd/m^2."""
        raise NotImplementedError(f"{self.name} has no observer model")

    def observer_steady_slope(self, L_b):
        """:meth:`observer_slope` of observers adapted to each of ``L_b`` (any shape)."""
        L = np.asarray(L_b, np.float64)
        return np.array([float(self.observer_slope(self.observer_preadapted(float(x), None), x))
                         for x in L.reshape(-1)]).reshape(L.shape)

    #: True where :meth:`observer_of` holds a state per pixel (local adaptation).
    observer_per_pixel = False

    def observer_of(self, state, stats=None) -> dict:
        """The observer state of a run's AdaptationState at a frame (global
        operators: its scalars)."""
        return dict(state.values)


#: The colour and metering stages every frame-metered operator starts with.
COLOUR_STAGE = Stage("colour", "colour", "working RGB x scale -> cd/m^2, Y, Y'; bad values "
                     "repaired", "models.photometry.sanitize", "colour.cl:scene_to_working4")
METER_STAGE = Stage("meter", "reduction", "adaptation goals G_rod (Y'), G_cone (Y) with the "
                    "run's --metering", "models.metering.reference_goal",
                    "metering.cl:meter_partial")


class ModelOperator(Operator):
    """A global operator whose state step, frame scalars and per-pixel reference are a
    model module's ``steady_state``, ``advance``, ``preadapted``, ``frame_params`` and
    ``map_reference`` (goals G_rod, G_cone)."""

    model = None

    def steady_state(self, stats):
        return self.model.steady_state(stats.G_rod, stats.G_cone)

    def preadapted(self, L_cd, seconds):
        return self.model.preadapted(L_cd, seconds)

    def advance(self, values, stats, dt):
        return self.model.advance(values, stats.G_rod, stats.G_cone, dt)

    def params(self, state, stats):
        return self.model.frame_params(state, self.display, **self.options)

    def map_reference(self, rgb, Y, Ys, p):
        return self.model.map_reference(rgb, Y, Ys, p)

    def observer_preadapted(self, L_cd, seconds):
        if self.uses_pigment():
            return self.pigment_observer(self.preadapted(L_cd, seconds), L_cd, seconds)
        return self.model.preadapted(L_cd, seconds)

    def observer_advance(self, obs, L_cd, dt):
        if self.uses_pigment():
            return self.pigment_observer_advance(obs, L_cd, dt)
        return self.model.advance(obs, L_cd * neutral_scotopic_ratio(), L_cd, dt)

    def observer_slope(self, obs, L_b):
        return self.model.response_slope(L_b, obs)

    def observer_level(self, obs):
        return self.model.adaptation_luminance(obs)

    def observer_steady_slope(self, L_b):
        return self.model.steady_slope(L_b)

    #: The per-pixel map's smooth part is ``map_reference`` with ``raw=True``
    #: (``colour/export.py`` samples it for an OCIO export).
    export_blocker = None

    def white_luminance_at(self, G_rod: float, G_cone: float, lo: float = 0.0) -> float:
        stats = FrameStats(1, 1, float(G_rod), float(G_cone))

        class _Steady:
            values = self.steady_state(stats)
        return self.white_luminance(self.params(_Steady, stats), lo)

    def white_luminance(self, params, lo: float = 0.0) -> float:
        """The scene luminance (cd/m^2) from which a neutral grey is shown at the
        display's white or beyond under the frame's ``params``: :func:`white_luminance`
        of the map before its highlight shoulder."""
        return white_luminance(lambda L: self.map_reference(
            np.repeat(L[:, None], 3, axis=1), L, L * NEUTRAL_SCOTOPIC, replace(params, raw=True)),
            float(params.white_signal), lo)

    def colour_axes(self, p) -> np.ndarray:
        """The 3x3 matrix M of the axes v = M rgb (working cd/m^2) along which the raw
        map's output channels cross zero (``colour/lattice.py``); identity here."""
        return np.eye(3)


#: Neutral Y'/Y (a grey of Y cd/m^2 has Y' = this x Y; models/photometry.py).
NEUTRAL_SCOTOPIC = neutral_scotopic_ratio()
#: white_luminance searches up to the scene ceiling (the bad-value policy's 1e10).
WHITE_SEARCH_TOP = 1.0e10
#: ... on a grid of this many points a decade (then linear in log L between two).
WHITE_SEARCH_PER_DECADE = 64


def white_luminance(shown, white: float, lo: float = 0.0) -> float:
    """The smallest scene luminance L >= ``lo`` (cd/m^2) whose neutral grey
    ``shown(L)`` (display-linear RGB of an array of luminances, before any
    highlight shoulder) reaches ``white`` in a channel: where the display runs out
    of range for this observer. Searched on a log grid from max(lo, 1e-6) up to
    1e10 cd/m^2, interpolated in log L between the two grid points around it;
    ``lo`` itself where it is already beyond white, inf where nothing up to 1e10
    is (a map that keeps every light within the display). Monotone maps only."""
    a = math.log10(max(float(lo), 1.0e-6))
    b = math.log10(WHITE_SEARCH_TOP)
    if a >= b:
        return math.inf
    n = max(2, int(math.ceil((b - a) * WHITE_SEARCH_PER_DECADE)) + 1)
    x = np.linspace(a, b, n)
    out = np.max(np.asarray(shown(10.0 ** x), np.float64), axis=-1)
    above = np.flatnonzero(out >= white)
    if above.size == 0:
        return math.inf
    k = int(above[0])
    if k == 0:
        return float(max(lo, 10.0 ** a))
    y0, y1 = out[k - 1], out[k]
    t = (white - y0) / (y1 - y0) if y1 > y0 else 1.0
    return float(10.0 ** (x[k - 1] + min(max(t, 0.0), 1.0) * (x[k] - x[k - 1])))


@dataclass(frozen=True)
class KernelCall:
    """A per-pixel kernel of signature ``(rgb, Y, Ys, out, n, __constant float *p)``
    (``params``: the frame's scalars in the kernel's order, packed as float32; with
    ``frame_params``, at most 16 of them as one float16 argument instead,
    kernels/common.h ``FRAME_PARAMS``: they travel with the launch, no upload) that maps
    ``pixels_per_item`` pixels per work-item (launched over ceil(n / that) items).
    ``buffers``: extra read-only float32 arrays passed after ``p`` (tables).
    ``defines``: the kernel file's model constants, (NAME, value) pairs given to the
    compiler as -DNAME=value beside the parameters' indices P_<name> (never retyped in
    the kernel; common.h's come with every program)."""

    file: str
    kernel: str
    params: tuple
    pixels_per_item: int = 1
    buffers: tuple = ()
    defines: tuple = ()
    frame_params: bool = False


def finite_positive(flag: str, upper: float = math.inf):
    def check(v):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 < v <= upper):
            raise ValueError(f"{flag} must be a positive number (got {v!r})")
    return check

