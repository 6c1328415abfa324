/* The fast flare (Spencer et al. 1995 as Durand & Dorsey 2000, Sec. 6 use it)
 * on the device: the source part, the pyramid's [1 3 3 1]/8 decimation and
 * bilinear upsampling, the level Gaussians (zero outside each level's
 * samples), and the flared frame. Pixels are float4 (r, g, b, 0); a level's
 * samples include its margins. Reference: ocl_tonemap/models/spencer1995.py
 * (source_part) and ocl_tonemap/backends/flare_exec.py (_down_axis, _up_axis,
 * convolve_fast). */

/* S = rgb max(0, 1 - lim / Y) of pixel i: the part above ``lim`` cd/m^2. */
inline float4 source_part(__global const float *rgb, const size_t i, const float lim)
{
    const float r = rgb[3 * i], g = rgb[3 * i + 1], b = rgb[3 * i + 2];
    const float Y = M_YR * r + M_YG * g + M_YB * b;
    if (!(Y > lim)) return (float4)(0.0f);
    const float f = 1.0f - lim / Y;
    return (float4)(r * f, g * f, b * f, 0.0f);
}

/* S of every pixel. partial: per group (sum of S r, g, b, number of source pixels). */
__kernel void flare_source(__global const float *rgb, const int n, const float lim,
                           __global float4 *S, __global float4 *partial,
                           __local float4 *scratch)
{
    const int i = get_global_id(0);
    float4 s = (float4)(0.0f);
    if (i < n) {
        s = source_part(rgb, (size_t)i, lim);
        S[i] = s;
    }
    const int src = (s.x != 0.0f || s.y != 0.0f || s.z != 0.0f);
    group_sum4(scratch, (float4)(s.x, s.y, s.z, (float)src), partial);
}

/* One level up: coarse (j, k) = sum over the 4 x 4 fine samples 2j-1..2j+2,
 * 2k-1..2k+2 with weights [1 3 3 1]/8 per axis; fine samples outside the
 * stored ones are 0. Sizes are the stored ones; fm, cm: the margins. */
__kernel void flare_down(__global const float4 *fine, const int fw, const int fh, const int fm,
                         __global float4 *coarse, const int cw, const int ch, const int cm)
{
    const int K = get_global_id(0), J = get_global_id(1);
    if (K >= cw || J >= ch) return;
    const int y0 = 2 * (J - cm) - 1 + fm, x0 = 2 * (K - cm) - 1 + fm;
    const float wt[4] = {1.0f, 3.0f, 3.0f, 1.0f};
    float4 acc = (float4)(0.0f);
    for (int t = 0; t < 4; ++t) {
        const int y = y0 + t;
        if (y < 0 || y >= fh) continue;
        __global const float4 *row = fine + (size_t)y * fw;
        float4 rs = (float4)(0.0f);
        for (int u = 0; u < 4; ++u) {
            const int x = x0 + u;
            if (x >= 0 && x < fw) rs += wt[u] * row[x];
        }
        acc += wt[t] * rs;
    }
    coarse[(size_t)J * cw + K] = acc * (1.0f / 64.0f);
}

/* Level 1 straight from the frame (the fused path: level 0's S is never stored
 * whole): flare_down's [1 3 3 1]/8 sums of S made from rgb (w x h, no margin) as they
 * are read; each coarse sample's own 2 x 2 fine pixels (its footprint's middle) go
 * to the group's sums as flare_source's do: partial[group] (S r, g, b, sources), and
 * to occ[coarse sample]: 1 where one of them is a source (level 0's tiles:
 * flare_tiles). */
__kernel void flare_down_src(__global const float *rgb, const int w, const int h,
                             const float lim, __global float4 *coarse, const int cw,
                             const int ch, const int cm, __global uchar *occ,
                             __global float4 *partial, __local float4 *scratch)
{
    const int K = get_global_id(0), J = get_global_id(1);
    float4 own = (float4)(0.0f);
    if (K < cw && J < ch) {
        const int y0 = 2 * (J - cm) - 1, x0 = 2 * (K - cm) - 1;
        const float wt[4] = {1.0f, 3.0f, 3.0f, 1.0f};
        float4 acc = (float4)(0.0f);
        for (int t = 0; t < 4; ++t) {
            const int y = y0 + t;
            if (y < 0 || y >= h) continue;
            float4 rs = (float4)(0.0f);
            for (int u = 0; u < 4; ++u) {
                const int x = x0 + u;
                if (x < 0 || x >= w) continue;
                const float4 v = source_part(rgb, (size_t)y * w + x, lim);
                rs += wt[u] * v;
                if (t == 1 || t == 2) {
                    if (u == 1 || u == 2)
                        own += (float4)(v.x, v.y, v.z,
                                        (v.x != 0.0f || v.y != 0.0f || v.z != 0.0f) ? 1.0f : 0.0f);
                }
            }
            acc += wt[t] * rs;
        }
        coarse[(size_t)J * cw + K] = acc * (1.0f / 64.0f);
        occ[(size_t)J * cw + K] = own.w != 0.0f;
    }
    group_sum4_into(scratch, own, get_local_id(1) * get_local_size(0) + get_local_id(0),
                    get_local_size(0) * get_local_size(1),
                    partial + get_group_id(1) * get_num_groups(0) + get_group_id(0));
}

/* floor(i / 2) for any sign. */
inline int half_floor(const int i) { return i >= 0 ? i / 2 : -((1 - i) / 2); }

/* Level 0's TILE0 x TILE0 tiles that need its Gaussians, in two passes from level 1's
 * flags of their own pixels (occ: cw x ch, margin cm). flare_tiles_x: near[TY tw + TX]
 * = 1 where a source pixel lies in the tile's rows within rx columns of it;
 * flare_tiles_y: tiles = near taken ny tiles up and down. With ny = ceil(R / TILE0)
 * (R: level 0's largest radius, rx = R): where the flared frame needs the Gaussians
 * (flare_finish0; elsewhere they are exactly 0); with ny = ceil((2 R + TILE0) /
 * TILE0): the rows along x flare_finish0 reads (flare_blur0_x). */
__kernel void flare_tiles_x(__global const uchar *occ, const int cw, const int ch,
                            const int cm, const int tw, const int th, const int rx,
                            __global uchar *near)
{
    const int TX = get_global_id(0), TY = get_global_id(1);
    if (TX >= tw || TY >= th) return;
    const int k0 = max(0, half_floor(TILE0 * TX - rx) + cm);
    const int k1 = min(cw - 1, half_floor(TILE0 * TX + TILE0 - 1 + rx) + cm);
    const int j0 = max(0, half_floor(TILE0 * TY) + cm);
    const int j1 = min(ch - 1, half_floor(TILE0 * TY + TILE0 - 1) + cm);
    int any = 0;
    for (int j = j0; j <= j1 && !any; ++j) {
        __global const uchar *row = occ + (size_t)j * cw;
        for (int k = k0; k <= k1; ++k) any |= row[k];
    }
    near[(size_t)TY * tw + TX] = any != 0;
}

__kernel void flare_tiles_y(__global const uchar *near, const int tw, const int th,
                            const int ny, __global uchar *tiles)
{
    const int TX = get_global_id(0), TY = get_global_id(1);
    if (TX >= tw || TY >= th) return;
    int any = 0;
    for (int j = max(0, TY - ny); j <= min(th - 1, TY + ny); ++j)
        any |= near[(size_t)j * tw + TX];
    tiles[(size_t)TY * tw + TX] = any != 0;
}

/* One level down: fine[2j] = .75 c[j] + .25 c[j - 1], fine[2j + 1] = .75 c[j] +
 * .25 c[j + 1] on both axes (held at the ends of the stored coarse samples). */
__kernel void flare_up(__global const float4 *coarse, const int cw, const int ch, const int cm,
                       __global float4 *fine, const int fw, const int fh, const int fm)
{
    const int X = get_global_id(0), Y = get_global_id(1);
    if (X >= fw || Y >= fh) return;
    const int i = Y - fm, k = X - fm;
    const int ji = half_floor(i), jk = half_floor(k);
    const int ni = (i - 2 * ji) == 0 ? ji - 1 : ji + 1;
    const int nk = (k - 2 * jk) == 0 ? jk - 1 : jk + 1;
    const int r0 = clamp(ji + cm, 0, ch - 1), r1 = clamp(ni + cm, 0, ch - 1);
    const int c0 = clamp(jk + cm, 0, cw - 1), c1 = clamp(nk + cm, 0, cw - 1);
    const float4 a = 0.75f * coarse[(size_t)r0 * cw + c0] + 0.25f * coarse[(size_t)r1 * cw + c0];
    const float4 b = 0.75f * coarse[(size_t)r0 * cw + c1] + 0.25f * coarse[(size_t)r1 * cw + c1];
    fine[(size_t)Y * fw + X] = 0.75f * a + 0.25f * b;
}

/* The Gaussian along x (taps[0] the centre, taps[r] at distance r; zero outside). */
__kernel void flare_blur_x(__global const float4 *src, __global float4 *dst, const int w,
                           const int h, __constant float *taps, const int radius)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    __global const float4 *row = src + (size_t)y * w;
    float4 acc = taps[0] * row[x];
    if (x >= radius && x + radius < w) {
        for (int r = 1; r <= radius; ++r) acc += taps[r] * (row[x - r] + row[x + r]);
    } else {
        for (int r = 1; r <= radius; ++r) {
            const float4 a = x - r >= 0 ? row[x - r] : (float4)(0.0f);
            const float4 b = x + r < w ? row[x + r] : (float4)(0.0f);
            acc += taps[r] * (a + b);
        }
    }
    dst[(size_t)y * w + x] = acc;
}

/* The Gaussian along y, weighted and added to acc (first: acc is overwritten). */
__kernel void flare_blur_y_add(__global const float4 *src, __global float4 *acc, const int w,
                               const int h, __constant float *taps, const int radius,
                               const float weight, const int first)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    __global const float4 *col = src + x;
    float4 s = taps[0] * col[(size_t)y * w];
    if (y >= radius && y + radius < h) {
        for (int r = 1; r <= radius; ++r)
            s += taps[r] * (col[(size_t)(y - r) * w] + col[(size_t)(y + r) * w]);
    } else {
        for (int r = 1; r <= radius; ++r) {
            const float4 a = y - r >= 0 ? col[(size_t)(y - r) * w] : (float4)(0.0f);
            const float4 b = y + r < h ? col[(size_t)(y + r) * w] : (float4)(0.0f);
            s += taps[r] * (a + b);
        }
    }
    const size_t o = (size_t)y * w + x;
    acc[o] = first ? weight * s : acc[o] + weight * s;
}

/* acc += part (the halo ring, made on the host). */
__kernel void flare_add(__global float4 *acc, __global const float4 *part, const int n)
{
    const int i = get_global_id(0);
    if (i < n) acc[i] += part[i];
}

/* The flared frame: rgb - S + max(a0 S + acc, 0) (acc may be absent: has_acc 0).
 * partial: per group (sum of the flare r, g, b, 0). */
__kernel void flare_finish(__global const float *rgb, __global const float4 *S,
                           __global const float4 *acc, const int has_acc, const float a0,
                           const int n, __global float *out, __global float4 *partial,
                           __local float4 *scratch)
{
    const int i = get_global_id(0);
    float4 F = (float4)(0.0f);
    if (i < n) {
        const float4 s = S[i];
        F = a0 * s;
        if (has_acc) F += acc[i];
        F = fmax(F, (float4)(0.0f));
        F.w = 0.0f;
        const size_t o = 3 * (size_t)i;
        out[o] = rgb[o] - s.x + F.x;
        out[o + 1] = rgb[o + 1] - s.y + F.y;
        out[o + 2] = rgb[o + 2] - s.z + F.z;
    }
    group_sum4(scratch, F, partial);
}

/* Level 0, fused (the frame's own resolution, where most of the work is), built
 * for the frame's Gaussians (-D by backends/opencl/flare.py from the plan: L0_NK
 * Gaussians, radii L0_RADII, first taps L0_FIRST in L0_TAPS (taps[0] the centre),
 * the largest radius L0_RMAX): tap loops of known length over a band padded with
 * zeros (L0_RMAX columns either side, its rows beyond the image) have no branch, so
 * the driver unrolls and vectorises them. The band's source part
 * (flare_source_band), its Gaussians along x all at once into L0_NK planes
 * (flare_blur0_x), then the flared frame straight from them (flare_finish0),
 * without level 0's accumulator:
 *   out = rgb - S + max(a0 S + U(acc_1) + sum_k w_k G_k,y * tmp_k, 0)
 * (flare_up, flare_blur_y_add and flare_finish in one pass). A band: image rows
 * t0 .. t0 + trows - 1 (t0 = y0 - L0_RMAX: the rows y0 .. y0 + rows - 1 it flares and
 * the halo its y taps reach), (w + 2 L0_RMAX) S samples a row. */
#ifdef L0_NK
#if L0_NK > 0
__constant int l0_radius[L0_NK] = {L0_RADII};
__constant int l0_first[L0_NK] = {L0_FIRST};
__constant float l0_taps[] = {L0_TAPS};
#endif

/* Whether level 0's tile of image pixel (x, y) needs its Gaussians (flare_tiles);
 * none outside the image. */
#define TILE_ON(tiles, tw, x, y, w, h) \
    ((x) >= 0 && (x) < (w) && (y) >= 0 && (y) < (h) && \
     (tiles)[(size_t)((y) / TILE0) * (tw) + (x) / TILE0])

/* S of a band (2D: padded column, row of the band); zero beyond the image and in
 * the tiles without a source near (tiles, tw: flare_tiles). */
__kernel void flare_source_band(__global const float *rgb, const int w, const int h,
                                const int t0, const int trows, const float lim,
                                __global const uchar *tiles, const int tw,
                                __global float4 *S)
{
    const int xp = get_global_id(0), yb = get_global_id(1);
    const int pw = w + 2 * L0_RMAX;
    if (xp >= pw || yb >= trows) return;
    const int x = xp - L0_RMAX, y = t0 + yb;
    S[(size_t)yb * pw + xp] = TILE_ON(tiles, tw, x, y, w, h)
                                ? source_part(rgb, (size_t)y * w + x, lim) : (float4)(0.0f);
}

/* The four float4 pixels at p as one float16 (float4 loads: PoCL's vload16 is a call). */
#define QUAD(p) ((float16)((p)[0], (p)[1], (p)[2], (p)[3]))

/* Four pixels a work-item (2D: x / 4, row of the band) as float16 (r, g, b, 0 of
 * each): a CPU driver runs work-items as a scalar loop, so the vectors are spelled
 * out here (flare_finish0: 38 -> ~20 ms a 1080p frame on PoCL). Loads may reach
 * past a short last quad (the buffers have 64 bytes to spare); only its pixels are
 * stored. Only the rows flare_finish0 reads are made (rows: flare_tiles' map for
 * them; the band's rows beyond the image are 0). */
__kernel void flare_blur0_x(__global const float4 *S, const int w, const int h,
                            const int t0, const int trows, __global const uchar *rows,
                            const int tw, __global float4 *tmp)
{
#if L0_NK > 0
    const int x = 4 * get_global_id(0), yb = get_global_id(1);
    if (x >= w || yb >= trows) return;
    __global const float4 *row = S + (size_t)yb * (w + 2 * L0_RMAX) + L0_RMAX + x;
    const size_t plane = (size_t)trows * w, o = (size_t)yb * w + x;
    const int y = t0 + yb;
    const int in = y >= 0 && y < h;
    if (in && !rows[(size_t)(y / TILE0) * tw + x / TILE0]) return;   /* never read */
    const float16 c = QUAD(row);
#pragma unroll
    for (int k = 0; k < L0_NK; ++k) {
        __constant float *t = l0_taps + l0_first[k];
        float16 acc = (float16)(0.0f);
        if (in) {
            acc = t[0] * c;
#pragma unroll
            for (int r = 1; r <= l0_radius[k]; ++r)
                acc += t[r] * (QUAD(row - r) + QUAD(row + r));
        }
        __global float4 *dst = tmp + k * plane + o;
        dst[0] = acc.s0123;                 /* (the quad's pixels in the row) */
        if (x + 1 < w) dst[1] = acc.s4567;
        if (x + 2 < w) dst[2] = acc.s89ab;
        if (x + 3 < w) dst[3] = acc.scdef;
    }
#endif
}

/* Rows y0 .. y0 + rows - 1 of the flared frame (2D: x / 4, row of the band; four
 * pixels a work-item as flare_blur0_x), from the band (S, tmp: image rows t0 ..).
 * coarse: level 1's accumulator (cw x ch with margin cm), has_coarse 0: none. kw: the
 * Gaussians' weights (the pupil's). partial[gbase + group]: the group's sum of the
 * flare (r, g, b, 0), as flare_finish. */
__kernel void flare_finish0(__global const float *rgb, __global const float4 *S, const int w,
                            const int y0, const int rows, __global const float4 *tmp,
                            const int t0, const int trows, const float16 kw16,
                            __global const float4 *coarse, const int cw, const int ch,
                            const int cm, const int has_coarse, const float a0,
                            const int h, __global const uchar *tiles, const int tw,
                            __global float *out, __global float4 *partial, const int gbase,
                            __local float4 *scratch)
{
    const int x = 4 * get_global_id(0), yb = get_global_id(1);
    float4 Fsum = (float4)(0.0f);
    if (x < w && yb < rows) {
        const int y = y0 + yb, ty = y - t0;
        const size_t p = (size_t)y * w + x;
        const float16 s = QUAD(S + (size_t)ty * (w + 2 * L0_RMAX) + L0_RMAX + x);
        float16 F = a0 * s;
        if (has_coarse) {   /* flare_up at x .. x + 3 (level 0 has no margin): coarse
                             * columns x/2 - 1 .. x/2 + 2, each pixel its nearest two */
            const int ji = half_floor(y);
            const int ni = (y - 2 * ji) == 0 ? ji - 1 : ji + 1;
            const int q0 = clamp(ji + cm, 0, ch - 1), q1 = clamp(ni + cm, 0, ch - 1);
            float4 a[4];
            for (int j = 0; j < 4; ++j) {
                const int c = clamp(x / 2 - 1 + j + cm, 0, cw - 1);
                a[j] = 0.75f * coarse[(size_t)q0 * cw + c] + 0.25f * coarse[(size_t)q1 * cw + c];
            }
            F += (float16)(0.75f * a[1] + 0.25f * a[0], 0.75f * a[1] + 0.25f * a[2],
                           0.75f * a[2] + 0.25f * a[1], 0.75f * a[2] + 0.25f * a[3]);
        }
#if L0_NK > 0
        float kw[16];                       /* the frame's weights: an argument, not a buffer */
        unpack16(kw16, kw);
        const size_t plane = (size_t)trows * w;
        if (TILE_ON(tiles, tw, x, y, w, h)) {    /* else no source near: all 0 */
#pragma unroll
            for (int k = 0; k < L0_NK; ++k) {
                __constant float *t = l0_taps + l0_first[k];
                __global const float4 *col = tmp + k * plane + (size_t)ty * w + x;
                float16 g = t[0] * QUAD(col);
#pragma unroll
                for (int r = 1; r <= l0_radius[k]; ++r)
                    g += t[r] * (QUAD(col - (size_t)r * w) + QUAD(col + (size_t)r * w));
                F += kw[k] * g;
            }
        }
#endif
        F = fmax(F, (float16)(0.0f));
        __global const float *in = rgb + 3 * p;
        __global float *o = out + 3 * p;
        if (x + 3 < w && (p & 3) == 0) {  /* 12 floats at a multiple of 16 bytes */
            __global const float4 *in4 = (__global const float4 *)in;
            __global float4 *o4 = (__global float4 *)o;
            o4[0] = in4[0] - (float4)(s.s0, s.s1, s.s2, s.s4) + (float4)(F.s0, F.s1, F.s2, F.s4);
            o4[1] = in4[1] - (float4)(s.s5, s.s6, s.s8, s.s9) + (float4)(F.s5, F.s6, F.s8, F.s9);
            o4[2] = in4[2] - (float4)(s.sa, s.sc, s.sd, s.se) + (float4)(F.sa, F.sc, F.sd, F.se);
            Fsum = (F.s0123 + F.s4567) + (F.s89ab + F.scdef);
        } else {                        /* a row's last 1-3 pixels, or w not 4k */
            float fs[16], ss[16];
            unpack16(F, fs);
            unpack16(s, ss);
            for (int j = 0; j < min(4, w - x); ++j) {
                for (int c = 0; c < 3; ++c)
                    o[3 * j + c] = in[3 * j + c] - ss[4 * j + c] + fs[4 * j + c];
                Fsum += vload4(j, fs);
            }
        }
        Fsum.w = 0.0f;
    }
    /* the group's sum (2D groups: flat local index) */
    group_sum4_into(scratch, Fsum, get_local_id(1) * get_local_size(0) + get_local_id(0),
                    get_local_size(0) * get_local_size(1),
                    partial + gbase + get_group_id(1) * get_num_groups(0) + get_group_id(0));
}
#endif

/* The halo ring (f3) on its level, on the device (issue 47: no round trip to a host
 * FFT). Its sources are few: flare_nonzero lists the level's nonzero samples in order
 * (one work-group: each work-item a contiguous share, an exclusive scan of their
 * counts in local memory), with their offsets in K's rows and their values, and
 * flare_ring sums each output sample over them with the f3
 * kernel of each channel, K: 3 planes of (2h-1) x (2w-1), centre at [h-1, w-1]
 * (spencer1995.basis_kernel), out = w3 (K * S), the same linear convolution as the
 * reference's FFT (backends/flare_exec.py fftconvolve_same), in a fixed order. */
__kernel void flare_nonzero(__global const float4 *S, const int n, const int w,
                            __global int *off, __global float4 *val, __global int *count,
                            __local int *scan)
{
    const int lid = get_local_id(0), lsz = get_local_size(0);
    const int per = (n + lsz - 1) / lsz;
    const int a = min(n, lid * per), b = min(n, a + per);
    int c = 0;
    for (int i = a; i < b; i++) {
        const float4 v = S[i];
        c += (v.x != 0.0f || v.y != 0.0f || v.z != 0.0f) ? 1 : 0;
    }
    scan[lid] = c;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0) {
        int t = 0;
        for (int j = 0; j < lsz; j++) {
            const int v = scan[j];
            scan[j] = t;
            t += v;
        }
        count[0] = t;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    int o = scan[lid];
    const int kw = 2 * w - 1;
    for (int i = a; i < b; i++) {
        const float4 v = S[i];
        if (v.x != 0.0f || v.y != 0.0f || v.z != 0.0f) {
            off[o] = (i / w) * kw + i % w;      /* its offset in K's rows */
            val[o++] = v;
        }
    }
}

__kernel void flare_ring(const int w, const int h, __global const int *off,
                         __global const float4 *val, __global const int *count,
                         __global const float *K, const float w3, __global float4 *out)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const int kw = 2 * w - 1, plane = kw * (2 * h - 1);
    const int m = count[0];
    const int base = (y + h - 1) * kw + (x + w - 1);
    float3 acc = 0.0f;
    for (int j = 0; j < m; j++) {
        const int k = base - off[j];
        const float4 s = val[j];
        acc += (float3)(K[k] * s.x, K[plane + k] * s.y, K[2 * plane + k] * s.z);
    }
    out[y * w + x] = (float4)(w3 * acc, 0.0f);
}
