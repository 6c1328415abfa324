"""CIE 88:2004's equivalent veiling luminance L_seq of a tunnel approach, float64.

Adrian (1987, LR&T 19:73) split the adaptation of a driver who looks at a tunnel
portal into the luminance of the 2-degree field of fixation and the straylight of
the field around it, L_A = L_20 + L_seq; L_seq is read off a polar diagram laid on
a picture of the approach, "with zones in which the luminance produces equal
amounts of straylight in the centre". CIE 88:2004 takes the diagram up. The
standard's text was not at hand; the diagram is reconstructed (docs/models.md,
"The veil of the whole field"):

- straylight per Stiles-Holladay, L_seq = 10 sum E_i / theta_i^2 (theta in degrees,
  E the illuminance at the eye from a zone; the young observer's, no age term);
- 12 sectors of 30 degrees and 9 rings from the fixation field's rim (1 degree)
  outwards, each ring's outer radius :data:`RING_RATIO` times its inner one, so
  that every zone of uniform luminance L adds the same straylight,
  10 (pi/180)^2 (2 pi/12) ln(RING_RATIO) L = 5.1e-4 L (:func:`zone_weight`);
  9 x 12 = 108 zones (the count CIE 88 software states), out to 17.8 degrees;
- L_seq = 5.1e-4 sum over the zones of their mean luminance.
"""

from __future__ import annotations

import math

import numpy as np

#: The straylight of one zone of uniform 1 cd/m^2 (cd/m^2).
ZONE_WEIGHT = 5.1e-4
SECTORS, RINGS = 12, 9
#: The fixation field's radius, degrees (Adrian's 2-degree field).
INNER_DEG = 1.0
#: Each ring's outer over inner radius: equal straylight per zone for ZONE_WEIGHT.
RING_RATIO = math.exp(ZONE_WEIGHT / (10.0 * math.radians(1.0) ** 2 * 2.0 * math.pi / SECTORS))


def zone_weight(ratio: float = RING_RATIO) -> float:
    """The straylight (cd/m^2) of a zone of 1 cd/m^2 between radii r and ratio x r,
    one of :data:`SECTORS` sectors, by Stiles-Holladay (small angles).

    >>> round(zone_weight(), 7)
    0.00051
    """
    return 10.0 * math.radians(1.0) ** 2 * (2.0 * math.pi / SECTORS) * math.log(ratio)


def ring_radii() -> np.ndarray:
    """The diagram's ring edges, degrees: INNER_DEG x RING_RATIO^i, i = 0..RINGS."""
    return INNER_DEG * RING_RATIO ** np.arange(RINGS + 1)


def l_seq(Y: np.ndarray, x: float, y: float, deg_per_px: float) -> tuple[float, dict]:
    """L_seq (cd/m^2) at pixel (x, y) (column, row; 0, 0 the top-left pixel's centre)
    of a picture of luminances ``Y`` (cd/m^2) taken as an angular grid of
    ``deg_per_px`` degrees a pixel: :data:`ZONE_WEIGHT` x the sum of the zones'
    mean luminances, a zone outside the picture counted dark; with the zones' means
    and how many of them the picture covers."""
    h, w = Y.shape
    yy, xx = np.mgrid[0:h, 0:w]
    dx, dy = (xx - x) * deg_per_px, (yy - y) * deg_per_px
    r = np.hypot(dx, dy)
    edges = ring_radii()
    ring = np.searchsorted(edges, r, side="right") - 1
    sector = (np.floor((np.arctan2(-dy, dx) % (2 * math.pi)) / (2 * math.pi / SECTORS))
              .astype(int) % SECTORS)
    inside = (ring >= 0) & (ring < RINGS)
    zone = ring * SECTORS + sector
    n = np.bincount(zone[inside], minlength=RINGS * SECTORS)
    s = np.bincount(zone[inside], weights=np.asarray(Y, np.float64)[inside],
                    minlength=RINGS * SECTORS)
    means = np.where(n > 0, s / np.maximum(n, 1), 0.0)
    return ZONE_WEIGHT * float(means.sum()), {
        "zones": RINGS * SECTORS, "covered": int((n > 0).sum()),
        "outer_deg": float(edges[-1]), "means": means.reshape(RINGS, SECTORS)}
