"""What the observer can see: Adrian 1989's threshold under an operator's own state.

The threshold luminance difference of a target on a background L_b (the glare veil
included, as CIE 88 adds L_seq) is Adrian's steady dL_th (``models/adrian1989.py``)
times the transient factor TAF of the observer's present adaptation
(``adrian1989.transient_factor``): each operator's response gain at L_b now
against its gain when adapted to L_b (``Operator.observer_*``). So the papers' time
courses drive the threshold, frame by frame.

Used by the ``visibility`` calculator (a step in a uniform field, :func:`trace`),
the run's ``--visibility`` planes (:func:`frame_planes`) and the benchmarks.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .models import adrian1989 as ad

#: The default target: 10 arcmin (the issue's and RP-8's small target is 7.3-10).
TARGET_ARCMIN = 10.0
#: The default observation time of a map, s (RP-8's 0.2 s fixation of a driver).
MAP_TIME_S = 0.2


@dataclass(frozen=True)
class Viewing:
    """The target and the observer: size (arcmin), age (years), observation time (s),
    field factor k."""

    size_arcmin: float = TARGET_ARCMIN
    age: float = 25.0
    time_s: float = 2.0
    k: float = ad.FIELD_FACTOR

    def check(self) -> "Viewing":
        if not (self.size_arcmin > 0 and math.isfinite(self.size_arcmin)):
            raise ValueError(f"the target size must be > 0 arcmin (got {self.size_arcmin:g})")
        if not 1.0 <= self.age <= 100.0:
            raise ValueError(f"the age must be 1..100 years (got {self.age:g})")
        if not self.time_s > 0:
            raise ValueError(f"the observation time must be > 0 s (got {self.time_s:g})")
        if not self.k > 0:
            raise ValueError(f"the field factor k must be > 0 (got {self.k:g})")
        return self

    def steady(self, L_b, polarity="positive") -> np.ndarray:
        """Adrian's dL_th (cd/m^2) of backgrounds ``L_b`` (any shape), the eye adapted
        to each; ``polarity`` "positive", "negative" or a boolean array (True:
        negative)."""
        L = np.maximum(np.asarray(L_b, np.float64), 1e-12)
        base = ad.basic_threshold(L, self.size_arcmin)
        neg = np.asarray(polarity == "negative") if isinstance(polarity, str) \
            else np.asarray(polarity, bool)
        fcp = np.where(neg, ad.polarity_factor(L, self.size_arcmin, self.k * base), 1.0)
        tf = 1.0 if math.isinf(self.time_s) else ad.time_factor(L, self.size_arcmin,
                                                                  self.time_s)
        return self.k * base * fcp * tf * ad.age_factor(self.age)


def transient(op, obs: dict, L_b) -> np.ndarray:
    """TAF of backgrounds ``L_b`` for an observer in state ``obs`` of operator ``op``."""
    L = np.asarray(L_b, np.float64)
    return ad.transient_factor(op.observer_steady_slope(L), op.observer_slope(obs, L))


@dataclass(frozen=True)
class TracePoint:
    """The observer ``t`` s after a step: adaptation luminance La, TAF, dL_th (and VL
    of a target)."""

    t: float
    L_a: float
    TAF: float
    dL_th: float
    VL: float | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def trace(op, L_from: float, seconds: float | None, L_b: float, times, view: Viewing,
          polarity: str = "positive", L_target: float | None = None) -> list[TracePoint]:
    """The observer of ``op`` adapted to a neutral field of ``L_from`` (for ``seconds``;
    None: fully), which steps to ``L_b`` at t = 0: its threshold at each of ``times``
    (s after the step, >= 0; the field held at L_b)."""
    obs = op.observer_preadapted(float(L_from), seconds)
    steady = float(view.steady(L_b, polarity))
    s_ss = float(op.observer_steady_slope(float(L_b)))
    out, now = [], 0.0
    for t in sorted(float(x) for x in times):
        obs = op.observer_advance(obs, float(L_b), t - now)
        now = t
        taf = float(ad.transient_factor(s_ss, op.observer_slope(obs, L_b)))
        dl = steady * taf
        vl = None if L_target is None else abs(L_target - L_b) / dl
        out.append(TracePoint(t, float(op.observer_level(obs)), taf, dl, vl))
    return out


# --- the per-frame planes (``run --visibility``) -----------------------------------------

#: The planes of a visibility EXR, in order, with their units (the header says them).
PLANES = (("La", "cd/m^2", "the eye's (cone) adaptation luminance, from the operator's state"),
          ("Lveil", "cd/m^2", "the glare veil (the flare's scattered light)"),
          ("Lb", "cd/m^2", "the background: the surround's luminance plus the veil"),
          ("dLth", "cd/m^2", "Adrian 1989's threshold x the transient factor"),
          ("VL", "1", "|target - background| / dLth (CIE 140 visibility level)"))
#: The background is the surround of a target: a Gaussian of this many target sizes.
SURROUND = 3.0
#: Samples per decade of L_b of the threshold's table (linear in log-log: <= 1e-6).
TABLE_PER_DECADE = 2000


def _fast_len(n: int) -> int:
    """The smallest 2^a 3^b 5^c >= n (numpy's FFT is quick on those)."""
    best, p2 = 1 << max(0, (n - 1).bit_length()), 1
    while p2 < 2 * n:
        p3 = p2
        while p3 < 2 * n:
            p5 = p3
            while p5 < n:
                p5 *= 5
            best = min(best, p5)
            p3 *= 3
        p2 *= 2
    return best


def _gauss_fft(F, shape, sigma_px: float, pad: int) -> np.ndarray:
    """A Gaussian of ``sigma_px`` applied to the padded image whose rfft2 is ``F``."""
    h, w = shape
    fy = np.fft.fftfreq(h)[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    g = np.exp(-2.0 * (np.pi * sigma_px) ** 2 * (fy * fy + fx * fx))
    return np.fft.irfft2(F * g, s=shape)


def target_and_surround(Y: np.ndarray, size_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(target, surround) luminance of every pixel: Gaussians of the target's size
    (sigma = size / 2.355, the disc's FWHM) and of :data:`SURROUND` sizes, on a
    reflected border."""
    s_t = max(size_px / 2.355, 0.0)
    s_b = SURROUND * size_px / 2.355
    pad = int(min(max(Y.shape), math.ceil(3.0 * s_b) + 1))
    P = np.pad(np.asarray(Y, np.float64), pad, mode="reflect") if min(Y.shape) > 1 else \
        np.pad(np.asarray(Y, np.float64), pad, mode="edge")
    # zero-filled to an FFT-friendly size beyond the reflected border (>= 3 sigma)
    P = np.pad(P, ((0, _fast_len(P.shape[0]) - P.shape[0]),
                   (0, _fast_len(P.shape[1]) - P.shape[1])))
    F = np.fft.rfft2(P)
    crop = (slice(pad, pad + Y.shape[0]), slice(pad, pad + Y.shape[1]))
    tgt = _gauss_fft(F, P.shape, s_t, pad)[crop] if s_t > 0.3 else np.asarray(Y, np.float64)
    sur = _gauss_fft(F, P.shape, s_b, pad)[crop]
    return np.maximum(tgt, 0.0), np.maximum(sur, 0.0)


def threshold_table(op, obs: dict, view: Viewing, lo: float, hi: float):
    """(log10 L_b grid, dL_th positive, dL_th negative) over [lo, hi] cd/m^2 for the
    scalar observer state ``obs``: Adrian's steady threshold x TAF, exact at each
    sample and at the model's range joins."""
    a, b = math.log10(max(lo, 1e-9)), math.log10(max(hi, lo * 1.0001, 1e-9))
    n = max(8, int(math.ceil((b - a) * TABLE_PER_DECADE)) + 1)
    x = np.linspace(a, b, n)
    joins = [math.log10(v) for v in (ad.L_LOW, ad.L_HIGH) if a < math.log10(v) < b]
    for j in joins:                      # both sides of a join, so no cell straddles it
        x = np.concatenate([x, [np.nextafter(j, -np.inf), j]])
    x = np.unique(x)
    L = 10.0 ** x
    taf = ad.transient_factor(op.observer_steady_slope(L), op.observer_slope(obs, L))
    return x, view.steady(L, "positive") * taf, view.steady(L, "negative") * taf


def frame_planes(op, obs: dict, Y: np.ndarray, veil: np.ndarray | None, view: Viewing,
                 px_per_arcmin: float) -> dict:
    """The visibility planes of one frame (float32, H x W): ``Y`` the scene's photopic
    luminance (cd/m^2, before the flare), ``veil`` the flare's veil (or None), ``obs``
    the operator's observer state at the frame (:meth:`Operator.observer_of`)."""
    Y = np.nan_to_num(np.asarray(Y, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    Y = np.maximum(Y, 0.0)
    tgt, sur = target_and_surround(Y, view.size_arcmin * px_per_arcmin)
    V = np.zeros_like(Y) if veil is None else np.maximum(np.asarray(veil, np.float64), 0.0)
    Lb = np.maximum(sur + V, 1e-6)
    dL = tgt - sur
    if op.observer_per_pixel:
        taf = ad.transient_factor(op.observer_steady_slope(Lb), op.observer_slope(obs, Lb))
        th = np.where(dL < 0, view.steady(Lb, True), view.steady(Lb, False)) * taf
        La = np.broadcast_to(op.observer_level(obs), Y.shape)
    else:
        x, pos, neg = threshold_table(op, obs, view, float(Lb.min()), float(Lb.max()))
        lx = np.log10(Lb)
        th = 10.0 ** np.where(dL < 0, np.interp(lx, x, np.log10(neg)),
                              np.interp(lx, x, np.log10(pos)))
        La = np.full(Y.shape, float(op.observer_level(obs)))
    return {"La": La.astype(np.float32), "Lveil": V.astype(np.float32),
            "Lb": Lb.astype(np.float32), "dLth": th.astype(np.float32),
            "VL": (np.abs(dL) / th).astype(np.float32)}
