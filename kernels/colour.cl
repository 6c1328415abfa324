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
    if (i < n) {
        float v[3];
        const bool counted = i >= count_lo && i < count_hi;
        for (int k = 0; k < 3; ++k)
            v[k] = repair_and_scale(src[(size_t)i * channels + k], scale, counted, lc);
        vstore3((float3)(v[0], v[1], v[2]), i, rgb);
        Y[i] = M_YR * v[0] + M_YG * v[1] + M_YB * v[2];
        Ys[i] = scotopic_luminance(v[0], v[1], v[2]);
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
    const float3 c = vload3(i, rgb) * (float3)(gr, gg, gb);
    vstore3(c, i, rgb);
    Y[i] = M_YR * c.x + M_YG * c.y + M_YB * c.z;
}
