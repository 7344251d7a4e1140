/* count (occupancy): n = the number of steps whose opacity exceeds the threshold; the voxel is
 * the data TF at f = n / W, premultiplied. RAW_PARTIAL writes (n, 0, 0, 0) for sliding windows. */
#ifndef SLIDING
typedef struct {
    floatv n;
} Count;
#define COUNT_INIT(s) s.n = 0.0f;
#define COUNT_STEP(s, k)                                \
    {                                                   \
        STEP_POSITION(k, p)                             \
        THRESHOLD_TEST(p, k, (intv)(-1), pass)          \
        s.n = SELECT(s.n, s.n + 1.0f, pass);            \
    }
#ifdef RAW_PARTIAL
#define COUNT_FINISH(s) STORE_RGBA(o, s.n, (floatv)(0.0f), (floatv)(0.0f), (floatv)(0.0f));
#else
#define COUNT_FINISH(s)                                                  \
    {                                                                    \
        const LutPos q = lut_pos_of(s.n / (float)w);                     \
        const floatv a = LUT_CHANNEL(lut, 3, q);                         \
        STORE_RGBA(o, LUT_CHANNEL(lut, 0, q) * a, LUT_CHANNEL(lut, 1, q) * a, \
                   LUT_CHANNEL(lut, 2, q) * a, a);                       \
    }
#endif

__kernel void integrate_count(KERNEL_ARGS, const float threshold, __global out_t *out)
{
    VECTOR_BODY(Count, 0, COUNT_INIT, COUNT_STEP, NEVER_DONE, COUNT_FINISH)
}

#if VEC == 16
__kernel void integrate_count_rows(KERNEL_ARGS, const float threshold, __global out_t *out,
                                   ROWS_ARGS(Count))
{
    ROWS_BODY(Count, 0, COUNT_INIT, COUNT_STEP, NEVER_DONE, COUNT_FINISH)
}
#endif
#else
/* The window's occupancy from its fixed-point counts (1 long per voxel) through the planar
 * data LUT (LUT_N entries per channel), as reference: f = n / W, premultiplied TF(f). */
__kernel void finish_count(__global const long *acc, __global const float *lut,
                           __global float4 *out, const float w, ELEMENT_ARGS)
{
    ELEMENT(i);
    const float f = (convert_float(acc[i]) / FIXED_ONE) / w;
    const float x = f * (float)(LUT_N - 1);
    const int i0 = min(convert_int(x), LUT_N - 2);
    const float t = x - convert_float(i0);
#define CH(c) (lut[(c) * LUT_N + i0] * (1.0f - t) + lut[(c) * LUT_N + i0 + 1] * t)
    const float a = CH(3);
    out[i] = (float4)(CH(0) * a, CH(1) * a, CH(2) * a, a);
#undef CH
}
#endif
