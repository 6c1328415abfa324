/* The example plugin's per-pixel stage: display-linear = rgb x gain, clamped.
 * common.h (SIGNAL_CEILING ...) is prepended by ocl-tonemap's runtime; the packed
 * scalars' indices P_<name> come from the operator's kernel_call. */
__kernel void exposure_map(__global const float *rgb, __global const float *Y,
                           __global const float *Ys, __global float *out, const int n,
                           __constant const float *p)
{
    const int i = get_global_id(0);
    if (i >= n) return;
    const float3 c = vload3(i, rgb) * p[P_gain];
    vstore3(clamp(c, 0.0f, p[P_ceiling]), i, out);
}
