/* Combining the partial chronovolumes of two consecutive runs of time steps, for sliding
 * windows (DESIGN.md section 3; chronocl/reference.py `combine` is the oracle). One voxel per
 * work-item; `front` holds the run integrated first. Partials are premultiplied RGBA float4,
 * t_index int (-1: no step) and, for max/min, the winning normalised value.
 *
 * Additive windows are not combined but updated in place: the colour sums are kept in
 * 40-bit fixed point (long per channel), so adding a step and later subtracting the very
 * same contribution cancels exactly and the window never drifts.
 *
 * Build options: IS_MIN (combine_extreme keeps the smaller value).
 */

#pragma OPENCL FP_CONTRACT OFF

#define FIXED_ONE 1099511627776.0f /* 2^40 */

__kernel void combine_over(__global const float4 *front, __global const float4 *back,
                           __global float4 *out)
{
    const size_t i = get_global_id(0);
    const float4 f = front[i];
    out[i] = f + (1.0f - f.w) * back[i];
}

__kernel void combine_first(__global const float4 *front, __global const int *front_t,
                            __global const float4 *back, __global const int *back_t,
                            __global float4 *out, __global int *out_t)
{
    const size_t i = get_global_id(0);
    const int keep = front_t[i] >= 0;
    out[i] = keep ? front[i] : back[i];
    out_t[i] = keep ? front_t[i] : back_t[i];
}

/* Ties keep the front: the step integrated first wins, as in integrate_extreme. */
__kernel void combine_extreme(__global const float4 *front, __global const int *front_t,
                              __global const float *front_v, __global const float4 *back,
                              __global const int *back_t, __global const float *back_v,
                              __global float4 *out, __global int *out_t, __global float *out_v)
{
    const size_t i = get_global_id(0);
    const float a = front_v[i], b = back_v[i];
#ifdef IS_MIN
    const int beats = b < a;
#else
    const int beats = b > a;
#endif
    const int keep = front_t[i] >= 0 && !(beats && back_t[i] >= 0);
    out[i] = keep ? front[i] : back[i];
    out_t[i] = keep ? front_t[i] : back_t[i];
    out_v[i] = keep ? a : b;
}

__kernel void combine_fmax(__global const float *front, __global const float *back,
                           __global float *out)
{
    const size_t i = get_global_id(0);
    out[i] = fmax(front[i], back[i]);
}

/* acc (3 longs per voxel) += sign * fixed(a_k * c_k) of one step's raw additive partial. */
__kernel void fixed_add(__global const float4 *step, __global long *acc, const int sign)
{
    const size_t i = get_global_id(0);
    const float4 s = step[i];
    const long r = convert_long_rtz(s.x * FIXED_ONE);
    const long g = convert_long_rtz(s.y * FIXED_ONE);
    const long b = convert_long_rtz(s.z * FIXED_ONE);
    acc[3 * i] += sign > 0 ? r : -r;
    acc[3 * i + 1] += sign > 0 ? g : -g;
    acc[3 * i + 2] += sign > 0 ? b : -b;
}

/* The finished additive chronovolume: sums / norm per channel (0 where norm is 0), clamped
 * to the window's largest opacity `alpha`, as reference.finalize does. */
__kernel void fixed_finalize(__global const long *acc, __global const float *alpha,
                             __global float4 *out, const float4 norm)
{
    const size_t i = get_global_id(0);
    const float a = alpha[i];
    const float r = convert_float(acc[3 * i]) / FIXED_ONE;
    const float g = convert_float(acc[3 * i + 1]) / FIXED_ONE;
    const float b = convert_float(acc[3 * i + 2]) / FIXED_ONE;
    out[i] = (float4)(norm.x > 0.0f ? fmin(r / norm.x, a) : 0.0f,
                      norm.y > 0.0f ? fmin(g / norm.y, a) : 0.0f,
                      norm.z > 0.0f ? fmin(b / norm.z, a) : 0.0f, a);
}
