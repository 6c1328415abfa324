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
* :class:`DeviceBilateral` ``exact`` -- the same brute force in float32 OpenCL;
* :class:`DeviceBilateral` ``fast`` -- a bilateral grid (Paris & Durand 2006;
  Chen, Paris & Durand 2007) on z = ln I (ratio) or z = v (difference), with
  grid spacing sigma_s / q_s in space and sigma_z / q_r in z. ``q_s``, ``q_r``
  are the speed/accuracy knob (benchmarks/bench_bilateral.py measures it).

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
    fw = spatial_weights(sigma_s)
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


# --- the bilateral grid, shared geometry ---------------------------------------------

@dataclass(frozen=True)
class GridGeometry:
    """Sampling of the bilateral grid for one image and one signal range."""

    s_s: float        # spatial spacing, pixels
    s_r: float        # z spacing
    z0: float         # z of bin 0
    gw: int
    gh: int
    nz: int
    sigma_blur_s: float   # Gaussian blur in cells (after tent compensation)
    z_scale: float        # range kernel stretch compensating the tents

    @property
    def cells(self) -> int:
        return self.gw * self.gh * self.nz

    @property
    def nbytes(self) -> int:
        return self.cells * 8


def grid_geometry(width: int, height: int, z_min: float, z_max: float, sigma_s: float,
                  rk: RangeKernel, q_s: float, q_r: float) -> GridGeometry:
    """Grid spacing sigma_s/q_s (>= 1 px) and sigma_z/q_r; blur widths compensated
    for the variance (1/6 cell^2 each) that tent splatting and trilinear slicing add."""
    s_s = max(sigma_s / q_s, 1.0)
    sz = rk.z_width()
    s_r = sz / q_r
    if not (math.isfinite(z_min) and math.isfinite(z_max)) or z_max < z_min:
        z_min = z_max = 0.0
    gw = int(math.floor((width - 1) / s_s)) + 2
    gh = int(math.floor((height - 1) / s_s)) + 2
    nz = int(math.floor((z_max - z_min) / s_r)) + 2
    var_s = (sigma_s / s_s) ** 2 - 1.0 / 3.0
    sb = math.sqrt(max(var_s, 0.0))
    var_z = sz ** 2 - s_r ** 2 / 3.0
    z_scale = sz / math.sqrt(var_z) if var_z > 0 else 1.0
    return GridGeometry(s_s, s_r, z_min, gw, gh, nz, sb, z_scale)


def blur_taps_spatial(g: GridGeometry) -> np.ndarray:
    if g.sigma_blur_s <= 1e-6:
        return np.ones(1, np.float32)
    R = int(math.ceil(SUPPORT * g.sigma_blur_s))
    k = np.arange(-R, R + 1, dtype=np.float64)
    return np.exp(-0.5 * (k / g.sigma_blur_s) ** 2).astype(np.float32)


def blur_taps_range(g: GridGeometry, rk: RangeKernel) -> np.ndarray:
    lo, hi = rk.z_extent()
    R = int(math.ceil(max(-lo, hi) * g.z_scale / g.s_r))
    k = np.arange(-R, R + 1, dtype=np.float64)
    return rk.weight_of_dz(k * g.s_r / g.z_scale).astype(np.float32)


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
    def parse(cls, method: str, sampling: str | None = None) -> "BilateralSpec":
        if sampling:
            try:
                parts = [float(x) for x in sampling.split(",")]
                q_s, q_r = (parts[0], parts[-1])
            except ValueError:
                raise ValueError(f"bad --bilateral-sampling {sampling!r}: use Q or QS,QR") from None
            return cls(method, q_s, q_r)
        return cls(method)


class DeviceBilateral:
    """The bilateral filter on an OpenCL runtime (kernels/bilateral.cl)."""

    #: Largest grid, as a fraction of device global memory.
    GRID_MEMORY_FRACTION = 0.25

    def __init__(self, rt):
        import pyopencl as cl
        self.rt = rt
        self._exact = rt.kernel("bilateral.cl", "bilateral_exact")
        self._minmax = rt.kernel("bilateral.cl", "z_minmax")
        self._splat = rt.kernel("bilateral.cl", "grid_splat")
        self._blur = rt.kernel("bilateral.cl", "grid_blur")
        self._slice = rt.kernel("bilateral.cl", "grid_slice")
        self._zmap = rt.kernel("bilateral.cl", "grid_z_map")
        self._zbuf = None
        self._cl = cl
        self._grid = None
        self._grid_bytes = 0
        self._mm = None

    # -- helpers -------------------------------------------------------------
    def _const(self, arr: np.ndarray):
        cl = self._cl
        return cl.Buffer(self.rt.context, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                         hostbuf=np.ascontiguousarray(arr, np.float32))

    def choose(self, spec: BilateralSpec, sigma_s: float, width: int, height: int) -> str:
        if spec.method != "auto":
            return spec.method
        if sigma_s <= spec.AUTO_EXACT_SIGMA:
            return "exact"
        # Worst-case grid (z spanning the whole float range of the signal is
        # rare; 300 bins ~ 20 decades at the default sampling).
        s_s = max(sigma_s / spec.q_s, 1.0)
        cells = ((width - 1) / s_s + 2) * ((height - 1) / s_s + 2) * 300
        if cells * 8 * 2 > self.GRID_MEMORY_FRACTION * self.rt.global_mem_bytes():
            return "exact"
        return "fast"

    # -- exact -----------------------------------------------------------------
    def exact(self, v_buf, out_buf, width: int, rows_in: int, in_y0: int, out_y0: int,
              rows_out: int, sigma_s: float, rk: RangeKernel):
        """Brute-force filter of rows [out_y0, out_y0+rows_out) from a buffer
        holding image rows [in_y0, in_y0+rows_in) (which must include the
        rows within ceil(3 sigma_s) that exist)."""
        from .runtime import round_up
        fw = spatial_weights(sigma_s)
        r = len(fw) - 1
        gx = -(-width // 4)
        wg = (16, 4)
        self._exact(self.rt.queue, (round_up(gx, wg[0]), round_up(rows_out, wg[1])), wg,
                    v_buf, np.int32(width), np.int32(rows_in), np.int32(in_y0),
                    np.int32(out_y0), np.int32(rows_out), self._const(fw), np.int32(r),
                    np.float32(rk.k), np.int32(1 if rk.ratio else 0), out_buf)

    # -- grid ------------------------------------------------------------------
    def z_range(self, v_buf, n: int, rk: RangeKernel) -> tuple[float, float]:
        """Min and max of z over n values (device reduction, host finishes)."""
        from .runtime import round_up
        cl = self._cl
        wg, groups = 64, 64
        if self._mm is None:
            self._mm = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, groups * 2 * 4)
        gsz = min(round_up(max(n, 1), wg), wg * groups)
        self._minmax(self.rt.queue, (gsz,), (wg,), v_buf, np.int32(n),
                     np.int32(1 if rk.ratio else 0), self._mm, cl.LocalMemory(2 * wg * 4))
        part = np.empty(2 * (gsz // wg), np.float32)
        cl.enqueue_copy(self.rt.queue, part, self._mm)
        return float(part[0::2].min()), float(part[1::2].max())

    def begin_grid(self, geom: GridGeometry):
        """Allocate (if needed) and zero the grid and its blur scratch."""
        cl = self._cl
        need = geom.nbytes
        if self._grid is None or self._grid_bytes < need:
            self._grid = [cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, max(need, 8))
                          for _ in range(2)]
            self._grid_bytes = need
        cl.enqueue_fill_buffer(self.rt.queue, self._grid[0], np.float32(0), 0, need)

    def splat(self, v_buf, width: int, rows_in: int, in_y0: int, geom: GridGeometry,
              rk: RangeKernel):
        """Add the pixels of one band (image rows [in_y0, in_y0+rows_in)) to the grid."""
        from .runtime import round_up
        cy_lo = max(0, int(math.floor(in_y0 / geom.s_s)) - 1)
        cy_hi = min(geom.gh - 1, int(math.floor((in_y0 + rows_in - 1) / geom.s_s)) + 1)
        ncy = cy_hi - cy_lo + 1
        n = width * rows_in
        cl = self._cl
        if self._zbuf is None or self._zbuf.size < n * 4:
            self._zbuf = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, max(n * 4, 16))
        self._zmap(self.rt.queue, (round_up(-(-n // 4), 64),), (64,), v_buf, np.int32(n),
                   np.int32(1 if rk.ratio else 0), self._zbuf)
        wg = (16, 1)
        self._splat(self.rt.queue, (round_up(geom.gw, wg[0]), ncy), wg,
                    v_buf, np.int32(width), np.int32(rows_in), np.int32(in_y0),
                    np.int32(1 if rk.ratio else 0), np.float32(geom.s_s), np.float32(geom.z0),
                    np.float32(1.0 / geom.s_r), np.int32(geom.gw), np.int32(cy_lo),
                    np.int32(geom.nz), self._grid[0], self._zbuf)

    def blur(self, geom: GridGeometry, rk: RangeKernel):
        """Blur the grid: Gaussian in x and y, the range kernel in z. Result in grid[0]."""
        from .runtime import round_up
        ts_arr, tz_arr = blur_taps_spatial(geom), blur_taps_range(geom, rk)
        ts, tz = self._const(ts_arr), self._const(tz_arr)
        Rs, Rz = (len(ts_arr) - 1) // 2, (len(tz_arr) - 1) // 2
        gsize = (round_up(geom.nz, 16), geom.gw, geom.gh)
        src, dst = self._grid
        for axis, taps, R in ((2, tz, Rz), (0, ts, Rs), (1, ts, Rs)):
            self._blur(self.rt.queue, gsize, (16, 1, 1), src, dst, np.int32(geom.gw),
                       np.int32(geom.gh), np.int32(geom.nz), np.int32(axis), taps, np.int32(R))
            src, dst = dst, src
        self._grid = [src, dst]

    def slice(self, v_buf, out_buf, width: int, rows_in: int, in_y0: int, out_y0: int,
              rows_out: int, geom: GridGeometry, rk: RangeKernel):
        from .runtime import round_up
        wg = (64, 1)
        self._slice(self.rt.queue, (round_up(width, wg[0]), rows_out), wg,
                    v_buf, np.int32(width), np.int32(rows_in), np.int32(in_y0),
                    np.int32(out_y0), np.int32(rows_out), np.int32(1 if rk.ratio else 0),
                    np.float32(geom.s_s), np.float32(geom.z0), np.float32(1.0 / geom.s_r),
                    np.int32(geom.gw), np.int32(geom.gh), np.int32(geom.nz), self._grid[0],
                    out_buf)

    def grid_limit_bytes(self) -> int:
        return int(min(self.rt.max_alloc_bytes(),
                       self.GRID_MEMORY_FRACTION * self.rt.global_mem_bytes()))

    def fit_geometry(self, width: int, height: int, z_min: float, z_max: float, sigma_s: float,
                     rk: RangeKernel, q_s: float, q_r: float) -> GridGeometry:
        """grid_geometry, coarsened (q_s, then q_r, down to 0.5) until the grid fits
        in GRID_MEMORY_FRACTION of device memory; ValueError if it never does."""
        limit = self.grid_limit_bytes()
        while True:
            g = grid_geometry(width, height, z_min, z_max, sigma_s, rk, q_s, q_r)
            if g.nbytes <= limit:
                return g
            if q_s > 0.5:
                q_s = max(0.5, q_s / 1.25)
            elif q_r > 0.5:
                q_r = max(0.5, q_r / 1.25)
            else:
                raise ValueError(f"bilateral grid needs {g.nbytes / 2**20:.0f} MiB even at the "
                                 f"coarsest sampling; use the exact filter")

    def fast(self, v_buf, out_buf, width: int, height: int, sigma_s: float, rk: RangeKernel,
             q_s: float = 2.0, q_r: float = 2.0) -> GridGeometry:
        """Whole-frame grid filter (signal resident in one buffer)."""
        z_min, z_max = self.z_range(v_buf, width * height, rk)
        geom = self.fit_geometry(width, height, z_min, z_max, sigma_s, rk, q_s, q_r)
        self.begin_grid(geom)
        self.splat(v_buf, width, height, 0, geom, rk)
        self.blur(geom, rk)
        self.slice(v_buf, out_buf, width, height, 0, 0, height, geom, rk)
        return geom

    def filter_banded(self, v: np.ndarray, sigma_s: float, rk: RangeKernel, method: str,
                      max_pixels: int, q_s: float = 2.0, q_r: float = 2.0) -> np.ndarray:
        """Filter a host 2-D array too large for the device in row bands of at most
        ``max_pixels``: exact bands carry ceil(3 sigma) halo rows; the grid gathers
        the frame's z range, splats band by band and slices band by band. The
        result equals the one-band filter (tested)."""
        cl = self._cl
        v = np.ascontiguousarray(prepare_signal(v, rk), np.float32)
        h, w = v.shape
        halo = spatial_radius(sigma_s) if method == "exact" else 0
        rows = max(1, min(h, max_pixels // max(w, 1) - 2 * halo))
        bands = [(y0, min(rows, h - y0)) for y0 in range(0, h, rows)]
        mf = cl.mem_flags
        out = np.empty_like(v)

        def upload(a, b):
            return cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR,
                             hostbuf=np.ascontiguousarray(v[a:b]))
        geom = None
        if method != "exact":
            lo, hi = np.inf, -np.inf
            for y0, nr in bands:
                zl, zh = self.z_range(upload(y0, y0 + nr), nr * w, rk)
                lo, hi = min(lo, zl), max(hi, zh)
            geom = self.fit_geometry(w, h, lo, hi, sigma_s, rk, q_s, q_r)
            self.begin_grid(geom)
            for y0, nr in bands:
                self.splat(upload(y0, y0 + nr), w, nr, y0, geom, rk)
            self.blur(geom, rk)
        for y0, nr in bands:
            a, b = max(0, y0 - halo), min(h, y0 + nr + halo)
            vb = upload(a, b)
            ob = cl.Buffer(self.rt.context, mf.READ_WRITE, nr * w * 4)
            if method == "exact":
                self.exact(vb, ob, w, b - a, a, y0, nr, sigma_s, rk)
            else:
                self.slice(vb, ob, w, b - a, a, y0, nr, geom, rk)
            cl.enqueue_copy(self.rt.queue, out[y0:y0 + nr], ob)
        return out

    def filter(self, v: np.ndarray, sigma_s: float, rk: RangeKernel = LEDDA_RANGE,
               method: str = "exact", q_s: float = 2.0, q_r: float = 2.0) -> np.ndarray:
        """Convenience: filter a host 2-D array (uploads, filters, downloads)."""
        cl = self._cl
        v = np.ascontiguousarray(prepare_signal(v, rk), np.float32)
        h, w = v.shape
        mf = cl.mem_flags
        vb = cl.Buffer(self.rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=v)
        ob = cl.Buffer(self.rt.context, mf.READ_WRITE, v.nbytes)
        if method == "exact":
            self.exact(vb, ob, w, h, 0, 0, h, sigma_s, rk)
        else:
            self.fast(vb, ob, w, h, sigma_s, rk, q_s, q_r)
        out = np.empty_like(v)
        cl.enqueue_copy(self.rt.queue, out, ob)
        return out
