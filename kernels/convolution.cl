/* Separable convolution of float planes (row-major, width w): one pass along
 * x or along y with a symmetric tap table (taps[0] is the centre, taps[r] the
 * weight at distance r, radius R). Used by the loss-of-acuity blur (clamped
 * edges), the flare pyramid's Gaussians (zero outside the image) and the
 * visibility planes' target and surround (reflected edges).
 * Reference: ocl_tonemap/models/convolution.py (blur_reference). */

#define EDGE_ZERO 0
#define EDGE_CLAMP 1
#define EDGE_REFLECT 2

/* i mirrored into 0..n-1 without repeating the edge, folded as often as it needs
 * (models/convolution.py reflect_index). */
inline int reflect_index(const int i, const int n)
{
    if (n == 1) return 0;
    const int p = 2 * (n - 1);
    int m = i % p;
    if (m < 0) m += p;
    return m >= n ? p - m : m;
}

inline float fetch(__global const float *src, const int x, const int y, const int w,
                   const int h, const int edge)
{
    if (x >= 0 && x < w && y >= 0 && y < h) return src[(size_t)y * w + x];
    if (edge == EDGE_ZERO) return 0.0f;
    if (edge == EDGE_REFLECT)
        return src[(size_t)reflect_index(y, h) * w + reflect_index(x, w)];
    return src[(size_t)clamp(y, 0, h - 1) * w + clamp(x, 0, w - 1)];
}

/* axis 0: along x; axis 1: along y. The pair (x - r, x + r) is summed first. */
__kernel void blur_axis(__global const float *src, __global float *dst, const int w,
                        const int h, __constant float *taps, const int radius,
                        const int axis, const int edge)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    float acc = taps[0] * src[(size_t)y * w + x];
    if (axis == 0) {
        if (x >= radius && x + radius < w) {
            __global const float *row = src + (size_t)y * w + x;
            for (int r = 1; r <= radius; ++r) acc += taps[r] * (row[-r] + row[r]);
        } else {
            for (int r = 1; r <= radius; ++r)
                acc += taps[r] * (fetch(src, x - r, y, w, h, edge) + fetch(src, x + r, y, w, h, edge));
        }
    } else {
        if (y >= radius && y + radius < h) {
            __global const float *col = src + (size_t)y * w + x;
            const size_t s = (size_t)w;
            for (int r = 1; r <= radius; ++r) acc += taps[r] * (col[-(long)(r * s)] + col[r * s]);
        } else {
            for (int r = 1; r <= radius; ++r)
                acc += taps[r] * (fetch(src, x, y - r, w, h, edge) + fetch(src, x, y + r, w, h, edge));
        }
    }
    dst[(size_t)y * w + x] = acc;
}

/* The loss-of-acuity blur on a display-linear RGB frame where the operator left it
 * (interleaved float RGB, clamped edges, as blur_axis with EDGE_CLAMP on each plane):
 * along x into dst, then along y from it, blended into img in place:
 * img = img + t (blur - img) (Eq. 10's blur with Sec. 7's blend and the plan's weight).
 * Reference: ocl_tonemap/models/shaler1937.py apply_acuity.
 *
 * A work-item takes the four pixels 4q .. 4q+3 of the frame (common.h ITEM_PIXELS; one
 * pixel elsewhere than on CPUs) as float4 planes: PoCL calls vload3 out of line, and a
 * pixel an item with a call per tap ran these at ~95 ms a pass on a 4K frame. Four
 * pixels in one row with the whole window inside the frame take the vector body,
 * every other pixel (the frame's edges, a quad across two rows) the scalar one, tap by
 * tap in the same order (taps: the centre and the weight at each distance 1 .. R). */
inline float3 acuity_x_pixel(__global const float *src, const int i, const int w,
                             __constant float *taps, const int radius)
{
    const int y = i / w, x = i - y * w;
    __global const float *row = src + 3 * (size_t)y * w;
    float3 acc = taps[0] * vload3(x, row);
    for (int r = 1; r <= radius; ++r)
        acc += taps[r] * (vload3(max(x - r, 0), row) + vload3(min(x + r, w - 1), row));
    return acc;
}

/* The four pixels at offset s (0 .. 4) from the start of quad a, b the quad after it. */
#define QUAD_AT(a, b, s) ((s) == 0 ? (a) : (s) == 1 ? (float4)((a).yzw, (b).x) : \
                          (s) == 2 ? (float4)((a).zw, (b).xy) : \
                          (s) == 3 ? (float4)((a).w, (b).xyz) : (b))

__kernel void acuity_rgb_x(__global const float *src, __global float *dst, const int w,
                           const int h, __constant float *taps, const int radius)
{
    const int q = get_global_id(0), n = w * h, i0 = ITEM_PIXELS(4) * q;
    if (i0 >= n) return;
    const int y = i0 / w, x0 = i0 - y * w, M = (radius + 3) / 4;
    if (VECTOR_PIXELS && x0 - 4 * M >= 0 && x0 + 3 + 4 * M < w) {
        float4 r, g, b, lr, lg, lb, rr, rg, rb;          /* quads q - m + 1 and q + m - 1 */
        load_rgb4(q, src, &r, &g, &b);
        float4 ar = taps[0] * r, ag = taps[0] * g, ab = taps[0] * b;
        lr = rr = r; lg = rg = g; lb = rb = b;
        for (int m = 1; m <= M; ++m) {
            float4 pr, pg, pb, nr, ng, nb;               /* quads q - m and q + m */
            load_rgb4(q - m, src, &pr, &pg, &pb);
            load_rgb4(q + m, src, &nr, &ng, &nb);
            #pragma unroll
            for (int s = 1; s <= 4; ++s) {               /* distance 4 (m - 1) + s */
                const int d = 4 * (m - 1) + s;
                if (d <= radius) {
                    const float t = taps[d];
                    ar += t * (QUAD_AT(pr, lr, 4 - s) + QUAD_AT(rr, nr, s));
                    ag += t * (QUAD_AT(pg, lg, 4 - s) + QUAD_AT(rg, ng, s));
                    ab += t * (QUAD_AT(pb, lb, 4 - s) + QUAD_AT(rb, nb, s));
                }
            }
            lr = pr; lg = pg; lb = pb; rr = nr; rg = ng; rb = nb;
        }
        store_rgb4(q, dst, ar, ag, ab);
        return;
    }
    for (int i = i0; i < min(i0 + ITEM_PIXELS(4), n); ++i)
        vstore3(acuity_x_pixel(src, i, w, taps, radius), i, dst);
}

__kernel void acuity_rgb_y_blend(__global const float *src, __global float *img, const int w,
                                 const int h, __constant float *taps, const int radius,
                                 const float t)
{
    const int q = get_global_id(0), n = w * h, i0 = ITEM_PIXELS(4) * q;
    if (i0 >= n) return;
    const int y = i0 / w, x0 = i0 - y * w;
    if (VECTOR_PIXELS && x0 + 3 < w && y - radius >= 0 && y + radius < h) {
        float4 r, g, b, ur, ug, ub, dr, dg, db;
        load_rgb4(q, src, &r, &g, &b);
        float4 ar = taps[0] * r, ag = taps[0] * g, ab = taps[0] * b;
        for (int k = 1; k <= radius; ++k) {
            const size_t off = 3 * ((size_t)k * w);
            load_rgb4_at(src + 12 * (size_t)q - off, &ur, &ug, &ub);
            load_rgb4_at(src + 12 * (size_t)q + off, &dr, &dg, &db);
            ar += taps[k] * (ur + dr);
            ag += taps[k] * (ug + dg);
            ab += taps[k] * (ub + db);
        }
        load_rgb4(q, img, &r, &g, &b);
        store_rgb4(q, img, r + t * (ar - r), g + t * (ag - g), b + t * (ab - b));
        return;
    }
    for (int i = i0; i < min(i0 + ITEM_PIXELS(4), n); ++i) {
        const int yi = i / w, x = i - yi * w;
        float3 acc = taps[0] * vload3(i, src);
        for (int k = 1; k <= radius; ++k)
            acc += taps[k] * (vload3((size_t)max(yi - k, 0) * w + x, src)
                              + vload3((size_t)min(yi + k, h - 1) * w + x, src));
        const float3 o = vload3(i, img);
        vstore3(o + t * (acc - o), i, img);
    }
}
