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
