"""pattanaik00: Pattanaik, Tumblin, Yee & Greenberg 2000, time-dependent global adaptation.

The model is ``models/pattanaik2000.py``; this module declares the operator: its
options, its state (the four receptor signals), its stages, and the packing of
the frame's scalars for ``kernels/pattanaik00.cl``.
"""

from __future__ import annotations

import math

import numpy as np

from ..models import pattanaik2000 as model
from ..models.photometry import Y_WEIGHTS
from .base import COLOUR_STAGE, METER_STAGE, KernelCall, ModelOperator, Option, Stage, StateSpec

MODE_OPTION = Option("mode", "--mode", "default: the operator as it looks right on photographs; "
                     "paper: its paper taken literally (docs/models.md says where they differ)",
                     choices=("default", "paper"))

#: Parameters of the per-pixel kernel, in their packed order (P_<name> in the kernel).
KERNEL_PARAMS = ("log2_sigma_rod", "log2_sigma_cone", "B_rod", "B_cone", "gain", "offset",
                 "dB_rod", "dB_cone", "ds_rod", "ds_cone", "colour", "out_black", "out_scale",
                 "inv_white", "knee", "toe")
#: Model constants of the per-pixel kernel, given as build options (never retyped there).
KERNEL_CONSTANTS = (("PN", model.N), ("L_FLOOR", model.L_FLOOR),
                    ("RATIO_FLOOR", model.RATIO_FLOOR),
                    ("RESPONSE_MARGIN", model.RESPONSE_MARGIN))


class Pattanaik00(ModelOperator):
    model = model
    name = "pattanaik00"
    description = "Pattanaik, Tumblin, Yee & Greenberg 2000: time-dependent global adaptation"
    citation = ("Pattanaik, Tumblin, Yee & Greenberg, Time-Dependent Visual Adaptation for "
                "Fast Realistic Image Display, SIGGRAPH 2000")
    options = (MODE_OPTION,)
    state = StateSpec(scalars=("A_rod", "A_cone", "B_rod", "B_cone"))
    stages = (
        COLOUR_STAGE, METER_STAGE,
        Stage("adapt", "state", "A: exponential t0 = 150/80 ms; B: Eq. 7 solved exactly",
              "models.pattanaik2000.receptor_levels_advance"),
        Stage("map", "pointwise", "Eqs. 2-3 responses, Sec. 4.3 inverse appearance and display",
              "models.pattanaik2000.map_reference", "pattanaik00.cl:pattanaik00_map8"),
    )

    pigment_course = True

    def advance(self, values, stats, dt):
        """The paper's Sec. 4.1.2 (``--mode paper``); by default A's filters toward the
        goals with the shared pigment's equivalent background, B static (Eq. 6)."""
        if self.uses_pigment():
            return model.receptor_levels_neural(values, stats.G_rod, stats.G_cone, dt)
        return model.advance(values, stats.G_rod, stats.G_cone, dt)

    def receptor_threshold(self, receptor, L):
        """Eq. 2's own threshold curve (``flash_threshold``)."""
        return math.log10(model.flash_threshold(max(L, model.A_FLOOR), receptor))

    def preadapted(self, L_cd, seconds):
        if self.uses_pigment():               # (the pigment's own course: ``pigment_goals``)
            return model.steady_state(L_cd * self.rod_per_cone(), L_cd)
        return model.preadapted(L_cd, seconds)

    def colour_axes(self, p):
        """The default colour's v_i = (1 - c) Y + c rgb_i: channel i of the display colour
        is v_i / Y, clamped at 0 where the chroma scale c pushes it below."""
        if p.chroma is None:
            return np.eye(3)
        return (1.0 - p.chroma) * np.outer(np.ones(3), Y_WEIGHTS) + p.chroma * np.eye(3)

    def kernel_call(self, p, vector: bool = True):
        d = p.display
        N = model.N
        # colour: > 0 Eq. 3's exponent factor ln10 n B_cone / S_d (the paper), else
        # minus the default mode's chroma scale (16 frame scalars at most: one slot)
        vals = (math.log2(p.sigma_rod), math.log2(p.sigma_cone), p.B_rod, p.B_cone, p.gain,
                p.offset, d.B_rod, d.B_cone, d.sigma_rod ** N, d.sigma_cone ** N,
                model.LN10 * N * p.B_cone / d.S_d if p.chroma is None else -p.chroma,
                d.signal_offset, d.gain, 1.0 / p.white_signal, p.shoulder_knee, p.toe)
        return KernelCall("pattanaik00.cl", "pattanaik00_map8" if vector else "pattanaik00_map",
                          tuple(zip(KERNEL_PARAMS, vals)), 8 if vector else 1,
                          defines=KERNEL_CONSTANTS, frame_params=True)

