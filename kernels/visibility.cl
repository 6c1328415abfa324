/* Visibility planes (run --visibility): the target's and the surround's luminance, the
 * veil of the whole field, the threshold under the observer's state and the visibility
 * level, per pixel. Reference: ocl_tonemap/models/visibility_map.py (reference_planes,
 * float64). The threshold comes from the run's tables of log2 dL_th over log2 L_b
 * (models/threshold_tables.py: Adrian's steady threshold of both polarities, times a
 * global observer's TAF; its segments split at Adrian's joins and the operator's steps,
 * so that a lookup is exact there). TAF_LOG2_MAX, LB_FLOOR and VIS_HALF_MAX come as
 * build options from ocl_tonemap/ (backends/opencl/visibility.py, KERNEL_CONSTANTS). */

/* Means of s x s blocks of a w x h plane into cw x ch cells (the edge blocks of the
 * pixels they have: visibility_map.block_mean), x unit. One cell a work-item. */
__kernel void vis_block_means(__global const float *Y, const int w, const int h,
                              const int s, const float unit, __global float *out,
                              const int cw, const int ch)
{
    const int cx = get_global_id(0), cy = get_global_id(1);
    if (cx >= cw || cy >= ch) return;
    const int x0 = cx * s, y0 = cy * s, x1 = min(x0 + s, w), y1 = min(y0 + s, h);
    float acc = 0.0f;
    for (int y = y0; y < y1; ++y) {
        __global const float *row = Y + (size_t)y * w;
        float r = 0.0f;
        for (int x = x0; x < x1; ++x) r += row[x];
        acc += r;
    }
    out[(size_t)cy * cw + cx] = acc / (float)((x1 - x0) * (y1 - y0)) * unit;
}

/* The veil at each cell's centre: every cell's luminance times the weight of its offset
 * (models/cie146.field_weights: (2 ch - 1) x (2 cw - 1), row-major, the offset target
 * minus source as the model's convolution takes it), >= 0. One cell a work-item: a
 * GPU's way (a CPU device's veil is the host's FFT of the same cells). */
__kernel void vis_veil_cells(__global const float *cells, const int cw, const int ch,
                             __global const float *K, __global float *out)
{
    const int cx = get_global_id(0), cy = get_global_id(1);
    if (cx >= cw || cy >= ch) return;
    const int kw = 2 * cw - 1;
    float acc = 0.0f;
    for (int y = 0; y < ch; ++y) {
        __global const float *krow = K + (size_t)(ch - 1 + cy - y) * kw + (cw - 1 + cx);
        __global const float *crow = cells + (size_t)y * cw;
        for (int x = 0; x < cw; ++x) acc += krow[-x] * crow[x];
    }
    out[(size_t)cy * cw + cx] = fmax(acc, 0.0f);
}

/* Where pixel i of a grid 2^l times coarser (block centres, n of them, its edges held)
 * falls: its two cells and the weight of the second; (i + 0.5)/s - 0.5 = k + f in
 * integers (no floor: PoCL calls it out of line), 2i + 1 - s over 2s shifted by one
 * cell so that the division, a shift, is of a positive number. */
inline void vis_cells(const int i, const int n, const int l, int *c0, int *c1, float *f)
{
    const int s = 1 << l, m = 2 * i + 1 + s;                /* (2i + 1 - s) + 2s > 0 */
    const int k = (m >> (l + 1)) - 1;
    *f = (float)(m & (2 * s - 1)) * (0.5f / (float)s);
    *c0 = clamp(k, 0, n - 1);
    *c1 = clamp(k + 1, 0, n - 1);
}

/* Pixel x of a grid 2^l times coarser (gw block centres a row, its edges held),
 * bilinearly: along y (rows r0, r1 and weight ay given), then along x
 * (visibility_map.upsample). */
inline float vis_up(__global const float *g, const int gw, const int l, const int x,
                    const int y0, const int y1, const float ay)
{
    if (l == 0) return g[(size_t)y0 * gw + x];
    int x0, x1;
    float ax;
    vis_cells(x, gw, l, &x0, &x1, &ax);
    __global const float *r0 = g + (size_t)y0 * gw, *r1 = g + (size_t)y1 * gw;
    const float c0 = r0[x0] * (1.0f - ay) + r1[x0] * ay;
    const float c1 = r0[x1] * (1.0f - ay) + r1[x1] * ay;
    return c0 * (1.0f - ax) + c1 * ax;
}

/* vis_up of the four pixels x0 .. x0 + 3 (x0 a multiple of 4). On grids 8 or more times
 * coarser the four share one pair of cells (the pairs change at the cells' centres,
 * (k + 1/2) s - 1/2, between two quads): four loads, their weights x0's and steps of
 * 1/s; else pixel by pixel. */
inline float4 vis_up4(__global const float *g, const int gw, const int l, const int x0,
                      const int y0, const int y1, const float ay)
{
    __global const float *r0 = g + (size_t)y0 * gw, *r1 = g + (size_t)y1 * gw;
    if (l == 0) return vload4(0, r0 + x0);
    if (l < 3) {                      /* vis_cells of the four lanes at once, then gathers */
        const int s = 1 << l;
        const int4 m = 2 * ((int4)(x0) + (int4)(0, 1, 2, 3)) + 1 + s;
        const int4 k = (m >> (l + 1)) - 1;
        const float4 ax = convert_float4(m & (2 * s - 1)) * (0.5f / (float)s);
        const int4 c0 = clamp(k, 0, gw - 1), c1 = clamp(k + 1, 0, gw - 1);
        const float4 a0 = (float4)(r0[c0.x], r0[c0.y], r0[c0.z], r0[c0.w]);
        const float4 b0 = (float4)(r1[c0.x], r1[c0.y], r1[c0.z], r1[c0.w]);
        const float4 a1 = (float4)(r0[c1.x], r0[c1.y], r0[c1.z], r0[c1.w]);
        const float4 b1 = (float4)(r1[c1.x], r1[c1.y], r1[c1.z], r1[c1.w]);
        return (a0 * (1.0f - ay) + b0 * ay) * (1.0f - ax) + (a1 * (1.0f - ay) + b1 * ay) * ax;
    }
    int c0, c1;
    float a;
    vis_cells(x0, gw, l, &c0, &c1, &a);
    const float v0 = r0[c0] * (1.0f - ay) + r1[c0] * ay;
    const float v1 = r0[c1] * (1.0f - ay) + r1[c1] * ay;
    const float4 ax = a + (float4)(0.0f, 1.0f, 2.0f, 3.0f) / (float)(1 << l);
    return v0 * (1.0f - ax) + v1 * ax;
}

/* A table's value at log2 L_b = lg: its segment (seg: [n, starts, steps, offsets,
 * total nodes]), then linear between the segment's nodes (threshold_tables.table_lookup). */
inline float table_at(const float lg, __constant float *seg, __global const float *t)
{
    const int n = (int)seg[0];
    int k = 0;
    for (int j = 1; j < n; ++j) k += lg >= seg[1 + j];
    const int off = (int)seg[1 + 2 * n + k];
    const int end = (int)seg[2 + 2 * n + k];            /* the next offset, or the total */
    const float u = clamp((lg - seg[1 + k]) * seg[1 + n + k], 0.0f, (float)(end - off - 1));
    const int i = min((int)u, end - off - 2);             /* (u >= 0: truncation floors) */
    const float f = u - (float)i;
    return t[off + i] * (1.0f - f) + t[off + i + 1] * f;
}

/* table_at of four pixels (log2 L_b lg, rows by polarity: row_off nodes in): the
 * segments found for the four at once, the nodes gathered. */
inline float4 table_at4(const float4 lg, const int4 row_off, __constant float *seg,
                        __global const float *t)
{
    const int n = (int)seg[0];
    int4 k = (int4)(0);
    for (int j = 1; j < n; ++j) k -= lg >= (float4)(seg[1 + j]);
    const float4 start = (float4)(seg[1 + k.x], seg[1 + k.y], seg[1 + k.z], seg[1 + k.w]);
    const float4 step = (float4)(seg[1 + n + k.x], seg[1 + n + k.y], seg[1 + n + k.z],
                                 seg[1 + n + k.w]);
    const int4 off = convert_int4((float4)(seg[1 + 2 * n + k.x], seg[1 + 2 * n + k.y],
                                           seg[1 + 2 * n + k.z], seg[1 + 2 * n + k.w]));
    const int4 end = convert_int4((float4)(seg[2 + 2 * n + k.x], seg[2 + 2 * n + k.y],
                                           seg[2 + 2 * n + k.z], seg[2 + 2 * n + k.w]));
    const float4 u = clamp((lg - start) * step, (float4)(0.0f), convert_float4(end - off - 1));
    const int4 i = min(convert_int4(u), end - off - 2);
    const float4 f = u - convert_float4(i);
    const int4 at = off + i + row_off;
    const float4 t0 = (float4)(t[at.x], t[at.y], t[at.z], t[at.w]);
    const float4 t1 = (float4)(t[at.x + 1], t[at.y + 1], t[at.z + 1], t[at.w + 1]);
    return t0 * (1.0f - f) + t1 * f;
}

/* The run's scalars (the float16 argument; backends/opencl/visibility.py planes()). */
#define V_GAIN 0            /* the ocular media's gain (the states hold the light behind it) */
#define V_LA 1              /* a global observer's cone level, scene cd/m^2 */
#define V_NODES 2           /* the tables' nodes (a row's length) */
#define V_ROD 3             /* a per-pixel observer's rod ratio */

/* log2 dL_th of a pixel: its polarity's row of the tables, with a per-pixel observer
 * (OBSERVER_LEDDA04) its TAF: steady gain (the third row) over its gain now, clipped
 * to 1 .. TAF_MAX; and its cone level La. */
inline float vis_log2_threshold(const float Lb, const float lg, const int negative,
                                __constant float *seg, __global const float *tab,
                                __global const float *state, const int stride, const int i,
                                const float *p, float *La)
{
    const int nodes = (int)p[V_NODES];
    float r = table_at(lg, seg, tab + (negative ? nodes : 0));
#ifdef OBSERVER_LEDDA04
    const float2 o = ledda04_observer(state, stride, i, Lb * p[V_GAIN], p[V_ROD]);
    const float ss = table_at(lg, seg, tab + 2 * nodes);
    r += clamp(ss - log2(fmax(o.x, 1.0e-30f)), 0.0f, TAF_LOG2_MAX);
    *La = o.y / p[V_GAIN];
#else
    *La = p[V_LA];
#endif
    return r;
}

/* One plane value out: float, or half (held at half's largest where beyond it,
 * counted in *over). */
inline void vis_store(const float v, const size_t at, __global void *out, int *over)
{
#if VIS_HALF
    *over += v > VIS_HALF_MAX;
    vstore_half_rte(fmin(v, VIS_HALF_MAX), at, (__global half *)out);
#else
    ((__global float *)out)[at] = v;
#endif
}

/* The planes of one pixel (x, y): La, Lveil, Lb, dLth, VL interleaved
 * (visibility_map.PLANES).
 *   tg, sg, vg: the target's and the surround's blurred grids, the veil's cells, each
 *   with its width, height and log2 of its step;
 *   tab: the run's tables on their segments (seg); state: ledda04's per-pixel state
 *   (OBSERVER_LEDDA04: its planes `stride` floats each). */
#define VIS_GRIDS __global const float *tg, const int tw, const int th, const int ts, \
                  __global const float *sg, const int sw, const int sh, const int ss, \
                  __global const float *vg, const int vw, const int vh, const int vs
#define VIS_GRID_ARGS tg, tw, th, ts, sg, sw, sh, ss, vg, vw, vh, vs

/* The three grids' rows at row y: each grid's two rows and the second's weight. */
typedef struct { int t0, t1, s0, s1, v0, v1; float ta, sa, va; } VisRows;

inline VisRows vis_rows(const int y, VIS_GRIDS)
{
    VisRows r;
    vis_cells(y, th, ts, &r.t0, &r.t1, &r.ta);
    vis_cells(y, sh, ss, &r.s0, &r.s1, &r.sa);
    vis_cells(y, vh, vs, &r.v0, &r.v1, &r.va);
    return r;
}

inline int vis_pixel(const int x, const int y, const int w, const VisRows r, VIS_GRIDS,
                     __constant float *seg, __global const float *tab,
                     __global const float *state, const int stride, const float *p,
                     __global void *out)
{
    const float tgt = fmax(vis_up(tg, tw, ts, x, r.t0, r.t1, r.ta), 0.0f);
    const float sur = fmax(vis_up(sg, sw, ss, x, r.s0, r.s1, r.sa), 0.0f);
    const float veil = fmax(vis_up(vg, vw, vs, x, r.v0, r.v1, r.va), 0.0f);
    const float Lb = fmax(sur + veil, LB_FLOOR);
    const float dL = tgt - sur;
    const int i = y * w + x;
    float La;
    const float dl = exp2(vis_log2_threshold(Lb, log2(Lb), dL < 0.0f, seg, tab, state,
                                             stride, i, p, &La));
    const size_t at = (size_t)i * 5;
    int over = 0;
    vis_store(La, at, out, &over);
    vis_store(veil, at + 1, out, &over);
    vis_store(Lb, at + 2, out, &over);
    vis_store(dl, at + 3, out, &over);
    vis_store(fabs(dL) / dl, at + 4, out, &over);
    return over;
}

/* One work-item a quad of a row (x0 = 4 gid0 .. x0 + 3; common.h ITEM_PIXELS): where the
 * quad lies whole in its row, the logarithms and the powers of two of its four pixels as
 * float4 (log2_positive4, one exp2: PoCL calls its built-ins out of line), the
 * grids and tables per pixel; elsewhere, and on GPUs, pixel by pixel. Values beyond
 * half's range are counted in *clamped. */
__kernel void vis_planes(const int w, const int h, VIS_GRIDS,
                         __constant float *seg, __global const float *tab,
                         __global const float *state, const int stride, const float16 pv,
                         __global void *out, __global int *clamped)
{
    const int K = ITEM_PIXELS(4), x0 = K * get_global_id(0), y = get_global_id(1);
    if (x0 >= w || y >= h) return;
    float p[16];
    unpack16(pv, p);
    int over = 0;
    const VisRows r = vis_rows(y, VIS_GRID_ARGS);
    if (K == 4 && x0 + 3 < w) {
        const float4 tgt = fmax(vis_up4(tg, tw, ts, x0, r.t0, r.t1, r.ta), 0.0f);
        const float4 sur = fmax(vis_up4(sg, sw, ss, x0, r.s0, r.s1, r.sa), 0.0f);
        const float4 veil = fmax(vis_up4(vg, vw, vs, x0, r.v0, r.v1, r.va), 0.0f);
        const float4 Lb = fmax(sur + veil, LB_FLOOR), dL = tgt - sur;
        const float4 lg = log2_positive4(Lb);
        const int i = y * w + x0;
        const int nodes = (int)p[V_NODES];
        float4 lt = table_at4(lg, select((int4)(0), (int4)(nodes), dL < 0.0f), seg, tab);
        float La[4] = {p[V_LA], p[V_LA], p[V_LA], p[V_LA]};
#ifdef OBSERVER_LEDDA04
        float4 Ia;
        const float4 now = ledda04_observer_now4(state, stride, i, Lb * p[V_GAIN], p[V_ROD], &Ia);
        lt += clamp(table_at4(lg, (int4)(2 * nodes), seg, tab)
                    - log2_positive4(fmax(now, 1.0e-30f)), 0.0f, TAF_LOG2_MAX);
        Ia /= p[V_GAIN];
        La[0] = Ia.x; La[1] = Ia.y; La[2] = Ia.z; La[3] = Ia.w;
#endif
        const float4 dl = exp2(lt);
        const float4 vl = fabs(dL) / dl;
        const size_t at = (size_t)i * 5;                     /* 20 values: 5 x 4 */
        const float4 v[5] = {(float4)(La[0], veil.x, Lb.x, dl.x),
                             (float4)(vl.x, La[1], veil.y, Lb.y),
                             (float4)(dl.y, vl.y, La[2], veil.z),
                             (float4)(Lb.z, dl.z, vl.z, La[3]),
                             (float4)(veil.w, Lb.w, dl.w, vl.w)};
        for (int j = 0; j < 5; ++j) {
#if VIS_HALF
            const int4 big = v[j] > (float4)(VIS_HALF_MAX);
            over -= big.x + big.y + big.z + big.w;
            vstore_half4_rte(fmin(v[j], (float4)(VIS_HALF_MAX)), 0,
                             (__global half *)out + at + 4 * j);
#else
            vstore4(v[j], 0, (__global float *)out + at + 4 * j);
#endif
        }
    } else {
        for (int x = x0; x < min(x0 + K, w); ++x)
            over += vis_pixel(x, y, w, r, VIS_GRID_ARGS, seg, tab, state, stride, p, out);
    }
    if (over) atomic_add(clamped, over);
}

/* --visibility-view: the shown frame (its output's code values, 8- or 16-bit
 * integers, or floats: SHOWN_BITS 8, 16 or 0) under VL's bands, from the planes just
 * made (their VL, interleaved fifth). paint: 4 band edges, 5 scales, 5 x 3 colours to
 * add, the hatch's colour (backends.base.ViewPaint: paint_view is the reference). Out:
 * 8-bit code values rounded as OIIO writes them (VIEW_U8) or floats, RGB. */
__kernel void vis_view(__global const void *shown, const int w, const int h,
                       __global const void *planes, __constant float *paint,
                       const int step, __global void *out)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    const size_t i = (size_t)y * w + x;
#if VIS_HALF
    const float vl = vload_half(i * 5 + 4, (__global const half *)planes);
#else
    const float vl = ((__global const float *)planes)[i * 5 + 4];
#endif
    const int band = (vl >= paint[0]) + (vl >= paint[1]) + (vl >= paint[2]) + (vl >= paint[3]);
#if SHOWN_BITS == 8
    const float3 c = convert_float3(vload3(i, (__global const uchar *)shown)) / 255.0f;
#elif SHOWN_BITS == 16
    const float3 c = convert_float3(vload3(i, (__global const ushort *)shown)) / (float)USHRT_MAX;
#else
    const float3 c = vload3(i, (__global const float *)shown);
#endif
    float3 o = clamp(c, 0.0f, 1.0f) * paint[4 + band] + vload3(band, paint + 9);
    if (band == 1 && ((x + y) / step) % 3 == 0) o = vload3(0, paint + 24);
#if VIEW_U8
    vstore3(convert_uchar3_sat_rte(clamp(o, 0.0f, 1.0f) * 255.0f), i, (__global uchar *)out);
#else
    vstore3(o, i, (__global float *)out);
#endif
}
