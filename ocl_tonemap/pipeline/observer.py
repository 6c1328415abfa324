"""The observer apart from the frame: its adaptation state and its clock.

The scalar state (:class:`~ocl_tonemap.pipeline.state.AdaptationState`) is kept here, the
per-pixel planes of local operators in the backend's schedule (where they stay on
the device between frames). One rule gives every way in (whole RGB, spectral,
streamed frames, a shot's integrate pass) its frame's time and step
(:meth:`Observer.clock`).
"""

from __future__ import annotations

import math

from .state import AUTO_SCALE_KEY, AdaptationState


def check_preadapt(preadapt) -> None:
    if preadapt is not None:
        L, s = preadapt
        if not (L >= 0 and math.isfinite(L)) or (s is not None and not (s >= 0 and math.isfinite(s))):
            raise ValueError(f"bad pre-adaptation {preadapt}: need L >= 0 cd/m^2 and seconds >= 0")


class Observer:
    """One observer's state and clock. ``op``: the operator (its pre-adaptation is
    the observer's); ``schedule``: where the per-pixel planes are kept."""

    def __init__(self, operator_name: str, op, schedule, state: AdaptationState | None = None,
                 preadapt=None):
        check_preadapt(preadapt)
        self.operator_name, self.op, self.schedule = operator_name, op, schedule
        self.preadapt = preadapt
        st = state.copy() if state is not None else AdaptationState(operator_name)
        if st.operator != operator_name:
            raise ValueError(f"state belongs to operator {st.operator!r}, not {operator_name!r}")
        self._set(st)

    def _set(self, st: AdaptationState) -> None:
        self.scalars = st
        self.schedule.set_pixel_state(st.pixels)
        st.pixels = None                  # the schedule holds them now

    # -- the state ------------------------------------------------------------------------
    def state(self) -> AdaptationState:
        """A copy of the state (serialisable; with the per-pixel planes of operators that
        keep them)."""
        st = self.scalars.copy()
        if self.op.state.planes:
            st.pixels = self.schedule.pixel_state()
        return st

    def set_state(self, value: AdaptationState) -> None:
        if value.operator != self.operator_name:
            raise ValueError(f"state belongs to operator {value.operator!r}")
        self._set(value.copy())

    def scalar_state(self) -> AdaptationState:
        """A copy of the state without the per-pixel planes (cheap)."""
        st = self.scalars.copy()
        st.pixels = None
        return st

    @property
    def adapted(self) -> bool:
        """Whether the observer has seen a frame (or was given a state)."""
        return bool(self.scalars.values)

    def remember(self, key: str, value) -> None:
        """Keep a JSON-able run value in the state's ``extra`` (saved and resumed)."""
        self.scalars.extra[key] = value

    def reset(self, preadapt=None) -> None:
        """A scene cut: fully adapted to the next frame again (``preadapt``: this one),
        no memory of the last shot; the time and the run's calibration constant kept."""
        keep = {k: v for k, v in self.scalars.extra.items() if k == AUTO_SCALE_KEY}
        self.preadapt = preadapt
        self.op.preadapt = preadapt
        self.set_state(AdaptationState(self.operator_name, time_s=self.scalars.time_s,
                                       frame=self.scalars.frame, extra=keep))

    # -- the clock ------------------------------------------------------------------------
    def clock(self, dt, time_s):
        """(time of this frame, step since the last one, fresh observer?): the one rule
        of every entry (RGB, spectral, streamed): ``time_s``, else the last frame's time
        plus ``dt``; a fresh observer's first frame needs neither."""
        st = self.scalars
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

    def shown(self, time_s: float, frame_number) -> None:
        """The frame at ``time_s`` has been shown: the clock's last frame."""
        self.scalars.time_s, self.scalars.frame = float(time_s), frame_number
