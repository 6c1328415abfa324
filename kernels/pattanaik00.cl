/* Pattanaik, Tumblin, Yee & Greenberg 2000: fused per-pixel pass.
 * Eq. 2 responses, Eq. 3 colour slope, Sec. 4.3 inverse appearance (as a
 * per-frame gain/offset) and inverse display response (quadratic in L^n).
 * Reference: ocl_tonemap/models/pattanaik2000.py (map_reference).
 *
 * PN (Eq. 2's n: N), L_FLOOR, RATIO_FLOOR and RESPONSE_MARGIN are given as build
 * options from ocl_tonemap/models/pattanaik2000.py (operators/pattanaik00.py,
 * KERNEL_CONSTANTS); DISPLAY_LINEAR_MAX and SIGNAL_CEILING with common.h's: one
 * definition, not retyped here. */

/* L^n/(L^n + sigma^n) = 1/(1 + 2^(n (log2 sigma - log2 L))) */
inline float saturation(float L, float log2_sigma)
{
    return 1.0f / (1.0f + exp2(PN * (log2_sigma - log2(fmax(L, L_FLOOR)))));
}

/* Sec. 4.3's gain R + offset, with the default mode's shadow toe below 2 R_0 (toe):
 * display black Rk + gain R^2 / (4 R_0) (pattanaik2000.display_response). */
inline float display_response(const float R, const float gain, const float offset,
                              const float toe, const float Rk)
{
    return (toe > 0.0f && R < 2.0f * toe) ? Rk + gain * R * R / (4.0f * toe)
                                          : gain * R + offset;
}

/* One pixel (the scalar path; also the tail of the float8 kernel). */
inline void map_one(const int i, __global const float *rgb, __global const float *Y,
                    __global const float *Ys, __global float *out,
                    const float log2_sigma_rod, const float log2_sigma_cone,
                    const float B_rod, const float B_cone, const float gain, const float offset,
                    const float dB_rod, const float dB_cone, const float ds_rod, const float ds_cone,
                    const float colour_k, const float out_black, const float out_scale,
                    const float inv_white, const float knee, const float chroma, const float toe)
{
    const float Lc = Y[i];
    const float xc = saturation(Lc, log2_sigma_cone);
    const float R = B_rod * saturation(Ys[i], log2_sigma_rod) + B_cone * xc;   /* Eq. 2 */
    const float e = colour_k * xc * (1.0f - xc);                               /* S_color/S_d */

    /* inverse display response: (Br+Bc-R) x^2 + (Br sc + Bc sr - R(sr+sc)) x - R sr sc = 0 */
    const float rmax = dB_rod + dB_cone;
    const float Rk = gain * toe + offset;                   /* the display's black response */
    const float Rd = clamp(display_response(R, gain, offset, toe, Rk), 0.0f,
                           rmax * (1.0f - RESPONSE_MARGIN));
    const float a = rmax - Rd;
    const float b = dB_rod * ds_cone + dB_cone * ds_rod - Rd * (ds_rod + ds_cone);
    const float c = Rd * ds_rod * ds_cone;
    const float disc = sqrt(b * b + 4.0f * a * c);
    const float x = b > 0.0f ? 2.0f * c / (b + disc) : (disc - b) / (2.0f * a);
    const bool black = Rd <= Rk || (Lc <= L_FLOOR && Ys[i] <= L_FLOOR);   /* no light */
    const float Ld = (toe > 0.0f && out_black > 0.0f && black) ? 0.0f          /* exactly */
        : fmin(fmax((x > 0.0f ? exp2(log2(x) * (1.0f / PN)) : 0.0f) - out_black, 0.0f)
               * out_scale, SIGNAL_CEILING);

    float4 col = (float4)(vload3(i, rgb), 1.0f);
    float4 ratio = Lc > L_FLOOR ? col / Lc : (float4)(1.0f);
    float4 cd = colour_k > 0.0f
        ? powp4(fmax(ratio, (float4)(RATIO_FLOOR)), (float4)(e))                /* Q_color^(1/S_d) */
        : fmax(1.0f + chroma * (ratio - 1.0f), 0.0f);                         /* default mode */
    float3 o = shoulder3(Ld * cd.xyz, inv_white, knee);
    vstore3(clamp(o, 0.0f, DISPLAY_LINEAR_MAX), i, out);
}

#define MAP_ARGS log2_sigma_rod, log2_sigma_cone, B_rod, B_cone, gain, offset, \
                 dB_rod, dB_cone, ds_rod, ds_cone, colour_k, out_black, out_scale, inv_white, knee, \
                 chroma, toe
/* The frame's scalars, packed by ocl_tonemap/operators/pattanaik00.py (kernel_call);
 * P_<name> (their indices) come from the same place, as build options (common.h
 * FRAME_PARAMS). */
#define MAP_PARAMS FRAME_PARAMS
#define MAP_LOAD \
    FRAME_PARAMS_LOAD; \
    const float log2_sigma_rod = p[P_log2_sigma_rod], log2_sigma_cone = p[P_log2_sigma_cone]; \
    const float B_rod = p[P_B_rod], B_cone = p[P_B_cone], gain = p[P_gain], offset = p[P_offset]; \
    const float dB_rod = p[P_dB_rod], dB_cone = p[P_dB_cone];              /* display */ \
    const float ds_rod = p[P_ds_rod], ds_cone = p[P_ds_cone];              /* display sigma^n */ \
    const float colour_k = fmax(p[P_colour], 0.0f);      /* ln10 n B_cone / S_d (paper) */ \
    const float chroma = -fmin(p[P_colour], 0.0f);       /* default colour scale */ \
    const float out_black = p[P_out_black];              /* display black taken out, cd/m^2 */ \
    const float out_scale = p[P_out_scale];              /* display-linear per cd/m^2 */ \
    const float inv_white = p[P_inv_white];              /* 1 / display white signal */ \
    const float knee = p[P_knee];                        /* shoulder knee, 0: none */ \
    const float toe = p[P_toe]                           /* shadow toe R_0, 0: none */

/* Scalar kernel: one pixel per work-item (kept for comparison in benchmarks). */
__kernel void pattanaik00_map(__global const float *rgb, __global const float *Y,
                              __global const float *Ys, __global float *out, const int n,
                              MAP_PARAMS)
{
    const int i = get_global_id(0);
    MAP_LOAD;
    if (i < n) map_one(i, rgb, Y, Ys, out, MAP_ARGS);
}

/* The colour part of four pixels (work-item quad q, their Lc, S_color/S_d e and Ld):
 * the colour ratio (Eq. 3, or the default chroma scale), the shoulder, the clamp. */
inline void colour4(const int q, __global const float *rgb, __global float *out,
                    const float4 Lc, const float4 e, const float4 Ld, const float colour_k,
                    const float chroma, const float inv_white, const float knee)
{
    /* 12 colour values of 4 pixels: p0 = c0.xyz, p1 = (c0.w, c1.xy), p2 = (c1.zw, c2.x), p3 = c2.yzw */
    __global const float *src = rgb + 12 * q;
    const float4 c0 = vload4(0, src), c1 = vload4(1, src), c2 = vload4(2, src);
    const float4 L0 = Lc.xxxy, L1 = Lc.yyzz, L2 = Lc.zwww;
    const float4 e0 = e.xxxy, e1 = e.yyzz, e2 = e.zwww;
    const float4 D0 = Ld.xxxy, D1 = Ld.yyzz, D2 = Ld.zwww;
    const float4 r0 = select((float4)(1.0f), c0 / L0, L0 > L_FLOOR);
    const float4 r1 = select((float4)(1.0f), c1 / L1, L1 > L_FLOOR);
    const float4 r2 = select((float4)(1.0f), c2 / L2, L2 > L_FLOOR);
    float4 o0, o1, o2;
    if (colour_k > 0.0f) {
        o0 = D0 * powp4(fmax(r0, RATIO_FLOOR), e0);
        o1 = D1 * powp4(fmax(r1, RATIO_FLOOR), e1);
        o2 = D2 * powp4(fmax(r2, RATIO_FLOOR), e2);
    } else {
        o0 = D0 * fmax(1.0f + chroma * (r0 - 1.0f), 0.0f);
        o1 = D1 * fmax(1.0f + chroma * (r1 - 1.0f), 0.0f);
        o2 = D2 * fmax(1.0f + chroma * (r2 - 1.0f), 0.0f);
    }
    /* the shoulder mixes a pixel's channels: take them apart (r, g, b of 4 pixels) */
    float4 r = (float4)(o0.x, o0.w, o1.z, o2.y), g = (float4)(o0.y, o1.x, o1.w, o2.z),
           bl = (float4)(o0.z, o1.y, o2.x, o2.w);
    shoulder4(&r, &g, &bl, inv_white, knee);
    store_rgb4(q, out, clamp(r, 0.0f, DISPLAY_LINEAR_MAX), clamp(g, 0.0f, DISPLAY_LINEAR_MAX),
               clamp(bl, 0.0f, DISPLAY_LINEAR_MAX));
}

/* Eight pixels per work-item: the responses and the display solve in float8 (three
 * log2/exp2 pairs a pixel: PoCL's float8 forms are ~1.4x faster per value than float4
 * and 6x than scalars), the colour in two float4 quads. 1080p 32 -> 26 ms, the same
 * values bit for bit (benchmarks/results/pattanaik00.md). */
__kernel void pattanaik00_map8(__global const float *rgb, __global const float *Y,
                               __global const float *Ys, __global float *out, const int n,
                               MAP_PARAMS)
{
    const int o = get_global_id(0), i0 = ITEM_PIXELS(8) * o;
    if (i0 >= n) return;
    MAP_LOAD;
    if (!VECTOR_PIXELS || i0 + 8 > n) {          /* common.h */
        for (int i = i0; i < min(i0 + ITEM_PIXELS(8), n); ++i) map_one(i, rgb, Y, Ys, out, MAP_ARGS);
        return;
    }
    const float8 Lc = vload8(o, Y), Ls = vload8(o, Ys);
    const float8 xc = 1.0f / (1.0f + exp2(PN * (log2_sigma_cone - log2(fmax(Lc, L_FLOOR)))));
    const float8 xr = 1.0f / (1.0f + exp2(PN * (log2_sigma_rod - log2(fmax(Ls, L_FLOOR)))));
    const float8 R = B_rod * xr + B_cone * xc;                                  /* Eq. 2 */
    const float8 e = colour_k * xc * (1.0f - xc);                               /* S_color/S_d */
    const float rmax = dB_rod + dB_cone;
    const float Rk = gain * toe + offset;                   /* the display's black response */
    const float8 line = gain * R + offset;
    const float8 Rd = clamp(toe > 0.0f ? select(line, Rk + gain * R * R / (4.0f * toe),
                                                R < 2.0f * toe) : line,
                            0.0f, rmax * (1.0f - RESPONSE_MARGIN));
    const float8 a = rmax - Rd;
    const float8 b = dB_rod * ds_cone + dB_cone * ds_rod - Rd * (ds_rod + ds_cone);
    const float8 c = Rd * ds_rod * ds_cone;
    const float8 disc = sqrt(b * b + 4.0f * a * c);
    const float8 x = select((disc - b) / (2.0f * a), 2.0f * c / (b + disc), b > 0.0f);
    float8 Ld = fmin(fmax(select((float8)(0.0f), exp2(log2(x) * (1.0f / PN)), x > 0.0f)
                          - out_black, 0.0f) * out_scale, SIGNAL_CEILING);
    if (toe > 0.0f && out_black > 0.0f)                     /* black (no light): exactly */
        Ld = select(Ld, (float8)(0.0f), Rd <= Rk || (Lc <= L_FLOOR && Ls <= L_FLOOR));
    colour4(2 * o, rgb, out, Lc.lo, e.lo, Ld.lo, colour_k, chroma, inv_white, knee);
    colour4(2 * o + 1, rgb, out, Lc.hi, e.hi, Ld.hi, colour_k, chroma, inv_white, knee);
}
