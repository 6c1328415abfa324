/* Shared by every program: constants that must match ocl_tonemap/models/photometry.py. */
#define L_MAX 1.0e10f            /* scene ceiling, cd/m^2 (+Inf maps here) */
#define NREPAIR 6                /* nan, pos_inf, neg_inf, negative, denormal, over_max */
#define LN10 2.302585092994046f

/* BT.709 linear RGB -> XYZ (D65) */
#define M_XR 0.4123907992659595f
#define M_XG 0.3575843393838780f
#define M_XB 0.1804807884018343f
#define M_YR 0.2126390058715104f
#define M_YG 0.7151686787677560f
#define M_YB 0.0721923153607337f
#define M_ZR 0.0193308187155918f
#define M_ZG 0.1191947797946260f
#define M_ZB 0.9505321522496606f

inline float scotopic_luminance(float r, float g, float b)
{
    /* Ward-Larson et al. 1997: Y' = Y (1.33 (1 + (Y+Z)/X) - 1.68) */
    float X = M_XR * r + M_XG * g + M_XB * b;
    float Y = M_YR * r + M_YG * g + M_YB * b;
    float Z = M_ZR * r + M_ZG * g + M_ZB * b;
    if (!(X > 0.0f)) return 0.0f;
    return fmax(Y * (1.33f * (1.0f + (Y + Z) / X) - 1.68f), 0.0f);
}

/* x^e for x > 0 as exp2(e*log2(x)): PoCL's scalar pow() is much slower. */
inline float powp(float x, float e) { return exp2(e * log2(x)); }
inline float4 powp4(float4 x, float4 e) { return exp2(e * log2(x)); }

/* Highlight shoulder (ocl_tonemap/models/display.py, apply_shoulder): luminance through
 * S (identity up to the knee, then knee + (1-knee) t/(1+t), t = (x-knee)/(1-knee)),
 * then desaturation toward it where the largest channel would exceed S'(max),
 * S' with the later knee CHANNEL_KNEE.
 * Values relative to white (inv_white); knee <= 0: none. */
#define CHANNEL_KNEE 0.9f
#define SIGNAL_CEILING 1.0e6f     /* ocl_tonemap/models/display.py SIGNAL_CEILING */

inline float shoulder_curve(const float x, const float knee)
{
    if (!(x > knee)) return x;
    const float t = (x - knee) / (1.0f - knee);
    return knee + (1.0f - knee) * t / (1.0f + t);
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
