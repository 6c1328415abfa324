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
 * to the group's sums as flare_source's do: partial[group] (S r, g, b, sources). */
__kernel void flare_down_src(__global const float *rgb, const int w, const int h,
                             const float lim, __global float4 *coarse, const int cw,
                             const int ch, const int cm, __global float4 *partial,
                             __local float4 *scratch)
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
    }
    group_sum4_into(scratch, own, get_local_id(1) * get_local_size(0) + get_local_id(0),
                    get_local_size(0) * get_local_size(1),
                    partial + get_group_id(1) * get_num_groups(0) + get_group_id(0));
}

/* S of image rows r0 .. r0 + rows - 1 into a band (the fused level 0's). */
__kernel void flare_source_rows(__global const float *rgb, const int w, const int r0,
                                const int rows, const float lim, __global float4 *S)
{
    const int i = get_global_id(0);
    if (i < rows * w) S[i] = source_part(rgb, (size_t)r0 * w + i, lim);
}

/* floor(i / 2) for any sign. */
inline int half_floor(const int i) { return i >= 0 ? i / 2 : -((1 - i) / 2); }

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

/* Level 0, fused (the frame's own resolution, where most of the work is): its
 * Gaussians along x all at once into nk planes of a band's rows, then the flared
 * frame straight from them (flare_finish0), without level 0's accumulator:
 *   out = rgb - S + max(a0 S + U(acc_1) + sum_k w_k G_k,y * tmp_k, 0)
 * (flare_up, flare_blur_y_add and flare_finish in one pass). kinfo[k]: (first tap,
 * radius) of Gaussian k in taps. S: the band's source part (flare_source_rows), rows
 * r0 .. of it for blur0_x; image rows t0 .. t0 + trows - 1 for finish0. */
__kernel void flare_blur0_x(__global const float4 *S, const int w, const int r0,
                            const int rows, __global float4 *tmp, __constant float *taps,
                            __constant int2 *kinfo, const int nk)
{
    const int x = get_global_id(0), yb = get_global_id(1);
    if (x >= w || yb >= rows) return;
    __global const float4 *row = S + (size_t)(r0 + yb) * w;
    const size_t plane = (size_t)rows * w, o = (size_t)yb * w + x;
    const float4 c = row[x];
    for (int k = 0; k < nk; ++k) {
        __constant float *t = taps + kinfo[k].x;
        const int radius = kinfo[k].y;
        float4 acc = t[0] * c;
        if (x >= radius && x + radius < w) {
            for (int r = 1; r <= radius; ++r) acc += t[r] * (row[x - r] + row[x + r]);
        } else {
            for (int r = 1; r <= radius; ++r) {
                const float4 a = x - r >= 0 ? row[x - r] : (float4)(0.0f);
                const float4 b = x + r < w ? row[x + r] : (float4)(0.0f);
                acc += t[r] * (a + b);
            }
        }
        tmp[k * plane + o] = acc;
    }
}

/* Rows y0 .. y0 + rows - 1 of the flared frame (2D: x, row of the band); tmp and S
 * hold image rows t0 .. t0 + trows - 1 (the band and its halo; rows outside the image
 * are zero). coarse: level 1's accumulator (cw x ch with margin cm), has_coarse 0: none.
 * partial[gbase + group]: the group's sum of the flare (r, g, b, 0), as flare_finish. */
__kernel void flare_finish0(__global const float *rgb, __global const float4 *S, const int w,
                            const int h, const int y0, const int rows,
                            __global const float4 *tmp, const int t0, const int trows,
                            __constant float *taps, __constant int2 *kinfo,
                            __constant float *kw, const int nk,
                            __global const float4 *coarse, const int cw, const int ch,
                            const int cm, const int has_coarse, const float a0,
                            __global float *out, __global float4 *partial, const int gbase,
                            __local float4 *scratch)
{
    const int x = get_global_id(0), yb = get_global_id(1);
    float4 F = (float4)(0.0f);
    if (x < w && yb < rows) {
        const int y = y0 + yb;
        const size_t p = (size_t)y * w + x;
        const float4 s = S[(size_t)(y - t0) * w + x];           /* S: the band's rows */
        F = a0 * s;
        if (has_coarse) {                 /* flare_up at (x, y): level 0 has no margin */
            const int ji = half_floor(y), jk = half_floor(x);
            const int ni = (y - 2 * ji) == 0 ? ji - 1 : ji + 1;
            const int nk_ = (x - 2 * jk) == 0 ? jk - 1 : jk + 1;
            const int q0 = clamp(ji + cm, 0, ch - 1), q1 = clamp(ni + cm, 0, ch - 1);
            const int c0 = clamp(jk + cm, 0, cw - 1), c1 = clamp(nk_ + cm, 0, cw - 1);
            const float4 a = 0.75f * coarse[(size_t)q0 * cw + c0] + 0.25f * coarse[(size_t)q1 * cw + c0];
            const float4 b = 0.75f * coarse[(size_t)q0 * cw + c1] + 0.25f * coarse[(size_t)q1 * cw + c1];
            F += 0.75f * a + 0.25f * b;
        }
        const size_t plane = (size_t)trows * w;
        const int ty = y - t0;
        for (int k = 0; k < nk; ++k) {
            __constant float *t = taps + kinfo[k].x;
            const int radius = kinfo[k].y;
            __global const float4 *col = tmp + k * plane + x;
            float4 g = t[0] * col[(size_t)ty * w];
            if (y >= radius && y + radius < h) {
                for (int r = 1; r <= radius; ++r)
                    g += t[r] * (col[(size_t)(ty - r) * w] + col[(size_t)(ty + r) * w]);
            } else {
                for (int r = 1; r <= radius; ++r) {
                    const float4 a = y - r >= 0 ? col[(size_t)(ty - r) * w] : (float4)(0.0f);
                    const float4 b = y + r < h ? col[(size_t)(ty + r) * w] : (float4)(0.0f);
                    g += t[r] * (a + b);
                }
            }
            F += kw[k] * g;
        }
        F = fmax(F, (float4)(0.0f));
        F.w = 0.0f;
        const size_t o = 3 * p;
        out[o] = rgb[o] - s.x + F.x;
        out[o + 1] = rgb[o + 1] - s.y + F.y;
        out[o + 2] = rgb[o + 2] - s.z + F.z;
    }
    /* the group's sum (2D groups: flat local index) */
    group_sum4_into(scratch, F, get_local_id(1) * get_local_size(0) + get_local_id(0),
                    get_local_size(0) * get_local_size(1),
                    partial + gbase + get_group_id(1) * get_num_groups(0) + get_group_id(0));
}
