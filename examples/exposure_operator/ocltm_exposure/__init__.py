"""An ocl-tonemap operator in one module and one kernel: time-adapted exposure.

The eye's adaptation level A follows the frame's metered log-average with a first-
order time course (time constant ``tau`` seconds, solved exactly), and the frame is
shown at ``key`` x display white per A: a camera's auto-exposure with the eye's
pace. Registered through the ``ocl_tonemap.operators`` entry-point group
(pyproject.toml), so ``ocl-tonemap run ... --operator exposure --exposure-key 0.18``
and ``Tonemapper("exposure")`` use it with no change to ocl-tonemap.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ocl_tonemap.models.display import DISPLAY_LINEAR_MAX
from ocl_tonemap.models.integrators import exponential_step
from ocl_tonemap.operators.base import KernelCall, Operator, Option, Stage, StateSpec
from ocl_tonemap.base.quantities import Quantity

KERNEL = str(Path(__file__).with_name("exposure.cl"))


@dataclass(frozen=True)
class ExposureParams:
    A: float          # adaptation level, cd/m^2
    gain: float       # display-linear per cd/m^2

    def as_dict(self) -> dict:
        return asdict(self)


class TimeAdaptedExposure(Operator):
    name = "exposure"
    description = "example plugin: exposure following the eye's adaptation level over time"
    citation = "ocl-tonemap docs/architecture.md (example)"
    options = (
        Option("key", "--exposure-key", "display level of the adaptation level, as a fraction "
               "of display white (default 0.18)", metavar="K",
               decl=Quantity("display level of the adaptation level", "", 0.0, 1.0, above=True)),
        Option("tau", "--exposure-tau", "adaptation time constant (default 0.4)", metavar="S",
               decl=Quantity("adaptation time constant", "s", 0.0, 1e7, above=True)),
    )
    state = StateSpec(scalars=("A",))
    stages = (
        Stage("colour", "colour", "working RGB x scale -> cd/m^2", "models.photometry.sanitize",
              "colour.cl:scene_to_working"),
        Stage("meter", "reduction", "adaptation goal (the run's --metering)",
              "models.metering.reference_goal", "metering.cl:meter_partial"),
        Stage("adapt", "state", "A -> goal, exponential, tau", "models.integrators.exponential_step"),
        Stage("map", "pointwise", "rgb x key white / A", "ocltm_exposure.map_reference",
              "exposure.cl:exposure_map"),
    )

    def steady_state(self, stats):
        return {"A": float(stats.G_cone)}

    def preadapted(self, L_cd, seconds):
        return {"A": float(L_cd)}

    def advance(self, values, stats, dt):
        return {"A": exponential_step(values["A"], float(stats.G_cone), dt,
                                      self.option("tau", 0.4))}

    def params(self, state, stats):
        A = max(state.values["A"], 1e-10)
        d = self.display
        return ExposureParams(A, self.option("key", 0.18) * d.white_cd / A / d.unit_cd)

    def map_reference(self, rgb, Y, Ys, p):
        return np.clip(np.asarray(rgb, np.float64) * p.gain, 0.0, DISPLAY_LINEAR_MAX)

    def kernel_call(self, p):
        return KernelCall(KERNEL, "exposure_map", (("gain", p.gain),
                                                   ("ceiling", DISPLAY_LINEAR_MAX)))
