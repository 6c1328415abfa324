/* Durand & Dorsey 2000: the per-pixel pass of the extended Ferwerda operator.
 * Eq. 5: out = m_C rgb + k m_R s_w (1.05, 0.97, 1.27), display-linear, with
 * the cone signals already chromatically adapted (Eq. 6, colour.cl's
 * apply_gains). Reference: ocl_tonemap/models/durand2000.py (map_reference); the scalars
 * are packed by ocl_tonemap/operators/durand00.py (P_<name>: their indices; common.h
 * FRAME_PARAMS);
 * DISPLAY_LINEAR_MAX and SIGNAL_CEILING come with common.h's build options. */

__kernel void durand00_map(__global const float *rgb, __global const float *Y,
                           __global const float *Ys, __global float *out, const int n,
                           FRAME_PARAMS)
{
    FRAME_PARAMS_LOAD;
    const int i = get_global_id(0);
    if (i >= n) return;
    const float m_cone = p[P_m_cone];                         /* m_C / display unit */
    const float rod_r = p[P_rod_r], rod_g = p[P_rod_g], rod_b = p[P_rod_b];
    const float inv_white = p[P_inv_white], knee = p[P_knee];  /* highlight shoulder */
    const float3 c = vload3(i, rgb);
    const float s = Ys[i];
    const float3 o = fmin(m_cone * c + s * (float3)(rod_r, rod_g, rod_b), SIGNAL_CEILING);
    vstore3(clamp(shoulder3(o, inv_white, knee), 0.0f, DISPLAY_LINEAR_MAX), i, out);
}

/* durand00_map four pixels per work-item (float4 across pixels where VECTOR_PIXELS;
 * the tail, and every pixel elsewhere, scalar). */
__kernel void durand00_map4(__global const float *rgb, __global const float *Y,
                            __global const float *Ys, __global float *out, const int n,
                            FRAME_PARAMS)
{
    FRAME_PARAMS_LOAD;
    const int q = get_global_id(0), i0 = ITEM_PIXELS(4) * q;
    if (i0 >= n) return;
    const float m_cone = p[P_m_cone];
    const float rod_r = p[P_rod_r], rod_g = p[P_rod_g], rod_b = p[P_rod_b];
    const float inv_white = p[P_inv_white], knee = p[P_knee];
    if (!VECTOR_PIXELS || i0 + 4 > n) {
        for (int i = i0; i < min(i0 + ITEM_PIXELS(4), n); ++i) {
            const float3 o = fmin(m_cone * vload3(i, rgb) + Ys[i] * (float3)(rod_r, rod_g, rod_b),
                                  SIGNAL_CEILING);
            vstore3(clamp(shoulder3(o, inv_white, knee), 0.0f, DISPLAY_LINEAR_MAX), i, out);
        }
        return;
    }
    float4 r, g, b;
    load_rgb4(q, rgb, &r, &g, &b);
    const float4 s = vload4(q, Ys);
    r = fmin(m_cone * r + s * rod_r, SIGNAL_CEILING);                      /* Eq. 5 */
    g = fmin(m_cone * g + s * rod_g, SIGNAL_CEILING);
    b = fmin(m_cone * b + s * rod_b, SIGNAL_CEILING);
    shoulder4(&r, &g, &b, inv_white, knee);
    store_rgb4(q, out, clamp(r, 0.0f, DISPLAY_LINEAR_MAX), clamp(g, 0.0f, DISPLAY_LINEAR_MAX),
               clamp(b, 0.0f, DISPLAY_LINEAR_MAX));
}

/* Sec. 5: the same through per-frame tables T_C (entries 0..n-1) and T_R
 * (n..2n-1), indexed by log10 of the signal, nearest entry (no interpolation,
 * as the paper). */
inline float lut_at(__global const float *t, const int nlut, const float lo,
                    const float inv_step, const float x)
{
    if (!(x > 0.0f)) return 0.0f;
    int idx = (int)rint((log10(x) - lo) * inv_step);
    return t[clamp(idx, 0, nlut - 1)];
}

__kernel void durand00_map_lut(__global const float *rgb, __global const float *Y,
                               __global const float *Ys, __global float *out, const int n,
                               FRAME_PARAMS, __global const float *tables)
{
    FRAME_PARAMS_LOAD;
    const int i = get_global_id(0);
    if (i >= n) return;
    const int nlut = (int)p[P_nlut];
    const float lo = p[P_lo], inv_step = p[P_inv_step];
    const float tint_r = p[P_tint_r], tint_g = p[P_tint_g], tint_b = p[P_tint_b];
    const float inv_white = p[P_inv_white], knee = p[P_knee];
    const float3 c = vload3(i, rgb);
    const float rod = lut_at(tables + nlut, nlut, lo, inv_step, Ys[i]);
    float3 o;
    o.x = lut_at(tables, nlut, lo, inv_step, c.x);
    o.y = lut_at(tables, nlut, lo, inv_step, c.y);
    o.z = lut_at(tables, nlut, lo, inv_step, c.z);
    o = fmin(o + rod * (float3)(tint_r, tint_g, tint_b), SIGNAL_CEILING);
    vstore3(clamp(shoulder3(o, inv_white, knee), 0.0f, DISPLAY_LINEAR_MAX), i, out);
}
