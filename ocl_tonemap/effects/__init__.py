"""Effects any operator can use, each in a declared slot of the frame's data flow.

=======================  =========  ==============================================
effect                   slot       module
=======================  =========  ==============================================
``flare``                optical    ``flare.py`` (Spencer et al. 1995)
``purkinje``             seen       ``purkinje.py`` (Kirk & O'Brien 2011)
``chromatic_adaptation`` seen       ``chromatic.py`` (Durand & Dorsey 2000, Eq. 6)
``acuity``               display    ``acuity.py`` (Shaler 1937, D&D Sec. 7)
=======================  =========  ==============================================

``base.py`` is the protocol (what an effect declares: its switch, slot, options,
gate and capabilities), ``settings.py`` the registry and :class:`EffectSettings`
(one field per declared option), ``runner.py`` the loop that runs a frame's
effects slot by slot, whole or in row bands (every built-in effect streams: the
flare's pyramid cut where its image fits the budget, the Purkinje shift and the
chromatic gains pointwise, acuity on the display bands on their way out).

Each effect takes ``on | off | auto``. ``auto`` leaves the choice to the frame's
mechanism plan (``ocl_tonemap/mechanisms/``): the gated effects (flare, acuity,
the Purkinje shift, and any installed one that says so) are skipped where their
predicted effect, summed over what is skipped, stays within one JND (Delta E ITP)
of running them, and blended in or out over a tenth of a second; chromatic
adaptation applies its degree of adaptation. The defaults come from ``--model``
(``MODEL_DEFAULTS``): ``auto`` (every effect the operator can take on ``auto``),
``full`` (all ``on``), ``none`` (the operator alone). Which effects ran, and with
what, is returned per frame for the metadata.

An installed package adds an effect through the ``ocl_tonemap.effects`` entry point
group: an :class:`~.base.Effect` subclass, whose switch and options become flags,
settings fields and API keywords, and whose ``predict`` the plan weighs
(``examples/night_noise_effect``).
"""

from .base import SLOTS, Effect, EffectOption, FrameContext
from .flare import DEFAULT_FOV
from .runner import Effects
from .settings import MODEL_DEFAULTS, MODES, EffectSettings, registry

__all__ = ["DEFAULT_FOV", "Effect", "EffectOption", "EffectSettings", "Effects",
           "FrameContext", "MODEL_DEFAULTS", "MODES", "SLOTS", "registry"]
