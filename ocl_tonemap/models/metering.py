"""Metering: the "Adaptation Goal Finder" (Pattanaik 2000, Fig. 4).

Rods are metered on scotopic luminance Y', cones on photopic Y. Modes:

``logmean`` (default)
    exp(mean(ln L)) over the *lit* pixels: those whose photopic or scotopic
    luminance is above the floor, 1e-6 cd/m^2 (the absolute threshold of
    vision). Pixels at or below it (exact zeros: black borders, letterboxes, a
    masked-out half) carry no weight in any statistic but ``max``: light the eye
    cannot sense does not pull its adaptation down (a half-black field of 100
    cd/m^2 meters 100, not the 0.01 that ln(1e-6) as a value would give). A
    frame with no lit pixel meters the floor (logmean) or 0 (mean).
``mean``
    arithmetic mean (of the lit pixels).
``max``
    maximum.
``centre[:mean]``
    Nikon-style centre-weighted: 75% of the weight in a central disc of
    diameter 1/3 of the frame height (the 8 mm circle of a 24 mm frame),
    25% on the rest; log-mean unless ``:mean``.
``spot:X,Y[,S]``
    Gaussian spot at (X, Y) in fractions of width/height, sigma S as a
    fraction of the width (default 0.02, about 1 degree of a 50-degree view:
    the foveal weighting of Ward-Larson et al. 1997 used for Fig. 7);
    log-mean unless a fourth field ``mean``.
``mask:PATH[:mean]``
    a weight image (any format OIIO reads; the mean of its colour channels,
    negatives and NaN as 0), resized to the frame; log-mean unless ``:mean``.
    Durand & Dorsey 2000, Sec. 4.1's weight texture.
``percentile:P``
    the P-th percentile (0-100) of the luminances above the floor. The reference is exact; the device bins
    log10 L in ``HIST_BINS`` bins over [HIST_LO, HIST_HI) and interpolates,
    so it is within one bin (0.0049 decades, 1.1%).

The device path is a two-stage reduction (kernels/metering.cl); images
processed in bands accumulate per band and give the same reading.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

LOG_FLOOR = 1.0e-6
HIST_LO, HIST_HI, HIST_BINS = -10.0, 10.0, 4096
CENTRE_FRACTION = 0.75


@dataclass(frozen=True)
class MeteringSpec:
    mode: str = "logmean"
    statistic: str = "logmean"   # for weighted modes
    x: float = 0.5
    y: float = 0.5
    sigma: float = 0.02
    percentile: float = 50.0
    mask: str | None = None

    @classmethod
    def parse(cls, text: str | None) -> "MeteringSpec":
        if not text:
            return cls()
        if text.lower().startswith("mask:"):
            path, stat = text[5:], "logmean"
            for suffix in (":mean", ":logmean"):
                if path.lower().endswith(suffix):
                    path, stat = path[: -len(suffix)], suffix[1:]
            if not path:
                raise ValueError("bad --metering mask: give the weight image, mask:PATH[:mean]")
            return cls("mask", stat, mask=path)
        head, _, rest = text.partition(":")
        head = head.strip().lower().replace("center", "centre")
        fields = [f.strip() for f in rest.split(",")] if rest else []
        try:
            if head in ("logmean", "mean", "max") and not fields:
                return cls(head, head)
            if head == "centre":
                stat = fields[0] if fields else "logmean"
                if stat not in ("mean", "logmean"):
                    raise ValueError
                return cls("centre", stat)
            if head == "spot":
                stat = "logmean"
                if fields and fields[-1] in ("mean", "logmean"):
                    stat = fields.pop()
                if len(fields) not in (2, 3):
                    raise ValueError
                x, y = float(fields[0]), float(fields[1])
                s = float(fields[2]) if len(fields) == 3 else 0.02
                if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0 and 0.0 < s <= 10.0):
                    raise ValueError
                return cls("spot", stat, x, y, s)
            if head == "percentile" and len(fields) == 1:
                p = float(fields[0])
                if not 0.0 <= p <= 100.0:
                    raise ValueError
                return cls("percentile", "percentile", percentile=p)
        except ValueError:
            pass
        raise ValueError(f"bad --metering {text!r}: use logmean | mean | max | centre[:mean] | "
                         "spot:X,Y[,SIGMA][,mean] | mask:PATH[:mean] | percentile:P")

    def describe(self) -> str:
        if self.mode == "spot":
            return f"spot:{self.x:g},{self.y:g},{self.sigma:g}:{self.statistic}"
        if self.mode == "centre":
            return f"centre:{self.statistic}"
        if self.mode == "percentile":
            return f"percentile:{self.percentile:g}"
        if self.mode == "mask":
            return f"mask:{self.mask}:{self.statistic}"
        return self.mode

    # -- weights -------------------------------------------------------------
    def weight_params(self, width: int, height: int):
        """(mode id, p0, p1, p2, w_in, w_out) for the device and the reference."""
        if self.mode == "centre":
            cx, cy, r = width / 2.0, height / 2.0, height / 6.0
            n_in = _centre_count(width, height)
            n_out = width * height - n_in
            if n_in == 0 or n_out == 0:
                return 0, 0.0, 0.0, 1.0, 1.0, 1.0
            return (1, cx, cy, r, CENTRE_FRACTION / n_in * width * height,
                    (1 - CENTRE_FRACTION) / n_out * width * height)
        if self.mode == "spot":
            return 2, self.x * width, self.y * height, self.sigma * width, 1.0, 1.0
        if self.mode == "mask":
            return 3, 0.0, 0.0, 1.0, 1.0, 1.0
        return 0, 0.0, 0.0, 1.0, 1.0, 1.0


@functools.lru_cache(maxsize=32)
def _centre_count(width: int, height: int) -> int:
    """Pixels whose centres lie in the centre disc (float64, as the device tests it in float32)."""
    cx, cy, r = width / 2.0, height / 2.0, np.float32(height / 6.0)
    ys = (np.arange(height, dtype=np.float32) + np.float32(0.5)) - np.float32(cy)
    xs = (np.arange(width, dtype=np.float32) + np.float32(0.5)) - np.float32(cx)
    return int(((xs[None, :] ** 2 + ys[:, None] ** 2) <= r * r).sum())


def weights(spec: MeteringSpec, width: int, height: int, y0: int = 0, rows: int | None = None,
            mask: np.ndarray | None = None):
    """Per-pixel metering weights (float64) for rows [y0, y0+rows); ``mask``: the
    (height, width) weight image of ``mask:`` metering (``backends/weights.py``)."""
    rows = height - y0 if rows is None else rows
    mode, p0, p1, p2, w_in, w_out = spec.weight_params(width, height)
    if mode == 0:
        return np.ones((rows, width))
    if mode == 3:
        return np.asarray(mask)[y0:y0 + rows].astype(np.float64)
    x = np.arange(width) + 0.5
    y = np.arange(y0, y0 + rows) + 0.5
    d2 = (x[None, :] - p0) ** 2 + (y[:, None] - p1) ** 2
    if mode == 1:
        return np.where(d2 <= p2 * p2, w_in, w_out)
    return np.exp(-0.5 * d2 / (p2 * p2))


def _statistic(stat: str, sw, swl, swln, mx):
    """``sw``: the lit pixels' weight; ``swl``, ``swln``: their sums of w L, w ln L."""
    if stat == "max":
        return mx
    if sw <= 0:                       # nothing lit: darkness
        return LOG_FLOOR if stat == "logmean" else 0.0
    if stat == "mean":
        return swl / sw
    return math.exp(swln / sw)


@dataclass
class MeterSums:
    """Accumulated metering sums of one frame (possibly over several bands), over
    its lit pixels (photopic or scotopic luminance above :data:`LOG_FLOOR`)."""

    sums: np.ndarray           # [sum w, sum wY, sum w lnY, sum wY', sum w lnY', max Y, max Y']
    hist_Y: np.ndarray | None = None
    hist_Ys: np.ndarray | None = None

    def add(self, other: "MeterSums") -> None:
        self.sums[:5] += other.sums[:5]
        self.sums[5:7] = np.maximum(self.sums[5:7], other.sums[5:7])
        if other.hist_Y is not None:
            self.hist_Y = other.hist_Y.copy() if self.hist_Y is None else self.hist_Y + other.hist_Y
            self.hist_Ys = other.hist_Ys.copy() if self.hist_Ys is None else self.hist_Ys + other.hist_Ys

    def goal(self, spec: MeteringSpec) -> tuple[float, float]:
        """(G_rod, G_cone) in scotopic / photopic cd/m^2."""
        s = self.sums
        if spec.mode == "percentile":
            return (histogram_percentile(self.hist_Ys, spec.percentile),
                    histogram_percentile(self.hist_Y, spec.percentile))
        stat = spec.statistic
        return (_statistic(stat, s[0], s[3], s[4], s[6]), _statistic(stat, s[0], s[1], s[2], s[5]))


def histogram_percentile(hist: np.ndarray, p: float) -> float:
    """Percentile from a log10 histogram of the luminances above the floor (the
    device counts only those), linear within the bin (in log10)."""
    h = np.asarray(hist, np.float64)
    total = h.sum()
    if total <= 0:
        return 0.0
    target = p / 100.0 * total
    cum = np.cumsum(h)
    b = int(np.searchsorted(cum, target, side="left"))
    b = min(b, len(h) - 1)
    before = cum[b - 1] if b > 0 else 0.0
    frac = (target - before) / h[b] if h[b] > 0 else 0.0
    width = (HIST_HI - HIST_LO) / len(h)
    if b == 0 and frac <= 0:
        return 0.0
    return 10.0 ** (HIST_LO + (b + min(max(frac, 0.0), 1.0)) * width)


def lit(Y: np.ndarray, Ys: np.ndarray) -> np.ndarray:
    """The pixels metering counts: photopic or scotopic luminance above the floor."""
    return np.maximum(Y, Ys) > LOG_FLOOR


# --- float64 reference ----------------------------------------------------------

def reference_sums(Y: np.ndarray, Ys: np.ndarray, spec: MeteringSpec, width: int, height: int,
                   y0: int = 0, mask: np.ndarray | None = None) -> MeterSums:
    rows = Y.shape[0]
    Y = np.asarray(Y, np.float64)
    Ys = np.asarray(Ys, np.float64)
    w = weights(spec, width, height, y0, rows, mask) * lit(Y, Ys)
    sums = np.array([w.sum(), (w * Y).sum(), (w * np.log(np.maximum(Y, LOG_FLOOR))).sum(),
                     (w * Ys).sum(), (w * np.log(np.maximum(Ys, LOG_FLOOR))).sum(),
                     Y.max(initial=0.0), Ys.max(initial=0.0)])
    return MeterSums(sums)


def reference_goal(Y: np.ndarray, Ys: np.ndarray, spec: MeteringSpec,
                   mask: np.ndarray | None = None) -> tuple[float, float]:
    """(G_rod, G_cone) of a whole frame, float64; percentiles exact (of the
    luminances above the floor); ``mask`` as :func:`weights`."""
    h, w = Y.shape
    if spec.mode == "percentile":
        def pct(L):
            L = np.asarray(L, np.float64)
            L = L[L > LOG_FLOOR]
            return float(np.percentile(L, spec.percentile)) if L.size else 0.0
        return pct(Ys), pct(Y)
    return reference_sums(Y, Ys, spec, w, h, 0, mask).goal(spec)


def block_sums(rgb: np.ndarray, s: int, y0: int = 0) -> tuple[np.ndarray, int]:
    """Sums of rgb and pixel counts over the s x s blocks of the full frame that rows
    ``y0 ..`` of it reach (the reference of ``metering.cl:block_sums``): returns
    (nb x bw x 4 array of (r, g, b, count), first block row)."""
    rgb = np.asarray(rgb, np.float64)[..., :3]
    rows, w = rgb.shape[:2]
    by0, by1 = y0 // s, (y0 + rows - 1) // s + 1
    bw = -(-w // s)
    out = np.zeros((by1 - by0, bw, 4))
    ys = (np.arange(rows) + y0) // s - by0
    xs = np.arange(w) // s
    col = np.zeros((rows, bw, 3))
    np.add.at(col, (slice(None), xs), rgb)           # along x: rows x bw
    cnt = np.bincount(xs, minlength=bw).astype(np.float64)
    for k in range(by1 - by0):
        sel = ys == k
        out[k, :, :3] = col[sel].sum(axis=0)
        out[k, :, 3] = cnt * int(sel.sum())
    return out, by0


#: The plan's proxy is held as 16-bit log2 codes (a device sends it down with the
#: metering's sums, 6 bytes a block: ``metering.cl:block_means_log16``): 0 for 0, else
#: 1 + round(LOG16_STEPS (log2 m + LOG16_OFFSET)) within 1..65535, i.e. 2^-64 .. 2^64
#: cd/m^2 in steps of 2^(1/512) (0.07 % at most). Every backend and path holds it so.
LOG16_STEPS, LOG16_OFFSET = 512, 64


def log16_encode(m: np.ndarray) -> np.ndarray:
    m = np.asarray(m, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        code = np.rint(LOG16_STEPS * (np.log2(np.where(m > 0, m, 1.0)) + LOG16_OFFSET) + 1.0)
    return np.where(m > 0, np.clip(code, 1, 65535), 0).astype(np.uint16)


def log16_decode(codes: np.ndarray) -> np.ndarray:
    c = np.asarray(codes).astype(np.float64)
    return np.where(c > 0, np.exp2((c - 1.0) / LOG16_STEPS - LOG16_OFFSET), 0.0)


def block_means(rgb: np.ndarray, s: int) -> np.ndarray:
    """The frame's proxy: the means of its s x s blocks (the last ones partial), held
    as :func:`log16_encode` codes."""
    sums, _ = block_sums(rgb, s)
    return log16_decode(log16_encode(sums[..., :3] / np.maximum(sums[..., 3:], 1.0)))
