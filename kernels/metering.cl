/* Metering reductions (two-stage): weighted sums of Y, log Y, Y', log Y' and
 * the maxima, then a log-luminance histogram for percentile metering. The sums
 * are over the lit pixels (Y or Y' above log_floor, models/metering.py): a pixel
 * at or below the floor adds to the maxima only.
 *
 * Weight modes: 0 uniform; 1 centre-weighted (w_in inside a disc of radius
 * p2 px at (p0, p1), w_out outside); 2 Gaussian spot at (p0, p1) px with
 * sigma p2 px; 3 a weight image (mask, full-frame, row-major). Pixel coordinates are of the full frame: a band starting at
 * row y0 meters exactly like the whole image. */

#define NMETER 8  /* lit pixels' sum w, sum wY, sum w lnY, sum wY', sum w lnY'; max Y, max Y'; pad */

inline float meter_weight(int mode, float x, float y, float p0, float p1, float p2,
                          float w_in, float w_out)
{
    if (mode == 0) return 1.0f;
    float dx = x - p0, dy = y - p1, d2 = dx * dx + dy * dy;
    if (mode == 1) return d2 <= p2 * p2 ? w_in : w_out;
    return exp(-0.5f * d2 / (p2 * p2));
}

/* Kahan-compensated accumulation: float32 sums over millions of pixels. */
inline void kahan(float *s, float *c, float v)
{
    float y = v - *c;
    float t = *s + y;
    *c = (t - *s) - y;
    *s = t;
}

/* Store each work-item's record in scratch and reduce them into record 0, read by
 * work-item 0 (sums 0-4 add, maxima 5-6 take the max). Local size must be a power of
 * two. */
inline void reduce_records(__local float *scratch, const int lid, const int lsz,
                           const float *s, const float mY, const float mYs)
{
    __local float *me = scratch + lid * NMETER;
    for (int k = 0; k < 5; ++k) me[k] = s[k];
    me[5] = mY; me[6] = mYs; me[7] = 0.0f;
    barrier(CLK_LOCAL_MEM_FENCE);
#if DEVICE_CPU
    /* one barrier, the first work-item adds the records in order (common.h
     * group_sum4_into says why) */
    if (lid == 0)
        for (int j = 1; j < lsz; ++j) {
            __local float *o = scratch + j * NMETER;
            for (int k = 0; k < 5; ++k) me[k] += o[k];
            me[5] = fmax(me[5], o[5]);
            me[6] = fmax(me[6], o[6]);
        }
#else
    for (int off = lsz / 2; off > 0; off >>= 1) {
        if (lid < off) {
            __local float *o = scratch + (lid + off) * NMETER;
            for (int k = 0; k < 5; ++k) me[k] += o[k];
            me[5] = fmax(me[5], o[5]);
            me[6] = fmax(me[6], o[6]);
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
#endif
}

__kernel void meter_partial(__global const float *Y, __global const float *Ys,
                            const int n, const int width, const int y0,
                            const int mode, const float p0, const float p1, const float p2,
                            const float w_in, const float w_out, const float log_floor,
                            __global const float *mask,
                            __global float *partial, __local float *scratch)
{
    const int lid = get_local_id(0), lsz = get_local_size(0);
    float s[5] = {0, 0, 0, 0, 0}, c[5] = {0, 0, 0, 0, 0};
    float mY = 0.0f, mYs = 0.0f;
    int start = get_global_id(0);
    if (mode == 0) {
        /* uniform weights: four pixels at a time in float4 (PoCL does not vectorise
         * scalar log across work-items), ln = log2 ln2, log2 inline (common.h) */
        float4 s0 = 0.0f, s1 = 0.0f, s2 = 0.0f, s3 = 0.0f, s4 = 0.0f;
        float4 c0 = 0.0f, c1 = 0.0f, c2 = 0.0f, c3 = 0.0f, c4 = 0.0f;
        float4 m1 = 0.0f, m2 = 0.0f;
        const int nq = n / 4;
        const float4 lf = (float4)(log_floor);
        int qa, qb, qs;
        share_range(nq, &qa, &qb, &qs);
        for (int q = qa; q < qb; q += qs) {
            const float4 l = vload4(q, Y), ls = vload4(q, Ys);
            const float4 w = select((float4)(0.0f), (float4)(1.0f), isgreater(fmax(l, ls), lf));
            float4 v, y, t;
#define KAHAN4(S, C, V) v = (V); y = v - C; t = S + y; C = (t - S) - y; S = t;
            KAHAN4(s0, c0, w)
            KAHAN4(s1, c1, w * l)
            KAHAN4(s2, c2, w * (log2_positive4(fmax(l, lf)) * M_LN2_F))
            KAHAN4(s3, c3, w * ls)
            KAHAN4(s4, c4, w * (log2_positive4(fmax(ls, lf)) * M_LN2_F))
#undef KAHAN4
            m1 = fmax(m1, l);
            m2 = fmax(m2, ls);
        }
        s[0] = (s0.x + s0.y) + (s0.z + s0.w);          /* lit pixels */
        s[1] = (s1.x + s1.y) + (s1.z + s1.w);
        s[2] = (s2.x + s2.y) + (s2.z + s2.w);
        s[3] = (s3.x + s3.y) + (s3.z + s3.w);
        s[4] = (s4.x + s4.y) + (s4.z + s4.w);
        mY = fmax(fmax(m1.x, m1.y), fmax(m1.z, m1.w));
        mYs = fmax(fmax(m2.x, m2.y), fmax(m2.z, m2.w));
        start = 4 * nq + get_global_id(0);          /* the scalar tail below */
    }
    for (int i = start; i < n; i += get_global_size(0)) {
        float x = (float)(i % width) + 0.5f, y = (float)(y0 + i / width) + 0.5f;
        float w = mode == 3 ? mask[(size_t)y0 * width + i]
                            : meter_weight(mode, x, y, p0, p1, p2, w_in, w_out);
        float l = Y[i], ls = Ys[i];
        w = fmax(l, ls) > log_floor ? w : 0.0f;
        kahan(&s[0], &c[0], w);
        kahan(&s[1], &c[1], w * l);
        kahan(&s[2], &c[2], w * log(fmax(l, log_floor)));
        kahan(&s[3], &c[3], w * ls);
        kahan(&s[4], &c[4], w * log(fmax(ls, log_floor)));
        mY = fmax(mY, l);
        mYs = fmax(mYs, ls);
    }
    reduce_records(scratch, lid, lsz, s, mY, mYs);
    __local float *me = scratch;
    if (lid == 0)
        for (int k = 0; k < NMETER; ++k) partial[get_group_id(0) * NMETER + k] = me[k];
}

/* Stage 2: one work-group folds `groups` partial records into one. */
__kernel void meter_final(__global const float *partial, const int groups,
                          __global float *result, __local float *scratch)
{
    const int lid = get_local_id(0), lsz = get_local_size(0);
    float s[5] = {0, 0, 0, 0, 0}, c[5] = {0, 0, 0, 0, 0};
    float mY = 0.0f, mYs = 0.0f;
    for (int g = lid; g < groups; g += lsz) {
        __global const float *p = partial + g * NMETER;
        for (int k = 0; k < 5; ++k) kahan(&s[k], &c[k], p[k]);
        mY = fmax(mY, p[5]);
        mYs = fmax(mYs, p[6]);
    }
    reduce_records(scratch, lid, lsz, s, mY, mYs);
    __local float *me = scratch;
    if (lid == 0)
        for (int k = 0; k < NMETER; ++k) result[k] = me[k];
}

/* Histogram of log10(L) over [lo, hi) in nbins bins (below -> bin 0, above ->
 * last bin) of the values above floor_L, accumulated into hist (which the host zeroes once per frame). */
__kernel void log_histogram(__global const float *L, const int n, const float lo,
                            const float hi, const int nbins, const float floor_L,
                            __global int *hist, __local int *lh)
{
    const int lid = get_local_id(0), lsz = get_local_size(0);
    for (int b = lid; b < nbins; b += lsz) lh[b] = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    const float scale = nbins / (hi - lo);
    for (int i = get_global_id(0); i < n; i += get_global_size(0)) {
        float v = L[i];
        if (!(v > floor_L)) continue;       /* at or below the floor: not metered */
        int b = (int)floor((log10(v) - lo) * scale);
        b = clamp(b, 0, nbins - 1);
        atomic_inc(&lh[b]);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int b = lid; b < nbins; b += lsz)
        if (lh[b]) atomic_add(&hist[b], lh[b]);
}

/* Illuminant estimate (models/durand2000.py): per work-group sums of Y*r, Y*g, Y*b, Y*Y
 * -- a luminance-weighted grey world, dominated by the bright regions and the
 * light sources. The host adds the group records in float64. */
__kernel void illuminant_partial(__global const float *rgb, __global const float *Y,
                                 const int n, __global float4 *partial,
                                 __local float4 *scratch)
{
    const int gid = get_global_id(0), gsz = get_global_size(0);
    /* four pixels per step in float4 (PoCL vectorises float4 within a work-item, not
       scalar code across them: 1080p 11 -> 3 ms), then the scalar tail */
    float4 s0 = 0.0f, s1 = 0.0f, s2 = 0.0f, s3 = 0.0f;
    float4 c0 = 0.0f, c1 = 0.0f, c2 = 0.0f, c3 = 0.0f, v, y4, t;
    const int nq = n / 4;
    int qa, qb, qs;
    share_range(nq, &qa, &qb, &qs);
    for (int q = qa; q < qb; q += qs) {
        float4 r, g, b;
        load_rgb4(q, rgb, &r, &g, &b);
        const float4 yq = vload4(q, Y);
#define KAHAN4(S, C, V) v = (V); y4 = v - C; t = S + y4; C = (t - S) - y4; S = t;
        KAHAN4(s0, c0, yq * r)
        KAHAN4(s1, c1, yq * g)
        KAHAN4(s2, c2, yq * b)
        KAHAN4(s3, c3, yq * yq)
#undef KAHAN4
    }
    float s[4] = {(s0.x + s0.y) + (s0.z + s0.w), (s1.x + s1.y) + (s1.z + s1.w),
                  (s2.x + s2.y) + (s2.z + s2.w), (s3.x + s3.y) + (s3.z + s3.w)};
    float c[4] = {0, 0, 0, 0};
    for (int i = 4 * nq + gid; i < n; i += gsz) {
        const float3 p = vload3(i, rgb);
        const float y = Y[i];
        kahan(&s[0], &c[0], y * p.x);
        kahan(&s[1], &c[1], y * p.y);
        kahan(&s[2], &c[2], y * p.z);
        kahan(&s[3], &c[3], y * y);
    }
    group_sum4(scratch, (float4)(s[0], s[1], s[2], s[3]), partial);
}

/* Block sums of the scene proxy (ocl_tonemap/mechanisms/analysis.py): one work-item
 * per s x s block of the full frame that this band's rows reach, summing the
 * band's working rgb in it: out[i] = (sum r, sum g, sum b, pixels). The host adds
 * the bands' sums (a block cut by a band edge gets its rows from both). With
 * lim > 0, the sums of the flare's source part rgb max(0, 1 - lim / Y) instead
 * (spencer1995.source_part: lamps smaller than a block keep their flux). */
static float4 block_acc(__global const float *rgb, const int w, const int rows,
                        const int y0, const int s, const int by, const int bx,
                        const float lim)
{
    const int ya = max(by * s - y0, 0), yb = min((by + 1) * s - y0, rows);
    const int xa = bx * s, xb = min(xa + s, w);
    float4 acc = 0.0f;
    for (int y = ya; y < yb; y++) {
        const int row = y * w;
        for (int x = xa; x < xb; x++) {
            const int k = 3 * (row + x);
            float f = 1.0f;
            if (lim > 0.0f) {
                const float Y = M_YR * rgb[k] + M_YG * rgb[k + 1] + M_YB * rgb[k + 2];
                f = Y > lim ? 1.0f - lim / Y : 0.0f;
            }
            acc += (float4)(rgb[k] * f, rgb[k + 1] * f, rgb[k + 2] * f, 1.0f);
        }
    }
    return acc;
}

__kernel void block_sums(__global const float *rgb, const int w, const int rows, const int y0,
                         const int s, const int bw, const int by0, const int nb,
                         const float lim, __global float4 *out)
{
    const int i = get_global_id(0);
    if (i >= nb * bw) return;
    out[i] = block_acc(rgb, w, rows, y0, s, by0 + i / bw, i % bw, lim);
}

/* The block means of a whole frame (rows = its height, y0 = 0) as 16-bit log2 codes,
 * three a block (the plan's proxy read in 6 bytes a block, with the metering's sums:
 * ocl_tonemap/models/metering.py log16_encode, LOG16_STEPS and LOG16_OFFSET from
 * there): 0 for 0, else 1 + LOG16_STEPS (log2 m + LOG16_OFFSET) rounded, within
 * 1..65535. */
#ifdef LOG16_STEPS
__kernel void block_means_log16(__global const float *rgb, const int w, const int rows,
                                const int s, const int bw, const int nb, const float lim,
                                __global ushort *out)
{
    const int i = get_global_id(0);
    if (i >= nb * bw) return;
    const float4 acc = block_acc(rgb, w, rows, 0, s, i / bw, i % bw, lim);
    const float m[3] = {acc.x / acc.w, acc.y / acc.w, acc.z / acc.w};
    for (int c = 0; c < 3; c++) {
        const float code = LOG16_STEPS * (log2(m[c]) + LOG16_OFFSET) + 1.0f;
        out[3 * i + c] = m[c] > 0.0f ? (ushort)clamp(rint(code), 1.0f, (float)USHRT_MAX) : (ushort)0;
    }
}
#endif

/* The sum of n float4 partials (a first stage's per-group sums), one work-group: each
 * work-item adds a strided share (Kahan-compensated), then group_sum4 in a fixed
 * order, into out[0]. The host reads it with the frame's other statistics. */
__kernel void sum4_final(__global const float4 *part, const int n, __global float4 *out,
                         __local float4 *scratch)
{
    const int lid = get_local_id(0), lsz = get_local_size(0);
    float s[4] = {0, 0, 0, 0}, c[4] = {0, 0, 0, 0};
    for (int i = lid; i < n; i += lsz) {
        const float4 v = part[i];
        kahan(&s[0], &c[0], v.x);
        kahan(&s[1], &c[1], v.y);
        kahan(&s[2], &c[2], v.z);
        kahan(&s[3], &c[3], v.w);
    }
    group_sum4(scratch, (float4)(s[0], s[1], s[2], s[3]), out);
}
