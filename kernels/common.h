/* Shared by every program: constants that must match ocl_tonemap/photometry.py. */
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

/* x^e for x > 0 as exp2(e*log2(x)): PoCL's scalar pow() is much slower. */
inline float powp(float x, float e) { return exp2(e * log2(x)); }
inline float4 powp4(float4 x, float4 e) { return exp2(e * log2(x)); }

/* Hue-preserving highlight shoulder (ocl_tonemap/display.py, apply_shoulder):
 * channels scaled by S(m)/m, m = max channel / white; S is identity up to the
 * knee, then knee + (1-knee) t/(1+t), t = (m-knee)/(1-knee). knee <= 0: none. */
inline float3 shoulder3(float3 c, const float inv_white, const float knee)
{
    const float m = fmax(fmax(c.x, c.y), c.z) * inv_white;
    if (!(knee > 0.0f) || !(m > knee)) return c;
    const float t = (m - knee) / (1.0f - knee);
    return c * ((knee + (1.0f - knee) * t / (1.0f + t)) / m);
}
