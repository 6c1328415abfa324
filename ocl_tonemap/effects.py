"""Effects any operator can use (Durand & Dorsey 2000, Secs. 3.4, 6, 7).

``flare``                light sources scatter in the eye (flare.py), added to
                         the scene (cd/m^2) before tone mapping;
``acuity``               loss of acuity in the dark: a Gaussian blur of the
                         displayed image, Eqs. 9-11 with Shaler's Table 1;
``chromatic_adaptation`` von Kries gains on the cone signals toward the
                         illuminant, Eq. 6, filtered with tau = 5 s;
``purkinje``             Kirk & O'Brien 2011's rod colour shift (Cao et al. 2008)
                         on the scene's chromaticity, luminance kept (the
                         operator models rod luminance itself).

Each takes ``on | off | auto``. ``auto`` runs an effect only where the frame
needs it (light sources present; cut-off frequency below the pixel
frequency; illuminant away from the working white by more than 1%), so its
output equals ``on`` and frames that do not need it cost nothing. Which
effects ran, and with what, is returned per frame for the metadata.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

from . import flare as fl
from .adaptation import exponential_step
from .convolution import EDGE_CLAMP, EDGE_ZERO, blur_reference, gaussian_taps
from .photometry import RGB709_TO_XYZ, Y_WEIGHTS, normalise_illuminant, xy_to_rgb  # noqa: F401

MODES = ("on", "off", "auto")

#: Chromatic adaptation time constant, s (Sec. 3.4; Fairchild & Reniff 1995).
TAU_CHROMA = 5.0
#: ``auto`` applies chromatic adaptation when a gain differs from 1 by more than this.
CHROMA_AUTO_TOLERANCE = 0.01
#: Default angular width of the image, degrees (the paper's 50-degree example, Sec. 8).
DEFAULT_FOV = 50.0

#: CIE 1931 xy chromaticities of named illuminants (CIE 15:2004).
ILLUMINANTS_XY = {
    "D50": (0.34567, 0.35850), "D55": (0.33242, 0.34743), "D65": (0.31270, 0.32900),
    "D75": (0.29902, 0.31485), "A": (0.44757, 0.40745), "TUNGSTEN": (0.44757, 0.40745),
    "F2": (0.37208, 0.37529), "F7": (0.31292, 0.32933), "F11": (0.38052, 0.37713),
    "LED-B3": (0.4474, 0.4066), "LED-B4": (0.4557, 0.4211),
}

#: Shaler 1937 via Durand & Dorsey 2000, Table 1: log10 L_wa (cd/m^2) -> highest
#: visible frequency omega (cycles/degree).
SHALER_LOG_L = np.arange(-3.5, 3.01, 0.5)
SHALER_OMEGA = np.array([2.1, 2.9, 4.1, 5.5, 9.0, 16.3, 23.8, 32.5, 38.5, 43.1, 46.0, 48.0,
                         48.8, 50.0])
#: Eq. 10: a = 1.86 omega makes the Gaussian's transfer 10^-0.395 at omega.
ACUITY_A_PER_OMEGA = math.sqrt(-math.log(10.0 ** -0.395) / math.pi) ** -1
#: Sec. 7: blur below a = 1 px^-1, fade it in between 1.1 and 1 px^-1.
ACUITY_FULL, ACUITY_NONE = 1.0, 1.1


@dataclass(frozen=True)
class EffectSettings:
    """Switches and parameters of the effects (CLI: --flare, --acuity,
    --chromatic-adaptation, --fov, --illuminant, --flare-method ...)."""

    flare: str = "off"
    acuity: str = "off"
    chromatic_adaptation: str = "off"
    purkinje: str = "off"
    fov_deg: float = DEFAULT_FOV
    flare_method: str = "fast"
    flare_threshold: float = fl.DEFAULT_THRESHOLD
    flare_per_octave: int = 1
    illuminant: str | None = None

    def __post_init__(self):
        for k in ("flare", "acuity", "chromatic_adaptation", "purkinje"):
            if getattr(self, k) not in MODES:
                raise ValueError(f"--{k.replace('_', '-')} must be on, off or auto "
                                 f"(got {getattr(self, k)!r})")
        if not (0 < self.fov_deg < 180):
            raise ValueError(f"--fov must be between 0 and 180 degrees (got {self.fov_deg})")
        if self.flare_method not in ("fast", "exact"):
            raise ValueError(f"--flare-method must be fast or exact (got {self.flare_method!r})")
        if not (self.flare_threshold > 0 and math.isfinite(self.flare_threshold)):
            raise ValueError("--flare-threshold must be a positive number")
        if self.flare_per_octave not in (1, 2, 3, 4):
            raise ValueError("--flare-sampling (Gaussians per octave) must be 1..4")
        if self.illuminant is not None:
            parse_illuminant(self.illuminant)

    @classmethod
    def for_operator(cls, operator: str, **given) -> "EffectSettings":
        """Defaults: durand00 (whose paper they come from) runs all three on
        ``auto``; the other operators leave them off unless asked."""
        base = cls(flare="auto", acuity="auto", chromatic_adaptation="auto") \
            if operator == "durand00" else cls()
        return replace(base, **{k: v for k, v in given.items() if v is not None})

    @property
    def any(self) -> bool:
        return any(getattr(self, k) != "off"
                   for k in ("flare", "acuity", "chromatic_adaptation", "purkinje"))

    def as_dict(self) -> dict:
        return asdict(self)


# --- illuminant -------------------------------------------------------------------

def parse_illuminant(text: str) -> np.ndarray:
    """A name (D65, A, F2, ...) or ``x,y`` chromaticity -> normalised working RGB."""
    t = text.strip().upper()
    if t in ILLUMINANTS_XY:
        return xy_to_rgb(*ILLUMINANTS_XY[t])
    try:
        x, y = (float(v) for v in text.split(","))
        return xy_to_rgb(x, y)
    except ValueError:
        raise ValueError(f"bad --illuminant {text!r}: use x,y or one of "
                         f"{', '.join(sorted(ILLUMINANTS_XY))}") from None


def illuminant_from_metadata(spec) -> np.ndarray | None:
    """The EXR ``adoptedNeutral`` chromaticity (x, y) of a frame, as normalised RGB."""
    if spec is None:
        return None
    v = spec.getattribute("adoptedNeutral")
    try:
        x, y = float(v[0]), float(v[1])
        return xy_to_rgb(x, y)
    except (TypeError, ValueError, IndexError):
        return None


def illuminant_estimate_reference(rgb: np.ndarray) -> np.ndarray:
    """Luminance-weighted grey world, sum(Y rgb) / sum(Y Y): bright regions and
    light sources dominate (they carry the illuminant's colour; Sec. 4.1 warns
    against the plain image average). Float64; the device does the same sums."""
    rgb = np.asarray(rgb, np.float64)
    Y = rgb @ Y_WEIGHTS
    return normalise_illuminant((Y[..., None] * rgb).reshape(-1, 3).sum(axis=0))


#: An estimated illuminant is held to the Planckian locus within ANSI C78.377's
#: tolerance for white light (|Duv| <= 0.006) and 1500-25000 K: real light sources
#: sit there, and coloured lamps or a green lawn must not read as a magenta or green
#: illuminant (which turned a lamp-lit night field purple).
ESTIMATE_DUV_MAX = 0.006
ESTIMATE_CCT_RANGE = (1500.0, 25000.0)


def plausible_illuminant(rgb) -> np.ndarray:
    """An illuminant estimate (working RGB) moved onto the band of real light
    sources around the Planckian locus (:data:`ESTIMATE_DUV_MAX`), normalised."""
    import warnings
    v = normalise_illuminant(rgb)
    XYZ = RGB709_TO_XYZ @ v
    if not (XYZ.sum() > 0):
        return v
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
        uv = colour.xy_to_UCS_uv(XYZ[:2] / XYZ.sum())
        cct, duv = colour.temperature.uv_to_CCT_Ohno2013(uv)
        cct = float(np.clip(cct, *ESTIMATE_CCT_RANGE))
        duv = float(np.clip(duv, -ESTIMATE_DUV_MAX, ESTIMATE_DUV_MAX))
        u, w = colour.temperature.CCT_to_uv_Ohno2013(np.array([cct, duv]))
    x, y = 3.0 * u / (2.0 * u - 8.0 * w + 4.0), 2.0 * w / (2.0 * u - 8.0 * w + 4.0)
    return xy_to_rgb(x, y)


def chromatic_step(illum, goal, dt: float) -> np.ndarray:
    """Exponential filter of (r_wa, g_wa, b_wa) toward the goal, tau = 5 s (exact)."""
    return normalise_illuminant([exponential_step(float(a), float(g), dt, TAU_CHROMA)
                                 for a, g in zip(illum, goal)])


def von_kries_gains(illum) -> np.ndarray:
    """Eq. 6 (corrected, docs/models.md): the cone signals are divided by the
    normalised illuminant, r_d = m_C r_w / r_wa etc."""
    return 1.0 / np.asarray(illum, np.float64)


# --- loss of acuity (Sec. 7) ----------------------------------------------------------

def acuity_cutoff(L_waR) -> np.ndarray:
    """omega(L_waR), cycles/degree: Table 1, linear in log10 L, held at the ends."""
    x = np.log10(np.maximum(np.asarray(L_waR, np.float64), 1e-30))
    return np.interp(x, SHALER_LOG_L, SHALER_OMEGA)


def acuity_a_px(L_waR, fov_deg: float, width: int) -> np.ndarray:
    """Eq. 11: a in cycles per pixel, 1.86 omega fov / width."""
    return ACUITY_A_PER_OMEGA * acuity_cutoff(L_waR) * fov_deg / width


def acuity_sigma_px(a_px) -> np.ndarray:
    """Standard deviation (px) of the unit-volume Gaussian a^2 exp(-pi (a r)^2)."""
    return 1.0 / (np.asarray(a_px, np.float64) * math.sqrt(2.0 * math.pi))


def acuity_blend(a_px) -> np.ndarray:
    """Share of the blurred image: 1 below a = 1 px^-1, 0 above 1.1, linear between."""
    return np.clip((ACUITY_NONE - np.asarray(a_px, np.float64)) / (ACUITY_NONE - ACUITY_FULL),
                   0.0, 1.0)


def apply_acuity(img: np.ndarray, L_waR: float, fov_deg: float, blur=None):
    """Blur a displayed frame as the eye adapted to ``L_waR`` would (clamped edges).
    Returns (image, info); ``blur(img, taps)`` defaults to the float64 reference."""
    h, w = img.shape[:2]
    a = float(acuity_a_px(L_waR, fov_deg, w))
    t = float(acuity_blend(a))
    info = {"a_px": a, "cutoff_cpd": float(acuity_cutoff(L_waR)), "blend": t,
            "sigma_px": float(acuity_sigma_px(a))}
    if t <= 0.0:
        return img, info
    taps = gaussian_taps(info["sigma_px"])
    blurred = blur(img, taps) if blur is not None else blur_reference(img, taps, EDGE_CLAMP)
    out = np.asarray(blurred, np.float64) * t + np.asarray(img, np.float64) * (1.0 - t)
    return out.astype(np.float32), info


# --- Purkinje shift (Kirk & O'Brien 2011) as an effect ----------------------------------

#: ``auto`` skips the shift when rods carry less than this share (photopic frames).
PURKINJE_AUTO_GAIN = 0.01


def apply_purkinje(rgb: np.ndarray, G_rod: float, G_cone: float, device=None,
                   sensitivity: float = 1.0):
    """Shift working RGB (cd/m^2) as kirk11 does with ``--kappa adaptive`` and keep
    each pixel's photopic luminance. ``G_rod``: the (adapted) scotopic level;
    ``sensitivity``: how far the rods are dark adapted (0..1, scales the rods'
    share). ``device``: a KirkDevice, else float64."""
    from . import kirk11 as ko
    from . import lmsr
    area = ko.model_scale()
    k1, k2, gain = ko.kappas(ko.KirkSettings(kappa="adaptive"), G_rod)
    k1, k2, gain = k1 * sensitivity, k2 * sensitivity, gain * sensitivity
    M = lmsr.fitted()["H"][:3]
    rgb = np.asarray(rgb)
    if gain <= 0.0:
        return rgb, {"rod_gain": 0.0, "fallback_fraction": 0.0}
    if device is not None:
        p, fb = device.shift_rgb(np.asarray(rgb, np.float32), area, k1, k2, gain, M,
                                 np.eye(3), ko.SHIFT_XYZ)
        p = p.astype(np.float64)
    else:
        q = lmsr.rgb_to_lmsr(rgb)
        qh, _ = ko.purkinje_shift(q, area, k1, k2, ko.SHIFT_XYZ, gain)
        p, fbm = ko.gamut_map(M, qh)
        fb = float(fbm.mean())
    y_in = np.asarray(rgb, np.float64) @ Y_WEIGHTS
    y_p = p @ Y_WEIGHTS
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.where(y_p > 0, y_in / np.where(y_p > 0, y_p, 1.0), 0.0)
    out = np.where((y_p > 0)[..., None], p * k[..., None], rgb)
    return out.astype(np.float32), {"rod_gain": float(gain), "k1": float(k1),
                                    "fallback_fraction": float(fb)}


# --- the stage ------------------------------------------------------------------

class Effects:
    """The effects of one observer: settings, the backend's device, and the
    chromatic adaptation state (kept in ``AdaptationState.extra``)."""

    STATE_KEY = "illuminant_rgb"

    def __init__(self, settings: EffectSettings, backend):
        self.s = settings
        self.backend = backend
        self.user_illuminant = parse_illuminant(settings.illuminant) if settings.illuminant else None
        self._blur = None
        if backend.name == "opencl":
            from .convolution import DeviceBlur
            self._blur = DeviceBlur(backend.rt, backend.max_band_pixels)

    def _device_blur(self, edge: int):
        """``blur(img, taps)`` on the device, or None (the float64 reference) on the
        reference backend."""
        if self._blur is None:
            return None
        dev = self._blur
        return lambda img, taps: dev.blur(img, taps, edge)

    # flare ----------------------------------------------------------------
    def flare(self, rgb: np.ndarray, G_rod: float, G_cone: float):
        """(new rgb or None, info) for one frame in cd/m^2."""
        if self.s.flare == "off":
            return None, {"ran": False}
        if self.s.flare == "auto":
            Ymax = float(np.max(rgb.reshape(-1, 3) @ Y_WEIGHTS, initial=0.0))
            if not Ymax > self.s.flare_threshold * G_cone:
                return None, {"ran": False, "reason": "no light sources"}
        out, info = fl.apply_flare(rgb, G_cone, G_rod, self.s.fov_deg, self.s.flare_method,
                                   self.s.flare_threshold, self.s.flare_per_octave,
                                   self._device_blur(EDGE_ZERO))
        info["ran"] = info["sources"] > 0
        return out.astype(np.float32), info

    # Purkinje shift ---------------------------------------------------------------
    LEVELS_KEY = "purkinje_levels"

    def purkinje(self, rgb: np.ndarray, G_rod: float, G_cone: float, extra: dict | None = None,
                 dt: float = 0.0, fresh: bool = True, preadapt=None):
        """(new rgb or None, info): the kirk11 shift applied to chromaticity only (each
        pixel keeps its Y), its strength from the shared receptor scheduler: the
        adapted scotopic level and the rods' dark adaptation (``extra`` keeps the
        levels in the adaptation state; without it, steady state at the frame)."""
        if self.s.purkinje == "off":
            return None, {"ran": False}
        from .adaptation import (receptor_levels_advance, receptor_levels_preadapted,
                                 receptor_levels_steady, rod_sensitivity)
        from .photometry import neutral_scotopic_ratio
        prev = (extra or {}).get(self.LEVELS_KEY)
        if prev is None or fresh:
            lv = (receptor_levels_preadapted(preadapt[0] * neutral_scotopic_ratio(),
                                             preadapt[0], preadapt[1])
                  if (fresh and preadapt is not None) else receptor_levels_steady(G_rod, G_cone))
        else:
            lv = receptor_levels_advance(prev, G_rod, G_cone, dt)
        if extra is not None:
            extra[self.LEVELS_KEY] = {k: float(v) for k, v in lv.items()}
        sens = rod_sensitivity(lv)
        out, info = apply_purkinje(rgb, lv["A_rod"], lv["A_cone"], self._kirk_device(), sens)
        info.update({"A_rod": lv["A_rod"], "rod_sensitivity": sens})
        if self.s.purkinje == "auto" and info["rod_gain"] <= PURKINJE_AUTO_GAIN:
            return None, {"ran": False, "reason": "photopic", **info}
        info["ran"] = True
        return out, info

    def _kirk_device(self):
        if self._blur is None:
            return None
        if getattr(self, "_kirk", None) is None:
            from .kirk11_device import KirkDevice
            self._kirk = KirkDevice(self.backend.rt)
        return self._kirk

    # chromatic adaptation --------------------------------------------------------
    def illuminant_goal(self, frame_hint, estimate_fn):
        """(normalised rgb, source): user value > frame metadata > estimate."""
        if self.user_illuminant is not None:
            return self.user_illuminant, "user"
        if frame_hint is not None:
            return normalise_illuminant(frame_hint), "adoptedNeutral"
        return plausible_illuminant(estimate_fn()), "estimate"

    def chromatic(self, extra: dict, goal, source: str, dt: float, fresh: bool,
                  preadapted: bool):
        """Advance the illuminant state; returns (gains or None, info)."""
        if self.s.chromatic_adaptation == "off":
            return None, {"ran": False}
        prev = extra.get(self.STATE_KEY)
        if fresh or prev is None:
            illum = np.ones(3) if preadapted else np.asarray(goal, np.float64)
        else:
            illum = chromatic_step(np.asarray(prev, np.float64), goal, dt)
        extra[self.STATE_KEY] = [float(v) for v in illum]
        g = von_kries_gains(illum)
        ran = self.s.chromatic_adaptation == "on" or \
            float(np.max(np.abs(g - 1.0))) > CHROMA_AUTO_TOLERANCE
        info = {"ran": ran, "source": source, "goal": [float(v) for v in goal],
                "illuminant": extra[self.STATE_KEY], "gains": [float(v) for v in g]}
        return (g if ran else None), info

    # acuity -----------------------------------------------------------------------
    def acuity(self, img: np.ndarray, G_rod: float):
        if self.s.acuity == "off":
            return img, {"ran": False}
        out, info = apply_acuity(img, G_rod, self.s.fov_deg, self._device_blur(EDGE_CLAMP))
        info["ran"] = info["blend"] > 0
        return out, info
