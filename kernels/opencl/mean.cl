/* mean: the time average of premultiplied colour and opacity, (1/W) sum (a_k * c_k, a_k).
 * RAW_PARTIAL writes the sums (a sliding window divides once, after adding and subtracting steps). */
#ifndef SLIDING
__kernel void integrate_mean(KERNEL_ARGS, __global float4 *out)
{
    VOXEL_PROLOGUE
    floatv cr = 0.0f, cg = 0.0f, cb = 0.0f, ca = 0.0f;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        STEP_RGBA(k, r, g, b, ak)
        cr += ak * r;
        cg += ak * g;
        cb += ak * b;
        ca += ak;
    }
#ifndef RAW_PARTIAL
    const float n = (float)w;
    cr /= n;
    cg /= n;
    cb /= n;
    ca /= n;
#endif
    STORE_RGBA(o, cr, cg, cb, ca);
}
#else
/* The window's average from its fixed-point sums (4 longs per voxel) and 1 / W. */
__kernel void finish_mean(__global const long *acc, __global float4 *out, const float inv_w)
{
    const size_t i = get_global_id(0);
    out[i] = (float4)(convert_float(acc[4 * i]) / FIXED_ONE, convert_float(acc[4 * i + 1]) / FIXED_ONE,
                      convert_float(acc[4 * i + 2]) / FIXED_ONE,
                      convert_float(acc[4 * i + 3]) / FIXED_ONE) * inv_w;
}
#endif
