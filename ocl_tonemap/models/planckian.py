"""The Planckian locus in CIE 1960 UCS (u, v): correlated colour temperature and Duv.

Ohno, Y. (2014). Practical use and calculation of CCT and Duv. LEUKOS 10(1), 47-55
(the 2013 CIE/IES method): CCT is the temperature of the nearest point of the
Planckian locus in (u, v); Duv is the signed distance to it, positive above the
locus (greenish), negative below (pinkish), along the locus normal
n = (t_v, -t_u) / |t| for the tangent t toward higher temperature.

The locus comes from ``data/planckian_locus.json``. It holds (u, v) of a blackbody
under the CIE 1931 2-degree observer every 0.5 mired (1e6 / T) from 1000 K to
100000 K. The values are colour-science's ``CCT_to_uv_Planck1900`` at 1 nm, and the
range is that of its Ohno 2013 table. :func:`make_table` writes the file.
- **Between samples:** the position is linear, and the tangent (central differences
  at the samples) is interpolated.
- **Against colour-science's Ohno 2013** (``tests/models/test_durand2000.py``), over
  1500-25000 K and |Duv| <= 0.02:
  - CCT within 5e-6 (relative);
  - Duv within 4e-8;
  - the inverse within 8e-8 in (u, v).
- **Outside the table**, below 1000 K or above 100000 K, the end sample and its
  normal are used. colour-science extrapolates its table there.
- **Why not import colour-science:** its import takes about 0.5 s, and this runs
  in every frame of a run that estimates the illuminant
  (``models.durand2000.plausible_illuminant``).

Units: T in kelvin; u, v and Duv dimensionless (CIE 1960 UCS).
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np

from .lmsr import colour_module

TABLE_FILE = Path(__file__).resolve().parent.parent / "data" / "planckian_locus.json"
#: The table's temperatures: every MIRED_STEP mired from T_MAX down to T_MIN.
T_MIN, T_MAX, MIRED_STEP = 1000.0, 100000.0, 0.5


def table_mireds() -> np.ndarray:
    """The table's samples in mired (1e6 / T), ascending (T descending)."""
    lo, hi = 1e6 / T_MAX, 1e6 / T_MIN
    return lo + MIRED_STEP * np.arange(int(round((hi - lo) / MIRED_STEP)) + 1)


def make_table() -> dict:
    """The locus table from colour-science (the reference; run by
    ``python -m ocl_tonemap.models.planckian`` to write :data:`TABLE_FILE`)."""
    colour = colour_module()
    mired = table_mireds()
    uv = colour.temperature.CCT_to_uv_Planck1900(1e6 / mired)
    return {"source": "colour-science " + colour.__version__ + " CCT_to_uv_Planck1900 "
                      "(CIE 1931 2 degree observer, 1 nm)",
            "mired_start": float(mired[0]), "mired_step": MIRED_STEP,
            "u": [float(x) for x in uv[:, 0]], "v": [float(x) for x in uv[:, 1]]}


@functools.lru_cache(maxsize=1)
def _locus() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mired (N,), uv (N, 2), unit tangents toward higher T (N, 2)) of the table; the
    tangents by central differences (second order; one-sided at the ends)."""
    d = json.loads(TABLE_FILE.read_text())
    uv = np.stack([np.asarray(d["u"], np.float64), np.asarray(d["v"], np.float64)], axis=-1)
    mired = d["mired_start"] + d["mired_step"] * np.arange(len(uv))
    tan = -np.gradient(uv, axis=0)                      # mired ascending = T descending
    return mired, uv, tan / np.hypot(tan[:, 0], tan[:, 1])[:, None]


def _normal(tangent: np.ndarray) -> np.ndarray:
    """The unit normal (t_v, -t_u) / |t| of a tangent toward higher temperature
    (Duv > 0 above the locus)."""
    t = np.asarray(tangent, np.float64)
    return np.array([t[1], -t[0]]) / np.hypot(t[0], t[1])


def _foot(a: np.ndarray, s: np.ndarray, T0: np.ndarray, dT: np.ndarray, guess: float) -> float:
    """The root t of (a - t s) . (T0 + t dT) = 0 nearest ``guess``."""
    c2, c1, c0 = -float(s @ dT), float(a @ dT - s @ T0), float(a @ T0)
    if abs(c2) > 1e-12 * max(abs(c1), 1e-300):
        disc = max(c1 * c1 - 4.0 * c2 * c0, 0.0)
        roots = [(-c1 + sg * np.sqrt(disc)) / (2.0 * c2) for sg in (1.0, -1.0)]
        return float(min(roots, key=lambda r: abs(r - guess)))
    return -c0 / c1 if c1 != 0.0 else guess


def uv_to_CCT_Duv(uv) -> tuple[float, float]:
    """(CCT in K, Duv) of a chromaticity (u, v): the point of the locus whose normal
    passes through it (on the nearest segment, the tangent interpolated along it;
    beyond the table's ends, its end point).

    D65 (u, v = 0.19783, 0.31221) is 6505 K, a little above the locus:

    >>> cct, duv = uv_to_CCT_Duv((0.19783, 0.31221))
    >>> round(cct), round(duv, 4)
    (6505, 0.0032)
    """
    mired, L, tan = _locus()
    p = np.asarray(uv, np.float64).reshape(2)
    seg = L[1:] - L[:-1]
    t = np.clip(np.einsum("ij,ij->i", p - L[:-1], seg) / np.einsum("ij,ij->i", seg, seg),
                0.0, 1.0)
    foot = L[:-1] + t[:, None] * seg
    k = int(np.argmin(np.einsum("ij,ij->i", p - foot, p - foot)))
    # (p - L_k - t s) . (T_k + t dT) = 0, a quadratic in t: the foot along the normal,
    # which may lie a segment or two from the nearest chord point (far from the locus,
    # where the segments are short: at high T)
    guess = float(t[k])
    for _ in range(8):
        a, s, T0, dT = p - L[k], seg[k], tan[k], tan[k + 1] - tan[k]
        tk = _foot(a, s, T0, dT, guess)
        if tk < 0.0 and k > 0:
            k, guess = k - 1, 1.0
        elif tk > 1.0 and k < len(seg) - 1:
            k, guess = k + 1, 0.0
        else:
            break
    tk = float(np.clip(tk, 0.0, 1.0))
    m = mired[k] + tk * (mired[k + 1] - mired[k])
    duv = float(np.dot(p - (L[k] + tk * s), _normal(T0 + tk * dT)))
    return 1e6 / m, duv


def CCT_Duv_to_uv(cct: float, duv: float) -> np.ndarray:
    """(u, v) at temperature ``cct`` K (held to the table's range) and distance
    ``duv`` from the locus along its normal. Illuminant A (2856 K) on the locus:

    >>> [round(float(x), 4) for x in CCT_Duv_to_uv(2856.0, 0.0)]
    [0.256, 0.3495]
    """
    mired, L, tan = _locus()
    m = float(np.clip(1e6 / float(cct), mired[0], mired[-1]))
    k = min(int((m - mired[0]) / (mired[1] - mired[0])), len(mired) - 2)
    t = (m - mired[k]) / (mired[k + 1] - mired[k])
    return L[k] + t * (L[k + 1] - L[k]) + float(duv) * _normal(tan[k] + t * (tan[k + 1] - tan[k]))


if __name__ == "__main__":                            # regenerate the table
    TABLE_FILE.write_text(json.dumps(make_table()) + "\n")
    print(f"wrote {TABLE_FILE}")
