"""The display observer: what the inverse models map onto.

Every operator ends in display-linear light, 1.0 = ``unit_cd`` cd/m^2 of the
display encoding (100 cd/m^2 for the OCIO display colourspaces, SDR and PQ
alike), which OCIO then encodes for the chosen display/view.

The display observer is steady-state adapted (Pattanaik 2000, Sec. 4.3):
reference white is the display white, reference black 1/32 of it (Hunt, as in
Eq. 8), adaptation luminance one fifth of white ("reference white = 5 x
adaptation"). For the paper's CRT those are 125, 4 and 25 cd/m^2.
"""

from __future__ import annotations

from dataclasses import dataclass, asdict

#: Largest display-linear value written: 100 x the encoding unit, i.e.
#: 10 000 cd/m^2, the PQ ceiling. Keeps half-float outputs finite.
DISPLAY_LINEAR_MAX = 100.0


@dataclass(frozen=True)
class DisplaySpec:
    """A display and its steady-state observer.

    white_cd : luminance of display white, cd/m^2 (the observer's REF_whit).
    black_cd : luminance of reference black, cd/m^2 (white/32 by default).
    adapt_cd : the display observer's adaptation luminance A, cd/m^2.
    unit_cd  : cd/m^2 of display-linear 1.0 in the OCIO display encoding.
    hdr      : True for PQ/HLG displays.
    paper_crt: use Pattanaik 2000's printed CRT constants verbatim.
    """

    name: str
    white_cd: float = 100.0
    black_cd: float = 100.0 / 32.0
    adapt_cd: float = 20.0
    unit_cd: float = 100.0
    hdr: bool = False
    paper_crt: bool = False

    @classmethod
    def from_white(cls, name: str, white_cd: float, unit_cd: float = 100.0, hdr: bool = False,
                   contrast: float = 32.0) -> "DisplaySpec":
        if not (white_cd > 0 and contrast > 1):
            raise ValueError(f"display white must be > 0 cd/m^2 (got {white_cd}) and contrast > 1")
        return cls(name, white_cd, white_cd / contrast, white_cd / 5.0, unit_cd, hdr, False)

    @classmethod
    def crt_2000(cls) -> "DisplaySpec":
        """Pattanaik 2000 Sec. 4.3: CRT in office light, A = 25, white 125,
        black 4 (= 125/32) cd/m^2; display-linear 1.0 is the CRT's white."""
        return cls("paper-crt", 125.0, 125.0 / 32.0, 25.0, 125.0, False, True)

    def as_dict(self) -> dict:
        return asdict(self)


HDR_KEYS = ("pq", "2100", "st2084", "hdr", "hlg")


def display_for(display_name: str, white_cd: float | None = None, peak_cd: float = 1000.0,
                model: str = "display") -> DisplaySpec:
    """The display observer for an OCIO display name.

    ``model="paper-crt"`` selects the paper's CRT constants. Otherwise SDR
    displays get a 100 cd/m^2 white; HDR (PQ/HLG) displays get their peak
    (``peak_cd``, 1000 by default) as white. ``white_cd`` overrides both.
    """
    if model == "paper-crt":
        return DisplaySpec.crt_2000()
    if model != "display":
        raise ValueError(f"unknown display model {model!r} (display | paper-crt)")
    hdr = any(k in display_name.lower() for k in HDR_KEYS)
    white = white_cd if white_cd else (peak_cd if hdr else 100.0)
    return DisplaySpec.from_white(display_name, white, 100.0, hdr)
