"""The display observer: what the inverse models map onto.

Every operator ends in display-linear light, 1.0 = ``unit_cd`` cd/m^2 of the
display encoding (100 cd/m^2 for the OCIO display colourspaces, SDR and PQ
alike), which OCIO then encodes for the chosen display/view.

The display observer is steady-state adapted (Pattanaik 2000, Sec. 4.3):
reference white is the display white, adaptation luminance one fifth of it
("reference white = 5 x adaptation"). Display black comes from the display:
white / 1000 for SDR displays (sRGB, Rec.1886, P3, gamma: 1000:1, a typical
LCD/OLED in a dim room), 0.005 cd/m^2 for HDR (PQ/HLG: the ST 2084 mastering
black of common HDR monitors); ``--display-black`` sets it. The paper's CRT
(``--display-model paper-crt``) keeps its printed 125, 4 (= 125/32) and 25 cd/m^2.

Where a model produces an absolute display luminance L (Pattanaik's inverse
display model), the display's own black is taken out of the signal: a display
with black b shows code value v at about b + (W - b) v, so
v = (L - b) / (W - b) (``DisplaySpec.to_signal``). The paper's CRT keeps
v = L / W, the paper's literal form.
"""

from __future__ import annotations

import math

import numpy as np
from dataclasses import dataclass, asdict

from .photometry import Y_WEIGHTS

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
    subtract_black : take the display's black out of absolute display
        luminances (see the module doc); off for the paper's CRT.
    """

    name: str
    white_cd: float = 100.0
    black_cd: float = 100.0 / 32.0
    adapt_cd: float = 20.0
    unit_cd: float = 100.0
    hdr: bool = False
    paper_crt: bool = False
    subtract_black: bool = False

    @classmethod
    def from_white(cls, name: str, white_cd: float, unit_cd: float = 100.0, hdr: bool = False,
                   contrast: float = 32.0, black_cd: float | None = None,
                   subtract_black: bool = False) -> "DisplaySpec":
        """A display of white ``white_cd``; black ``black_cd``, else white / ``contrast``."""
        if not (white_cd > 0 and math.isfinite(white_cd)):
            raise ValueError(f"display white must be a positive number of cd/m^2 (got {white_cd})")
        black = white_cd / contrast if black_cd is None else black_cd
        if not (0 < black < white_cd and math.isfinite(black)):
            raise ValueError(f"--display-black {black:g} cd/m^2 must be above 0 and below the "
                             f"display's white ({white_cd:g} cd/m^2{'' if hdr else ', SDR'}; "
                             f"--display-white sets it)")
        return cls(name, white_cd, black, white_cd / 5.0, unit_cd, hdr, False, subtract_black)

    def to_signal(self, L_cd):
        """Display-linear signal (1.0 = ``unit_cd``) that makes this display show
        ``L_cd`` cd/m^2: (L - black) / (white - black) x white / unit, or L / unit."""
        import numpy as np
        L = np.asarray(L_cd, np.float64)
        if not self.subtract_black:
            return L / self.unit_cd
        return np.maximum(L - self.black_cd, 0.0) * self.signal_gain

    def from_signal(self, v):
        """Inverse of :meth:`to_signal`: the cd/m^2 the display shows for signal ``v``
        (its black at 0 when it has one)."""
        import numpy as np
        return np.asarray(v, np.float64) / self.signal_gain + self.signal_offset

    @property
    def signal_offset(self) -> float:
        """cd/m^2 taken off before :attr:`signal_gain` (the device pass's form)."""
        return self.black_cd if self.subtract_black else 0.0

    @property
    def signal_gain(self) -> float:
        if not self.subtract_black:
            return 1.0 / self.unit_cd
        return self.white_cd / ((self.white_cd - self.black_cd) * self.unit_cd)

    @classmethod
    def crt_2000(cls) -> "DisplaySpec":
        """Pattanaik 2000 Sec. 4.3: CRT in office light, A = 25, white 125,
        black 4 (= 125/32) cd/m^2; display-linear 1.0 is the CRT's white."""
        return cls("paper-crt", 125.0, 125.0 / 32.0, 25.0, 125.0, False, True)

    def as_dict(self) -> dict:
        return asdict(self)


HDR_KEYS = ("pq", "2100", "st2084", "hdr", "hlg")
#: Default display contrast (white : black) of SDR displays.
SDR_CONTRAST = 1000.0
#: Default black of HDR displays, cd/m^2.
HDR_BLACK_CD = 0.005


def display_for(display_name: str, white_cd: float | None = None, peak_cd: float = 1000.0,
                model: str = "display", black_cd: float | None = None) -> DisplaySpec:
    """The display observer for an OCIO display name.

    ``model="paper-crt"`` selects the paper's CRT constants. Otherwise SDR
    displays get a 100 cd/m^2 white and white/1000 black; HDR (PQ/HLG)
    displays get their peak (``peak_cd``, 1000 by default) as white and
    0.005 cd/m^2 black. ``white_cd`` and ``black_cd`` override them.
    """
    if model == "paper-crt":
        if black_cd is not None or white_cd is not None:
            raise ValueError("--display-model paper-crt has the paper's white and black "
                             "(125 and 4 cd/m^2); drop --display-white/--display-black")
        return DisplaySpec.crt_2000()
    if model != "display":
        raise ValueError(f"unknown display model {model!r} (display | paper-crt)")
    for flag, v in (("--display-white", white_cd), ("--display-peak", peak_cd),
                    ("--display-black", black_cd)):
        if v is not None and not (v > 0 and math.isfinite(v)):
            raise ValueError(f"{flag} must be a positive number of cd/m^2 (got {v})")
    hdr = any(k in display_name.lower() for k in HDR_KEYS)
    white = white_cd if white_cd else (peak_cd if hdr else 100.0)
    if black_cd is None:
        black_cd = HDR_BLACK_CD if hdr else white / SDR_CONTRAST
    return DisplaySpec.from_white(display_name, white, 100.0, hdr, black_cd=black_cd,
                                  subtract_black=True)


# --- where an adapted scene sits on the display ---------------------------------

def scene_key(L_adapted):
    """The display level, as a fraction of display white, at which a scene adapted
    to L cd/m^2 shows its adaptation level: Krawczyk, Myszkowski & Seidel 2005's
    key a = 1.03 - 2 / (2 + log10(L + 1)) (floored at 0.02), put on the display
    as Reinhard et al. 2002's photographic operator puts it, a / (1 + a):
    0.02 at 0.001, 0.03 at 0.01, 0.14 at 1, 0.35 at 100, 0.41 at 10^4 cd/m^2."""
    L = np.maximum(np.asarray(L_adapted, np.float64), 0.0)
    a = np.maximum(1.03 - 2.0 / (2.0 + np.log10(L + 1.0)), 0.02)
    return a / (1.0 + a)


# --- highlights ------------------------------------------------------------------

#: Display-linear values are capped here before the shoulder: the inverse display
#: response diverges near saturation, and inf x 0 would be NaN (common.h: the same).
SIGNAL_CEILING = 1.0e6
#: Default knee of the highlight shoulder, as a fraction of display white.
SHOULDER_KNEE = 0.7
#: Knee of the per-channel cap after the luminance shoulder: colours are desaturated
#: only where a channel would pass 0.9 of white (kernels/common.h: CHANNEL_KNEE).
CHANNEL_KNEE = 0.9
#: The shoulder's power p (issue 67): above the knee, 1 - (1 + t)^-p of the way to
#: white. Reinhard's t/(1+t) (p = 1) put a pixel at code 255 from ~21x white (a
#: channel from ~3x): a daylight photograph's sky and sunlit walls clipped over up to
#: 9 % of the frame with light sources left out. p = 1/2 reaches code 255 at ~690x
#: white (a channel at ~27x), keeping the slope 1 at the knee.
SHOULDER_POWER = 0.5


def shoulder_curve(m, knee: float = SHOULDER_KNEE):
    """The highlight shoulder on a value relative to display white: identity up to
    ``knee``, then ``knee + (1 - knee) (1 - (1 + t)^-p)`` with ``t = (m - knee) /
    ((1 - knee) p)``, p = :data:`SHOULDER_POWER`: continuous with slope 1 at the knee,
    monotone, and approaching display white without reaching it (code 255, 0.9956 of
    white, at ~690x white for the default knee)."""
    import numpy as np
    m = np.asarray(m, np.float64)
    p = SHOULDER_POWER
    t = np.maximum(m - knee, 0.0) / ((1.0 - knee) * p)
    return np.where(m > knee, knee + (1.0 - knee) * (1.0 - (1.0 + t) ** -p), m)


def apply_shoulder(rgb, white_signal: float, knee: float = SHOULDER_KNEE):
    """Highlight shoulder of display-linear working RGB (..., 3), luminance first:
    the luminance Y goes through :func:`shoulder_curve` (relative to
    ``white_signal``), so the order of luminances is kept (no gradient reversal);
    then, where the largest channel m would still exceed its own shoulder value
    S(m), the colour is desaturated toward that luminance until it does (hue
    kept, luminance kept; channels use the later :data:`CHANNEL_KNEE`). No channel
    reaches display white. ``knee`` <= 0 or
    >= 1: unchanged (a hard clip follows at display white)."""
    rgb = np.asarray(rgb, np.float64)
    if not (0.0 < knee < 1.0):
        return rgb
    c = np.maximum(rgb / white_signal, 0.0)
    Y = c @ Y_WEIGHTS
    m = np.max(c, axis=-1)
    Ys = shoulder_curve(Y, knee)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(Y > 0, Ys / np.where(Y > 0, Y, 1.0), 0.0)
        top = m * g                                   # the largest channel after scaling
        cap = shoulder_curve(m, CHANNEL_KNEE)        # channels: a later knee
        t = np.where(top > cap, (cap - Ys) / np.where(top > Ys, top - Ys, 1.0), 1.0)
    t = np.clip(t, 0.0, 1.0)
    out = Ys[..., None] + (c * g[..., None] - Ys[..., None]) * t[..., None]
    return out * white_signal
