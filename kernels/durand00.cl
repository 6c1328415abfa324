/* Durand & Dorsey 2000: the per-pixel pass of the extended Ferwerda operator.
 * Eq. 5: out = m_C rgb + k m_R s_w (1.05, 0.97, 1.27), display-linear, with
 * the cone signals already chromatically adapted (Eq. 6, colour.cl's
 * apply_gains). Reference: ocl_tonemap/durand00.py (map_reference). */

#define DISPLAY_LINEAR_MAX 100.0f

__kernel void durand00_map(__global const float *rgb, __global const float *Ys,
                           __global float *out, const int n,
                           const float m_cone,                 /* m_C / display unit */
                           const float rod_r, const float rod_g, const float rod_b,
                           const float inv_white, const float knee)   /* highlight shoulder */
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float3 c = vload3(i, rgb);
    const float s = Ys[i];
    const float3 o = fmin(m_cone * c + s * (float3)(rod_r, rod_g, rod_b), SIGNAL_CEILING);
    vstore3(clamp(shoulder3(o, inv_white, knee), 0.0f, DISPLAY_LINEAR_MAX), i, out);
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

__kernel void durand00_map_lut(__global const float *rgb, __global const float *Ys,
                               __global float *out, const int n,
                               __global const float *tables, const int nlut,
                               const float lo, const float inv_step,
                               const float tint_r, const float tint_g, const float tint_b,
                               const float inv_white, const float knee)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float3 c = vload3(i, rgb);
    const float rod = lut_at(tables + nlut, nlut, lo, inv_step, Ys[i]);
    float3 o;
    o.x = lut_at(tables, nlut, lo, inv_step, c.x);
    o.y = lut_at(tables, nlut, lo, inv_step, c.y);
    o.z = lut_at(tables, nlut, lo, inv_step, c.z);
    o = fmin(o + rod * (float3)(tint_r, tint_g, tint_b), SIGNAL_CEILING);
    vstore3(clamp(shoulder3(o, inv_white, knee), 0.0f, DISPLAY_LINEAR_MAX), i, out);
}
