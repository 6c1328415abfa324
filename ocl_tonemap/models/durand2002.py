"""Durand & Dorsey 2002: fast bilateral filtering for the display of HDR images --
the base/detail range reduction on log luminance (kirk11's range reduction).

>>> import numpy as np
>>> out = range_reduce(np.array([0.0, 4.0]), np.array([0.0, 4.0]), 100.0)
>>> [round(float(v), 6) for v in out]        # a 4-decade base compressed to 2 decades
[-2.0, 0.0]
"""

from __future__ import annotations

import functools
import math

import numpy as np


#: The base layer's robust range is read off a histogram (so that it adds up over
#: row bands in bounded memory, and the float64 reference and the float32 device
#: path bin the same values alike): log10 values in [-12, 12] in 2^16 bins,
#: 3.7e-4 decade (0.085% in luminance) each, interpolated within the bin.
BASE_HIST_LO, BASE_HIST_HI, BASE_HIST_BINS = -12.0, 12.0, 1 << 16


@functools.lru_cache(maxsize=None)
def base_hist_edges() -> tuple[int, int, int]:
    """(num, off, den): bin k starts at e_k = (k num + off) / den, exactly (den a power
    of two, |k num + off| < 2^24: every edge is a float32). The device bins a float32
    value by comparing it with these edges (kirk11.cl ``base_histogram``), the host by
    :func:`base_hist_bins`; both give floor((b - LO) BINS / (HI - LO)) exactly."""
    from fractions import Fraction
    step = Fraction(BASE_HIST_HI - BASE_HIST_LO) / BASE_HIST_BINS
    off = Fraction(BASE_HIST_LO) * step.denominator
    den = step.denominator
    if off.denominator != 1 or den & (den - 1) or \
            max(abs(off), abs(BASE_HIST_BINS * step.numerator + off)) >= 1 << 24:
        raise ValueError("BASE_HIST_* give edges that are not all float32")
    return step.numerator, int(off), den


def base_hist_bins(b) -> np.ndarray:
    """The bin k of each value, e_k <= b < e_k+1 (:func:`base_hist_edges`), clamped to
    the bins (NaN: bin 0, as the device's clamp): floor((b - LO) BINS / (HI - LO)),
    then moved by one where the value lies across the exact edge (b - LO rounds for
    b within ~1e-15 of an edge at 0), as the device does."""
    num, off, den = base_hist_edges()
    b = np.asarray(b, np.float64)
    x = ((b - BASE_HIST_LO) * BASE_HIST_BINS) / (BASE_HIST_HI - BASE_HIST_LO)
    k = np.fmin(np.fmax(np.floor(x), 0.0), BASE_HIST_BINS - 1).astype(np.int64)
    k -= (b < (k * num + off) / den) & (k > 0)
    k += (b >= ((k + 1) * num + off) / den) & (k < BASE_HIST_BINS - 1)
    return k


class BaseRange:
    """The base layer's range (lo, hi) in log10, accumulated over row bands.

    ``percentiles`` (p_lo, p_hi): (0, 100) is the exact minimum and maximum
    (Durand & Dorsey 2002 as printed); otherwise those percentiles of the base, from
    a histogram (``BASE_HIST_*``) clamped to the exact extremes. pfstools'
    ``pfstmo_durand02`` takes 1% and 99% ("skip 1% of outliers"): a handful of
    lamp pixels then cannot set the whole frame's compression and exposure, which
    the exact extremes let them (and which a smoothed grid base moves)."""

    def __init__(self, percentiles=(0.0, 100.0)):
        self.p_lo, self.p_hi = (float(v) for v in percentiles)
        if not 0.0 <= self.p_lo < self.p_hi <= 100.0:
            raise ValueError(f"base percentiles need 0 <= lo < hi <= 100 (got {percentiles})")
        self.exact = (self.p_lo, self.p_hi) == (0.0, 100.0)
        self.lo, self.hi, self.n = math.inf, -math.inf, 0
        self.hist = None if self.exact else np.zeros(BASE_HIST_BINS, np.int64)

    def add(self, base) -> "BaseRange":
        b = np.asarray(base).ravel()
        if not b.size:
            return self
        self.lo, self.hi = min(self.lo, float(b.min())), max(self.hi, float(b.max()))
        self.n += b.size
        if self.hist is not None:
            self.hist += np.bincount(base_hist_bins(b), minlength=BASE_HIST_BINS)
        return self

    def add_counts(self, hist, lo: float, hi: float, n: int) -> "BaseRange":
        """Adds n values given by their extremes and their counts in the bins
        (``hist``: BASE_HIST_BINS counts, None for the exact range): a device's."""
        if n <= 0:
            return self
        self.lo, self.hi = min(self.lo, float(lo)), max(self.hi, float(hi))
        self.n += int(n)
        if self.hist is not None:
            self.hist += np.asarray(hist, np.int64)
        return self

    def _percentile(self, p: float) -> float:
        r = p / 100.0 * (self.n - 1)                 # rank, as numpy's linear percentile
        cum = np.cumsum(self.hist)
        b = int(np.searchsorted(cum, r, side="right"))
        before = float(cum[b - 1]) if b else 0.0
        width = (BASE_HIST_HI - BASE_HIST_LO) / BASE_HIST_BINS
        v = BASE_HIST_LO + (b + (r - before + 0.5) / self.hist[b]) * width
        return min(max(v, self.lo), self.hi)

    def result(self) -> tuple[float, float]:
        if self.n == 0:
            return 0.0, 0.0
        if self.exact:
            return self.lo, self.hi
        return self._percentile(self.p_lo), self._percentile(self.p_hi)


def compression(base_range: tuple[float, float], target_contrast: float) -> float:
    """Durand & Dorsey 2002: the base layer's scale c, its span brought to
    log10(target_contrast) (never expanded)."""
    span = base_range[1] - base_range[0]
    return min(1.0, math.log10(target_contrast) / span) if span > 0 else 1.0


def range_reduce(logY: np.ndarray, base: np.ndarray, target_contrast: float,
                 percentiles=(0.0, 100.0)) -> np.ndarray:
    """Durand & Dorsey 2002: log10 of the output luminance relative to display white:
    the base compressed to ``target_contrast`` with its top (the maximum, or the
    ``percentiles``' upper one: :class:`BaseRange`) at white, detail kept."""
    lo, hi = BaseRange(percentiles).add(base).result()
    c = compression((lo, hi), target_contrast)
    return c * (base - hi) + (logY - base)
