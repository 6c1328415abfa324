"""The bilateral filter on an OpenCL runtime (kernels/bilateral.cl): brute force
and the bilateral grid (Paris & Durand 2006; Chen, Paris & Durand 2007).

The float64 reference is ``models/bilateral.py``; which of the two runs, and at
what grid sampling, is the operator's option (``models/bilateral.py`` ``BilateralSpec``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...models.bilateral import (LEDDA_RANGE, SUPPORT, RangeKernel, prepare_signal,
                                 spatial_radius, spatial_weights)
from ...models.bilateral import BilateralSpec
from ..bands import row_bands
from .runtime import round_up
from .stats import statistics
from .transfers import ConstantBuffers, host_buffer, transfer

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


#: z_range over values that are z already (the z buffer): no log taken again.
Z_IDENTITY = RangeKernel("difference", 1.0)


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


class DeviceBilateral:
    """The bilateral filter on an OpenCL runtime (kernels/bilateral.cl)."""

    #: Largest grid, as a fraction of device global memory.
    GRID_MEMORY_FRACTION = 0.25

    def __init__(self, rt):
        import pyopencl as cl
        self.rt = rt
        self._consts = ConstantBuffers(rt.context)
        self._exact = rt.kernel("bilateral.cl", "bilateral_exact")
        self._minmax = rt.kernel("bilateral.cl", "z_minmax")
        self._minmax_final = rt.kernel("bilateral.cl", "z_minmax_final")
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
        return self._consts.get(np.asarray(arr, np.float32))

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
              rows_out: int, sigma_s: float, rk: RangeKernel, gate=None):
        """Brute-force filter of rows [out_y0, out_y0+rows_out) from a buffer
        holding image rows [in_y0, in_y0+rows_in) (which must include the
        rows within ceil(3 sigma_s) that exist)."""
        fw = spatial_weights(sigma_s)
        fw = fw[:max(width, rows_in)]         # offsets past the image add nothing
        r = len(fw) - 1
        gx = -(-width // 4)
        wg = (16, 4)
        self._exact(self.rt.queue, (round_up(gx, wg[0]), round_up(rows_out, wg[1])), wg,
                    v_buf, np.int32(width), np.int32(rows_in), np.int32(in_y0),
                    np.int32(out_y0), np.int32(rows_out), self._const(fw), np.int32(r),
                    np.float32(rk.k), np.int32(1 if rk.ratio else 0), out_buf, *self._gate(gate))

    # -- grid ------------------------------------------------------------------
    def z_range(self, v_buf, n: int, rk: RangeKernel) -> tuple[float, float]:
        """Min and max of z over n values (a device reduction); ``v_buf`` may be the z
        buffer itself with an identity (difference) kernel ``rk``."""
        return self.z_range_later(v_buf, n, rk)[0]()

    def z_range_later(self, v_buf, n: int, rk: RangeKernel):
        """:meth:`z_range` enqueued: (a function giving (min, max), read with the frame's
        other statistics; the device buffer holding them, a filter's ``gate``)."""
        cl = self._cl
        wg, groups = 64, 64
        if self._mm is None:
            self._mm = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, groups * 2 * 4)
        gsz = min(round_up(max(n, 1), wg), wg * groups)
        self._minmax(self.rt.queue, (gsz,), (wg,), v_buf, np.int32(n),
                     np.int32(1 if rk.ratio else 0), self._mm, cl.LocalMemory(2 * wg * 4))
        out = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, 8)
        self._minmax_final(self.rt.queue, (1,), None, self._mm, np.int32(gsz // wg), out)
        got = statistics(self.rt).put(out, 8, np.float32)
        return (lambda: (float(got.get()[0]), float(got.get()[1]))), out

    def begin_grid(self, geom: GridGeometry):
        """Allocate (if needed) and zero the grid and its blur scratch."""
        cl = self._cl
        need = geom.nbytes
        if self._grid is None or self._grid_bytes < need:
            self._grid = [cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, max(need, 8))
                          for _ in range(2)]
            self._grid_bytes = need
        cl.enqueue_fill_buffer(self.rt.queue, self._grid[0], np.float32(0), 0, need)

    def z_map(self, v_buf, n: int, rk: RangeKernel):
        """z of n values into the z buffer (float4 log2: once per pixel, read by the
        splat, the slice and the min/max); returns the buffer."""
        cl = self._cl
        if self._zbuf is None or self._zbuf.size < n * 4:
            self._zbuf = cl.Buffer(self.rt.context, cl.mem_flags.READ_WRITE, max(n * 4, 16))
        self._zmap(self.rt.queue, (round_up(-(-n // 4), 64),), (64,), v_buf, np.int32(n),
                   np.int32(1 if rk.ratio else 0), self._zbuf)
        return self._zbuf

    def splat(self, v_buf, width: int, rows_in: int, in_y0: int, geom: GridGeometry,
              rk: RangeKernel, z_ready: bool = False):
        """Add the pixels of one band (image rows [in_y0, in_y0+rows_in)) to the grid
        (``z_ready``: the z buffer holds this band's z already)."""
        cy_lo = max(0, int(math.floor(in_y0 / geom.s_s)) - 1)
        cy_hi = min(geom.gh - 1, int(math.floor((in_y0 + rows_in - 1) / geom.s_s)) + 1)
        ncy = cy_hi - cy_lo + 1
        if not z_ready:
            self.z_map(v_buf, width * rows_in, rk)
        wg = (16, 1)
        self._splat(self.rt.queue, (round_up(geom.gw, wg[0]), ncy), wg,
                    v_buf, np.int32(width), np.int32(rows_in), np.int32(in_y0),
                    np.int32(1 if rk.ratio else 0), np.float32(geom.s_s), np.float32(geom.z0),
                    np.float32(1.0 / geom.s_r), np.int32(geom.gw), np.int32(cy_lo),
                    np.int32(geom.nz), self._grid[0], self._zbuf)

    def blur(self, geom: GridGeometry, rk: RangeKernel):
        """Blur the grid: Gaussian in x and y, the range kernel in z. Result in grid[0]."""
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
              rows_out: int, geom: GridGeometry, rk: RangeKernel, z_ready: bool = False,
              gate=None):
        if not z_ready:
            self.z_map(v_buf, width * rows_in, rk)
        wg = (64, 1)
        self._slice(self.rt.queue, (round_up(width, wg[0]), rows_out), wg,
                    v_buf, np.int32(width), np.int32(rows_in), np.int32(in_y0),
                    np.int32(out_y0), np.int32(rows_out), np.int32(1 if rk.ratio else 0),
                    np.float32(geom.s_s), np.float32(geom.z0), np.float32(1.0 / geom.s_r),
                    np.int32(geom.gw), np.int32(geom.gh), np.int32(geom.nz), self._grid[0],
                    out_buf, self._zbuf, *self._gate(gate))

    @staticmethod
    def _gate(gate) -> tuple:
        """A filter's gate arguments (kernels/bilateral.cl GATED_OFF): ``gate`` None, or
        (min/max buffer of :meth:`z_range_later`, floor, the rows to write instead)."""
        if gate is None:
            return None, np.float32(0.0), None
        buf, floor, alt = gate
        return buf, np.float32(floor), alt

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
        n = width * height
        z = self.z_map(v_buf, n, rk)                    # z once per pixel, reused below
        z_min, z_max = self.z_range(z, n, Z_IDENTITY)
        geom = self.fit_geometry(width, height, z_min, z_max, sigma_s, rk, q_s, q_r)
        self.begin_grid(geom)
        self.splat(v_buf, width, height, 0, geom, rk, z_ready=True)
        self.blur(geom, rk)
        self.slice(v_buf, out_buf, width, height, 0, 0, height, geom, rk, z_ready=True)
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
        bands = row_bands(h, w, max_pixels, halo)
        mf = cl.mem_flags
        out = np.empty_like(v)

        def upload(a, b):
            return host_buffer(self.rt.context, np.ascontiguousarray(v[a:b]))
        geom = None
        if method != "exact":
            lo, hi = np.inf, -np.inf
            for y0, nr in bands:
                zl, zh = self.z_range(self.z_map(upload(y0, y0 + nr), nr * w, rk), nr * w,
                                      Z_IDENTITY)
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
            transfer(self.rt.queue, out[y0:y0 + nr], ob)
        return out

    def filter(self, v: np.ndarray, sigma_s: float, rk: RangeKernel = LEDDA_RANGE,
               method: str = "exact", q_s: float = 2.0, q_r: float = 2.0) -> np.ndarray:
        """Convenience: filter a host 2-D array (uploads, filters, downloads)."""
        cl = self._cl
        v = np.ascontiguousarray(prepare_signal(v, rk), np.float32)
        h, w = v.shape
        mf = cl.mem_flags
        vb = host_buffer(self.rt.context, v)
        ob = cl.Buffer(self.rt.context, mf.READ_WRITE, v.nbytes)
        if method == "exact":
            self.exact(vb, ob, w, h, 0, 0, h, sigma_s, rk)
        else:
            self.fast(vb, ob, w, h, sigma_s, rk, q_s, q_r)
        out = np.empty_like(v)
        transfer(self.rt.queue, out, ob)
        return out
