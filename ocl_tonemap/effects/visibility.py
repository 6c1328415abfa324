"""What the observer can see: Adrian 1989's threshold under an operator's own state.

The threshold luminance difference of a target on a background L_b (the glare veil
included, as CIE 88 adds L_seq) is Adrian's steady dL_th (``models/adrian1989.py``)
times the transient factor TAF of the observer's present adaptation
(``adrian1989.transient_factor``): each operator's response gain at L_b now
against its gain when adapted to L_b (``Operator.observer_*``). So the papers' time
courses drive the threshold, frame by frame.

One observer serves the ``visibility`` calculator (a step in a uniform field,
:func:`trace`), the run's ``--visibility`` planes and its ``--target`` line:
:class:`Viewing` with one default look (:data:`OBSERVATION_S`), its inputs declared
once (:data:`INPUTS`). The planes' algorithm is
``models/visibility_map.py`` (float64, the reference backend's);
``backends/opencl/visibility.py`` runs the same steps in float32 kernels.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..models import adrian1989 as ad
from ..models import cie203
from ..models.visibility_map import transient
from ..base.quantities import LUMINANCE_RANGE, OBSERVATION_S, TARGET_ARCMIN, VISIBILITY

_LO = LUMINANCE_RANGE[0]
#: Every number the visibility takes, declared once (``quantities.VISIBILITY``).
INPUTS = VISIBILITY
#: The seconds after a step the calculator reports by default (``--after``).
AFTER_S = (0.5, 2.0, 10.0)


def check_input(name: str, value, flag: str) -> float:
    """``value`` checked against :data:`INPUTS`' declaration of ``name``."""
    return INPUTS[name].check(value, flag)


@dataclass(frozen=True)
class Viewing:
    """The target and the observer: size (arcmin), age (years), observation time (s),
    field factor k, Adrian's variant (``1989`` or ``rp8``)."""

    size_arcmin: float = TARGET_ARCMIN
    age: float = 25.0
    time_s: float = OBSERVATION_S
    k: float = ad.FIELD_FACTOR
    adrian: str = ad.ADRIAN_1989.name

    #: The flags that give each field, for the errors (the calculator's by default).
    FLAGS = {"size": "--size", "age": "--age", "time": "--time", "k": "--k"}

    def check(self, flags: dict | None = None) -> "Viewing":
        """Each field against :data:`INPUTS` (ValueError in one line naming the flag
        of ``flags``); a warning where Adrian's data are extrapolated."""
        fl = {**self.FLAGS, **(flags or {})}
        for name, v in (("size", self.size_arcmin), ("age", self.age), ("time", self.time_s),
                        ("k", self.k)):
            INPUTS[name].check(v, fl[name])
            INPUTS[name].warn_beyond_data(float(v), fl[name])
        ad.variant(self.adrian)
        return self

    @property
    def variant(self) -> ad.Variant:
        return ad.variant(self.adrian)

    def steady(self, L_b, polarity="positive") -> np.ndarray:
        """Adrian's dL_th (cd/m^2) of backgrounds ``L_b`` (any shape), the eye adapted
        to each; ``polarity`` "positive", "negative" or a boolean array (True:
        negative)."""
        neg = np.asarray(polarity == "negative") if isinstance(polarity, str) \
            else np.asarray(polarity, bool)
        return ad.threshold_of(L_b, self.size_arcmin, self.age, self.time_s, neg, self.k,
                               self.variant)

    @property
    def media_gain(self) -> float:
        """The scene-to-retina factor of this observer's ocular media (CIE 203), the
        run's at the same age: the operators' states hold the light behind the media,
        so their responses are read at gain x L_b (Adrian's AF holds the threshold's
        own part of the media, measured on observers with their lenses)."""
        return cie203.media_gain(self.age)

    def describe(self) -> dict:
        """What a header, a report and the calculator's table say of this observer."""
        return {"target_arcmin": float(self.size_arcmin), "age": float(self.age),
                "observation_s": float(self.time_s), "k": float(self.k),
                "adrian": self.adrian}


@dataclass(frozen=True)
class Seen:
    """One target's visibility: its background L_b (the veil added), the eye's cone
    level La (scene cd/m^2), TAF, dL_th and VL (None without a target luminance)."""

    L_b: float
    L_a: float
    TAF: float
    dL_th: float
    VL: float | None = None


def seen(op, obs: dict, view: Viewing, L_background: float, L_veil: float = 0.0,
         L_target: float | None = None, negative: bool = False) -> Seen:
    """The calculator's and the run's ``--target`` line's one formula: a target on a
    background ``L_background`` with the veil ``L_veil`` over both (CIE 88: L_seq
    adds to the background's adaptation, not to the difference), seen by ``op``'s
    observer in state ``obs``. ``L_target``: its VL, and its polarity (darker than
    the background: negative); without one, ``negative`` says the polarity."""
    L_b = max(float(L_background) + float(L_veil), _LO)
    neg = negative if L_target is None else L_target < L_background
    taf = float(transient(op, obs, L_b, view.media_gain))
    dl = float(view.steady(L_b, "negative" if neg else "positive")) * taf
    vl = None if L_target is None else abs(L_target - L_background) / dl
    return Seen(L_b, float(np.mean(op.observer_level(obs))) / view.media_gain, taf, dl, vl)


@dataclass(frozen=True)
class TracePoint:
    """The observer ``t`` s after a step: adaptation luminance La, TAF, dL_th (and VL
    of a target)."""

    t: float
    L_a: float
    TAF: float
    dL_th: float
    VL: float | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def trace(op, L_from: float, seconds: float | None, L_b: float, times, view: Viewing,
          polarity: str = "positive", L_target: float | None = None,
          L_veil: float = 0.0) -> list[TracePoint]:
    """The observer of ``op`` adapted to a neutral field of ``L_from`` (for ``seconds``;
    None: fully), which steps to ``L_b`` (plus the veil ``L_veil``) at t = 0: its
    threshold at each of ``times`` (s after the step, >= 0; the field held there)."""
    g = view.media_gain                       # the operator sees the light behind the media
    Lv = float(L_b) + float(L_veil)
    obs = op.observer_preadapted(float(L_from) * g, seconds)
    steady = float(view.steady(Lv, polarity))
    s_ss = float(op.observer_steady_slope(Lv * g))
    out, now = [], 0.0
    for t in sorted(float(x) for x in times):
        obs = op.observer_advance(obs, Lv * g, t - now)
        now = t
        taf = float(ad.transient_factor(s_ss, op.observer_slope(obs, Lv * g)))
        dl = steady * taf
        vl = None if L_target is None else abs(L_target - L_b) / dl
        out.append(TracePoint(t, float(op.observer_level(obs)) / g, taf, dl, vl))
    return out
