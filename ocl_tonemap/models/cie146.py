"""Disability glare of a point source: CIE 146:2002 (CIE equations for disability
glare), float64; the age term CIE 180:2010 takes up for road lighting.

A source that gives the illuminance E (lx) at the eye, theta degrees from the line of
sight, veils the retinal image with an equivalent luminance L_veil (cd/m^2):

    general (0.1 < theta < 100 deg):
        L_veil / E = 10/theta^3 + (5/theta^2 + 0.1 p/theta) (1 + (A/62.5)^4) + 0.0025 p
    age-adjusted Stiles-Holladay (1 < theta < 30 deg):
        L_veil / E = 10/theta^2 (1 + (A/70)^4)

A: age in years; p: the eye's pigmentation (0 black, 0.5 brown, 1 light blue-green,
1.2 very light): it matters beyond ~30 degrees.
"""

from __future__ import annotations

import math

import numpy as np

from .convolution import fft_size

#: CIE 146's pigmentation factors.
PIGMENT = {"black": 0.0, "brown": 0.5, "light": 1.0, "very light": 1.2}
#: Brown eyes: the pigmentation of most of the world's drivers (CIE 146's 0.5).
DEFAULT_PIGMENT = 0.5


def veil_per_lux(theta_deg, age=25.0, p: float = DEFAULT_PIGMENT) -> np.ndarray:
    """L_veil / E, (cd/m^2)/lx, CIE 146's general equation (theta held at >= 0.1 deg).

    >>> round(float(veil_per_lux(10.0, 25, 0.5)), 4)   # 0.01 + 0.055 x 1.0256 + 0.00125
    0.0677
    """
    t = np.maximum(np.asarray(theta_deg, np.float64), 0.1)
    A = np.asarray(age, np.float64)
    return 10.0 / t ** 3 + (5.0 / t ** 2 + 0.1 * p / t) * (1.0 + (A / 62.5) ** 4) + 0.0025 * p


def stiles_holladay(theta_deg, age=25.0) -> np.ndarray:
    """L_veil / E, CIE 146's age-adjusted Stiles-Holladay equation (1 .. 30 deg).

    >>> round(float(stiles_holladay(10.0, 70)), 3)      # 10/theta^2 x 2
    0.2
    """
    t = np.asarray(theta_deg, np.float64)
    return 10.0 / t ** 2 * (1.0 + (np.asarray(age, np.float64) / 70.0) ** 4)


def age_glare_factor(age) -> np.ndarray:
    """How much more an observer of ``age`` is veiled than a young one at the angles
    that rule a road's glare: (1 + (A/62.5)^4) (CIE 146's general equation)."""
    return 1.0 + (np.asarray(age, np.float64) / 62.5) ** 4


# --- the veil of a whole field (``run --visibility``'s Lveil) ------------------------------

#: The field within this angle of a point is left out of the point's veil: CIE 88's
#: 2-degree field of fixation (Adrian 1987: L_A = L_20 + L_seq, the scatter from the
#: field outside it; CIE 140's threshold increment starts at 1.5 degrees). Its own
#: light is the target's background, not glare.
EXCLUDE_DEG = 1.0
#: Midpoints per cell side of :func:`field_weights`' rule (a 0.4-degree cell: 0.05
#: degrees apart, where 10/theta^3 changes by 15 % at the 1-degree edge).
SUBSAMPLES = 8


def field_weights(shape: tuple[int, int], deg_per_cell: float, age: float = 25.0,
                  p: float = DEFAULT_PIGMENT, exclude_deg: float = EXCLUDE_DEG,
                  sub: int = SUBSAMPLES) -> np.ndarray:
    """(2h-1, 2w-1) weights K, float64: the veil (cd/m^2) at a cell's centre of
    1 cd/m^2 filling the cell (dy, dx) cells away, K[h-1+dy, w-1+dx] =
    integral over that cell of (L_veil/E)(theta) cos(theta) dOmega, the general
    equation (:func:`veil_per_lux`) at ``age`` and ``p``, theta the angle from the
    point (the eye looking at it: E on the plane facing it), the part within
    ``exclude_deg`` left out, and what lies 90 degrees or more away (behind the plane
    the eye faces: no illuminance on it; CIE 146 holds to ~100 degrees); a ``sub`` x
    ``sub`` midpoint rule over square cells ``deg_per_cell`` wide (the picture taken as
    an angular grid, as the flare does)."""
    h, w = shape
    d = float(deg_per_cell)
    o = (np.arange(sub) + 0.5) / sub - 0.5                       # midpoints in a cell
    ty = (np.arange(-(h - 1), h)[:, None] + o[None, :]).reshape(-1) * d
    tx = (np.arange(-(w - 1), w)[:, None] + o[None, :]).reshape(-1) * d
    K = np.zeros((2 * h - 1, 2 * w - 1))
    dA = np.radians(d / sub) ** 2                                # sr of a midpoint's area
    for i in range(sub):                                         # (rows a slice at a time)
        th = np.hypot(ty[i::sub, None], tx[None, :])             # (2h-1, (2w-1) sub)
        f = np.where((th >= exclude_deg) & (th < 90.0),
                     veil_per_lux(th, age, p) * np.cos(np.radians(th)), 0.0)
        K += f.reshape(2 * h - 1, 2 * w - 1, sub).sum(axis=2)
    return K * dA


def field_veil(cells: np.ndarray, K: np.ndarray) -> np.ndarray:
    """The veil (cd/m^2) at each cell's centre of a field of cell luminances ``cells``
    (h x w, cd/m^2, nothing outside the picture): their linear convolution with
    :func:`field_weights`' K (2h-1 x 2w-1), float64 by FFT."""
    h, w = cells.shape
    H, W = fft_size(2 * h - 1), fft_size(2 * w - 1)
    F = np.fft.irfft2(np.fft.rfft2(np.asarray(cells, np.float64), (H, W)) *
                      np.fft.rfft2(K, (H, W)), (H, W))
    return np.maximum(F[h - 1:2 * h - 1, w - 1:2 * w - 1], 0.0)


def uniform_field_veil(half_w_deg: float, half_h_deg: float, age: float = 25.0,
                       p: float = DEFAULT_PIGMENT, exclude_deg: float = EXCLUDE_DEG,
                       at=(0.0, 0.0), n: int = 2000) -> float:
    """The veil (cd/m^2) of 1 cd/m^2 filling the rectangle +-half_w x +-half_h degrees
    (the angular grid's), at the point ``at`` (degrees from its centre): the glare
    function's integral over the field, by a fine midpoint rule (``n`` a side) in
    polar coordinates about the point (the reference :func:`field_weights` is held
    to)."""
    r_max = math.hypot(half_w_deg + abs(at[0]), half_h_deg + abs(at[1]))
    r = exclude_deg + (np.arange(n) + 0.5) / n * (r_max - exclude_deg)
    phi = (np.arange(n) + 0.5) / n * 2.0 * math.pi
    x = at[0] + r[:, None] * np.cos(phi)[None, :]
    y = at[1] + r[:, None] * np.sin(phi)[None, :]
    inside = (np.abs(x) <= half_w_deg) & (np.abs(y) <= half_h_deg)
    f = veil_per_lux(r, age, p) * np.cos(np.radians(r)) * r        # x r dr dphi
    dr, dphi = (r_max - exclude_deg) / n, 2.0 * math.pi / n
    return float((inside * f[:, None]).sum() * dr * dphi * np.radians(1.0) ** 2)
