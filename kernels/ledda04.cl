/* Ledda, Santos & Chalmers 2004: per-pixel luminances, time course and mapping.
 * Reference: ocl_tonemap/models/ledda2004.py (float64). */

/* V_FLOOR, ALPHA, BETA_CONE, BETA_ROD, TAU_CONE, TAU_ROD, LN_RHO_CONE, LN_RHO_ROD,
 * K_MAX, K_SLOPE, E_MAX, E_CEILING, T_DONE, T_HOLD, COURSE_DONE, COURSE_RUNNING,
 * AHEAD_TOL, JUMP_LOG2, MES_LOG_OFFSET, MES_LOG_SPAN, N_EXP (Eqs. 1-3's n),
 * Y_COEFF_R/G/B (Eq. 6) and YS_COEFF_R/G/B (Eq. 7) are given as build options from
 * ocl_tonemap/models/ledda2004.py (backends/opencl/ledda04.py, KERNEL_CONSTANTS);
 * DISPLAY_LINEAR_MAX and SIGNAL_CEILING with common.h's: one definition, not retyped
 * here. */

/* Eqs. 6-7; Y' clamped at 0. ward: Y' of Ward-Larson et al. 1997 instead of
 * Eq. 7 (the default mode; ocl_tonemap/models/ledda2004.py, luminances). */
inline float ledda_Y(float3 c) { return Y_COEFF_R * c.x + Y_COEFF_G * c.y + Y_COEFF_B * c.z; }
inline float ledda_Ys(float3 c, const int ward)
{
    return ward ? scotopic_luminance(c.x, c.y, c.z)
                : fmax(YS_COEFF_R * c.x + YS_COEFF_G * c.y + YS_COEFF_B * c.z, 0.0f);
}

/* The signals the bilateral filter sees: Y and Y', floored at V_FLOOR. */
__kernel void ledda04_luminance(__global const float *rgb, const int n,
                                __global float *Y, __global float *Ys, const int ward)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    float3 c = vload3(i, rgb);
    Y[i] = fmax(ledda_Y(c), V_FLOOR);
    Ys[i] = fmax(ledda_Ys(c, ward), V_FLOOR);
}

inline float sigma_of(float I, float beta) { return beta * powp(fmax(I, V_FLOOR), ALPHA); }

inline float K_of_energy(float E) { return K_MAX + K_SLOPE * clamp(E, 0.0f, E_MAX); }

/* Eq. 14 with Table 1's normalisers, as a fraction between sigma_fin (0) and sigma_in (1). */
inline float dark_fraction(float t, float K, float tau)
{
    if (t >= tau) return 0.0f;
    float tt = fmax(t, 1.0f);
    float e_tau = exp(K / tau);
    return clamp((exp(K / tt) - e_tau) / (exp(K) - e_tau), 0.0f, 1.0f);
}

/* Eq. 15: 1 - ln t / ln rho. */
inline float light_fraction(float t, float ln_rho)
{
    return clamp(1.0f - log(fmax(t, 1.0f)) / ln_rho, 0.0f, 1.0f);
}

inline float sigma_cone_at(float s_in, float s_fin, float t, float K)
{
    float f = s_fin < s_in ? dark_fraction(t, K, TAU_CONE) : light_fraction(t, LN_RHO_CONE);
    return s_fin + f * (s_in - s_fin);
}

inline float sigma_rod_at(float s_in, float s_fin, float t, float K)
{
    float f = s_fin < s_in ? dark_fraction(t - TAU_CONE, K, TAU_ROD) : light_fraction(t, LN_RHO_ROD);
    return s_fin + f * (s_in - s_fin);
}

/* dR/dln L of Eqs. 2-3 for a small neutral increment on L (cd/m^2) seen with the cone and
 * rod sigmas sc, sr, mixed by Eq. 11's mes at the cone level sc gives
 * (ledda2004.response_slope); x (1 - x) as r / (1 + r)^2, r = (sigma / L)^n (no
 * cancellation where L >> sigma). */
inline float ledda_response_slope(const float L, const float sc, const float sr,
                                  const float rod_ratio)
{
    const float Ia = powp(sc / BETA_CONE, 1.0f / ALPHA);
    const float u = clamp((log10(fmax(Ia, V_FLOOR)) + MES_LOG_OFFSET) / MES_LOG_SPAN, 0.0f, 1.0f);
    const float mes = u * u * (3.0f - 2.0f * u);
    const float rc = powp(sc / L, N_EXP), rr = powp(sr / (L * rod_ratio), N_EXP);
    return N_EXP * (mes * rc / ((1.0f + rc) * (1.0f + rc))
                    + (1.0f - mes) * rr / ((1.0f + rr) * (1.0f + rr)));
}

/* Each pixel's adaptation levels (cones, rods) of this frame: the filtered levels,
 * blended with the frame's global level in the default mode (I_local^s G^(1-s)). */
inline float2 adaptation_levels(__global const float *Ic, __global const float *Ir, const int i,
                                const int rod_from_cone, const float rod_scale,
                                const float strength, const float ln_global_c,
                                const float ln_global_r, const float gain_c, const float gain_r)
{
    float ic = Ic[i];
    float ir = rod_from_cone ? rod_scale * ic : Ir[i];
    if (strength < 1.0f) {
        ic = exp(strength * log(fmax(ic, V_FLOOR)) + (1.0f - strength) * ln_global_c);
        ir = rod_from_cone ? rod_scale * ic
                           : exp(strength * log(fmax(ir, V_FLOOR)) + (1.0f - strength) * ln_global_r);
    }
    /* the shared pigment course's equivalent background, as the frame's factor on every
     * pixel's level (ledda04.py LeddaSchedule: 1 with --mode paper) */
    return (float2)(ic * gain_c, ir * gain_r);
}

/* goal_ahead of ledda2004.py: the course s_in -> s_fin has a direction and the new
 * goal lies beyond the current sigma in it. */
inline bool goal_ahead(const float s_in, const float s_fin, const float now, const float goal)
{
    const float d = s_fin - s_in;
    if (!(fabs(d) > 1.0e-5f * s_in)) return false;
    return d > 0.0f ? goal > now * (1.0f - AHEAD_TOL) : goal < now * (1.0f + AHEAD_TOL);
}

/* course_done of ledda2004.py: at most COURSE_RUNNING of the course is left. */
inline bool course_done(const float s_in, const float s_fin, const float now)
{
    const float d = s_fin - s_in;
    return !(fabs(d) > 1.0e-5f * s_in) || (s_fin - now) / d <= COURSE_RUNNING;
}

/* course_clock of ledda2004.py: the time on the curve s_in -> goal (Eqs. 14-15
 * inverted) at which sigma stands at now; t_now while the course is in its hold,
 * T_DONE once sigma is within COURSE_DONE of the goal. */
inline float course_clock(const float s_in, const float goal, const float now, const float K,
                          const float t_now, const int rod)
{
    const float f = clamp((goal - now) / (goal - s_in), 0.0f, 1.0f);
    if (fabs(goal - now) <= COURSE_DONE * goal) return T_DONE;
    const bool dark = goal < s_in;
    const float lag = (rod && dark) ? TAU_CONE : 0.0f;
    if (f >= 1.0f - 1.0e-5f) return fmin(t_now, lag + T_HOLD);
    if (!dark) return exp((1.0f - f) * (rod ? LN_RHO_ROD : LN_RHO_CONE));
    const float a = exp(K / (rod ? TAU_ROD : TAU_CONE));
    return lag + K / log(a + f * (exp(K) - a));
}

/* integrate: one frame for every pixel: take the new goals (init: become fully
 * adapted to them with energy E_init; else advance each receptor's course by dt,
 * re-aim it at a goal ahead, and begin a new one where the goal turned back more
 * than change_log2 from its anchor: step_reference of ledda2004.py).
 *   Ic, Ir: adaptation luminances of cones and rods; Ir is read as
 *           rod_scale * Ic[i] when rod_from_cone is set (rods not filtered).
 *   state:  the planes of ledda2004.STATE_CHANNELS, in that order, `stride` floats
 *           each; this band starts at plane offset 0.
 *   counts[0] += pixels that began a new course. */
/* One pixel of ledda04_step; returns 1 when it began a new course. */
inline int ledda04_step_one(__global const float *Ic, __global const float *Ir,
                            const int rod_from_cone, const float rod_scale,
                            __global float *state, const int stride, const int i,
                            const float dt, const int init, const float E_init,
                            const float change_log2, const float strength,
                            const float ln_global_c, const float ln_global_r,
                            const float gain_c, const float gain_r)
{
    __global float *s = state + i;
    const float2 lv = adaptation_levels(Ic, Ir, i, rod_from_cone, rod_scale, strength,
                                        ln_global_c, ln_global_r, gain_c, gain_r);
    const float gc = sigma_of(lv.x, BETA_CONE), gr = sigma_of(lv.y, BETA_ROD);
    float sic, sfc, sac, sir, sfr, sar, tc, tr, E, K;
    int restarted = 0;
    if (init) {
        sic = sfc = sac = gc;
        sir = sfr = sar = gr;
        tc = tr = T_DONE; E = E_init; K = K_of_energy(E_init);
    } else {
        sic = s[0]; sfc = s[stride]; sac = s[2 * stride];
        sir = s[3 * stride]; sfr = s[4 * stride]; sar = s[5 * stride];
        tc = fmin(s[6 * stride] + dt, T_DONE); tr = fmin(s[7 * stride] + dt, T_DONE);
        E = s[8 * stride]; K = s[9 * stride];
        const float nc = sigma_cone_at(sic, sfc, tc, K), nr = sigma_rod_at(sir, sfr, tr, K);
        const float i_prev = powp(sfc / BETA_CONE, 1.0f / ALPHA);
        E = fmin(E + i_prev * dt, E_CEILING);
        const bool moved = fabs(log2(gc / sac)) > change_log2 ||
                           fabs(log2(gr / sar)) > change_log2;
        const bool jumped = fabs(log2(gc / sfc)) > JUMP_LOG2 || fabs(log2(gr / sfr)) > JUMP_LOG2;
        const bool ac = goal_ahead(sic, sfc, nc, gc), ar = goal_ahead(sir, sfr, nr, gr);
        if (ac && gc != sfc) tc = course_clock(sic, gc, nc, K, tc, 0);   /* a goal that */
        if (ar && gr != sfr) tr = course_clock(sir, gr, nr, K, tr, 1);   /* moved */
        if (moved) {
            sac = gc; sar = gr;
            if (!(ac && ar) || (jumped && course_done(sic, sfc, nc))) {
                sic = nc; sir = nr;
                tc = tr = jumped ? 0.0f : T_HOLD;
                K = K_of_energy(E); E = 0.0f;
                restarted = 1;
            }
        }
        sfc = gc; sfr = gr;
    }
    s[0] = sic; s[stride] = sfc; s[2 * stride] = sac;
    s[3 * stride] = sir; s[4 * stride] = sfr; s[5 * stride] = sar;
    s[6 * stride] = tc; s[7 * stride] = tr; s[8 * stride] = E; s[9 * stride] = K;
    return restarted;
}

__kernel void ledda04_step(__global const float *Ic, __global const float *Ir,
                           const int rod_from_cone, const float rod_scale,
                           __global float *state, const int stride, const int n,
                           const float dt, const int init, const float E_init,
                           const float change_log2, __global int *counts,
                           const float strength, const float ln_global_c,
                           const float ln_global_r, const float gain_c, const float gain_r)
{
    __local int lrestart;
    if (get_local_id(0) == 0) lrestart = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int i = get_global_id(0);
    if (i < n && ledda04_step_one(Ic, Ir, rod_from_cone, rod_scale, state, stride, i, dt,
                                  init, E_init, change_log2, strength, ln_global_c,
                                  ln_global_r, gain_c, gain_r))
        atomic_inc(&lrestart);
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0 && lrestart) atomic_add(&counts[0], lrestart);
}

/* Pixel i's observer for a visibility threshold (kernels/visibility.cl, its
 * OBSERVER_LEDDA04 build; ledda04.py observer_slope, observer_level): (gain now, cone
 * level I_A) at a background of L cd/m^2 (the light behind the media), from its
 * state's current sigmas; the gain when adapted there comes from the run's table. */
inline float2 ledda04_observer(__global const float *state, const int stride, const int i,
                               const float L, const float rod_ratio)
{
    __global const float *s = state + i;
    const float K = s[9 * stride];
    const float sc = sigma_cone_at(s[0], s[stride], s[6 * stride], K);
    const float sr = sigma_rod_at(s[3 * stride], s[4 * stride], s[7 * stride], K);
    return (float2)(ledda_response_slope(fmax(L, V_FLOOR), sc, sr, rod_ratio),
                    powp(sc / BETA_CONE, 1.0f / ALPHA));
}

/* apply: Eqs. 11-13 with the current sigmas of the state, then the shoulder.
 *   rgb: working-space cd/m^2, pixel i of this band at rgb_off + i.
 *   out: display-linear RGB. */
__kernel void ledda04_map(__global const float *rgb, const int rgb_off,
                          __global const float *Ic, __global const float *state,
                          const int stride, const int n, const float sigma_disp,
                          const float inv_unit, __global float *out, const float strength,
                          const float ln_global_c, const float inv_white, const float knee,
                          const int ward, const float mes_gain)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    __global const float *s = state + i;
    float ic = Ic[i];                      /* the cone level, as adaptation_levels gives it */
    if (strength < 1.0f)
        ic = exp(strength * log(fmax(ic, V_FLOOR)) + (1.0f - strength) * ln_global_c);
    const float sic = s[0], sfc = s[stride], sir = s[3 * stride], sfr = s[4 * stride];
    const float K = s[9 * stride];
    const float sc = sigma_cone_at(sic, sfc, s[6 * stride], K);
    const float sr = sigma_rod_at(sir, sfr, s[7 * stride], K);
    /* Eq. 11 at the cone level times the frame's pigment factor (Ledda04.mesopic_gain) */
    const float u = clamp((log10(fmax(ic * mes_gain, V_FLOOR)) + MES_LOG_OFFSET) / MES_LOG_SPAN,
                          0.0f, 1.0f);
    const float mes = u * u * (3.0f - 2.0f * u);
    const float3 c = vload3(rgb_off + i, rgb);
    const float cone_gain = mes * sigma_disp / sc * inv_unit;            /* Eq. 12 */
    const float rod_out = (1.0f - mes) * sigma_disp * ledda_Ys(c, ward) / sr * inv_unit; /* Eq. 13 */
    float3 o = fmin(c * cone_gain + rod_out, SIGNAL_CEILING);
    vstore3(clamp(shoulder3(o, inv_white, knee), 0.0f, DISPLAY_LINEAR_MAX), i, out);
}

/* ledda04_map four pixels per work-item: the same steps in float4 (both branches of
 * the time course computed, one selected per pixel); the tail pixels scalar. */
inline float4 dark_fraction4(const float4 t, const float4 K, const float tau)
{
    const float4 e_tau = exp(K / tau);
    const float4 f = clamp((exp(K / fmax(t, 1.0f)) - e_tau) / (exp(K) - e_tau), 0.0f, 1.0f);
    return select(f, (float4)(0.0f), isgreaterequal(t, (float4)(tau)));
}

inline float4 light_fraction4(const float4 t, const float ln_rho)
{
    return clamp(1.0f - log(fmax(t, 1.0f)) / ln_rho, 0.0f, 1.0f);
}

/* sigma_cone_at / sigma_rod_at on four pixels: both branches, selected per pixel. */
inline float4 sigma_cone_at4(const float4 s_in, const float4 s_fin, const float4 t,
                             const float4 K)
{
    const float4 f = select(light_fraction4(t, LN_RHO_CONE), dark_fraction4(t, K, TAU_CONE),
                            isless(s_fin, s_in));
    return s_fin + f * (s_in - s_fin);
}

inline float4 sigma_rod_at4(const float4 s_in, const float4 s_fin, const float4 t,
                            const float4 K)
{
    const float4 f = select(light_fraction4(t, LN_RHO_ROD),
                            dark_fraction4(t - TAU_CONE, K, TAU_ROD), isless(s_fin, s_in));
    return s_fin + f * (s_in - s_fin);
}

/* The default mode's blend of a local level with the frame's global one, I^s G^(1-s). */
inline float4 blend_global4(const float4 v, const float strength, const float ln_global)
{
    return exp(strength * log(fmax(v, V_FLOOR)) + (1.0f - strength) * ln_global);
}

/* ledda_response_slope on four pixels (logarithms inline: log2_positive4). */
inline float4 ledda_response_slope4(const float4 L, const float4 sc, const float4 sr,
                                    const float rod_ratio)
{
    const float4 lsc = log2_positive4(sc);
    const float4 Ia_log2 = (lsc - log2(BETA_CONE)) / ALPHA;             /* log2 I_A */
    const float4 u = clamp((fmax(Ia_log2, log2(V_FLOOR)) * M_LN2_F / M_LN10_F + MES_LOG_OFFSET)
                           / MES_LOG_SPAN, 0.0f, 1.0f);
    const float4 mes = u * u * (3.0f - 2.0f * u);
    const float4 lL = log2_positive4(L);
    const float4 rc = exp2(N_EXP * (lsc - lL));
    const float4 rr = exp2(N_EXP * (log2_positive4(sr) - lL - log2(rod_ratio)));
    return N_EXP * (mes * rc / ((1.0f + rc) * (1.0f + rc))
                    + (1.0f - mes) * rr / ((1.0f + rr) * (1.0f + rr)));
}

/* ledda04_observer of the four pixels i .. i + 3: their gains now at L (float4), and
 * their cone levels I_A in *Ia; the steady gain comes from the run's table. */
inline float4 ledda04_observer_now4(__global const float *state, const int stride, const int i,
                                    const float4 L, const float rod_ratio, float4 *Ia)
{
    __global const float *s = state + i;
    const float4 K = vload4(0, s + 9 * stride);
    const float4 sc = sigma_cone_at4(vload4(0, s), vload4(0, s + stride), vload4(0, s + 6 * stride), K);
    const float4 sr = sigma_rod_at4(vload4(0, s + 3 * stride), vload4(0, s + 4 * stride),
                                    vload4(0, s + 7 * stride), K);
    *Ia = exp2((log2_positive4(sc) - log2(BETA_CONE)) / ALPHA);
    return ledda_response_slope4(fmax(L, V_FLOOR), sc, sr, rod_ratio);
}

__kernel void ledda04_map4(__global const float *rgb, const int rgb_off,
                           __global const float *Ic, __global const float *state,
                           const int stride, const int n, const float sigma_disp,
                           const float inv_unit, __global float *out, const float strength,
                           const float ln_global_c, const float inv_white, const float knee,
                           const int ward, const float mes_gain)
{
    const int q = get_global_id(0), i0 = ITEM_PIXELS(4) * q;
    if (i0 >= n) return;
    if (!VECTOR_PIXELS || i0 + 4 > n) {            /* common.h */
        for (int i = i0; i < min(i0 + ITEM_PIXELS(4), n); ++i) {
            __global const float *s = state + i;
            float ic = Ic[i];
            if (strength < 1.0f)
                ic = exp(strength * log(fmax(ic, V_FLOOR)) + (1.0f - strength) * ln_global_c);
            const float sc = sigma_cone_at(s[0], s[stride], s[6 * stride], s[9 * stride]);
            const float sr = sigma_rod_at(s[3 * stride], s[4 * stride], s[7 * stride],
                                          s[9 * stride]);
            const float u = clamp((log10(fmax(ic * mes_gain, V_FLOOR)) + MES_LOG_OFFSET)
                                  / MES_LOG_SPAN, 0.0f, 1.0f);
            const float mes = u * u * (3.0f - 2.0f * u);
            const float3 c = vload3(rgb_off + i, rgb);
            const float3 o = fmin(c * (mes * sigma_disp / sc * inv_unit)
                                  + (1.0f - mes) * sigma_disp * ledda_Ys(c, ward) / sr * inv_unit,
                                  SIGNAL_CEILING);
            vstore3(clamp(shoulder3(o, inv_white, knee), 0.0f, DISPLAY_LINEAR_MAX), i, out);
        }
        return;
    }
    __global const float *s = state + i0;
    float4 ic = vload4(q, Ic);
    if (strength < 1.0f)
        ic = blend_global4(ic, strength, ln_global_c);
    const float4 K = vload4(0, s + 9 * stride);
    const float4 sc = sigma_cone_at4(vload4(0, s), vload4(0, s + stride),
                                     vload4(0, s + 6 * stride), K);
    const float4 sr = sigma_rod_at4(vload4(0, s + 3 * stride), vload4(0, s + 4 * stride),
                                    vload4(0, s + 7 * stride), K);
    const float4 u = clamp((log10(fmax(ic * mes_gain, V_FLOOR)) + MES_LOG_OFFSET) / MES_LOG_SPAN,
                           0.0f, 1.0f);
    const float4 mes = u * u * (3.0f - 2.0f * u);                        /* Eq. 11 */
    float4 r, g, b;
    load_rgb4(0, rgb + 3 * (size_t)(rgb_off + i0), &r, &g, &b);
    const float4 cone_gain = mes * sigma_disp / sc * inv_unit;           /* Eq. 12 */
    const float4 ys = ward ? scotopic_luminance4(r, g, b, M_YR * r + M_YG * g + M_YB * b)
                           : fmax(YS_COEFF_R * r + YS_COEFF_G * g + YS_COEFF_B * b, 0.0f);
    const float4 rod_out = (1.0f - mes) * sigma_disp * ys / sr * inv_unit;  /* Eq. 13 */
    r = fmin(r * cone_gain + rod_out, SIGNAL_CEILING);
    g = fmin(g * cone_gain + rod_out, SIGNAL_CEILING);
    b = fmin(b * cone_gain + rod_out, SIGNAL_CEILING);
    shoulder4(&r, &g, &b, inv_white, knee);
    store_rgb4(q, out, clamp(r, 0.0f, DISPLAY_LINEAR_MAX), clamp(g, 0.0f, DISPLAY_LINEAR_MAX),
               clamp(b, 0.0f, DISPLAY_LINEAR_MAX));
}


/* ledda04_step four pixels per work-item (same arguments; launched over n/4 items):
 * the same steps in float4, both branches computed and selected per lane. Tail
 * pixels scalar. */
inline float4 sigma_of4(const float4 I, const float beta)
{
    return beta * powp4(fmax(I, V_FLOOR), (float4)(ALPHA));
}

inline int4 goal_ahead4(const float4 s_in, const float4 s_fin, const float4 now,
                        const float4 goal)
{
    const float4 d = s_fin - s_in;
    return isgreater(fabs(d), 1.0e-5f * s_in) &
           select(isless(goal, now * (1.0f + AHEAD_TOL)), isgreater(goal, now * (1.0f - AHEAD_TOL)),
                  isgreater(d, (float4)(0.0f)));
}

inline int4 course_done4(const float4 s_in, const float4 s_fin, const float4 now)
{
    const float4 d = s_fin - s_in;
    return islessequal(fabs(d), 1.0e-5f * s_in) |
           islessequal((s_fin - now) / d, (float4)(COURSE_RUNNING));
}

inline float4 course_clock4(const float4 s_in, const float4 goal, const float4 now,
                            const float4 K, const float4 t_now, const int rod)
{
    const float4 f = clamp((goal - now) / (goal - s_in), 0.0f, 1.0f);
    const int4 dark = isless(goal, s_in);
    const float4 lag = rod ? select((float4)(0.0f), (float4)(TAU_CONE), dark) : (float4)(0.0f);
    const float4 a = exp(K / (rod ? TAU_ROD : TAU_CONE));
    const float4 t_dark = lag + K / log(a + f * (exp(K) - a));
    const float4 t_light = exp((1.0f - f) * (rod ? LN_RHO_ROD : LN_RHO_CONE));
    float4 t = select(t_light, t_dark, dark);
    t = select(t, fmin(t_now, lag + T_HOLD), isgreaterequal(f, (float4)(1.0f - 1.0e-5f)));
    return select(t, (float4)(T_DONE), islessequal(fabs(goal - now), COURSE_DONE * goal));
}

__kernel void ledda04_step4(__global const float *Ic, __global const float *Ir,
                            const int rod_from_cone, const float rod_scale,
                            __global float *state, const int stride, const int n,
                            const float dt, const int init, const float E_init,
                            const float change_log2, __global int *counts,
                            const float strength, const float ln_global_c,
                            const float ln_global_r, const float gain_c, const float gain_r)
{
    __local int lrestart;
    if (get_local_id(0) == 0) lrestart = 0;
    barrier(CLK_LOCAL_MEM_FENCE);
    const int q = get_global_id(0), i0 = ITEM_PIXELS(4) * q;
    if (!VECTOR_PIXELS || i0 + 4 > n) {            /* common.h */
        for (int i = i0; i < min(i0 + ITEM_PIXELS(4), n); ++i)
            if (ledda04_step_one(Ic, Ir, rod_from_cone, rod_scale, state, stride, i, dt, init,
                                 E_init, change_log2, strength, ln_global_c, ln_global_r,
                                 gain_c, gain_r))
                atomic_inc(&lrestart);
    } else {
        __global float *s = state + i0;
        float4 ic = vload4(q, Ic);
        float4 ir = rod_from_cone ? rod_scale * ic : vload4(q, Ir);
        if (strength < 1.0f) {
            ic = blend_global4(ic, strength, ln_global_c);
            ir = rod_from_cone ? rod_scale * ic : blend_global4(ir, strength, ln_global_r);
        }
        ic *= gain_c;
        ir *= gain_r;
        const float4 gc = sigma_of4(ic, BETA_CONE), gr = sigma_of4(ir, BETA_ROD);
        float4 sic, sfc, sac, sir, sfr, sar, tc, tr, E, K;
        if (init) {
            sic = sfc = sac = gc;
            sir = sfr = sar = gr;
            tc = tr = (float4)(T_DONE);
            E = (float4)(E_init); K = (float4)(K_of_energy(E_init));
        } else {
            sic = vload4(0, s); sfc = vload4(0, s + stride); sac = vload4(0, s + 2 * stride);
            sir = vload4(0, s + 3 * stride); sfr = vload4(0, s + 4 * stride);
            sar = vload4(0, s + 5 * stride);
            tc = fmin(vload4(0, s + 6 * stride) + dt, T_DONE);
            tr = fmin(vload4(0, s + 7 * stride) + dt, T_DONE);
            E = vload4(0, s + 8 * stride); K = vload4(0, s + 9 * stride);
            const float4 nc = sigma_cone_at4(sic, sfc, tc, K);
            const float4 nr = sigma_rod_at4(sir, sfr, tr, K);
            const float4 i_prev = powp4(sfc / BETA_CONE, (float4)(1.0f / ALPHA));
            E = fmin(E + i_prev * dt, E_CEILING);
            const int4 moved = isgreater(fabs(log2(gc / sac)), (float4)(change_log2)) |
                               isgreater(fabs(log2(gr / sar)), (float4)(change_log2));
            const int4 jumped = isgreater(fabs(log2(gc / sfc)), (float4)(JUMP_LOG2)) |
                                isgreater(fabs(log2(gr / sfr)), (float4)(JUMP_LOG2));
            const int4 ac = goal_ahead4(sic, sfc, nc, gc), ar = goal_ahead4(sir, sfr, nr, gr);
            const int4 rc = ac & isnotequal(gc, sfc), rr = ar & isnotequal(gr, sfr);
            if (any(rc)) tc = select(tc, course_clock4(sic, gc, nc, K, tc, 0), rc);
            if (any(rr)) tr = select(tr, course_clock4(sir, gr, nr, K, tr, 1), rr);
            if (any(moved)) {
                const int4 change = moved & (~(ac & ar) | (jumped & course_done4(sic, sfc, nc)));
                sac = select(sac, gc, moved);
                sar = select(sar, gr, moved);
                sic = select(sic, nc, change);
                sir = select(sir, nr, change);
                const float4 t0 = select((float4)(T_HOLD), (float4)(0.0f), jumped);
                tc = select(tc, t0, change);
                tr = select(tr, t0, change);
                K = select(K, K_MAX + K_SLOPE * clamp(E, 0.0f, E_MAX), change);
                E = select(E, (float4)(0.0f), change);
                atomic_add(&lrestart, -(change.x + change.y + change.z + change.w));
            }
            sfc = gc; sfr = gr;
        }
        vstore4(sic, 0, s); vstore4(sfc, 0, s + stride); vstore4(sac, 0, s + 2 * stride);
        vstore4(sir, 0, s + 3 * stride); vstore4(sfr, 0, s + 4 * stride);
        vstore4(sar, 0, s + 5 * stride);
        vstore4(tc, 0, s + 6 * stride); vstore4(tr, 0, s + 7 * stride);
        vstore4(E, 0, s + 8 * stride); vstore4(K, 0, s + 9 * stride);
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (get_local_id(0) == 0 && lrestart) atomic_add(&counts[0], lrestart);
}
