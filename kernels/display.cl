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
 *
 * Built with OUT_U8=1 the code values are written as 8-bit integers, quantised as
 * OIIO's ImageOutput converts float to uint8 when it writes (v 255 rounded to the
 * nearest, ties to even, clamped to [0, 255]; NaN 0), so an 8-bit file gets the same
 * bytes and a quarter of the download; with OUT_U16=1 as 16-bit integers, the same
 * rule with 65535 (OIIO's, measured on every value: tests/colour/test_display_table.py),
 * half the download.
 */

#ifndef OUT_U8
#define OUT_U8 0
#endif
#ifndef OUT_U16
#define OUT_U16 0
#endif

#if OUT_U16
typedef ushort out_t;
inline ushort to_out(const float v)
{
    /* 0x1.fffep15f = 65535 */
    return (ushort)((clamp(v * 0x1.fffep15f, 0.0f, 0x1.fffep15f) + 0x1.8p23f) - 0x1.8p23f);
}
#elif OUT_U8
typedef uchar out_t;
inline uchar to_out(const float v)
{
    /* as pack_u8 below: ties to even (OIIO's own rounding of an exact tie depends on
       the machine: tests/colour/test_display_table.py); clamp takes NaN to 0 (fmax);
       convert_uchar_sat_rte gives the same bytes at twice the time on PoCL */
    return (uchar)((clamp(v * 255.0f, 0.0f, 255.0f) + 0x1.8p23f) - 0x1.8p23f);
}
#else
typedef float out_t;
inline float to_out(const float v) { return v; }
#endif

inline float coord_bits(const float v, const float eps, const int e_eps, const float s_lo,
                        const float scale, const float fmax_idx)
{
    const int bits = as_int(fabs(v) + eps);
    const float m = (float)(bits & 0x7FFFFF) * 0x1p-23f;
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

/* lut: 3 x size pairs (value at k, value at k+1 minus it), channel after channel: one
 * load per value looked up (PoCL gathers element by element; 1080p 15.5 -> 8.2 ms). */
__kernel void display_lut1d(__global const float *restrict src, __global out_t *restrict dst,
                            const int n, const int cin, const int cout,
                            __global const float *restrict par, const int e_eps, const int size,
                            __global const float2 *restrict lut)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    __global const float *p = src + (size_t)i * cin;
    const float r = p[0], g = p[1], b = p[2];
    const float eps = par[12], s_lo = par[13], scale = par[14];
    const float fmax_idx = (float)(size - 1);
    __global out_t *q = dst + (size_t)i * cout;
    float o[3];
    for (int c = 0; c < 3; ++c) {
        const float v = par[3 * c] * r + par[3 * c + 1] * g + par[3 * c + 2] * b + par[9 + c];
        const float f = coord_bits(v, eps, e_eps, s_lo, scale, fmax_idx);
        const int k = min((int)f, size - 2);
        const float t = f - (float)k;
        const float2 e = lut[c * size + k];
        o[c] = fma(t, e.y, e.x);
    }
    q[0] = to_out(o[0]);
    q[1] = to_out(o[1]);
    q[2] = to_out(o[2]);
    if (cin == 4 && cout == 4) q[3] = to_out(p[3]);
}

/* coord_bits on four values. */
inline float4 coord_bits4(const float4 v, const float eps, const int e_eps, const float s_lo,
                          const float scale, const float fmax_idx)
{
    const int4 bits = as_int4(fabs(v) + eps);
    const float4 m = convert_float4(bits & 0x7FFFFF) * 0x1p-23f;
    float4 s = convert_float4((bits >> 23) - e_eps) + m * (4.0f - m) * (1.0f / 3.0f);
    s = select(s, -s, isless(v, (float4)(0.0f)));
    return clamp((s - s_lo) * scale, 0.0f, fmax_idx);
}

/* One channel of four pixels through its curve (channel c of the pair table). */
inline float4 curve4(const float4 v, const int c, __global const float2 *restrict lut,
                     const float eps, const int e_eps, const float s_lo, const float scale,
                     const int size)
{
    const float4 f = coord_bits4(v, eps, e_eps, s_lo, scale, (float)(size - 1));
    const int4 k = min(convert_int4(f), size - 2);
    const float4 t = f - convert_float4(k);
    __global const float2 *curve = lut + c * size;
    const float2 a = curve[k.x], b = curve[k.y], d = curve[k.z], e = curve[k.w];
    return fma(t, (float4)(a.y, b.y, d.y, e.y), (float4)(a.x, b.x, d.x, e.x));
}

#if OUT_U8 && !OUT_U16
/* Four code values as the four bytes of a little-endian uint (PoCL stores bytes
 * slowly; the host checks the device is little-endian). */
inline uint pack_u8(const float4 a)
{
    /* clamp (NaN -> 0), then round to nearest, ties to even, by adding 1.5 2^23: the
       sum's low mantissa bits are the rounded value (PoCL's rint on float4 is slow) */
    const uint4 i = as_uint4(clamp(a * 255.0f, 0.0f, 255.0f) + 0x1.8p23f);
    return as_uint(as_uchar16(i).s048c);         /* each lane's low byte, in order */
}

inline void store_out4(const int q, __global uchar *restrict dst, const float4 r,
                       const float4 g, const float4 b)
{
    __global uint *d = (__global uint *)dst + 3 * (size_t)q;
    d[0] = pack_u8((float4)(r.x, g.x, b.x, r.y));
    d[1] = pack_u8((float4)(g.y, b.y, r.z, g.z));
    d[2] = pack_u8((float4)(b.z, r.w, g.w, b.w));
}
#elif OUT_U16
/* Two code values as the two halves of a little-endian uint, rounded as to_out. */
inline uint2 pack_u16(const float4 a)
{
    const uint4 i = as_uint4(clamp(a * 0x1.fffep15f, 0.0f, 0x1.fffep15f) + 0x1.8p23f) & 0xFFFFu;
    return (uint2)(i.x | (i.y << 16), i.z | (i.w << 16));
}

inline void store_out4(const int q, __global ushort *restrict dst, const float4 r,
                       const float4 g, const float4 b)
{
    __global uint *d = (__global uint *)dst + 6 * (size_t)q;
    const uint2 a = pack_u16((float4)(r.x, g.x, b.x, r.y));
    const uint2 c = pack_u16((float4)(g.y, b.y, r.z, g.z));
    const uint2 e = pack_u16((float4)(b.z, r.w, g.w, b.w));
    d[0] = a.x; d[1] = a.y; d[2] = c.x; d[3] = c.y; d[4] = e.x; d[5] = e.y;
}
#else
inline void store_out4(const int q, __global float *restrict dst, const float4 r,
                       const float4 g, const float4 b)
{
    store_rgb4(q, dst, r, g, b);
}
#endif

/* display_lut1d on RGB (cin = cout = 3), four pixels per work-item (launched over
 * n / 4 items; the tail by display_lut1d): PoCL runs it ~4x faster. */
__kernel void display_lut1d_rgb4(__global const float *restrict src,
                                 __global out_t *restrict dst, const int n,
                                 __global const float *restrict par, const int e_eps,
                                 const int size, __global const float2 *restrict lut)
{
    const int q = get_global_id(0);
    if (4 * q + 4 > n) return;
    const float eps = par[12], s_lo = par[13], scale = par[14];
    float4 r, g, b;
    load_rgb4(q, src, &r, &g, &b);                 /* (common.h: float4 loads, no call) */
    float4 o[3];
    for (int c = 0; c < 3; ++c) {
        const float4 v = par[3 * c] * r + par[3 * c + 1] * g + par[3 * c + 2] * b + par[9 + c];
        o[c] = curve4(v, c, lut, eps, e_eps, s_lo, scale, size);
    }
    store_out4(q, dst, o[0], o[1], o[2]);
}

/* lut: size^3 x 3 floats, index ((ir * size + ig) * size + ib) * 3 + channel. */
__kernel void display_lut3d(__global const float *restrict src, __global out_t *restrict dst,
                            const int n, const int cin, const int cout,
                            __global const float *restrict par, const int e_eps, const int size,
                            __global const float *restrict lut)
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
    __global out_t *q = dst + (size_t)i * cout;
    for (int c = 0; c < 3; ++c) {
        const float a0 = c000[c], a1 = c000[o1 + c], a2 = c000[o2 + c], a3 = c000[o3 + c];
        q[c] = to_out(a0 + w1 * (a1 - a0) + w2 * (a2 - a1) + w3 * (a3 - a2));
    }
    if (cin == 4 && cout == 4) q[3] = to_out(p[3]);
}
