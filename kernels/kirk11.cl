/* Kirk & O'Brien 2011: receptor responses, the Purkinje shift (Cao et al. 2008)
 * with the non-negative display solve, and the final composition.
 * Reference: ocl_tonemap/kirk11.py. */

#define L_MAX_F 0.637f
#define M_MAX_F 0.392f
#define S_MAX_F 1.606f
#define ALPHA_F 0.619f
#define Y_FLOOR 1.0e-10f
#define DISPLAY_LINEAR_MAX 100.0f

/* q (4 per pixel) = W (4 x nc, row-major) . in (nc per pixel): RGB via H
 * (Sec. 4) or a sampled spectrum (Eq. 8). */
__kernel void to_lmsr(__global const float *in, const int nc, const int n,
                      __constant float *W, __global float *q)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    __global const float *v = in + (size_t)i * nc;
    float4 acc = (float4)(0.0f);
    for (int c = 0; c < nc; ++c)
        acc += v[c] * (float4)(W[c], W[nc + c], W[2 * nc + c], W[3 * nc + c]);
    vstore4(acc, i, q);
}

/* Eqs. 10-13 and 15-16. par: scale (model units per cd/m^2), k1, k2, rod_gain, x, y, z, rho1..4.
 * solvers: 7 (3x3) matrices, full support first; M: display RGB -> LMS;
 * D: display RGB -> working RGB. Output: working RGB (cd/m^2 units), w. */
__kernel void kirk11_shift(__global const float *q, const int n, __constant float *par,
                           __constant float *solvers, __constant float *M,
                           __constant float *D, __global float *rgb_out,
                           __global float *w_out, __global float *logY,
                           __global int *fallbacks)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float area = par[0], k1 = par[1], k2 = par[2], gain = par[3];
    const float4 qq = vload4(i, q);
    const float4 qt = qq * area;                                  /* Eq. 10 units */
    const float gl = rsqrt(1.0f + 0.33f * (qt.x + k1 * qt.w));         /* Eq. 10 */
    const float gm = rsqrt(1.0f + 0.33f * (qt.y + k1 * qt.w));
    const float gs = rsqrt(1.0f + 0.33f * (qt.z + k2 * qt.w));
    const float nl = gl / L_MAX_F, nm = gm / M_MAX_F, ns = gs / S_MAX_F;
    const float lum = ALPHA_F * nl + (1.0f - ALPHA_F) * nm;            /* w, Eq. 16 */
    const float rod = gain * qt.w;
    const float d0 = par[4] * k1 * (par[7] * nm - par[8] * nl) * rod;  /* Eq. 12 */
    const float d1 = par[5] * (par[9] * ns - par[10] * lum) * rod;
    const float d2 = par[6] * lum * rod;
    /* A^-1 of Eq. 11 (o = A q^): rows from the host-checked closed form */
    const float inv_area = 1.0f / area;
    float3 qh;
    qh.x = qq.x + (-0.5f * d0 + 0.5f * d2) * inv_area;
    qh.y = qq.y + (0.5f * d0 + 0.5f * d2) * inv_area;
    qh.z = qq.z + (d1 + d2) * inv_area;
    /* Eq. 15: unconstrained first, then the best feasible smaller support */
    float3 best = (float3)(0.0f);
    float best_res = dot(qh, qh);
    int fb = 0;
    for (int k = 0; k < 7; ++k) {
        __constant float *P = solvers + 9 * k;
        float3 p = (float3)(P[0] * qh.x + P[1] * qh.y + P[2] * qh.z,
                            P[3] * qh.x + P[4] * qh.y + P[5] * qh.z,
                            P[6] * qh.x + P[7] * qh.y + P[8] * qh.z);
        const float tol = -1e-6f * fmax(fmax(fabs(qh.x), fabs(qh.y)), fabs(qh.z));
        if (p.x < tol || p.y < tol || p.z < tol) { if (k == 0) fb = 1; continue; }
        p = fmax(p, (float3)(0.0f));
        float3 r = (float3)(M[0] * p.x + M[1] * p.y + M[2] * p.z,
                            M[3] * p.x + M[4] * p.y + M[5] * p.z,
                            M[6] * p.x + M[7] * p.y + M[8] * p.z) - qh;
        const float res = dot(r, r);
        if (k == 0) { best = p; best_res = res; break; }
        if (res < best_res) { best = p; best_res = res; }
    }
    if (fb) atomic_inc(fallbacks);
    const float3 o = (float3)(D[0] * best.x + D[1] * best.y + D[2] * best.z,
                              D[3] * best.x + D[4] * best.y + D[5] * best.z,
                              D[6] * best.x + D[7] * best.y + D[8] * best.z);
    vstore3(o, i, rgb_out);
    w_out[i] = lum;
    logY[i] = log10(fmax(M_YR * o.x + M_YG * o.y + M_YB * o.z, Y_FLOOR));
}

/* Range reduction (Durand & Dorsey 2002), mesopic dimming and (RGB input) the
 * blend from the source by w. */
__kernel void kirk11_compose(__global const float *src, __global const float *shifted,
                             __global const float *w, __global const float *logY,
                             __global const float *base, const int n, const float c,
                             const float base_max, const float beta, const float gamma,
                             const float out_scale, const int blend, __global float *out)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float ly = logY[i], b = base[i];
    const float ly_out = c * (b - base_max) + (ly - b);
    const float s = exp10(ly_out - ly);
    const float wi = w[i];
    const float dim = fmax(1.0f - wi / beta, gamma);
    float3 o = vload3(i, shifted) * (s * dim);
    if (blend) {
        const float t = clamp(wi / beta, 0.0f, 1.0f);
        const float3 sc = vload3(i, src);
        const float ys = fmax(M_YR * sc.x + M_YG * sc.y + M_YB * sc.z, Y_FLOOR);
        o = (1.0f - t) * sc * (exp10(ly_out) / ys) + t * o;
    }
    vstore3(clamp(o * out_scale, 0.0f, DISPLAY_LINEAR_MAX), i, out);
}
