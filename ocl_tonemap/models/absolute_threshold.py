"""What lies below the observer's absolute threshold is not seen (issue 66): the
dark-adaptation course on the display, for every operator.

An operator's response maps a faint light to a faint display light, and a display
viewed in the dark shows far less than the eye can see at its black: a target the
observer, just in from daylight, cannot see yet still shows on the display. The
observer's threshold on a black field is set by the eye's own noise, its dark light
(Barlow 1957) and the equivalent background of the pigment still bleached (Crawford
1947; ``bleaching.py`` Eq. 6). Here the light of each pixel is weighted by how far its
chance of being detected exceeds the threshold's own, so that a light at or below the
observer's threshold is black and what is shown follows the threshold as it falls
over the minutes in the dark (``--threshold``):

>>> seen_fraction(1.0), seen_fraction(0.5), round(seen_fraction(1.5), 3)
(0.0, 0.0, 0.886)
>>> round(seen_fraction(3.0), 9)
1.0
>>> Tr, Tc = thresholds(bleaching.dark())          # fully dark adapted
>>> f"{Tr:.2e} {Tc:.2e}"
'6.13e-05 1.12e-03'

1. The thresholds on a black field (a Weber observer with the pigment model's dark
   lights I_D, as ``bleaching.elevation``): rods T_r = T0_r (1 + L_eq,r / I_D,r)
   (scotopic cd/m^2), cones T_c = T0_c (1 + L_eq,c / I_D,c) (cd/m^2), L_eq the
   equivalent backgrounds (``bleaching.equivalent_background`` on the frame's field:
   its early neural phase counts the field's memory above the field itself).
   T0: Hecht, Haig & Chase 1937's dark-adapted threshold (rods) and cone plateau
   (cones) for their 3-degree field (:data:`T0_ROD`, :data:`T0_CONE`).
2. A pixel of photopic Y and scotopic Y' is x = max(Y / T_c, Y' / T_r) thresholds
   of light to the receptor that sees it best (probability summation over the two
   is left out: the largest term rules within a factor 2^(1/beta)).
3. It is detected with Quick 1974's psychometric function (the Weibull form),
   P(x) = 1 - 2^(-x^beta), beta = 3.5 (:data:`BETA`: Nachmias 1981, 3-4 for
   luminance increments; Pelli 1987); the threshold is its 50 % point. What is shown
   is the light seen beyond the threshold's own chance, Abbott's correction at
   P(1) = 1/2: w(x) = max(0, (P(x) - P(1)) / (1 - P(1))) = max(0, 1 - 2^(1 - x^beta)).
   Nothing at or below the threshold shows, 0.46 of the light at 1.2 T, 0.89 at
   1.5 T, 1 - 8e-4 at 2 T, 1 - 2e-14 at 3 T (all of it from 2.54 T in float32); the
   weight is continuous and rises monotonically, so a gradient that crosses the
   threshold fades to black with no edge. Black stays black. (Weighting by P itself
   showed targets at a tenth to a half of the threshold plainly on the display,
   whose viewer sees a step of ~2 % near its black: the display's course then ran
   0.3-1.4 log units below the observer's, and by a margin that changed with the
   operator and with the minutes in the dark; ``docs/models.md``.)

Nothing here depends on an operator: every operator's display takes it from the
same pigment state, after the optical effects (the veil of a bright source counts
as light on the retina) and before the operator's response.
"""

from __future__ import annotations

import math

import numpy as np

from . import bleaching
from .photometry import photopic_luminance, scotopic_luminance

#: The rods' dark-adapted threshold for a neutral 3-degree field, scotopic cd/m^2:
#: Hecht, Haig & Chase 1937's after 30 minutes in the dark (the median of every
#: point, 2.81 log micro-micro-lamberts of their violet, 2.06e-6 cd/m^2), times the
#: violet's L'/L (29.8 at 450 nm, CIE 1951 V' over CIE 1924 V):
#: 10^(2.81 - 12) x 10^4 / pi x 29.8. ``tests/effects/test_absolute_threshold.py``
#: reads it off the data.
T0_ROD = 6.13e-5
#: The cones' dark-adapted threshold, cd/m^2: the data's cone plateau, 5-12 min
#: after 400 000 td (the median, 10^-2.95), taken as the cones' absolute threshold
#: after every field.
T0_CONE = 1.12e-3
#: The psychometric function's slope (Quick 1974; Nachmias 1981: 3-4 for luminance
#: detection).
BETA = 3.5
#: x at and above which w is 1 in float64 and float32 (2^(1 - 8^3.5) = 2^-1447): the
#: kernel's early way out.
X_SURE = 8.0
#: The largest scotopic/photopic ratio of any non-negative working RGB: its bluest
#: primary's (``peak_seen``).
SCOTOPIC_RATIO_MAX = float(np.max(scotopic_luminance(np.eye(3)) / photopic_luminance(np.eye(3))))


def thresholds(pig: dict, G_rod: float = 0.0, G_cone: float = 0.0) -> tuple[float, float]:
    """Eq. 1: (T_rod scotopic, T_cone photopic cd/m^2) of the pigment state ``pig`` on
    a frame whose field is (``G_rod``, ``G_cone``)."""
    Lr, Lc = bleaching.equivalent_background(pig, G_rod, G_cone)
    return (T0_ROD * (1.0 + Lr / bleaching.I_D_ROD),
            T0_CONE * (1.0 + Lc / bleaching.I_D_CONE))


def seen_fraction(x):
    """Eq. 3: the share of a light of x thresholds that is shown,
    w = max(0, 1 - 2^(1 - x^beta)) (NaN and negatives: 0)."""
    x = np.asarray(x, np.float64)
    x = np.where(x > 1.0, np.minimum(x, X_SURE), 1.0)
    w = np.maximum(-np.expm1(math.log(2.0) * (1.0 - x ** BETA)), 0.0)
    return float(w) if w.ndim == 0 else w


def apply_reference(rgb: np.ndarray, T_rod: float, T_cone: float) -> np.ndarray:
    """Working RGB (cd/m^2) with each pixel's light weighted by the share of it seen
    beyond the threshold (Eqs. 2-3), float64."""
    rgb = np.asarray(rgb, np.float64)[..., :3]
    x = np.maximum(photopic_luminance(rgb) / T_cone, scotopic_luminance(rgb) / T_rod)
    return rgb * seen_fraction(x)[..., None]


def peak_seen(max_Y: float, T_rod: float, T_cone: float, max_Ys: float | None = None
              ) -> float:
    """Eq. 3 at the frame's brightest light: the share of it that is shown, for
    operators whose range reduction maps the frame's peak to white whatever its level
    (kirk11). x is taken from the frame's largest photopic (``max_Y``) and scotopic
    (``max_Ys``) luminances, metered alike: no pixel's x is larger (a lone target's is
    exactly it), so the factor errs toward showing light, never toward hiding what is
    seen. Without ``max_Ys`` the largest scotopic/photopic ratio of any working colour
    (its bluest primary) bounds it. A peak that is not a number, or infinite, keeps 1."""
    Y = float(max_Y)
    Ys = Y * SCOTOPIC_RATIO_MAX if max_Ys is None else float(max_Ys)
    if not (math.isfinite(Y) and math.isfinite(Ys)):
        return 1.0
    return seen_fraction(max(Y / T_cone, Ys / T_rod))
