/* mean: the time average of premultiplied colour and opacity, (1/W) sum (a_k * c_k, a_k).
 * RAW_PARTIAL writes the sums (a sliding window divides once, after adding and subtracting steps). */
#ifndef SLIDING
#define MEAN_STEP(s, k)                          \
    {                                            \
        STEP_RGBA(k, r, g, b, ak)                \
        s.r = madd(ak, r, s.r);                  \
        s.g = madd(ak, g, s.g);                  \
        s.b = madd(ak, b, s.b);                  \
        s.a += ak;                               \
    }
#ifdef RAW_PARTIAL
#define MEAN_FINISH(s) STORE_RGBA(o, s.r, s.g, s.b, s.a);
#else
#define MEAN_FINISH(s)                                                   \
    {                                                                    \
        const float n = (float)w;                                        \
        STORE_RGBA(o, s.r / n, s.g / n, s.b / n, s.a / n);                \
    }
#endif

__kernel void integrate_mean(KERNEL_ARGS, __global out_t *out)
{
    VECTOR_BODY(Rgba, 0, RGBA_ZERO, MEAN_STEP, NEVER_DONE, MEAN_FINISH)
}

#if VEC == 16
__kernel void integrate_mean_rows(KERNEL_ARGS, __global out_t *out, ROWS_ARGS(Rgba))
{
    ROWS_BODY(Rgba, 0, RGBA_ZERO, MEAN_STEP, NEVER_DONE, MEAN_FINISH)
}
#endif
#else
/* The window's average from its fixed-point sums (4 longs per voxel) and 1 / W. */
__kernel void finish_mean(__global const long *acc, __global float4 *out, const float inv_w,
                          ELEMENT_ARGS)
{
    ELEMENT(i);
    out[i] = (float4)(convert_float(acc[4 * i]) / FIXED_ONE, convert_float(acc[4 * i + 1]) / FIXED_ONE,
                      convert_float(acc[4 * i + 2]) / FIXED_ONE,
                      convert_float(acc[4 * i + 3]) / FIXED_ONE) * inv_w;
}
#endif
