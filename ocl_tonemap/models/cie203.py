"""The ocular media by age: CIE 203:2012 (van de Kraats & van Norren 2007).

The optical density of the eye's media (cornea, lens, humours) at wavelength
lambda (nm) and age A (years), van de Kraats & van Norren 2007, "Optical density
of the aging human ocular media in the visible and the UV", JOSA A 24(7),
1842-1857, Eq. 8, the form CIE 203:2012 takes:

    D(lambda, A) = (d_RL + 0.000031 A^2) (400/lambda)^4                 Rayleigh loss
                 + 14.19 x 10.68 exp(-(0.057 (lambda - 273))^2)         tryptophan
                 + (d_LY - 0.000063 A^2) 2.13 exp(-(0.029 (lambda - 370))^2)   young lens
                 + (0.059 + 0.000186 A^2) 11.95 exp(-(0.021 (lambda - 325))^2) old lens, UV
                 + (0.016 + 0.000132 A^2) 1.43 exp(-(0.008 (lambda - 325))^2)  old lens
                 + d_N                                                   neutral

The public forms differ only in the terms without A: the paper's d_RL = 0.446
(a 1-degree field; 0.225 for large fields), d_LY = 0.998, d_N = 0.111; CIE 203's
erratum 0.15, 1.05 and 0.06 (docs/models.md, "Observer age"). Every age term is
the same in all of them, so the transmittance of one age relative to another,
10^-(D(lambda, A) - D(lambda, A_ref)), which is all this package uses, is the same
whichever form is taken (tests).

What the media take (:func:`media_factors`): the light of a white (D65) that
reaches the cones (V(lambda)) and the rods (V'(lambda)) of an eye of age A, relative
to :data:`AGE_REF`.
"""

from __future__ import annotations

import functools

import numpy as np

from .lmsr import colour_module
from .spencer1995 import is_literal

#: The observer the operators' data stand for (the default ``--age``): the media
#: factors are 1 there. (The CIE's standard observer is usually put at 32 years,
#: CIE 203 / CIE S 026; the papers' observers, and Adrian's AF = 1, are younger.)
AGE_REF = 25.0

#: The terms without age, (d_RL, d_LY, d_N), of each public form.
FORMS = {"paper": (0.446, 0.998, 0.111),        # van de Kraats & van Norren 2007, 1 deg
         "paper-large-field": (0.225, 0.998, 0.111),
         "cie203": (0.15, 1.05, 0.06)}          # CIE 203:2012 with its erratum


def optical_density(lam_nm, age, form: str = "cie203") -> np.ndarray:
    """D(lambda, A) of the whole ocular media (Eq. 8 of van de Kraats & van Norren
    2007), float64, for wavelengths ``lam_nm`` (nm) and an ``age`` (years)."""
    lam = np.asarray(lam_nm, np.float64)
    A2 = float(age) ** 2
    d_rl, d_ly, d_n = FORMS[form]
    return ((d_rl + 0.000031 * A2) * (400.0 / lam) ** 4
            + 14.19 * 10.68 * np.exp(-(0.057 * (lam - 273.0)) ** 2)
            + (d_ly - 0.000063 * A2) * 2.13 * np.exp(-(0.029 * (lam - 370.0)) ** 2)
            + (0.059 + 0.000186 * A2) * 11.95 * np.exp(-(0.021 * (lam - 325.0)) ** 2)
            + (0.016 + 0.000132 * A2) * 1.43 * np.exp(-(0.008 * (lam - 325.0)) ** 2)
            + d_n)


def relative_transmittance(lam_nm, age, ref: float = AGE_REF) -> np.ndarray:
    """The media's transmittance at ``age`` over that at ``ref`` (the same in every
    public form: their terms without age cancel).

    >>> [round(float(t), 3) for t in relative_transmittance([450.0, 550.0, 650.0], 70)]
    [0.411, 0.854, 0.955]
    """
    return 10.0 ** -(optical_density(lam_nm, age) - optical_density(lam_nm, ref))


#: The grid the factors integrate on, nm.
WL = np.arange(380.0, 781.0, 5.0)


@functools.lru_cache(maxsize=1)
def _spectra() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(D65, V, V') on :data:`WL` (colour-science's tables)."""
    colour = colour_module()
    from colour.colorimetry import SDS_ILLUMINANTS, SDS_LEFS_PHOTOPIC, SDS_LEFS_SCOTOPIC
    shape = colour.SpectralShape(float(WL[0]), float(WL[-1]), float(WL[1] - WL[0]))

    def on(sd):
        return np.asarray(sd.copy().align(shape).values, np.float64)
    return (on(SDS_ILLUMINANTS["D65"]),
            on(SDS_LEFS_PHOTOPIC["CIE 1924 Photopic Standard Observer"]),
            on(SDS_LEFS_SCOTOPIC["CIE 1951 Scotopic Standard Observer"]))


@functools.lru_cache(maxsize=256)
def _factors(age: float, ref: float) -> tuple[float, float]:
    S, V, Vs = _spectra()
    t = relative_transmittance(WL, age, ref)
    return float((S * V * t).sum() / (S * V).sum()), float((S * Vs * t).sum() / (S * Vs).sum())


def media_factors(age: float, ref: float = AGE_REF) -> tuple[float, float]:
    """(photopic, scotopic): the share of a white's (D65) light that reaches the cones
    (V(lambda)-weighted) and the rods (V'(lambda)-weighted) through the media of an
    eye of ``age``, relative to one of ``ref``. 70 years: (0.84, 0.66)."""
    if float(age) == float(ref):
        return 1.0, 1.0
    return _factors(round(float(age), 3), float(ref))


def media_gain(age) -> float:
    """The scene-to-retina factor the run applies for an observer of ``age``: the
    media's photopic factor (:func:`media_factors`); 1 at :data:`AGE_REF` and for
    Spencer's ageless observer (``age`` None or ``"spencer"``)."""
    if is_literal(age):
        return 1.0
    return media_factors(float(age))[0]
