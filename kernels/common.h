/* Shared by every program. Its model constants come as build options from
 * ocl_tonemap/backends/opencl/constants.py (COMMON), generated from ocl_tonemap/models/:
 *   M_XR .. M_ZB        BT.709 linear RGB -> XYZ (D65), photometry.RGB709_TO_XYZ
 *                       (the M_Y* row: photopic luminance Y)
 *   WARD97_GAIN, WARD97_OFFSET  photometry (scotopic luminance, Ward-Larson et al. 1997)
 *   L_MAX               photometry.L_MAX: scene ceiling, cd/m^2 (+Inf maps here)
 *   NREPAIR             len(photometry.RepairCounts.KEYS): nan, pos_inf, neg_inf,
 *                       negative, denormal, over_max
 *   SIGNAL_CEILING, CHANNEL_KNEE, DISPLAY_LINEAR_MAX  models/display.py
 * one definition, not retyped here. */

/* No a*b+c contracted into fma: OpenCL C allows it by default and GPU compilers do it
 * where the expression's shape lets them, so a vector body and its scalar tail (or a
 * band's pixel at another offset in its quad) could round the same formula apart:
 * banded frames would no longer equal whole ones bit for bit (seen on NVIDIA). */
#pragma OPENCL FP_CONTRACT OFF

/* How the work-items of a reduction share `count` items (quads, pixels): loop
 *     for (int q = lo; q < hi; q += step)
 * A contiguous stretch per work-item on CPU devices (DEVICE_CPU: -D by the runtime;
 * PoCL runs a group's items one after another, so each streams its own memory: 1080p
 * metering 9.7 -> 5.4 ms), interleaved elsewhere (neighbouring items read neighbouring
 * addresses: coalesced on GPUs). */
#ifndef DEVICE_CPU
#define DEVICE_CPU 0
#endif

/* Per-pixel kernels written several pixels to a work-item (float4/float8 across pixels)
 * take that vector body on CPU devices only, where it pays (PoCL: SIMD lanes, scalar
 * code is not vectorised across work-items). A GPU runs a work-item's lanes as scalar
 * code anyway, and its compiler may round a vector body's formula apart from the
 * scalar one by an ulp (seen on NVIDIA: ledda04's banded frames then differed from whole
 * ones where a band's pixel sat at another place in its quad); there every pixel takes
 * the scalar path, so a pixel's value does not depend on where it lies.
 * -D by the runtime (Runtime.vector_pixels: DEVICE_CPU unless OCLTM_VECTOR_PIXELS says). */
#ifndef VECTOR_PIXELS
#define VECTOR_PIXELS DEVICE_CPU
#endif
/* The pixels a work-item of such a kernel (written for K a work-item) takes: K with the
 * vector body, else one, so that neighbouring work-items read neighbouring pixels
 * (coalesced loads on GPUs: on the H100, K consecutive pixels an item had left
 * ledda04_step4 at 0.40 of the copy roofline, one an item runs it at 1.09). The host
 * launches Runtime.pixel_items(n, K) items. */
#define ITEM_PIXELS(K) (VECTOR_PIXELS ? (K) : 1)

/* A per-pixel kernel's frame scalars (operators' KernelCall params, P_<name> their
 * indices): a float16 argument, so that a frame's new values travel with the launch
 * instead of as an upload (issue 47); FRAME_PARAMS_LOAD makes them p[0..15]. */
#define FRAME_PARAMS const float16 pv
#define FRAME_PARAMS_LOAD float p[16]; unpack16(pv, p)

/* v's 16 lanes into p[0..15]. Not vstore16 to private memory: PoCL 3.0's LLVM 14 takes
 * a Zen 4 host (family 25, model 17: AVX-512) for znver3 (none), links its AVX-512
 * built-ins, and aborts compiling that store ("LLVM ERROR: Do not know how to scalarize
 * this operator's operand", or a segmentation fault when the binary is fetched). */
inline void unpack16(const float16 v, float *p)
{
    p[0] = v.s0; p[1] = v.s1; p[2] = v.s2; p[3] = v.s3; p[4] = v.s4; p[5] = v.s5;
    p[6] = v.s6; p[7] = v.s7; p[8] = v.s8; p[9] = v.s9; p[10] = v.sa; p[11] = v.sb;
    p[12] = v.sc; p[13] = v.sd; p[14] = v.se; p[15] = v.sf;
}

/* fmax, fmin, clamp, select and comparisons inline on CPU devices. PoCL as
 * pyopencl's wheel ships it calls these built-ins out of line: perf put ~5% of a 1080p sequence's CPU in _cl_clamp,
 * _cl_fmax and _cl_fmin, and a call keeps the driver from vectorising a loop across
 * work-items. Here they are overloaded inline functions with the built-ins' values:
 * fmax/fmin give the other argument where one is NaN, clamp(x, lo, hi) =
 * fmin(fmax(x, lo), hi) (NaN -> lo), as the OpenCL C specification defines them; for
 * integers clamp is min(max(x, lo), hi). GPU compilers inline their own. (PoCL's
 * headers map these names to its _cl_* functions by macros: #undef first, or its
 * compiler warns on every build.) */
#if DEVICE_CPU
#define OCLTM_FMINMAX(T) \
    __attribute__((overloadable)) inline T ocltm_fmax(const T a, const T b) \
    { return (a >= b || b != b) ? a : b; } \
    __attribute__((overloadable)) inline T ocltm_fmin(const T a, const T b) \
    { return (a <= b || b != b) ? a : b; } \
    __attribute__((overloadable)) inline T ocltm_clamp(const T x, const T lo, const T hi) \
    { return ocltm_fmin(ocltm_fmax(x, lo), hi); }
#define OCLTM_FMINMAX_V(T) OCLTM_FMINMAX(T) \
    __attribute__((overloadable)) inline T ocltm_fmax(const T a, const float b) \
    { return ocltm_fmax(a, (T)(b)); } \
    __attribute__((overloadable)) inline T ocltm_fmin(const T a, const float b) \
    { return ocltm_fmin(a, (T)(b)); } \
    __attribute__((overloadable)) inline T ocltm_clamp(const T x, const float lo, const float hi) \
    { return ocltm_clamp(x, (T)(lo), (T)(hi)); }
#define OCLTM_ICLAMP(T) \
    __attribute__((overloadable)) inline T ocltm_clamp(const T x, const T lo, const T hi) \
    { const T a = x > lo ? x : lo; return a < hi ? a : hi; }
OCLTM_FMINMAX(float)
OCLTM_FMINMAX_V(float2)
OCLTM_FMINMAX_V(float3)
OCLTM_FMINMAX_V(float4)
OCLTM_FMINMAX_V(float8)
OCLTM_FMINMAX_V(float16)
OCLTM_ICLAMP(int)
OCLTM_ICLAMP(int4)
/* min, max (integers and floats: y < x ? y : x, as defined where neither is NaN), fabs
 * (the sign bit cleared) and fma (the fused operation, lane by lane, where the target
 * has it: the same value) likewise: PoCL called _cl_min, _cl_fabs and _cl_fma out of line
 * in the display encoding, ~14% of its time. */
#define OCLTM_MINMAX(T) \
    __attribute__((overloadable)) inline T ocltm_min(const T a, const T b) \
    { return b < a ? b : a; } \
    __attribute__((overloadable)) inline T ocltm_max(const T a, const T b) \
    { return b > a ? b : a; }
#define OCLTM_MINMAX_V(T, S) OCLTM_MINMAX(T) \
    __attribute__((overloadable)) inline T ocltm_min(const T a, const S b) \
    { return ocltm_min(a, (T)(b)); } \
    __attribute__((overloadable)) inline T ocltm_max(const T a, const S b) \
    { return ocltm_max(a, (T)(b)); }
#define OCLTM_FABS(T, U) \
    __attribute__((overloadable)) inline T ocltm_fabs(const T x) \
    { return as_##T(as_##U(x) & 0x7fffffffu); }
OCLTM_MINMAX(int)
OCLTM_MINMAX(uint)
OCLTM_MINMAX(long)
OCLTM_MINMAX(ulong)
OCLTM_MINMAX(float)
OCLTM_MINMAX_V(int2, int)
OCLTM_MINMAX_V(int4, int)
OCLTM_MINMAX_V(int8, int)
OCLTM_MINMAX_V(float2, float)
OCLTM_MINMAX_V(float4, float)
OCLTM_MINMAX_V(float8, float)
OCLTM_FABS(float, uint)
OCLTM_FABS(float2, uint2)
OCLTM_FABS(float3, uint3)
OCLTM_FABS(float4, uint4)
OCLTM_FABS(float8, uint8)
OCLTM_FABS(float16, uint16)
#undef min
#define min ocltm_min
#undef max
#define max ocltm_max
#undef fabs
#define fabs ocltm_fabs
#if defined(__FMA__)
__attribute__((overloadable)) inline float ocltm_fma(const float a, const float b, const float c)
{ return __builtin_fmaf(a, b, c); }
__attribute__((overloadable)) inline float4 ocltm_fma(const float4 a, const float4 b,
                                                      const float4 c)
{
    return (float4)(__builtin_fmaf(a.x, b.x, c.x), __builtin_fmaf(a.y, b.y, c.y),
                    __builtin_fmaf(a.z, b.z, c.z), __builtin_fmaf(a.w, b.w, c.w));
}
#undef fma
#define fma ocltm_fma
#endif
#undef fmax
#define fmax ocltm_fmax
#undef fmin
#define fmin ocltm_fmin
#undef clamp
#define clamp ocltm_clamp
/* select and the ordered comparisons as the operators they equal: a vector ?: takes
 * each lane by its condition's most significant bit, as select does; comparisons give
 * -1 / 0 lanes (1 / 0 for scalars) and false where a NaN is compared, as these do. */
#undef select
#define select(a, b, c) ((c) ? (b) : (a))
#undef isgreater
#define isgreater(a, b) ((a) > (b))
#undef isgreaterequal
#define isgreaterequal(a, b) ((a) >= (b))
#undef isless
#define isless(a, b) ((a) < (b))
#undef islessequal
#define islessequal(a, b) ((a) <= (b))
#endif
/* The sum of a work-group's float4 records (v: this work-item's; lid, lsz: its flat
 * local index and the group's size, a power of two; scratch: one float4 per
 * work-item) into *slot. The host adds the groups (in float64). */
inline void group_sum4_into(__local float4 *scratch, const float4 v, const int lid,
                            const int lsz, __global float4 *slot)
{
    scratch[lid] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
#if DEVICE_CPU
    /* One barrier, the first work-item adds the group's records in order: a CPU driver
     * runs the work-items between barriers as loops (PoCL), so a tree of log2(size)
     * barriers costs log2(size) passes over the group (flare_source: 20.8 -> 5 ms a
     * 1080p frame on PoCL). */
    if (lid == 0) {
        float4 s = scratch[0];
        for (int j = 1; j < lsz; ++j) s += scratch[j];
        *slot = s;
    }
#else
    for (int off = lsz >> 1; off > 0; off >>= 1) {
        if (lid < off) scratch[lid] += scratch[lid + off];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) *slot = scratch[0];
#endif
}

/* ... of a 1D work-group into partial[group]. */
inline void group_sum4(__local float4 *scratch, const float4 v, __global float4 *partial)
{
    group_sum4_into(scratch, v, get_local_id(0), get_local_size(0),
                    partial + get_group_id(0));
}

inline void share_range(const int count, int *lo, int *hi, int *step)
{
#if DEVICE_CPU
    const int g = (int)get_global_size(0);
    const int per = (count + g - 1) / g;
    *lo = min(count, (int)get_global_id(0) * per);
    *hi = min(count, *lo + per);
    *step = 1;
#else
    *lo = (int)get_global_id(0);
    *hi = count;
    *step = (int)get_global_size(0);
#endif
}

inline float scotopic_luminance(float r, float g, float b)
{
    /* Ward-Larson et al. 1997: Y' = Y (1.33 (1 + (Y+Z)/X) - 1.68) (WARD97_GAIN, _OFFSET) */
    float X = M_XR * r + M_XG * g + M_XB * b;
    float Y = M_YR * r + M_YG * g + M_YB * b;
    float Z = M_ZR * r + M_ZG * g + M_ZB * b;
    if (!(X > 0.0f)) return 0.0f;
    return fmax(Y * (WARD97_GAIN * (1.0f + (Y + Z) / X) - WARD97_OFFSET), 0.0f);
}

/* scotopic_luminance of four pixels (Y: their photopic luminance). */
inline float4 scotopic_luminance4(const float4 r, const float4 g, const float4 b,
                                  const float4 Y)
{
    const float4 X = M_XR * r + M_XG * g + M_XB * b;
    const float4 Z = M_ZR * r + M_ZG * g + M_ZB * b;
    const float4 ys = fmax(Y * (WARD97_GAIN * (1.0f + (Y + Z) / X) - WARD97_OFFSET), 0.0f);
    return select((float4)(0.0f), ys, isgreater(X, (float4)(0.0f)));
}

/* log2 of four positive normal floats, inline: PoCL (pyopencl's wheel) calls its log2
 * out of line, and the call cost meter_partial more than its sums (perf). The
 * exponent from the bits; the mantissa m, taken to [sqrt(1/2), sqrt(2)), by the
 * series log2 m = 2/ln2 (t + t^3/3 + ... + t^9/9), t = (m - 1)/(m + 1), |t| < 0.172:
 * the first term left out is below 3e-10; float32 rounding dominates (within 1.2e-7
 * of max(1, |log2 x|) from 1e-6 to 1e10 where the division is correctly rounded, as on
 * CPU drivers; 1.33e-7 on NVIDIA's, within the specification's 2.5-ulp division:
 * tests/backends/test_opencl_vs_reference.py). */
inline float4 log2_positive4(const float4 x)
{
    const int4 bits = as_int4(x);
    const int4 big = (bits & 0x007fffff) > 0x003504f3;          /* m > sqrt(2): -1 */
    const float4 m = as_float4(((bits & 0x007fffff) | 0x3f800000) - (big & 0x00800000));
    const int4 e = ((bits >> 23) & 0xff) - 127 - big;
    const float4 t = (m - 1.0f) / (m + 1.0f), t2 = t * t;
    const float c = 2.0f * M_LOG2E_F;                            /* 2 / ln 2 */
    const float4 p = c * t * (1.0f + t2 * (1.0f / 3.0f + t2 * (1.0f / 5.0f
                     + t2 * (1.0f / 7.0f + t2 * (1.0f / 9.0f)))));
    return (as_float4(e + 0x4b400000) - 0x1.8p23f) + p;      /* (float)e, |e| < 2^22 */
}

/* x^e for x > 0 as exp2(e*log2(x)): PoCL's scalar pow() is much slower. */
inline float powp(float x, float e) { return exp2(e * log2(x)); }
inline float4 powp4(float4 x, float4 e) { return exp2(e * log2(x)); }

/* Highlight shoulder (ocl_tonemap/models/display.py, apply_shoulder): luminance through
 * S (identity up to the knee, then knee + (1-knee)(1 - (1+t)^-p), t = (x-knee) /
 * ((1-knee) p), p = SHOULDER_POWER),
 * then desaturation toward it where the largest channel would exceed S'(max),
 * S' with the later knee CHANNEL_KNEE.
 * Values relative to white (inv_white); knee <= 0: none. */

inline float shoulder_curve(const float x, const float knee)
{
    if (!(x > knee)) return x;
    const float t = (x - knee) / ((1.0f - knee) * SHOULDER_POWER);
    return knee + (1.0f - knee) * (1.0f - powp(1.0f + t, -SHOULDER_POWER));
}

inline float3 shoulder3(float3 c, const float inv_white, const float knee)
{
    if (!(knee > 0.0f)) return c;
    c = fmax(c * inv_white, 0.0f);
    const float m = fmax(fmax(c.x, c.y), c.z);
    if (!(m > knee)) return c / inv_white;
    const float Y = M_YR * c.x + M_YG * c.y + M_YB * c.z;
    if (!(Y > 0.0f)) return (float3)(0.0f);
    const float Ys = shoulder_curve(Y, knee);
    const float g = Ys / Y;
    const float top = m * g, cap = shoulder_curve(m, CHANNEL_KNEE);
    const float t = top > cap ? clamp((cap - Ys) / fmax(top - Ys, 1.0e-30f), 0.0f, 1.0f) : 1.0f;
    return (Ys + (c * g - Ys) * t) / inv_white;
}

/* Four pixels at a time, their channels apart (r, g, b hold pixels 4q .. 4q+3):
 * twelve interleaved floats in and out, and shoulder3 on each of the four. The 12
 * floats of quad q go as float4 loads and stores where they start at a multiple of 16
 * bytes (a whole buffer's quads), else by vload4/vstore4 (a band's offset): PoCL
 * calls vload4 and vstore4 out of line. load_rgb4_at: the four pixels from p, wherever
 * they start. */
inline void load_rgb4_at(__global const float *p, float4 *r, float4 *g, float4 *b)
{
    float4 a0, a1, a2;
    if (((size_t)p & 15) == 0) {
        __global const float4 *p4 = (__global const float4 *)p;
        a0 = p4[0]; a1 = p4[1]; a2 = p4[2];
    } else {
        a0 = vload4(0, p); a1 = vload4(1, p); a2 = vload4(2, p);
    }
    *r = (float4)(a0.x, a0.w, a1.z, a2.y);
    *g = (float4)(a0.y, a1.x, a1.w, a2.z);
    *b = (float4)(a0.z, a1.y, a2.x, a2.w);
}

/* Pixels 4q .. 4q+3 of an interleaved RGB buffer. */
inline void load_rgb4(const int q, __global const float *rgb, float4 *r, float4 *g, float4 *b)
{
    load_rgb4_at(rgb + 12 * (size_t)q, r, g, b);
}

inline void store_rgb4(const int q, __global float *rgb, const float4 r, const float4 g,
                       const float4 b)
{
    __global float *p = rgb + 12 * (size_t)q;
    const float4 a0 = (float4)(r.x, g.x, b.x, r.y), a1 = (float4)(g.y, b.y, r.z, g.z),
                 a2 = (float4)(b.z, r.w, g.w, b.w);
    if (((size_t)p & 15) == 0) {
        __global float4 *p4 = (__global float4 *)p;
        p4[0] = a0; p4[1] = a1; p4[2] = a2;
    } else {
        vstore4(a0, 0, p); vstore4(a1, 1, p); vstore4(a2, 2, p);
    }
}

inline float4 shoulder_curve4(const float4 x, const float knee)
{
    const float4 t = fmax(x - knee, 0.0f) / ((1.0f - knee) * SHOULDER_POWER);
    return select(x, knee + (1.0f - knee) * (1.0f - powp4(1.0f + t, (float4)(-SHOULDER_POWER))),
                  isgreater(x, (float4)(knee)));
}

/* shoulder3 of four pixels: the same steps, each pixel's branches as selects. */
inline void shoulder4(float4 *r, float4 *g, float4 *b, const float inv_white, const float knee)
{
    if (!(knee > 0.0f)) return;
    const float4 cr = fmax(*r * inv_white, 0.0f), cg = fmax(*g * inv_white, 0.0f),
                 cb = fmax(*b * inv_white, 0.0f);
    const float4 m = fmax(fmax(cr, cg), cb);
    const int4 bright = isgreater(m, (float4)(knee));
    if (!(bright.x | bright.y | bright.z | bright.w)) {  /* all four below the knee (any():
                                                        * a call on PoCL) */
        *r = cr / inv_white; *g = cg / inv_white; *b = cb / inv_white;
        return;
    }
    const float4 Y = M_YR * cr + M_YG * cg + M_YB * cb;
    const float4 Ys = shoulder_curve4(Y, knee);
    const float4 gY = Ys / Y;
    const float4 top = m * gY, cap = shoulder_curve4(m, CHANNEL_KNEE);
    const float4 t = select((float4)(1.0f),
                            clamp((cap - Ys) / fmax(top - Ys, 1.0e-30f), 0.0f, 1.0f),
                            isgreater(top, cap));
    const int4 lit = isgreater(Y, (float4)(0.0f));
    const float4 zero = (float4)(0.0f);
    *r = select(cr, select(zero, Ys + (cr * gY - Ys) * t, lit), bright) / inv_white;
    *g = select(cg, select(zero, Ys + (cg * gY - Ys) * t, lit), bright) / inv_white;
    *b = select(cb, select(zero, Ys + (cb * gY - Ys) * t, lit), bright) / inv_white;
}

