"""Edge-preserving (bilateral) filtering of luminance, exact and fast.

    J(s) = sum_p f(p - s) g(I_p, I_s) I_p / k(s)      Ledda et al. 2004, Eqs. 8-10

f is a Gaussian of ``sigma_spatial`` pixels. Two range kernels g:

``ratio`` (Ledda 2004, Eq. 10 with sigma_g = 0.15 * I_s):
    g = exp(-(I_p - I_s)^2 / (2 (0.15 I_s)^2)) = exp(-(I_p/I_s - 1)^2 / (2 * 0.15^2)).
    It depends only on ln I_p - ln I_s, so on a log-luminance axis it is a
    fixed (slightly asymmetric) kernel -- which is what the bilateral grid needs.
``difference`` (Durand & Dorsey 2002 on log luminance):
    g = exp(-(v_p - v_s)^2 / (2 sigma^2)) for a signal v that is already a log.

Implementations with one interface:

* :func:`bilateral_reference` -- float64 brute force over |dx|, |dy| <= ceil(3 sigma_s):
  the ground truth;
* ``backends/opencl/bilateral.py`` -- the same brute force in float32 OpenCL, and a
  bilateral grid (Paris & Durand 2006; Chen, Paris & Durand 2007) on z = ln I
  (ratio) or z = v (difference), with grid spacing sigma_s / q_s in space and
  sigma_z / q_r in z. ``q_s``, ``q_r`` are the speed/accuracy knob of the
  per-frame choice (:class:`BilateralSpec`, ``auto``; benchmarks/bench_bilateral.py measures it).

Units: the signal is whatever is filtered (cd/m^2 for Ledda's I_A; log
luminance for range reduction); sigma_spatial in pixels.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

#: Ledda 2004 Sec. 4.2: sigma_g = 0.15 * I_s.
LEDDA_SIGMA_RELATIVE = 0.15
#: Floor applied to a ratio-mode signal (cd/m^2): log and ratio need v > 0.
#: Far below the absolute threshold of vision (~1e-6 cd/m^2).
V_FLOOR = 1.0e-10
#: Spatial support of the exact filter, in sigma_s.
SUPPORT = 3.0


@dataclass(frozen=True)
class RangeKernel:
    """The range (edge-stopping) kernel g.

    kind  : ``"ratio"`` (relative width ``sigma`` of I_s, Ledda) or
            ``"difference"`` (absolute width ``sigma`` in units of the signal).
    sigma : 0.15 for Ledda; e.g. 0.4 * ln(10) for Durand & Dorsey 2002 on ln Y.
    """

    kind: str = "ratio"
    sigma: float = LEDDA_SIGMA_RELATIVE

    def __post_init__(self):
        if self.kind not in ("ratio", "difference"):
            raise ValueError(f"range kernel kind must be ratio or difference (got {self.kind!r})")
        if not (self.sigma > 0 and math.isfinite(self.sigma)):
            raise ValueError(f"range sigma must be > 0 (got {self.sigma})")

    @property
    def ratio(self) -> bool:
        return self.kind == "ratio"

    @property
    def k(self) -> float:
        """g = exp(-k t^2)."""
        return 1.0 / (2.0 * self.sigma ** 2)

    def weight_of_dz(self, dz):
        """g as a function of dz = z_p - z_s on the grid's z axis (float64)."""
        dz = np.asarray(dz, np.float64)
        t = np.expm1(dz) if self.ratio else dz
        return np.exp(-self.k * t * t)

    def z_width(self) -> float:
        """Standard deviation of g along z (for ratio: of exp(-k (e^dz - 1)^2), numerically)."""
        return _z_width(self)

    def _z_width(self) -> float:
        if not self.ratio:
            return self.sigma
        d = np.linspace(-12 * self.sigma, 12 * self.sigma, 20001)
        w = self.weight_of_dz(d)
        m = (w * d).sum() / w.sum()
        return float(math.sqrt((w * (d - m) ** 2).sum() / w.sum()))

    def z_extent(self, eps: float = 1e-4) -> tuple[float, float]:
        """dz range outside which g < eps."""
        if not self.ratio:
            r = self.sigma * math.sqrt(2.0 * math.log(1.0 / eps))
            return -r, r
        t = self.sigma * math.sqrt(2.0 * math.log(1.0 / eps))
        lo = math.log(1.0 - t) if t < 1.0 else -50.0
        return lo, math.log1p(t)


@functools.lru_cache(maxsize=16)
def _z_width(rk: RangeKernel) -> float:
    return rk._z_width()


LEDDA_RANGE = RangeKernel("ratio", LEDDA_SIGMA_RELATIVE)


def spatial_radius(sigma_s: float) -> int:
    return max(0, int(math.ceil(SUPPORT * sigma_s)))


def spatial_weights(sigma_s: float) -> np.ndarray:
    """1-D Gaussian weights f(d), d = 0..radius (unnormalised; f is separable)."""
    r = spatial_radius(sigma_s)
    d = np.arange(r + 1, dtype=np.float64)
    return np.exp(-0.5 * (d / sigma_s) ** 2) if sigma_s > 0 else np.ones(1)


def prepare_signal(v: np.ndarray, rk: RangeKernel) -> np.ndarray:
    """Ratio mode filters max(v, V_FLOOR) (ratios and logs need v > 0)."""
    v = np.asarray(v, np.float64)
    return np.maximum(v, V_FLOOR) if rk.ratio else v


def bilateral_reference(v: np.ndarray, sigma_s: float, rk: RangeKernel = LEDDA_RANGE) -> np.ndarray:
    """Float64 brute-force bilateral filter of a 2-D signal (Ledda Eqs. 8-10).

    Neighbours outside the image are left out (k(s) renormalises). Ratio mode
    filters max(v, V_FLOOR). Returns float64 of v's shape.
    """
    v = prepare_signal(v, rk)
    h, w = v.shape
    fw = spatial_weights(sigma_s)[:max(h, w)]      # offsets past the image add nothing
    r = len(fw) - 1
    pad = np.pad(v, r, mode="constant", constant_values=np.nan)
    num = np.zeros_like(v)
    den = np.zeros_like(v)
    a = 1.0 / v if rk.ratio else 1.0
    b = -1.0 if rk.ratio else -v
    with np.errstate(over="ignore", invalid="ignore"):
        for dy in range(-r, r + 1):
            for dx in range(-r, r + 1):
                vp = pad[r + dy:r + dy + h, r + dx:r + dx + w]
                t = vp * a + b
                wgt = fw[abs(dy)] * fw[abs(dx)] * np.exp(-rk.k * t * t)
                ok = ~np.isnan(vp)
                num += np.where(ok, wgt * vp, 0.0)
                den += np.where(ok, wgt, 0.0)
    return num / den


@dataclass(frozen=True)
class BilateralSpec:
    """How to filter: ``method`` exact | fast | auto, sigma_s in pixels, grid sampling.

    ``auto`` uses the exact filter when it is cheap (sigma_s <= AUTO_EXACT_SIGMA
    px: on PoCL the grid is slower than brute force at sigma_s = 4 px and 37x
    faster at 12.8, see benchmarks/results/bilateral_ledda04.md) or the grid
    would not fit in memory, and the grid otherwise.
    """

    method: str = "auto"
    q_s: float = 2.0
    q_r: float = 2.0

    AUTO_EXACT_SIGMA = 5.0

    def __post_init__(self):
        if self.method not in ("exact", "fast", "auto"):
            raise ValueError(f"bilateral method must be exact, fast or auto (got {self.method!r})")
        if not (self.q_s >= 0.5 and self.q_r >= 0.5):
            raise ValueError("bilateral sampling rates must be >= 0.5")

    @classmethod
    def parse(cls, method: str, sampling=None) -> "BilateralSpec":
        """``sampling``: (Q,) or (QS, QR), or their text ``Q[,QR]``."""
        if sampling:
            try:
                parts = [float(x) for x in (sampling.split(",") if isinstance(sampling, str)
                                            else sampling)]
                q_s, q_r = (parts[0], parts[-1])
            except (ValueError, IndexError):
                raise ValueError(f"bad --bilateral-sampling {sampling!r}: use Q or QS,QR") from None
            return cls(method, q_s, q_r)
        return cls(method)
