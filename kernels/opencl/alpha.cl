/* alpha: front-to-back `over` through time, premultiplied; the first step in the order is in
 * front. C += (1 - A) * a_k * c_k; A += (1 - A) * a_k. */
#ifndef SLIDING
#define OVER_STEP(s, k)                          \
    {                                            \
        STEP_RGBA(k, r, g, b, ak)                \
        const floatv tk = (1.0f - s.a) * ak;     \
        s.r = madd(tk, r, s.r);                  \
        s.g = madd(tk, g, s.g);                  \
        s.b = madd(tk, b, s.b);                  \
        s.a += tk;                               \
    }
#ifdef EARLY_EXIT
/* What the remaining steps could add is at most the transmittance 1 - A. */
#define OVER_DONE(s) ALL(1.0f - (s).a < 1e-6f)
#else
#define OVER_DONE(s) NEVER_DONE(s)
#endif
#define OVER_FINISH(s) STORE_RGBA(o, s.r, s.g, s.b, s.a);

__kernel void integrate_alpha(KERNEL_ARGS, __global out_t *out)
{
    VECTOR_BODY(Rgba, 0, RGBA_ZERO, OVER_STEP, OVER_DONE, OVER_FINISH)
}

#if VEC == 16
__kernel void integrate_alpha_rows(KERNEL_ARGS, __global out_t *out, ROWS_ARGS(Rgba))
{
    ROWS_BODY(Rgba, 0, RGBA_ZERO, OVER_STEP, OVER_DONE, OVER_FINISH)
}
#endif
#else
/* Combining the partials of two consecutive runs of steps, `front` integrated first
 * (chronocl/modes/alpha.py `combine` is the oracle). One voxel per work-item. */

__kernel void combine_over(__global const float4 *front, __global const float4 *back,
                           __global colour_t *out, ELEMENT_ARGS)
{
    ELEMENT(i);
    const float4 f = front[i];
    out[i] = COLOUR(f + (1.0f - f.w) * back[i]);
}
#endif
