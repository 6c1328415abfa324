/* Colour and luminance stage: scene values -> sanitised working-space cd/m^2,
 * photopic Y and scotopic Y' (see ocl_tonemap/models/photometry.py for the policy). */

/* Classify one input value by its bits (robust when the device flushes
 * denormals in arithmetic): returns the repaired value before scaling and
 * sets *kind to the repair index, or -1 when none. */
inline float repair_value(float x, int *kind)
{
    uint u = as_uint(x);
    uint e = (u >> 23) & 0xffu, m = u & 0x7fffffu, s = u >> 31;
    *kind = -1;
    if (e == 0xffu) {
        if (m) { *kind = 0; return 0.0f; }          /* NaN */
        if (!s) { *kind = 1; return INFINITY; }     /* +Inf -> L_MAX after scale */
        *kind = 2; return 0.0f;                     /* -Inf */
    }
    if (s && (e | m)) { *kind = 3; return 0.0f; }   /* negative (incl. negative denormal) */
    if (e == 0u && m) { *kind = 4; return 0.0f; }   /* positive denormal */
    return x;
}

/* The policy and the scale for one value; repairs counted in lc when `counted`. */
inline float repair_and_scale(const float raw, const float scale, const bool counted,
                              __local int *lc)
{
    int kind;
    float x = repair_value(raw, &kind);
    if (kind >= 0 && counted) atomic_inc(&lc[kind]);
    if (kind == 1) return L_MAX;
    x *= scale;
    if (x > L_MAX) { if (counted) atomic_inc(&lc[5]); x = L_MAX; }
    return x;
}

/* One pixel: repaired, scaled to cd/m^2, stored with its Y and Y'. */
inline void working_pixel(__global const float *src, const int channels, const int i,
                          const float scale, __global float *rgb, __global float *Y,
                          __global float *Ys, __local int *lc, const int count_lo,
                          const int count_hi)
{
    float v[3];
    const bool counted = i >= count_lo && i < count_hi;
    for (int k = 0; k < 3; ++k)
        v[k] = repair_and_scale(src[(size_t)i * channels + k], scale, counted, lc);
    vstore3((float3)(v[0], v[1], v[2]), i, rgb);
    Y[i] = M_YR * v[0] + M_YG * v[1] + M_YB * v[2];
    Ys[i] = scotopic_luminance(v[0], v[1], v[2]);
}

/* src: n pixels of `channels` floats (RGB first); rgb out: n*3 floats.
 * Repairs are counted for pixels [count_lo, count_hi) only (a band's halo
 * rows are another band's own). */
__kernel void scene_to_working(__global const float *src, const int channels, const int n,
                               const float scale, __global float *rgb,
                               __global float *Y, __global float *Ys,
                               __global int *counts, const int count_lo, const int count_hi)
{
    __local int lc[NREPAIR];
    const int lid = get_local_id(0);
    if (lid < NREPAIR) lc[lid] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int i = get_global_id(0);
    if (i < n) working_pixel(src, channels, i, scale, rgb, Y, Ys, lc, count_lo, count_hi);
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid < NREPAIR && lc[lid]) atomic_add(&counts[lid], lc[lid]);
}

/* scene_to_working four pixels per work-item (work-item q: pixels 4q .. 4q+3), for
 * RGB and RGBA sources: PoCL vectorises float4 arithmetic within a work-item, not scalar
 * code across work-items (4-6x faster than scene_to_working on 2 CPU cores). A quad
 * whose every value is +-0 or a positive normal number and stays under L_MAX after
 * the scale takes the vector path (the raw bits are tested, as repair_value does); any other quad (and the tail when n % 4 != 0) runs
 * the scalar policy above, value by value, so repairs and their counts are the same. */
inline int4 clean4(const float4 x)
{
    const uint4 u = as_uint4(x) & 0x7fffffffu;        /* -0 is clean (kept as -0) */
    return (u == 0u) | ((u >= 0x00800000u) & (u < 0x7f800000u) & (as_uint4(x) >> 31 == 0u));
}

__kernel void scene_to_working4(__global const float *src, const int channels, const int n,
                                const float scale, __global float *rgb,
                                __global float *Y, __global float *Ys,
                                __global int *counts, const int count_lo, const int count_hi)
{
    __local int lc[NREPAIR];
    const int lid = get_local_id(0);
    if (lid < NREPAIR) lc[lid] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int q = get_global_id(0), i0 = ITEM_PIXELS(4) * q;
    bool done = false;
    if (VECTOR_PIXELS && i0 + 3 < n && (channels == 3 || channels == 4)) {   /* common.h */
        float4 r, g, b;
        if (channels == 3) {
            load_rgb4(q, src, &r, &g, &b);
        } else {                /* (float4 loads: PoCL calls vload4 out of line) */
            __global const float4 *s4 = (__global const float4 *)src + i0;
            const float4 p0 = s4[0], p1 = s4[1], p2 = s4[2], p3 = s4[3];
            r = (float4)(p0.x, p1.x, p2.x, p3.x);
            g = (float4)(p0.y, p1.y, p2.y, p3.y);
            b = (float4)(p0.z, p1.z, p2.z, p3.z);
        }
        const int4 raw_ok = clean4(r) & clean4(g) & clean4(b);   /* the raw values' bits */
        r *= scale; g *= scale; b *= scale;
        const int4 ok = raw_ok & (r <= L_MAX) & (g <= L_MAX) & (b <= L_MAX);
        if (all(ok)) {
            store_rgb4(q, rgb, r, g, b);
            const float4 y = M_YR * r + M_YG * g + M_YB * b;
            ((__global float4 *)Y)[q] = y;
            ((__global float4 *)Ys)[q] = scotopic_luminance4(r, g, b, y);
            done = true;
        }
    }
    if (!done) {
        for (int i = i0; i < min(i0 + ITEM_PIXELS(4), n); ++i)
            working_pixel(src, channels, i, scale, rgb, Y, Ys, lc, count_lo, count_hi);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid < NREPAIR && lc[lid]) atomic_add(&counts[lid], lc[lid]);
}

/* The bad-value policy and the scale on n values in place (any number of
 * channels: spectral frames), counting repairs as scene_to_working does. */
__kernel void repair_scale(__global float *v, const int n, const float scale,
                           __global int *counts)
{
    __local int lc[NREPAIR];
    const int lid = get_local_id(0);
    if (lid < NREPAIR) lc[lid] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int i = get_global_id(0);
    if (i < n) v[i] = repair_and_scale(v[i], scale, true, lc);
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid < NREPAIR && lc[lid]) atomic_add(&counts[lid], lc[lid]);
}

/* Von Kries chromatic adaptation of the cone signals (Durand & Dorsey 2000,
 * Eq. 6): rgb *= gains, photopic Y recomputed; the rod signal Y' is left as
 * it was (rods do not adapt chromatically). */
__kernel void apply_gains(__global float *rgb, __global float *Y, const int n,
                          const float gr, const float gg, const float gb)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    __global float *p = rgb + 3 * (size_t)i;    /* (vload3, vstore3: calls on PoCL) */
    const float r = p[0] * gr, g = p[1] * gg, b = p[2] * gb;
    p[0] = r; p[1] = g; p[2] = b;
    Y[i] = M_YR * r + M_YG * g + M_YB * b;
}

/* A frame that came up in its stored half floats (a half EXR: half the upload) to
 * float32, exactly (every half is a float32), for scene_to_working4; n values. */
__kernel void half_to_float(__global const half *src, __global float *dst, const int n)
{
    const int i = get_global_id(0);
    if (i < n) dst[i] = vload_half(i, src);
}

/* Chromatic gains on a frame held on the device (effects/chromatic.py, the seen
 * slot for ledda04 and kirk11): rgb *= g in place, the float32 products of the host's
 * (np.float32 rgb * gains), so the frame need not cross to the host and back. */
__kernel void scale_rgb(__global float *rgb, const int n,
                        const float gr, const float gg, const float gb)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    __global float *p = rgb + 3 * (size_t)i;
    p[0] = p[0] * gr; p[1] = p[1] * gg; p[2] = p[2] * gb;
}

/* The observer's absolute threshold on a frame held on the device (effects/threshold.py,
 * models/absolute_threshold.py Eqs. 2-3): each pixel's light weighted by the share
 * seen beyond the threshold, w = max(0, 1 - 2^(1 - x^beta)), x = max(Y / T_c, Y' / T_r),
 * in place. inv_tc, inv_tr: 1 / T; x at or above x_sure is shown whole (w = 1 in float). */
__kernel void absolute_threshold_rgb(__global float *rgb, const int n, const float inv_tc,
                                     const float inv_tr, const float beta, const float x_sure)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    __global float *p = rgb + 3 * (size_t)i;
    const float r = p[0], g = p[1], b = p[2];
    const float Y = M_YR * r + M_YG * g + M_YB * b;
    const float x = fmax(Y * inv_tc, scotopic_luminance(r, g, b) * inv_tr);
    if (x >= x_sure) return;
    const float w = x > 1.0f ? -expm1(M_LN2_F * (1.0f - pow(x, beta))) : 0.0f;
    p[0] = r * w; p[1] = g * w; p[2] = b * w;
}

/* Spectral radiance to LMSR in one pass (kirk11, Eq. 8; host side
 * backends/opencl/kirk11.py lmsr_band): each value through the bad-value policy and
 * the scale (repair_and_scale, counted), then q = W v, channel by channel in the order
 * of kirk11.cl to_lmsr. Wt: nc float4, the weights of channel c for L, M, S, R. Four
 * channels at a time where their raw bits are clean (clean4) and stay under L_MAX
 * once scaled; any other value takes the scalar policy. The cube is read once and
 * not written (repair_scale + to_lmsr read it twice and wrote it once). */
__kernel void spectrum_to_lmsr(__global const float *in, const int nc, const int n,
                               const float scale, __constant float4 *Wt,
                               __global float *q, __global int *counts)
{
    __local int lc[NREPAIR];
    const int lid = get_local_id(0);
    if (lid < NREPAIR) lc[lid] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int i = get_global_id(0);
    if (i < n) {
        __global const float *v = in + (size_t)i * nc;
        float4 acc = (float4)(0.0f);
        int c = 0;
        for (; c + 4 <= nc; c += 4) {
            float4 x = vload4(0, v + c);
            if (all(clean4(x) & (x * scale <= L_MAX))) {
                x *= scale;
            } else {
                x = (float4)(repair_and_scale(x.x, scale, true, lc),
                             repair_and_scale(x.y, scale, true, lc),
                             repair_and_scale(x.z, scale, true, lc),
                             repair_and_scale(x.w, scale, true, lc));
            }
            acc += x.x * Wt[c];
            acc += x.y * Wt[c + 1];
            acc += x.z * Wt[c + 2];
            acc += x.w * Wt[c + 3];
        }
        for (; c < nc; ++c)
            acc += repair_and_scale(v[c], scale, true, lc) * Wt[c];
        vstore4(acc, i, q);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid < NREPAIR && lc[lid]) atomic_add(&counts[lid], lc[lid]);
}
