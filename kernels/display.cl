/* The OCIO display/view transform baked into a table (ocl_tonemap/colour.py,
 * bake_display_table; host side ocl_tonemap/backends/opencl/display.py).
 *
 * Input: display-linear working-space RGB, `cin` floats per pixel (3 or 4); output:
 * display code values, `cout` floats per pixel (a 4th channel is copied when both
 * have one). Table coordinate per channel (colour.shaper), with v = M rgb + offset (1D
 * form) or v = rgb (3D form):
 *     f = clamp((s(v) - s_lo) scale, 0, size - 1)
 * 1D, shaper "bits": from the float32 bits of |v| + eps = 2^e (1 + m),
 *     s = sign(v) (e - log2(eps) + m (4 - m) / 3),
 * a smooth stand-in for log2(1 + |v|/eps) without a transcendental;
 * 3D, shaper "log2": s = sign(v) (log2(|v| + eps) - log2(eps)).
 * NaN and +-Inf read the last entry.
 * par[0..8] = M (row major), par[9..11] = offset, par[12] = eps (a power of two),
 * par[13] = s_lo, par[14] = scale; e_eps = the biased exponent of eps. The float64 NumPy
 * reference is colour.DisplayTable.apply.
 */

inline float coord_bits(const float v, const float eps, const int e_eps, const float s_lo,
                        const float scale, const float fmax_idx)
{
    const int bits = as_int(fabs(v) + eps);
    const float m = (float)(bits & 0x7FFFFF) * (1.0f / 8388608.0f);
    float s = (float)((bits >> 23) - e_eps) + m * (4.0f - m) * (1.0f / 3.0f);
    s = (v < 0.0f) ? -s : s;
    return clamp((s - s_lo) * scale, 0.0f, fmax_idx);
}

inline float coord_log2(const float v, const float eps, const int e_eps, const float s_lo,
                        const float scale, const float fmax_idx)
{
    float s = log2(fabs(v) + eps) - (float)(e_eps - 127);
    s = (v < 0.0f) ? -s : s;
    s = isnan(s) ? INFINITY : s;
    return clamp((s - s_lo) * scale, 0.0f, fmax_idx);
}

/* lut: size x 3 floats (the channel curves interleaved). */
__kernel void display_lut1d(__global const float *src, __global float *dst, const int n,
                            const int cin, const int cout, __global const float *par,
                            const int e_eps, const int size,
                            __global const float *lut)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    __global const float *p = src + (size_t)i * cin;
    const float r = p[0], g = p[1], b = p[2];
    const float eps = par[12], s_lo = par[13], scale = par[14];
    const float fmax_idx = (float)(size - 1);
    __global float *q = dst + (size_t)i * cout;
    for (int c = 0; c < 3; ++c) {
        const float v = par[3 * c] * r + par[3 * c + 1] * g + par[3 * c + 2] * b + par[9 + c];
        const float f = coord_bits(v, eps, e_eps, s_lo, scale, fmax_idx);
        const int k = min((int)f, size - 2);
        const float t = f - (float)k;
        const float lo = lut[3 * k + c], hi = lut[3 * k + 3 + c];
        q[c] = fma(t, hi - lo, lo);
    }
    if (cin == 4 && cout == 4) q[3] = p[3];
}

/* lut: size^3 x 3 floats, index ((ir * size + ig) * size + ib) * 3 + channel. */
__kernel void display_lut3d(__global const float *src, __global float *dst, const int n,
                            const int cin, const int cout, __global const float *par,
                            const int e_eps, const int size,
                            __global const float *lut)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    __global const float *p = src + (size_t)i * cin;
    const float eps = par[12], s_lo = par[13], scale = par[14];
    const float fmax_idx = (float)(size - 1);
    const float fr = coord_log2(p[0], eps, e_eps, s_lo, scale, fmax_idx);
    const float fg = coord_log2(p[1], eps, e_eps, s_lo, scale, fmax_idx);
    const float fb = coord_log2(p[2], eps, e_eps, s_lo, scale, fmax_idx);
    const int ir = min((int)fr, size - 2), ig = min((int)fg, size - 2),
              ib = min((int)fb, size - 2);
    const float r = fr - (float)ir, g = fg - (float)ig, b = fb - (float)ib;
    const int sr = size * size * 3, sg = size * 3, sb = 3;
    __global const float *c000 = lut + ir * sr + ig * sg + ib * sb;
    /* the six tetrahedra (as colour._tetrahedral): from c000 to c111 along the axes in
       decreasing order of their fractions */
    int o1, o2;
    float w1, w2, w3;          /* the fractions, largest first */
    if (r >= g) {
        if (g >= b)      { o1 = sr; o2 = sr + sg; w1 = r; w2 = g; w3 = b; }
        else if (r >= b) { o1 = sr; o2 = sr + sb; w1 = r; w2 = b; w3 = g; }
        else             { o1 = sb; o2 = sr + sb; w1 = b; w2 = r; w3 = g; }
    } else {
        if (r >= b)      { o1 = sg; o2 = sr + sg; w1 = g; w2 = r; w3 = b; }
        else if (g >= b) { o1 = sg; o2 = sg + sb; w1 = g; w2 = b; w3 = r; }
        else             { o1 = sb; o2 = sg + sb; w1 = b; w2 = g; w3 = r; }
    }
    const int o3 = sr + sg + sb;
    __global float *q = dst + (size_t)i * cout;
    for (int c = 0; c < 3; ++c) {
        const float a0 = c000[c], a1 = c000[o1 + c], a2 = c000[o2 + c], a3 = c000[o3 + c];
        q[c] = a0 + w1 * (a1 - a0) + w2 * (a2 - a1) + w3 * (a3 - a2);
    }
    if (cin == 4 && cout == 4) q[3] = p[3];
}
