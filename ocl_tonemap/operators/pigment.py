"""The shared pigment course in the operators (issue 66): what every operator with
``pigment_course`` gets from ``models/bleaching.py`` in its default mode, as a mixin
of :class:`~ocl_tonemap.operators.base.Operator`.

A frame's step advances the pigment state (``AdaptationState.extra["pigment"]``)
and raises the frame's goals by the equivalent backgrounds (the cones' lowered by
their onset lag on a field that came on lately), read on the operator's
own threshold curve (:meth:`PigmentCourse.receptor_threshold`): the goals its own
(fast) time course then follows. The visibility observer carries the same pigment
(:meth:`PigmentCourse.pigment_observer_advance`)."""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from ..models import bleaching
from ..models.photometry import neutral_scotopic_ratio

#: Where the shared pigment course keeps its state (``AdaptationState.extra``).
PIGMENT_KEY = "pigment"


class PigmentCourse:
    """The pigment course's part of an operator (``options``, ``preadapt`` and
    ``advance`` are the operator's own)."""

    #: Whether the default mode's slow time course is the shared pigment model
    #: (``models/bleaching.py``: bleaching and regeneration, the early neural phase),
    #: reaching the operator as an equivalent background on its goals
    #: (:meth:`pigment_goals`); ``--mode paper`` keeps the paper's own.
    pigment_course = False
    #: How the Weber observer's elevation is read on the operator's curve
    #: (:meth:`equivalent_goal`): ``"absolute"``, the background at the same threshold
    #: counted from the dark (curves with a dark light of their own), or ``"local"``,
    #: the same factor on the threshold from the operator's goal (a curve with no dark
    #: light, whose level in the dark is only its metering's floor: ledda04's).
    pigment_matching = "absolute"

    def uses_pigment(self) -> bool:
        return self.pigment_course and self.options.get("mode", "default") != "paper"

    def rod_per_cone(self) -> float:
        """A neutral field's scotopic luminance per photopic (the rods' goal of a
        pre-adapting field)."""
        return neutral_scotopic_ratio()

    def pigment_goals(self, state, stats, dt: float, fresh: bool):
        """The shared pigment course over one frame (``state.extra["pigment"]``, the
        frame's goals held over ``dt``), and the frame's statistics with its goals
        raised by the equivalent backgrounds (``bleaching.equivalent_background``)."""
        G_r, G_c = float(stats.G_rod), float(stats.G_cone)
        pig = state.extra.get(PIGMENT_KEY)
        if fresh or not bleaching.check(pig):
            pig = (bleaching.preadapted(self.preadapt[0], self.preadapt[1], self.rod_per_cone())
                   if fresh and self.preadapt is not None else bleaching.steady(G_r, G_c))
        else:
            pig = bleaching.advance(pig, G_r, G_c, dt)
        state.extra[PIGMENT_KEY] = pig
        return self.raised_goals(pig, stats)

    def raised_goals(self, pig: dict, stats):
        """The frame's statistics with its goals raised by the equivalent backgrounds of
        the pigment state ``pig`` (already advanced over the frame) and the cones' taken
        down by the onset lag (``bleaching.onset_lag``)."""
        G_r, G_c = self.shifted_goals(pig, float(stats.G_rod), float(stats.G_cone))
        return replace(stats, G_rod=G_r, G_cone=G_c)

    def shifted_goals(self, pig: dict, G_r: float, G_c: float) -> tuple[float, float]:
        """(rod, cone) goals on fields ``G_r``, ``G_c`` with the pigment state ``pig``:
        each raised by its equivalent background (:meth:`equivalent_goal`), the cones'
        then lowered by the lag of their adaptation behind a field that came on lately
        (Eq. 7: their response compressed, the field white at first)."""
        Lr, Lc = bleaching.equivalent_background(pig, G_r, G_c)
        lag = bleaching.onset_lag(pig, G_c)
        return (G_r + self.equivalent_goal("rod", Lr, G_r),
                (G_c + self.equivalent_goal("cone", Lc, G_c)) * 10.0 ** -lag)

    def receptor_threshold(self, receptor: str, L: float) -> float:
        """log10 of the threshold of a flash on a black field (cd/m^2; scotopic for the
        rods) for this operator's observer adapted to a background ``L`` of the
        receptor: its own threshold-versus-intensity, which turns the pigment model's
        elevation into the background that raises its threshold as much
        (:meth:`equivalent_goal`). Here a Weber observer with the pigment model's dark
        lights (``bleaching.I_D_ROD``, ``I_D_CONE``)."""
        return math.log10(bleaching.dark_light(receptor) + max(L, 0.0))

    def equivalent_goal(self, receptor: str, L_eq: float, G: float = 0.0) -> float:
        """What to add to the goal ``G`` so that this operator's own threshold rises as
        much as the pigment model's equivalent background ``L_eq`` raises a Weber
        observer's (dark light I_D) on the background that observer meets at the
        same threshold as the operator at ``G``: Crawford's equivalent background in
        the operator's terms (on a dark field: the background of the same elevation;
        on a bright one, where L_eq is small beside it, little). Beyond its curve's
        end, the end."""
        I_D = bleaching.dark_light(receptor)
        if not L_eq > 0.0:
            return 0.0
        logL, elev = self._elevation_tables()[receptor]
        G = max(float(G), 0.0)
        E_G = float(np.interp(math.log10(G), logL, elev)) if G > 10.0 ** logL[0] else 0.0
        if self.pigment_matching == "local":         # the same factor at the goal itself
            E = E_G + math.log10(1.0 + L_eq / (I_D + G))
        else:
            G_w = I_D * (10.0 ** E_G - 1.0)          # the Weber observer's background there
            E = math.log10(1.0 + (G_w + L_eq) / I_D)
        total = float(10.0 ** logL[-1]) if E >= elev[-1] else \
            float(10.0 ** np.interp(E, elev, logL)) if E > elev[0] else 0.0
        return max(total - G, 0.0)

    def _elevation_tables(self) -> dict:
        """(log10 L, elevation) of each receptor's threshold curve, rising, from the
        dark to where it ends (a receptor that can no longer see): made once."""
        tabs = getattr(self, "_elev_tabs", None)
        if tabs is None:
            tabs = {}
            logL = np.arange(-12.0, 9.0 + 1e-9, 0.05)
            for r in ("rod", "cone"):
                t0 = self.receptor_threshold(r, 0.0)
                e = np.array([self.receptor_threshold(r, float(10.0 ** x)) for x in logL]) - t0
                ok = np.isfinite(e)
                last = int(np.argmin(ok)) if not ok.all() else len(e)
                e, x = np.maximum.accumulate(e[:last]), logL[:last]
                keep = np.r_[True, np.diff(e) > 1e-12]           # strictly rising
                tabs[r] = (x[keep], e[keep])
            self._elev_tabs = tabs
        return tabs

    # The observer with the shared pigment course (the calculator's and the maps' own,
    # as a run's): the values and the pigment under PIGMENT_KEY.
    def pigment_observer(self, values: dict, L_cd: float, seconds: float | None) -> dict:
        return {**values, PIGMENT_KEY: bleaching.preadapted(L_cd, seconds, self.rod_per_cone())}

    def pigment_observer_advance(self, obs: dict, L_cd: float, dt: float) -> dict:
        """``dt`` s more of a neutral field of ``L_cd``: the pigment, then the operator's
        own step toward the goals raised by its equivalent backgrounds."""
        L_r = L_cd * self.rod_per_cone()
        pig = obs.get(PIGMENT_KEY)
        pig = bleaching.advance(pig if bleaching.check(pig) else bleaching.steady(L_r, L_cd),
                                L_r, L_cd, dt)
        G_r, G_c = self.shifted_goals(pig, L_r, L_cd)
        goals = SimpleNamespace(G_rod=G_r, G_cone=G_c)
        values = self.advance({k: v for k, v in obs.items() if k != PIGMENT_KEY}, goals, dt)
        return {**values, PIGMENT_KEY: pig}
