/* Separable convolution of float planes (row-major, width w): one pass along
 * x or along y with a symmetric tap table (taps[0] is the centre, taps[r] the
 * weight at distance r, radius R). Used by the loss-of-acuity blur (clamped
 * edges) and the flare pyramid's Gaussians (zero outside the image).
 * Reference: ocl_tonemap/models/convolution.py (blur_reference). */

#define EDGE_ZERO 0
#define EDGE_CLAMP 1

inline float fetch(__global const float *src, const int x, const int y, const int w,
                   const int h, const int edge)
{
    if (x >= 0 && x < w && y >= 0 && y < h) return src[(size_t)y * w + x];
    if (edge == EDGE_ZERO) return 0.0f;
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
 * Reference: ocl_tonemap/models/shaler1937.py apply_acuity. */
__kernel void acuity_rgb_x(__global const float *src, __global float *dst, const int w,
                           const int h, __constant float *taps, const int radius)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    __global const float *row = src + 3 * (size_t)y * w;
    float3 acc = taps[0] * vload3(x, row);
    for (int r = 1; r <= radius; ++r)
        acc += taps[r] * (vload3(max(x - r, 0), row) + vload3(min(x + r, w - 1), row));
    vstore3(acc, (size_t)y * w + x, dst);
}

__kernel void acuity_rgb_y_blend(__global const float *src, __global float *img, const int w,
                                 const int h, __constant float *taps, const int radius,
                                 const float t)
{
    const int x = get_global_id(0), y = get_global_id(1);
    if (x >= w || y >= h) return;
    float3 acc = taps[0] * vload3((size_t)y * w + x, src);
    for (int r = 1; r <= radius; ++r)
        acc += taps[r] * (vload3((size_t)max(y - r, 0) * w + x, src)
                          + vload3((size_t)min(y + r, h - 1) * w + x, src));
    const size_t i = (size_t)y * w + x;
    const float3 o = vload3(i, img);
    vstore3(o + t * (acc - o), i, img);
}
