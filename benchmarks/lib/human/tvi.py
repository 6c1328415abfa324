"""Experiment 3: increment thresholds (Ferwerda et al. 1996's rod and cone TVI, fitted to
Blackwell and to Aguilar & Stiles) against what each operator shows.

At steady state (``Tonemapper(op, preadapt=(La, None))``, the frame's own level) a disk
of La + dL on a uniform field of La (cd/m^2, neutral) goes through the public API; the
display increment is the disk's colour against the field's in the light the display
emits (display-linear x display white), in Delta E ITP (BT.2124: 1 = one just
noticeable difference). The world increment that gives Delta E ITP = 1 (bisection in
log dL) is the display's threshold seen through the operator; the world threshold is
Ferwerda's at La for a neutral light: min(eps_C(La), eps_R(La S) / S), S = the working
space's L'/L of a neutral. Their ratio is 1 where one world threshold maps to one
display threshold (Durand & Dorsey's aim, Sec. 3.1). A second ratio takes the display
threshold as Durand & Dorsey do, Ferwerda's cone threshold at the display observer's
adaptation (durand00's own L_da; half the display white for the others), instead of
Delta E ITP.
"""

from __future__ import annotations

import numpy as np

OPERATORS = ("durand00", "pattanaik00", "ledda04", "kirk11")
LEVELS = 10.0 ** np.arange(-4.0, 4.01, 1.0)        # La, cd/m^2
SIZE, RADIUS = 24, 5                               # the frame, px; the disk


def world_threshold(La: float) -> float:
    """Ferwerda's increment threshold of a neutral test at La (photopic cd/m^2)."""
    from ocl_tonemap.models.ferwerda1996 import threshold_cone, threshold_rod
    from ocl_tonemap.models.photometry import neutral_scotopic_ratio
    S = neutral_scotopic_ratio()
    return float(min(threshold_cone(La), threshold_rod(La * S) / S))


def _frame(La: float, dL: float) -> np.ndarray:
    yy, xx = np.mgrid[:SIZE, :SIZE] - (SIZE - 1) / 2.0
    f = np.full((SIZE, SIZE, 3), La, np.float64)
    f[(xx ** 2 + yy ** 2) <= RADIUS ** 2] += dL
    return f.astype(np.float32)


class Viewer:
    """One operator's steady-state observer at La: display Delta E ITP of a disk."""

    def __init__(self, op: str, La: float, backend=None):
        from ocl_tonemap import Tonemapper
        self.La = float(La)
        self.tm = Tonemapper(op, backend=backend, preadapt=(self.La, None), model="none")
        self.white = float(self.tm.display.white_cd)

    def _disk_field(self, dL: float):
        self.tm.reset_adaptation((self.La, None))
        out = np.asarray(self.tm.process(_frame(self.La, dL)), np.float64)[..., :3]
        c = SIZE // 2
        return out[c, c] * self.white, out[1, 1] * self.white

    def delta_e(self, dL: float) -> float:
        """Delta E ITP between the displayed disk and field."""
        from ocl_tonemap.models.ictcp import delta_e_itp, rgb709_to_ictcp
        disk, field = self._disk_field(dL)
        return float(delta_e_itp(rgb709_to_ictcp(disk), rgb709_to_ictcp(field)))

    def ferwerda_steps(self, dL: float) -> float:
        """The displayed luminance step in units of Ferwerda's cone threshold at the
        display observer's adaptation: durand00's own L_da (its frame record; it follows
        the scene's key by default), else Durand & Dorsey's display white / 2."""
        from ocl_tonemap.models.durand2000 import display_adaptation
        from ocl_tonemap.models.ferwerda1996 import threshold_cone
        from ocl_tonemap.models.photometry import Y_WEIGHTS
        disk, field = self._disk_field(dL)
        step = abs(float((disk - field) @ Y_WEIGHTS))
        p = self.tm.last.params
        p = p if isinstance(p, dict) else vars(p)
        L_da = p.get("L_da") or display_adaptation(self.tm.display)
        return step / float(threshold_cone(L_da))


def display_threshold(op: str, La: float, backend=None, jnd: float = 1.0,
                      criterion: str = "itp") -> float:
    """The world increment (cd/m^2) that gives ``jnd`` on the display: Delta E ITP
    (``itp``) or Ferwerda's display threshold (``ferwerda``); inf where even 1000 x La
    does not."""
    v = Viewer(op, La, backend)
    f = v.delta_e if criterion == "itp" else v.ferwerda_steps
    lo, hi = np.log10(La) - 8.0, np.log10(La) + 3.0
    if f(10.0 ** hi) < jnd:
        return np.inf
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if f(10.0 ** mid) < jnd:
            lo = mid
        else:
            hi = mid
    return 10.0 ** (0.5 * (lo + hi))


def run_all(backend=None, operators=OPERATORS, levels=LEVELS):
    """{op: [(La, world threshold, display threshold (Delta E ITP 1), ratio,
    ratio by Ferwerda's display threshold)]}."""
    out = {}
    for op in operators:
        rows = []
        for La in levels:
            w = world_threshold(La)
            d = display_threshold(op, La, backend)
            fd = display_threshold(op, La, backend, criterion="ferwerda")
            rows.append((float(La), w, d, d / w, fd / w))
        out[op] = rows
    return out
