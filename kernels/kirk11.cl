/* Kirk & O'Brien 2011: receptor responses, the Purkinje shift (Cao et al. 2008)
 * with the non-negative display solve, and the final composition.
 * Reference: ocl_tonemap/models/kirk2011.py.
 *
 * L_MAX_F, M_MAX_F, S_MAX_F (models/lmsr.py L_MAX, M_MAX, S_MAX), ALPHA_F (Eq. 16),
 * REGULATION_C (Eq. 10), A_INV_00, A_INV_02, A_INV_10, A_INV_12 (Eq. 11's A^-1),
 * N_SUPPORTS (Eq. 15's supports), Y_FLOOR, LOG_FLOOR and PURKINJE_WG (purkinje_rgb's
 * work-group size) are given as build options
 * from ocl_tonemap/models/kirk2011.py (backends/opencl/kirk11.py, KERNEL_CONSTANTS);
 * DISPLAY_LINEAR_MAX and SIGNAL_CEILING with common.h's: one definition, not retyped
 * here. */

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

/* Eqs. 10-13 and 15-16. par: scale (model units per cd/m^2), k1, k2, rod_gain, x, y, z,
 * rho1..4, then D_W (L, M, S: the white-referenced opponent space, kirk11.white_norm;
 * 1,1,1 in the paper mode), then exact (1: Eq. 15's NNLS over the 7 supports,
 * kirk11.nnls3; 0: the gamut map, kirk11.gamut_map).
 * Minv: M^-1 (3x3); solvers: 7 (3x3), full support first; M: display RGB -> LMS
 * (its row sums give the neutral); D: display RGB -> working RGB.
 * Output: working RGB (cd/m^2 units), w. */
/* One pixel of Eqs. 10-13, 15-16 (kirk11_shift, purkinje_rgb): from its LMSR ``qq``
 * the display RGB solution (before D) and w (Eq. 16); *fb_out is 1 where the solve
 * fell back (Eq. 15's full support infeasible, or the gamut map moved it). ``exact``:
 * Eq. 15's NNLS, else the gamut map (a literal 0 leaves straight-line code that the
 * driver vectorises across work-items). */
inline float3 shift_pixel(const float4 qq, const float *par, __constant float *Minv,
                          __constant float *solvers, __constant float *M, float *lum_out,
                          int *fb_out, const int exact)
{
    const float area = par[0], k1 = par[1], k2 = par[2], gain = par[3];
    const float4 dw = (float4)(par[11], par[12], par[13], 1.0f);
    const float4 qt = qq * dw * area;                             /* Eq. 10 units */
    const float gl = rsqrt(1.0f + REGULATION_C * (qt.x + k1 * qt.w));  /* Eq. 10 */
    const float gm = rsqrt(1.0f + REGULATION_C * (qt.y + k1 * qt.w));
    const float gs = rsqrt(1.0f + REGULATION_C * (qt.z + k2 * qt.w));
    const float nl = gl / L_MAX_F, nm = gm / M_MAX_F, ns = gs / S_MAX_F;
    const float lum = ALPHA_F * nl + (1.0f - ALPHA_F) * nm;            /* w, Eq. 16 */
    const float rod = gain * qt.w;
    const float d0 = par[4] * k1 * (par[7] * nm - par[8] * nl) * rod;  /* Eq. 12 */
    const float d1 = par[5] * (par[9] * ns - par[10] * lum) * rod;
    const float d2 = par[6] * lum * rod;
    /* A^-1 of Eq. 11 (o = A q^), its zero entries left out and its last row (0, 1, 1)
     * written out (tests/backends/test_kernel_constants.py checks kirk2011.A_INV has that form) */
    float3 qh;
    qh.x = qq.x + (A_INV_00 * d0 + A_INV_02 * d2) / (dw.x * area);
    qh.y = qq.y + (A_INV_10 * d0 + A_INV_12 * d2) / (dw.y * area);
    qh.z = qq.z + (d1 + d2) / (dw.z * area);
    const float3 p = (float3)(Minv[0] * qh.x + Minv[1] * qh.y + Minv[2] * qh.z,
                              Minv[3] * qh.x + Minv[4] * qh.y + Minv[5] * qh.z,
                              Minv[6] * qh.x + Minv[7] * qh.y + Minv[8] * qh.z);
    float3 best;
    int fb = 0;
    if (exact) {
        /* Eq. 15 as printed: unconstrained first, then the best feasible smaller support */
        best = (float3)(0.0f);
        float best_res = dot(qh, qh);
        for (int k = 0; k < N_SUPPORTS; ++k) {
            __constant float *P = solvers + 9 * k;
            float3 pk = (float3)(P[0] * qh.x + P[1] * qh.y + P[2] * qh.z,
                                 P[3] * qh.x + P[4] * qh.y + P[5] * qh.z,
                                 P[6] * qh.x + P[7] * qh.y + P[8] * qh.z);
            const float tol = -1e-6f * fmax(fmax(fabs(qh.x), fabs(qh.y)), fabs(qh.z));
            if (pk.x < tol || pk.y < tol || pk.z < tol) { if (k == 0) fb = 1; continue; }
            pk = fmax(pk, (float3)(0.0f));
            float3 r = (float3)(M[0] * pk.x + M[1] * pk.y + M[2] * pk.z,
                                M[3] * pk.x + M[4] * pk.y + M[5] * pk.z,
                                M[6] * pk.x + M[7] * pk.y + M[8] * pk.z) - qh;
            const float res = dot(r, r);
            if (k == 0) { best = pk; best_res = res; break; }
            if (res < best_res) { best = pk; best_res = res; }
        }
    } else {
        /* the unconstrained solve; outside the gamut, toward the neutral of the
         * same L + M until it enters (kirk11.gamut_map) */
        const float pn = fmax(qh.x + qh.y, 0.0f)
                         / (M[0] + M[1] + M[2] + M[3] + M[4] + M[5]);
        float t = 1.0f;
        if (p.x < 0.0f) t = fmin(t, pn / (pn - p.x));
        if (p.y < 0.0f) t = fmin(t, pn / (pn - p.y));
        if (p.z < 0.0f) t = fmin(t, pn / (pn - p.z));
        t = clamp(t, 0.0f, 1.0f);
        best = fmax((float3)(pn) + t * (p - (float3)(pn)), (float3)(0.0f));
        fb = (p.x < 0.0f || p.y < 0.0f || p.z < 0.0f) ? 1 : 0;
    }
    *lum_out = lum;
    *fb_out = fb;
    return best;
}

__kernel void kirk11_shift(__global const float *q, const int n, const float16 parv,
                           __constant float *Minv, __constant float *solvers,
                           __constant float *M,
                           __constant float *D, __global float *rgb_out,
                           __global float *w_out, __global float *logY,
                           __global int *fallbacks)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    float par[16];                          /* the frame's shift: an argument, no upload */
    unpack16(parv, par);
    float lum;
    int fb;
    const float3 best = shift_pixel(vload4(i, q), par, Minv, solvers, M, &lum, &fb,
                                     par[14] > 0.5f);
    if (fb) atomic_inc(fallbacks);
    const float3 o = (float3)(D[0] * best.x + D[1] * best.y + D[2] * best.z,
                              D[3] * best.x + D[4] * best.y + D[5] * best.z,
                              D[6] * best.x + D[7] * best.y + D[8] * best.z);
    vstore3(o, i, rgb_out);
    w_out[i] = lum;
    logY[i] = log10(fmax(M_YR * o.x + M_YG * o.y + M_YB * o.z, Y_FLOOR));
}

/* The Purkinje effect on other operators (effects/purkinje.py), in place on working
 * RGB (cd/m^2): to LMSR through H (4 x 3, row-major; to_lmsr), the shift with the
 * gamut map and D = I (shift_pixel), then the shifted colour scaled back to the
 * source's photopic luminance Y (the operator models rod luminance itself; where the
 * shifted colour has no luminance, the source). Fallbacks are counted per work-group
 * (PURKINJE_WG items, a build option), then once into ``fallbacks``. */
/* shift_pixel's gamut-map path on four pixels, a lane each (l, m, s, r: their LMSR):
 * the display RGB solution in *pr, *pg, *pb; the lanes that fell back are -1 in *fb.
 * The same operations as shift_pixel's, in vector form (PoCL runs the scalar form
 * per work-item: measured 2.2x slower on a CPU). */
inline void shift_gamut4(const float4 l, const float4 m, const float4 s, const float4 r,
                         const float *par, __constant float *Minv, __constant float *M,
                         float4 *pr, float4 *pg, float4 *pb, int4 *fb)
{
    const float area = par[0], k1 = par[1], k2 = par[2], gain = par[3];
    const float dwx = par[11], dwy = par[12], dwz = par[13];
    const float4 tl = l * dwx * area, tm = m * dwy * area, ts = s * dwz * area, tr = r * area;
    const float4 gl = rsqrt(1.0f + REGULATION_C * (tl + k1 * tr));      /* Eq. 10 */
    const float4 gm = rsqrt(1.0f + REGULATION_C * (tm + k1 * tr));
    const float4 gs = rsqrt(1.0f + REGULATION_C * (ts + k2 * tr));
    const float4 nl = gl / L_MAX_F, nm = gm / M_MAX_F, ns = gs / S_MAX_F;
    const float4 lum = ALPHA_F * nl + (1.0f - ALPHA_F) * nm;             /* Eq. 16 */
    const float4 rod = gain * tr;
    const float4 d0 = par[4] * k1 * (par[7] * nm - par[8] * nl) * rod;   /* Eq. 12 */
    const float4 d1 = par[5] * (par[9] * ns - par[10] * lum) * rod;
    const float4 d2 = par[6] * lum * rod;
    const float4 qx = l + (A_INV_00 * d0 + A_INV_02 * d2) / (dwx * area);
    const float4 qy = m + (A_INV_10 * d0 + A_INV_12 * d2) / (dwy * area);
    const float4 qz = s + (d1 + d2) / (dwz * area);
    const float4 px = Minv[0] * qx + Minv[1] * qy + Minv[2] * qz;
    const float4 py = Minv[3] * qx + Minv[4] * qy + Minv[5] * qz;
    const float4 pz = Minv[6] * qx + Minv[7] * qy + Minv[8] * qz;
    const float4 pn = fmax(qx + qy, 0.0f) / (M[0] + M[1] + M[2] + M[3] + M[4] + M[5]);
    float4 t = (float4)(1.0f);
    t = select(t, fmin(t, pn / (pn - px)), px < 0.0f);
    t = select(t, fmin(t, pn / (pn - py)), py < 0.0f);
    t = select(t, fmin(t, pn / (pn - pz)), pz < 0.0f);
    t = clamp(t, 0.0f, 1.0f);
    *pr = fmax(pn + t * (px - pn), 0.0f);
    *pg = fmax(pn + t * (py - pn), 0.0f);
    *pb = fmax(pn + t * (pz - pn), 0.0f);
    *fb = (px < 0.0f) | (py < 0.0f) | (pz < 0.0f);
}

/* The shifted colour scaled back to the source's photopic Y (yp: its own; where it
 * has none, the source a). */
inline float3 keep_y(const float3 a, const float3 p)
{
    const float yp = M_YR * p.x + M_YG * p.y + M_YB * p.z;
    const float ya = M_YR * a.x + M_YG * a.y + M_YB * a.z;
    return yp > 0.0f ? p * (ya / yp) : a;
}

__kernel void purkinje_rgb(__global float *rgb, const int n, __constant float *H,
                           const float16 parv, __constant float *Minv,
                           __constant float *solvers, __constant float *M,
                           __global int *fallbacks)
{
    float par[16];                          /* the frame's shift: an argument, no upload */
    unpack16(parv, par);
    __local int fbs[PURKINJE_WG];
    const int q = get_global_id(0), lid = get_local_id(0), i0 = ITEM_PIXELS(4) * q;
    int fb = 0;
    if (VECTOR_PIXELS && i0 + 3 < n) {                  /* four pixels, a lane each */
        float4 r, g, b;
        load_rgb4(q, rgb, &r, &g, &b);
        float4 pr, pg, pb;
        int4 f;
        shift_gamut4(H[0] * r + H[1] * g + H[2] * b, H[3] * r + H[4] * g + H[5] * b,
                     H[6] * r + H[7] * g + H[8] * b, H[9] * r + H[10] * g + H[11] * b,
                     par, Minv, M, &pr, &pg, &pb, &f);
        const float4 yp = M_YR * pr + M_YG * pg + M_YB * pb;
        const float4 k = (M_YR * r + M_YG * g + M_YB * b) / yp;
        const int4 keep = yp > 0.0f;
        store_rgb4(q, rgb, select(r, pr * k, keep), select(g, pg * k, keep),
                   select(b, pb * k, keep));
        fb = -(f.x + f.y + f.z + f.w);
    } else {
        for (int i = i0; i < min(i0 + ITEM_PIXELS(4), n); ++i) {
            const float3 a = vload3(i, rgb);
            const float4 qq = (float4)(H[0] * a.x + H[1] * a.y + H[2] * a.z,
                                       H[3] * a.x + H[4] * a.y + H[5] * a.z,
                                       H[6] * a.x + H[7] * a.y + H[8] * a.z,
                                       H[9] * a.x + H[10] * a.y + H[11] * a.z);
            float lum;
            int f;
            vstore3(keep_y(a, shift_pixel(qq, par, Minv, solvers, M, &lum, &f, 0)), i, rgb);
            fb += f;
        }
    }
    fbs[lid] = fb;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0) {
        int c = 0;
        for (int k = 0; k < PURKINJE_WG; ++k) c += fbs[k];
        if (c) atomic_add(fallbacks, c);
    }
}

/* Range reduction (Durand & Dorsey 2002), mesopic dimming and (RGB input) the
 * blend from the source by w. */
__kernel void kirk11_compose(__global const float *src, __global const float *shifted,
                             __global const float *w, __global const float *logY,
                             __global const float *base, const int n,
                             __global const float *rp, const float beta, const float gamma,
                             const float out_scale, const int blend, __global float *out,
                             const int dim_all)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float c = rp[0], base_max = rp[1];          /* kirk11_range */
    const float ly = logY[i], b = base[i];
    const float ly_out = c * (b - base_max) + (ly - b);
    const float s = exp10(ly_out - ly);
    const float wi = w[i];
    const float dim = fmax(1.0f - wi / beta, gamma);
    float3 o = vload3(i, shifted) * (dim_all ? s : s * dim);
    if (blend) {
        const float t = clamp(wi / beta, 0.0f, 1.0f);
        const float3 sc = vload3(i, src);
        const float ys = fmax(M_YR * sc.x + M_YG * sc.y + M_YB * sc.z, Y_FLOOR);
        o = (1.0f - t) * sc * (exp10(ly_out) / ys) + t * o;
    }
    /* default mode: the whole pixel dimmed; the absolute-level gain
     * (kirk11.KirkObserver.finish) and the clamp follow on the host */
    vstore3(fmax(o * ((dim_all ? dim : 1.0f) * out_scale), (float3)(0.0f)), i, out);
}

/* The frame's reductions, per work-group (Kahan in float32; the host adds the groups
 * in float64), two values per group in `partial` (LOG_FLOOR: 1e-6):
 *   mode 0, x = LMSR (4 per pixel): ln max(R, 1e-6), ln max(L + M, 1e-6)  (logmean)
 *   mode 1, x = a plane:            x, 0                                  (w_mean, Eq. 16)
 *   mode 2, x = display-linear RGB: ln max(Y / u, 1e-6), 0                (anchor_gain)
 * Four pixels per step in float4 (PoCL vectorises log on float4, not across items). */
inline float4 kirk_terms4(__global const float *x, const int q, const int mode,
                          const float inv_u, float4 *second, float4 *lit)
{
    /* lit: 1 where the pixel is metered (above LOG_FLOOR: models/metering.py's rule,
     * an unlit pixel -- exact zeros, black borders -- adds nothing to a log-average) */
    if (mode == 0) {
        const float4 a = vload4(4 * q, x), b = vload4(4 * q + 1, x),
                     c = vload4(4 * q + 2, x), d = vload4(4 * q + 3, x);
        const float4 lm = (float4)(a.x + a.y, b.x + b.y, c.x + c.y, d.x + d.y),
                     r = (float4)(a.w, b.w, c.w, d.w);
        *lit = select((float4)(0.0f), (float4)(1.0f), isgreater(fmax(lm, r), (float4)(LOG_FLOOR)));
        *second = *lit * log(fmax(lm, LOG_FLOOR));
        return *lit * log(fmax(r, LOG_FLOOR));
    }
    *second = (float4)(0.0f);
    *lit = (float4)(1.0f);
    if (mode == 1) return vload4(q, x);
    float4 r, g, b;
    load_rgb4(q, x, &r, &g, &b);
    const float4 y = (M_YR * r + M_YG * g + M_YB * b) * inv_u;
    *lit = select((float4)(0.0f), (float4)(1.0f), isgreater(y, (float4)(LOG_FLOOR)));
    return *lit * log(fmax(y, LOG_FLOOR));
}

inline float3 kirk_terms1(__global const float *x, const int i, const int mode,
                          const float inv_u)
{
    if (mode == 0) {
        const float4 v = vload4(i, x);
        const float lm = v.x + v.y;
        if (!(fmax(lm, v.w) > LOG_FLOOR)) return (float3)(0.0f);
        return (float3)(log(fmax(v.w, LOG_FLOOR)), log(fmax(lm, LOG_FLOOR)), 1.0f);
    }
    if (mode == 1) return (float3)(x[i], 0.0f, 1.0f);
    const float3 c = vload3(i, x);
    const float y = (M_YR * c.x + M_YG * c.y + M_YB * c.z) * inv_u;
    if (!(y > LOG_FLOOR)) return (float3)(0.0f);
    return (float3)(log(fmax(y, LOG_FLOOR)), 0.0f, 1.0f);
}

/* Sums over n pixels: (first term, second term, pixels metered) per group. */
__kernel void kirk11_sums(__global const float *x, const int n, const int mode,
                          const float inv_u, __global float4 *partial,
                          __local float4 *scratch)
{
    const int gid = get_global_id(0), gsz = get_global_size(0);
    float4 s1 = 0.0f, s2 = 0.0f, s3 = 0.0f, c1 = 0.0f, c2 = 0.0f, c3 = 0.0f, v, y, t, sec, lit;
    const int nq = n / 4;
    int qa, qb, qs;
    share_range(nq, &qa, &qb, &qs);
    for (int q = qa; q < qb; q += qs) {
#define KAHAN4(S, C, V) v = (V); y = v - C; t = S + y; C = (t - S) - y; S = t;
        KAHAN4(s1, c1, kirk_terms4(x, q, mode, inv_u, &sec, &lit))
        KAHAN4(s2, c2, sec)
        KAHAN4(s3, c3, lit)
#undef KAHAN4
    }
    float a = (s1.x + s1.y) + (s1.z + s1.w), b = (s2.x + s2.y) + (s2.z + s2.w),
          k = (s3.x + s3.y) + (s3.z + s3.w);
    for (int i = 4 * nq + gid; i < n; i += gsz) {
        const float3 e = kirk_terms1(x, i, mode, inv_u);
        a += e.x;
        b += e.y;
        k += e.z;
    }
    group_sum4(scratch, (float4)(a, b, k, 0.0f), partial);
}

/* Kirk11.finish (operators/kirk11.py) in place on display-linear RGB: the
 * absolute-level gain (anchor_gain) under the signal ceiling, the highlight shoulder
 * (knee 0: none, the paper mode, gain 1) and the clamp. Four pixels per work-item,
 * launched over ceil(n / 4) items. */
__kernel void kirk11_finish(__global float *rgb, const int n, __global const float *gp,
                            const float inv_white, const float knee)
{
    const float gain = gp[0];                          /* kirk11_gain */
    const int q = get_global_id(0);
    const int i0 = ITEM_PIXELS(4) * q;            /* common.h */
    if (i0 >= n) return;
    if (!VECTOR_PIXELS || i0 + 4 > n) {
        for (int i = i0; i < min(i0 + ITEM_PIXELS(4), n); ++i) {
            const float3 c = shoulder3(fmin(vload3(i, rgb) * gain, SIGNAL_CEILING),
                                       inv_white, knee);
            vstore3(clamp(c, 0.0f, DISPLAY_LINEAR_MAX), i, rgb);
        }
        return;
    }
    float4 r, g, b;
    load_rgb4(q, rgb, &r, &g, &b);
    r = fmin(r * gain, SIGNAL_CEILING);
    g = fmin(g * gain, SIGNAL_CEILING);
    b = fmin(b * gain, SIGNAL_CEILING);
    shoulder4(&r, &g, &b, inv_white, knee);
    store_rgb4(q, rgb, clamp(r, 0.0f, DISPLAY_LINEAR_MAX), clamp(g, 0.0f, DISPLAY_LINEAR_MAX),
               clamp(b, 0.0f, DISPLAY_LINEAR_MAX));
}

/* Durand & Dorsey 2002's base range (models/durand2002.py, BaseRange): the counts of n
 * base values (log10) in nbins bins; bin k = [e_k, e_k+1), e_k = (k num + off) / den
 * exactly in float (base_hist_edges: den a power of two), clamped to the bins, NaN in
 * bin 0: the host's bins (base_hist_bins) bit for bit. A stretch of values per
 * work-item, a run of one bin added with one atomic (the base layer is smooth). */
inline float base_edge(const int k, const int num, const int off, const float inv_den)
{
    return (float)(k * num + off) * inv_den;
}

__kernel void base_histogram(__global const float *v, const int n, const int nbins,
                             const float lo, const float scale, const int num,
                             const int off, const float inv_den,
                             __global int *hist)
{
    const int g = get_global_id(0), gs = get_global_size(0);
    const int per = (n + gs - 1) / gs, a = g * per, b = min(n, a + per);
    int cur = -1, run = 0;
    for (int i = a; i < b; ++i) {
        const float x = v[i];
        int k = (int)clamp(floor((x - lo) * scale), 0.0f, (float)(nbins - 1));
        if (k > 0 && x < base_edge(k, num, off, inv_den))
            --k;
        else if (k < nbins - 1 && x >= base_edge(k + 1, num, off, inv_den))
            ++k;
        if (k != cur) {
            if (run) atomic_add(&hist[cur], run);
            cur = k;
            run = 0;
        }
        ++run;
    }
    if (run) atomic_add(&hist[cur], run);
}

/* The base range's compression on the device (models/durand2002.py BaseRange.result and
 * compression; issue 47: no read between the base layer and the composition): from the
 * exact extremes mm (bilateral.cl z_minmax_final) or, for percentiles, the base
 * histogram (base_histogram): rp[0] = c, rp[1] = the top (base_max). A percentile's
 * rank r = p (n - 1) / 100 comes as its floor r_k (an integer: the first bin whose
 * cumulative count passes it is the host's searchsorted) and fraction f_k. One
 * work-group of KIRK_RANGE_WG items (a build option). */
__kernel void kirk11_range(__global const float *mm, __global const int *hist,
                           const int nbins, const int exact, const int n,
                           const int r_lo, const float f_lo, const int r_hi, const float f_hi,
                           const float hist_lo, const float width, const float log_target,
                           __global float *rp)
{
    __local int chunk[KIRK_RANGE_WG];
    __local int found[4];                       /* (bin, count before it) of lo, hi */
    const int lid = get_local_id(0), lsz = get_local_size(0);
    const float lo = mm[0], hi = mm[1];
    if (!exact) {
        const int per = (nbins + lsz - 1) / lsz, a = min(nbins, lid * per),
                  b = min(nbins, a + per);
        int s = 0;
        for (int k = a; k < b; ++k) s += hist[k];
        chunk[lid] = s;
        barrier(CLK_LOCAL_MEM_FENCE);
        if (lid == 0) {                         /* exclusive prefix of the chunks */
            int t = 0;
            for (int j = 0; j < lsz; ++j) {
                const int v = chunk[j];
                chunk[j] = t;
                t += v;
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        const int ranks[2] = {r_lo, r_hi};
        for (int p = 0; p < 2; ++p) {
            int cum = chunk[lid];
            const int end = cum + s;
            if (cum <= ranks[p] && ranks[p] < end) {
                for (int k = a; k < b; ++k) {
                    if (cum + hist[k] > ranks[p]) {
                        found[2 * p] = k;
                        found[2 * p + 1] = cum;
                        break;
                    }
                    cum += hist[k];
                }
            }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid != 0) return;
    float v_lo = lo, v_hi = hi;
    if (n <= 0) {
        v_lo = 0.0f;
        v_hi = 0.0f;
    } else if (!exact) {
        const float fr[2] = {f_lo, f_hi};
        const int ranks[2] = {r_lo, r_hi};
        float v[2];
        for (int p = 0; p < 2; ++p) {
            const int k = found[2 * p];
            const float x = hist_lo + ((float)k + ((float)(ranks[p] - found[2 * p + 1]) + fr[p]
                                                   + 0.5f) / (float)hist[k]) * width;
            v[p] = fmin(fmax(x, lo), hi);
        }
        v_lo = v[0];
        v_hi = v[1];
    }
    const float span = v_hi - v_lo;
    rp[0] = span > 0.0f ? fmin(1.0f, log_target / span) : 1.0f;
    rp[1] = v_hi;
}

/* anchor_gain (models/kirk2011.py) on the device from kirk11_sums' groups (mode 2):
 * the log-average of the composed frame's luminance over white, la (LOG_FLOOR where
 * nothing is lit), then gain[0] = key / la, ``key`` the host's scene key of the adapted
 * cone level times the transient factor. One work-item. */
__kernel void kirk11_gain(__global const float4 *partial, const int groups, const float key,
                          __global float *gain)
{
    if (get_global_id(0) != 0) return;
    float s = 0.0f, k = 0.0f, cs = 0.0f, ck = 0.0f;
    for (int g = 0; g < groups; ++g) {
        const float4 p = partial[g];
        float y = p.x - cs, t = s + y;
        cs = (t - s) - y;
        s = t;
        y = p.z - ck;
        t = k + y;
        ck = (t - k) - y;
        k = t;
    }
    const float la = k > 0.0f ? fmax(exp(s / k), LOG_FLOOR) : LOG_FLOOR;
    gain[0] = key / la;
}
