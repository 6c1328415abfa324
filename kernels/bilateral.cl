/* Bilateral filtering of a luminance-like signal v (one float per pixel).
 *
 *   J(s) = sum_p f(p - s) g(t(p, s)) v_p / sum_p f(p - s) g(t(p, s))   (Ledda 2004 Eqs. 8-10)
 *
 * f: Gaussian of sigma_s pixels. g(t) = exp(-k_r t^2) on
 *   ratio mode (ratio = 1): t = v_p / v_s - 1, i.e. Ledda's sigma_g = 0.15 * I_s
 *                           (v must be floored > 0 by the caller);
 *   difference mode (0):    t = v_p - v_s, a Gaussian on v (e.g. log luminance,
 *                           Durand & Dorsey 2002).
 * Both depend on z_p - z_s only, with z = ln v (ratio) or z = v (difference):
 * the bilateral grid below lives on that z axis.
 *
 * Two implementations share this interface:
 *   bilateral_exact  brute force over |dx|,|dy| <= radius (the ground truth);
 *   grid_*           bilateral grid (Paris & Durand 2006; Chen, Paris & Durand
 *                    2007): splat, blur, slice.
 * Both work on row bands: input rows [0, rows_in) of a buffer whose first row
 * is image row in_y0; outputs cover image rows [out_y0, out_y0 + rows_out). */

/* A filter gated on the device (issue 47: no read between two passes): with ``gate``
 * (a min/max pair, z_minmax_final) it filters only where gate[0] < gate_floor, and
 * else writes ``alt`` (the same rows of another level) as its output: ledda04's rod
 * levels where the frame's darkest cone level is photopic, decided as the host
 * did, without reading it first. A NULL gate: always filters. */
#define GATED_OFF(gate, gate_floor) ((gate) != 0 && !((gate)[0] < (gate_floor)))

/* ------------------------------------------------------------------ exact */

/* Four horizontally adjacent centres per work-item: for a given (dx, dy) the
 * four taps are contiguous, so the loads are one vload4 and the spatial
 * weight is shared. fw[0..radius]: 1-D Gaussian weights (f is separable). */
__kernel void bilateral_exact(__global const float *v, const int width, const int rows_in,
                              const int in_y0, const int out_y0, const int rows_out,
                              __constant float *fw, const int radius, const float k_r,
                              const int ratio, __global float *out,
                              __global const float *gate, const float gate_floor,
                              __global const float *alt)
{
    const int x0 = get_global_id(0) * 4;
    const int ro = get_global_id(1);
    if (x0 >= width || ro >= rows_out) return;
    if (GATED_OFF(gate, gate_floor)) {
        for (int j = 0; j < min(4, width - x0); ++j)
            out[(size_t)ro * width + x0 + j] = alt[(size_t)ro * width + x0 + j];
        return;
    }
    const int yc = out_y0 + ro - in_y0;               /* centre row in the buffer */
    const int ylo = max(yc - radius, 0), yhi = min(yc + radius, rows_in - 1);
    const int nx = min(4, width - x0);
    float4 vs;
    vs.s0 = v[(size_t)yc * width + x0];
    vs.s1 = nx > 1 ? v[(size_t)yc * width + x0 + 1] : vs.s0;
    vs.s2 = nx > 2 ? v[(size_t)yc * width + x0 + 2] : vs.s0;
    vs.s3 = nx > 3 ? v[(size_t)yc * width + x0 + 3] : vs.s0;
    const float4 a = ratio ? 1.0f / vs : (float4)(1.0f);
    const float4 b = ratio ? (float4)(-1.0f) : -vs;
    float4 num = (float4)(0.0f), den = (float4)(0.0f);
    const bool inner = (x0 - radius >= 0) && (x0 + 3 + radius < width);
    for (int y = ylo; y <= yhi; ++y) {
        const float fy = fw[abs(y - yc)];
        __global const float *row = v + (size_t)y * width;
        if (inner) {
            for (int dx = -radius; dx <= radius; ++dx) {
                float4 vp = vload4(0, row + x0 + dx);
                float4 t = mad(vp, a, b);
                float4 w = (fy * fw[abs(dx)]) * exp(-k_r * t * t);
                num = mad(w, vp, num);
                den += w;
            }
        } else {   /* offsets with no pixel of the four in the row add nothing: skipped */
            const int dlo = max(-radius, -x0 - 3), dhi = min(radius, width - 1 - x0);
            for (int dx = dlo; dx <= dhi; ++dx) {
                const float fxy = fy * fw[abs(dx)];
                float vpa[4], wa[4];
                for (int j = 0; j < 4; ++j) {
                    int xx = x0 + j + dx;
                    bool ok = xx >= 0 && xx < width;
                    vpa[j] = ok ? row[xx] : 0.0f;
                    wa[j] = ok ? fxy : 0.0f;
                }
                float4 vp = (float4)(vpa[0], vpa[1], vpa[2], vpa[3]);
                float4 t = mad(vp, a, b);
                float4 w = (float4)(wa[0], wa[1], wa[2], wa[3]) * exp(-k_r * t * t);
                num = mad(w, vp, num);
                den += w;
            }
        }
    }
    /* den >= 1 (the centre's own weight), so the quotient is finite. */
    const float4 r = num / den;
    __global float *o = out + (size_t)ro * width + x0;
    o[0] = r.s0;
    if (nx > 1) o[1] = r.s1;
    if (nx > 2) o[2] = r.s2;
    if (nx > 3) o[3] = r.s3;
}

/* ------------------------------------------------------------------ grid */

inline float grid_z(float v, int ratio) { return ratio ? log(v) : v; }

/* z of n values once per pixel, four at a time (log2 on float4; the splat then
 * reads z instead of taking a log on each of the ~4 cells that visit a pixel). */
__kernel void grid_z_map(__global const float *v, const int n, const int ratio,
                         __global float *z)
{
    const int q = get_global_id(0), i0 = 4 * q;
    if (i0 >= n) return;
    if (i0 + 4 <= n) {
        const float4 x = vload4(q, v);
        vstore4(ratio ? log2(x) * M_LN2_F : x, q, z);
        return;
    }
    /* the tail the same way (float4, padded), so a pixel's z does not depend on
     * where a band boundary falls */
    float4 x = (float4)(1.0f);
    x.x = v[i0];
    if (i0 + 1 < n) x.y = v[i0 + 1];
    if (i0 + 2 < n) x.z = v[i0 + 2];
    const float4 r = ratio ? log2(x) * M_LN2_F : x;
    z[i0] = r.x;
    if (i0 + 1 < n) z[i0 + 1] = r.y;
    if (i0 + 2 < n) z[i0 + 2] = r.z;
}

/* Per-work-group min and max of z over n values -> partial[2*group + {0,1}]. */
__kernel void z_minmax(__global const float *v, const int n, const int ratio,
                       __global float *partial, __local float *scratch)
{
    const int lid = get_local_id(0), lsz = get_local_size(0);
    /* four values at a time, z as grid_z_map takes it (float4 log2), so the range
     * is that of the z the splat reads */
    float4 lo4 = (float4)(INFINITY), hi4 = (float4)(-INFINITY);
    const int nq = n / 4, gsz = get_global_size(0);
    int qa, qb, qs;
    share_range(nq, &qa, &qb, &qs);
    if (ratio) {
        for (int q = qa; q < qb; q += qs) {
            const float4 z = log2(vload4(q, v)) * M_LN2_F;
            lo4 = fmin(lo4, z);
            hi4 = fmax(hi4, z);
        }
    } else {
        for (int q = qa; q < qb; q += qs) {
            const float4 z = vload4(q, v);
            lo4 = fmin(lo4, z);
            hi4 = fmax(hi4, z);
        }
    }
    for (int i = 4 * nq + get_global_id(0); i < n; i += gsz) {
        const float z = ratio ? log2(v[i]) * M_LN2_F : v[i];
        lo4.x = fmin(lo4.x, z);
        hi4.x = fmax(hi4.x, z);
    }
    float lo = fmin(fmin(lo4.x, lo4.y), fmin(lo4.z, lo4.w));
    float hi = fmax(fmax(hi4.x, hi4.y), fmax(hi4.z, hi4.w));
    scratch[2 * lid] = lo;
    scratch[2 * lid + 1] = hi;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int off = lsz / 2; off > 0; off >>= 1) {
        if (lid < off) {
            scratch[2 * lid] = fmin(scratch[2 * lid], scratch[2 * (lid + off)]);
            scratch[2 * lid + 1] = fmax(scratch[2 * lid + 1], scratch[2 * (lid + off) + 1]);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) {
        partial[2 * get_group_id(0)] = scratch[0];
        partial[2 * get_group_id(0) + 1] = scratch[1];
    }
}

/* The min and max of z_minmax's partials (one work-item): out[0], out[1]. */
__kernel void z_minmax_final(__global const float *partial, const int groups,
                             __global float *out)
{
    if (get_global_id(0) != 0) return;
    float lo = INFINITY, hi = -INFINITY;
    for (int g = 0; g < groups; ++g) {
        lo = fmin(lo, partial[2 * g]);
        hi = fmax(hi, partial[2 * g + 1]);
    }
    out[0] = lo;
    out[1] = hi;
}

/* Splat (gather form, no atomics): grid cell (cx, cy) owns its column of nz
 * bins and adds the pixels of this band that fall in its tent footprint
 * |x/s_s - cx| < 1, |y/s_s - cy| < 1, with trilinear (tent) weights; each
 * pixel's z goes to its two nearest bins. grid: float2 (sum w v, sum w) at
 * ((cy * gw + cx) * nz + iz). Cells cy in [cy0, cy0 + get_global_size(1)). */
__kernel void grid_splat(__global const float *v, const int width, const int rows_in,
                         const int in_y0, const int ratio, const float s_s,
                         const float z0, const float inv_s_r, const int gw, const int cy0,
                         const int nz, __global float2 *grid,
                         __global const float *zv)     /* z of v (grid_z_map) */
{
    const int cx = get_global_id(0), cy = cy0 + get_global_id(1);
    if (cx >= gw) return;
    __global float2 *col = grid + ((size_t)cy * gw + cx) * nz;
    const int xa = max((int)ceil((cx - 1) * s_s), 0);
    const int xb = min((int)floor((cx + 1) * s_s), width - 1);
    const int ya = max((int)ceil((cy - 1) * s_s), in_y0);
    const int yb = min((int)floor((cy + 1) * s_s), in_y0 + rows_in - 1);
    const float inv_s = 1.0f / s_s;
    for (int y = ya; y <= yb; ++y) {
        const float wy = 1.0f - fabs(y * inv_s - cy);
        if (wy <= 0.0f) continue;
        __global const float *row = v + (size_t)(y - in_y0) * width;
        __global const float *zrow = zv + (size_t)(y - in_y0) * width;
        for (int x = xa; x <= xb; ++x) {
            const float wxy = wy * (1.0f - fabs(x * inv_s - cx));
            if (wxy <= 0.0f) continue;
            const float val = row[x];
            float gz = (zrow[x] - z0) * inv_s_r;
            gz = clamp(gz, 0.0f, (float)(nz - 1));
            const int iz = min((int)gz, nz - 2 >= 0 ? nz - 2 : 0);
            const float fz = nz > 1 ? gz - iz : 0.0f;
            col[iz] += (float2)(val, 1.0f) * (wxy * (1.0f - fz));
            if (nz > 1) col[iz + 1] += (float2)(val, 1.0f) * (wxy * fz);
        }
    }
}

/* One separable pass of the grid blur along axis 0 (x), 1 (y) or 2 (z):
 *   dst(c) = sum_{k=-R..R} taps[k + R] * src(c + k e_axis)   (outside = 0)
 * For z this is the range kernel g evaluated at k * s_r: g may be asymmetric
 * (ratio mode), and the correlation form pairs bin z_s with bins z_s + k. */
__kernel void grid_blur(__global const float2 *src, __global float2 *dst,
                        const int gw, const int gh, const int nz, const int axis,
                        __constant float *taps, const int R)
{
    const int iz = get_global_id(0), cx = get_global_id(1), cy = get_global_id(2);
    if (iz >= nz || cx >= gw || cy >= gh) return;
    const int pos = axis == 0 ? cx : (axis == 1 ? cy : iz);
    const int len = axis == 0 ? gw : (axis == 1 ? gh : nz);
    const size_t stride = axis == 0 ? (size_t)nz : (axis == 1 ? (size_t)gw * nz : 1);
    const size_t base = ((size_t)cy * gw + cx) * nz + iz;
    float2 acc = (float2)(0.0f);
    const int ka = max(-R, -pos), kb = min(R, len - 1 - pos);
    for (int k = ka; k <= kb; ++k)
        acc += taps[k + R] * src[base + (long)k * (long)stride];
    dst[base] = acc;
}

/* Slice: trilinear interpolation of the blurred grid at each pixel's
 * (x/s_s, y/s_s, z); output = interpolated sum(w v) / sum(w). z: the pixels' z
 * (grid_z_map, laid out as v), the same values the splat used. */
__kernel void grid_slice(__global const float *v, const int width, const int rows_in,
                         const int in_y0, const int out_y0, const int rows_out,
                         const int ratio, const float s_s, const float z0,
                         const float inv_s_r, const int gw, const int gh, const int nz,
                         __global const float2 *grid, __global float *out,
                         __global const float *zv, __global const float *gate,
                         const float gate_floor, __global const float *alt)
{
    const int x = get_global_id(0), ro = get_global_id(1);
    if (x >= width || ro >= rows_out) return;
    if (GATED_OFF(gate, gate_floor)) {
        out[(size_t)ro * width + x] = alt[(size_t)ro * width + x];
        return;
    }
    const int y = out_y0 + ro;
    const size_t iv = (size_t)(y - in_y0) * width + x;
    const float val = v[iv];
    const float inv_s = 1.0f / s_s;
    const float gx = x * inv_s, gy = y * inv_s;
    const int ix = min((int)gx, gw - 2 >= 0 ? gw - 2 : 0);
    const int iy = min((int)gy, gh - 2 >= 0 ? gh - 2 : 0);
    const float fx = gw > 1 ? gx - ix : 0.0f, fy = gh > 1 ? gy - iy : 0.0f;
    float gz = clamp((zv[iv] - z0) * inv_s_r, 0.0f, (float)(nz - 1));
    const int iz = min((int)gz, nz - 2 >= 0 ? nz - 2 : 0);
    const float fz = nz > 1 ? gz - iz : 0.0f;
    const int dx = gw > 1 ? nz : 0, dy = gh > 1 ? gw * nz : 0, dz = nz > 1 ? 1 : 0;
    __global const float2 *c = grid + ((size_t)iy * gw + ix) * nz + iz;
    float2 c00 = mix(c[0], c[dz], fz), c01 = mix(c[dx], c[dx + dz], fz);
    float2 c10 = mix(c[dy], c[dy + dz], fz), c11 = mix(c[dy + dx], c[dy + dx + dz], fz);
    float2 r = mix(mix(c00, c01, fx), mix(c10, c11, fx), fy);
    /* A pixel always splats into the cells around it, so r.y > 0 up to
     * rounding; fall back to the pixel itself if it underflows. */
    out[(size_t)ro * width + x] = r.y > 1e-20f ? r.x / r.y : val;
}
