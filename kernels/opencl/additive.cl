/* additive: C = sum a_k * c_k, A = max a_k. With NORM_TIME the colour is divided per channel
 * by N = sum a_t * rgb_t (norm.xyz; a channel with N = 0 gives 0) and clamped to A here;
 * otherwise the raw sums are written and the host normalises by the volume's maximum. */
#ifndef SLIDING
#define SUM_STEP(s, k)                           \
    {                                            \
        STEP_RGBA(k, r, g, b, ak)                \
        s.r = madd(ak, r, s.r);                  \
        s.g = madd(ak, g, s.g);                  \
        s.b = madd(ak, b, s.b);                  \
        s.a = VMAX(s.a, ak);                     \
    }
#ifdef NORM_TIME
#define SUM_FINISH(s)                                                          \
    STORE_RGBA(o, norm.x > 0.0f ? VMIN(s.r / norm.x, s.a) : (floatv)(0.0f),     \
               norm.y > 0.0f ? VMIN(s.g / norm.y, s.a) : (floatv)(0.0f),       \
               norm.z > 0.0f ? VMIN(s.b / norm.z, s.a) : (floatv)(0.0f), s.a);
#else
#define SUM_FINISH(s) STORE_RGBA(o, s.r, s.g, s.b, s.a);
#endif

__kernel void integrate_additive(KERNEL_ARGS, const float4 norm, __global out_t *out)
{
    VECTOR_BODY(Rgba, 0, RGBA_ZERO, SUM_STEP, NEVER_DONE, SUM_FINISH)
}

#if VEC == 16
__kernel void integrate_additive_rows(KERNEL_ARGS, const float4 norm, __global out_t *out,
                                      ROWS_ARGS(Rgba))
{
    ROWS_BODY(Rgba, 0, RGBA_ZERO, SUM_STEP, NEVER_DONE, SUM_FINISH)
}
#endif
#else
/* Combining the partials of two consecutive runs of steps, `front` integrated first
 * (chronocl/modes/additive.py `combine` is the oracle). One voxel per work-item. */

__kernel void combine_fmax(__global const float *front, __global const float *back,
                           __global float *out, ELEMENT_ARGS)
{
    ELEMENT(i);
    out[i] = fmax(front[i], back[i]);
}

/* The finished additive chronovolume: sums / norm per channel (0 where norm is 0), clamped
 * to the window's largest opacity `alpha`, as reference.finalize does. */
__kernel void finish_additive(__global const long *acc, __global const float *alpha,
                             __global float4 *out, const float4 norm, ELEMENT_ARGS)
{
    ELEMENT(i);
    const float a = alpha[i];
    const float r = convert_float(acc[3 * i]) / FIXED_ONE;
    const float g = convert_float(acc[3 * i + 1]) / FIXED_ONE;
    const float b = convert_float(acc[3 * i + 2]) / FIXED_ONE;
    out[i] = (float4)(norm.x > 0.0f ? fmin(r / norm.x, a) : 0.0f,
                      norm.y > 0.0f ? fmin(g / norm.y, a) : 0.0f,
                      norm.z > 0.0f ? fmin(b / norm.z, a) : 0.0f, a);
}
#endif
