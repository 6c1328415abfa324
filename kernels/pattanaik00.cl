/* Pattanaik, Tumblin, Yee & Greenberg 2000: fused per-pixel pass.
 * Eq. 2 responses, Eq. 3 colour slope, Sec. 4.3 inverse appearance (as a
 * per-frame gain/offset) and inverse display response (quadratic in L^n).
 * Reference: ocl_tonemap/pattanaik00.py (map_reference). */

#define PN 0.73f
#define L_FLOOR 1.0e-10f
#define RATIO_FLOOR 1.0e-12f
#define DISPLAY_LINEAR_MAX 100.0f

/* L^n/(L^n + sigma^n) = 1/(1 + 2^(n (log2 sigma - log2 L))) */
inline float saturation(float L, float log2_sigma)
{
    return 1.0f / (1.0f + exp2(PN * (log2_sigma - log2(fmax(L, L_FLOOR)))));
}

__kernel void pattanaik00_map(__global const float *rgb, __global const float *Y,
                              __global const float *Ys, __global float *out, const int n,
                              const float log2_sigma_rod, const float log2_sigma_cone,
                              const float B_rod, const float B_cone,
                              const float gain, const float offset,
                              const float dB_rod, const float dB_cone,
                              const float ds_rod, const float ds_cone,   /* display sigma^n */
                              const float colour_k,                      /* ln10 n B_cone / S_d */
                              const float out_scale)                     /* 1 / display unit */
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float Lc = Y[i];
    const float xc = saturation(Lc, log2_sigma_cone);
    const float R = B_rod * saturation(Ys[i], log2_sigma_rod) + B_cone * xc;   /* Eq. 2 */
    const float e = colour_k * xc * (1.0f - xc);                               /* S_color/S_d */

    /* inverse display response: (Br+Bc-R) x^2 + (Br sc + Bc sr - R(sr+sc)) x - R sr sc = 0 */
    const float rmax = dB_rod + dB_cone;
    const float Rd = clamp(gain * R + offset, 0.0f, rmax * (1.0f - 1.0e-6f));
    const float a = rmax - Rd;
    const float b = dB_rod * ds_cone + dB_cone * ds_rod - Rd * (ds_rod + ds_cone);
    const float c = Rd * ds_rod * ds_cone;
    const float disc = sqrt(b * b + 4.0f * a * c);
    const float x = b > 0.0f ? 2.0f * c / (b + disc) : (disc - b) / (2.0f * a);
    const float Ld = x > 0.0f ? exp2(log2(x) * (1.0f / PN)) : 0.0f;

    float4 col = (float4)(vload3(i, rgb), 1.0f);
    float4 ratio = Lc > L_FLOOR ? col / Lc : (float4)(1.0f);
    float4 cd = powp4(fmax(ratio, (float4)(RATIO_FLOOR)), (float4)(e));      /* Q_color^(1/S_d) */
    float4 o = clamp(Ld * out_scale * cd, 0.0f, DISPLAY_LINEAR_MAX);
    vstore3(o.xyz, i, out);
}
