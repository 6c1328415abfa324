"""durand00: Durand & Dorsey 2000, Ferwerda's threshold operator made time-dependent,
with the mesopic blue shift; its paper's effects (flare, acuity, chromatic
adaptation) are the effects every operator can take (``effects/``).

The model is ``models/durand2000.py`` (with ``models/ferwerda1996.py``); this
module declares the operator and packs the frame's scalars for
``kernels/durand00.cl``.
"""

from __future__ import annotations

import math

from ..models import durand2000 as model
from ..models import ferwerda1996
from ..base.quantities import Numbers, Quantity
from .base import COLOUR_STAGE, METER_STAGE, KernelCall, ModelOperator, Option, Stage, StateSpec
from .pattanaik00 import MODE_OPTION


def _some_light(rgb) -> str:
    return "" if max(rgb) > 0 else "at least one of R, G, B above 0 (the rods' signal)"


#: The packed scalars of kernels/durand00.cl, one layout for both its kernels
#: (P_<name> in the kernels; each kernel reads its own).
KERNEL_PARAMS = ("m_cone", "rod_r", "rod_g", "rod_b", "inv_white", "knee", "nlut", "lo",
                 "inv_step", "tint_r", "tint_g", "tint_b")


def _packed(**given) -> tuple:
    return tuple((k, given.get(k, 0.0)) for k in KERNEL_PARAMS)


class Durand00(ModelOperator):
    model = model
    name = "durand00"
    description = ("Durand & Dorsey 2000: Ferwerda threshold mapping, mesopic blue shift, "
                   "light and chromatic adaptation")
    citation = "Durand & Dorsey, Interactive Tone Mapping, Eurographics Workshop on Rendering 2000"
    options = (
        MODE_OPTION,
        Option("tint", "--blue-shift", "colour of rod signals (Eq. 5): default a 480 nm blue, xy "
               "0.289,0.308 (the paper's 1.05,0.97,1.27 with --mode paper); 1,1,1 for none",
               metavar="R,G,B",
               decl=Numbers("colour of the rods' signal", "R,G,B", rule=_some_light,
                            parts=tuple(Quantity(c, "", 0.0, 10.0)
                                        for c in ("red", "green", "blue")))),
        Option("lut", "--lut", "evaluate the mapping through per-frame tables of N entries over "
               "12 decades (Sec. 5; the paper uses 2000); 0 = direct (default)",
               default=0, metavar="N",
               decl=Quantity("table entries", "", 2, 1 << 20, zero=True, integer=True)),
    )
    state = StateSpec(scalars=("inv_eps_rod", "inv_eps_cone", "L_waR", "L_wa"))
    #: Sec. 3.3 is light adaptation only (0.1 / 0.4 s): by default the shared pigment
    #: course gives it the minutes of dark adaptation (``--mode paper``: none).
    pigment_course = True

    def receptor_threshold(self, receptor, L):
        """Ferwerda's thresholds themselves (Eqs. 1-2 of Ferwerda et al. 1996)."""
        return math.log10(ferwerda1996.threshold_rod(L) if receptor == "rod"
                          else ferwerda1996.threshold_cone(L))

    stages = (
        COLOUR_STAGE, METER_STAGE,
        Stage("adapt", "state", "1/eps filtered with tau 0.4 s (rods), 0.1 s (cones), Sec. 3.3",
              "models.durand2000.advance"),
        Stage("map", "pointwise", "Eq. 5: m_C rgb + k m_R s_w tint (Eq. 6 gains before it)",
              "models.durand2000.map_reference", "durand00.cl:durand00_map4"),
    )

    def kernel_call(self, p):
        import numpy as np
        if not p.lut:
            rod = p.rod_rgb
            vals = _packed(m_cone=p.m_cone / p.unit_cd, rod_r=rod[0], rod_g=rod[1],
                           rod_b=rod[2], inv_white=1.0 / p.white_signal, knee=p.shoulder_knee)
            return KernelCall("durand00.cl", "durand00_map4", vals, pixels_per_item=4,
                              frame_params=True)
        tc, tr, lo, step = model.lut_tables(p)
        vals = _packed(nlut=p.lut, lo=lo, inv_step=1.0 / step, tint_r=p.tint[0],
                       tint_g=p.tint[1], tint_b=p.tint[2], inv_white=1.0 / p.white_signal,
                       knee=p.shoulder_knee)
        return KernelCall("durand00.cl", "durand00_map_lut", vals,
                          buffers=(np.concatenate([tc, tr]).astype(np.float32),),
                          frame_params=True)
