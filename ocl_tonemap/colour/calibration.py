"""Absolute calibration: how many cd/m^2 a pixel value of 1.0 is.

The models need absolute luminance: the same picture is a daylight scene at
5000 cd/m^2 and a moonlit one at 0.01. The scale comes from, first that applies:

1. ``--luminance-scale S`` (a number): 1.0 = S cd/m^2;
2. the EXR ``whiteLuminance`` attribute (cd/m^2 of RGB 1,1,1);
3. camera metadata (EXIF ``ExposureTime`` t, ``FNumber`` N and
   ``ISOSpeedRatings``/``ExposureIndex`` S): the reflected-light meter
   equation (ISO 2720) N^2 / t = L S / K with K = 12.5 gives the scene
   luminance L = K N^2 / (t S) that the camera exposed to mid-grey, and
   scene-linear mid-grey is 0.18, so 1.0 = L / 0.18 cd/m^2;
4. ``--luminance-scale auto:LEVEL``: the scale that puts the log-average
   luminance of the first frame of the run at LEVEL cd/m^2 (a number or a
   named level, :data:`NAMED_LEVELS`); one constant for the whole sequence;
5. Radiance ``.hdr``: 179 lm/W, the format's definition of its radiance
   units, after its EXPOSURE is divided out (``io/radiance.py``): a rendering (a
   Radiance renderer in its header) is absolute; photographs saved as .hdr are
   seldom absolute (reported);
6. 1 cd/m^2 per unit, with a warning naming the assumption and the flags.

Absolute sources (2, 3) are read per frame: they describe each frame (a
camera's auto-exposure is undone). The ``auto`` level is fixed once per run
(and kept in the adaptation state, so a resumed chunk uses the same constant):
scaling every frame to the same level would erase the adaptation the tool
exists to show.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..models.photometry import Y_WEIGHTS
from ..base.quantities import NAMED_LEVELS, luminance_scale  # noqa: F401 (NAMED_LEVELS: its API)

#: ISO 2720 reflected-light meter calibration constant K (cd s m^-2 ISO).
METER_K = 12.5
#: Scene-linear value a camera exposes a metered (mid-grey) surface to.
MID_GREY = 0.18
#: Radiance RGBE: 1.0 = 179 cd/m^2 (WHITE_EFFICACY, lm/W).
RADIANCE_EFFICACY = 179.0

@dataclass(frozen=True)
class CalibrationRequest:
    """What the user asked for: a fixed ``scale``, an ``auto_level`` (cd/m^2), or neither."""

    scale: float | None = None
    auto_level: float | None = None
    auto_name: str | None = None

    @classmethod
    def parse(cls, text: str | float | None) -> "CalibrationRequest":
        """``S`` (cd/m^2 of 1.0) or ``auto:LEVEL`` (cd/m^2 or a named level), as
        declared (``quantities.luminance_scale``)."""
        if text is None:
            return cls()
        scale, level, name = luminance_scale(text)
        return cls(scale=scale, auto_level=level, auto_name=name)


def _attr_number(spec, *names) -> float | None:
    for n in names:
        v = spec.getattribute(n)
        if isinstance(v, (tuple, list)) and v:
            v = v[0]
        try:
            f = float(v)
        except (TypeError, ValueError):
            continue
        if math.isfinite(f) and f > 0:
            return f
    return None


def camera_scale(spec) -> tuple[float, str] | None:
    """(cd/m^2 of 1.0, description) from EXIF exposure metadata, or None."""
    if spec is None:
        return None
    t = _attr_number(spec, "ExposureTime", "Exif:ExposureTime")
    N = _attr_number(spec, "FNumber", "Exif:FNumber")
    S = _attr_number(spec, "Exif:ISOSpeedRatings", "Exif:PhotographicSensitivity",
                     "Exif:ExposureIndex", "ISOSpeedRatings", "ExposureIndex")
    if t is None or N is None or S is None:
        return None
    L = METER_K * N * N / (t * S)
    return L / MID_GREY, (f"camera metadata: t = {t:g} s, N = f/{N:g}, ISO {S:g} -> "
                          f"mid-grey {L:.4g} cd/m^2 (K = {METER_K}, mid-grey {MID_GREY})")


#: ``auto:LEVEL`` meters at most this many pixels of a frame (a strided subsample).
LOG_AVERAGE_SAMPLES = 1 << 20


class LogAverage:
    """exp(mean(ln Y)) of the positive, finite photopic luminances of working RGB,
    over a strided subsample of at most ``max_samples`` of the frame's ``n_pixels``
    (every ``step``-th pixel in row order), given whole or in row bands in order:
    a streamed frame is metered on the same pixels as a whole one."""

    def __init__(self, n_pixels: int, max_samples: int = LOG_AVERAGE_SAMPLES):
        self.step = max(1, int(n_pixels) // max_samples)
        self.pos = 0
        self.total, self.count = 0.0, 0

    def add(self, rgb: np.ndarray) -> "LogAverage":
        flat = np.asarray(rgb)[..., :3].reshape(-1, 3)
        first = (-self.pos) % self.step
        Y = flat[first::self.step].astype(np.float64) @ Y_WEIGHTS
        Y = Y[np.isfinite(Y) & (Y > 0)]
        self.pos += flat.shape[0]
        if Y.size:
            self.total += float(np.log(Y).sum())
            self.count += Y.size
        return self

    def result(self) -> float | None:
        """None when no metered pixel has light."""
        return float(np.exp(self.total / self.count)) if self.count else None


def log_average(rgb: np.ndarray, max_samples: int = LOG_AVERAGE_SAMPLES) -> float | None:
    """:class:`LogAverage` of one whole frame."""
    a = np.asarray(rgb)
    return LogAverage(a.size // max(a.shape[-1], 1), max_samples).add(a).result()


@dataclass
class Calibration:
    """The scale of one frame: value, where it came from, and whether it was assumed."""

    scale: float
    source: str
    assumed: bool = False


class Calibrator:
    """Applies the precedence of the module doc to the frames of one run.

    ``auto_scale``: the constant of an ``auto:LEVEL`` request, fixed by the first
    frame that needs it (give it to resume a run with the same constant).
    """

    def __init__(self, request: CalibrationRequest, auto_scale: float | None = None):
        self.request = request
        self.auto_scale = auto_scale
        self._said_over_auto: set = set()     # calibration sources said to overrule auto

    def frame(self, spec, format_name: str, working_rgb_fn, radiance=None) -> Calibration:
        """The calibration of one frame. ``working_rgb_fn()`` returns its working RGB
        (only called for ``auto`` on the first frame); ``radiance``: a Radiance
        picture's header (``io/radiance.py``; its EXPOSURE is already divided out)."""
        r = self.request
        if r.scale is not None:
            return Calibration(r.scale, "--luminance-scale")
        wl = _attr_number(spec, "whiteLuminance") if spec is not None else None
        if wl is not None:
            return self._over_auto(Calibration(wl, "whiteLuminance attribute"))
        cam = camera_scale(spec)
        if cam is not None:
            return self._over_auto(Calibration(cam[0], cam[1]))
        if r.auto_level is not None:
            if self.auto_scale is None:
                la = log_average(working_rgb_fn())
                if la is None:
                    raise ValueError("--luminance-scale auto: the first frame has no light to "
                                     "meter (all pixels <= 0); give a number instead")
                self.auto_scale = r.auto_level / la
            name = f" ({r.auto_name})" if r.auto_name else ""
            return Calibration(self.auto_scale, f"auto: first frame's log-average = "
                               f"{r.auto_level:g} cd/m^2{name}")
        if radiance is not None and radiance.xyze:     # Y is luminance, cd/m^2 (ra_xyze)
            return Calibration(1.0, "Radiance XYZE: Y in cd/m^2" + (
                f" (a rendering: {radiance.renderer})" if radiance.absolute
                else " (no Radiance renderer in its header)"), assumed=not radiance.absolute)
        if radiance is not None and radiance.absolute:
            return Calibration(RADIANCE_EFFICACY, f"Radiance rendering ({radiance.renderer}): "
                               "179 lm/W, Radiance's absolute units")
        if format_name == "hdr" or radiance is not None:
            what = "a photograph (hdrgen)" if radiance is not None and radiance.photographic \
                else "no Radiance renderer in its header"
            return Calibration(RADIANCE_EFFICACY, f"Radiance efficacy 179 lm/W (the .hdr "
                               f"format's units; {what}: photographs are seldom absolute)",
                               assumed=True)
        return Calibration(1.0, "assumed: pixel values are cd/m^2", assumed=True)

    def _over_auto(self, cal: "Calibration") -> "Calibration":
        """An absolute calibration of the file wins over ``auto:LEVEL``: said once."""
        r = self.request
        if r.auto_level is not None and cal.source not in self._said_over_auto:
            self._said_over_auto.add(cal.source)
            import logging
            logging.getLogger("ocl_tonemap").warning(
                "--luminance-scale auto:%s is not used: the file's %s (1.0 = %g cd/m^2) "
                "comes first, being absolute; give --luminance-scale S to set the scale "
                "yourself", r.auto_name or f"{r.auto_level:g}", cal.source, cal.scale)
        return cal


ASSUMED_HELP = ("set --luminance-scale S (1.0 = S cd/m^2) or --luminance-scale auto:LEVEL "
                f"(LEVEL cd/m^2 or {'|'.join(NAMED_LEVELS)}), or write whiteLuminance into the file")
