/* additive: C = sum a_k * c_k, A = max a_k. With NORM_TIME the colour is divided per channel
 * by N = sum a_t * rgb_t (norm.xyz; a channel with N = 0 gives 0) and clamped to A here;
 * otherwise the raw sums are written and the host normalises by the volume's maximum. */
#ifndef SLIDING
__kernel void integrate_additive(KERNEL_ARGS, const float4 norm, __global float4 *out)
{
    VOXEL_PROLOGUE
    floatv cr = 0.0f, cg = 0.0f, cb = 0.0f, ca = 0.0f;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        STEP_RGBA(k, r, g, b, ak)
        cr += ak * r;
        cg += ak * g;
        cb += ak * b;
        ca = VMAX(ca, ak);
    }
#ifdef NORM_TIME
    cr = norm.x > 0.0f ? VMIN(cr / norm.x, ca) : (floatv)(0.0f);
    cg = norm.y > 0.0f ? VMIN(cg / norm.y, ca) : (floatv)(0.0f);
    cb = norm.z > 0.0f ? VMIN(cb / norm.z, ca) : (floatv)(0.0f);
#endif
    STORE_RGBA(o, cr, cg, cb, ca);
}
#else
/* Combining the partials of two consecutive runs of steps, `front` integrated first
 * (chronocl/modes/additive.py `combine` is the oracle). One voxel per work-item. */

__kernel void combine_fmax(__global const float *front, __global const float *back,
                           __global float *out)
{
    const size_t i = get_global_id(0);
    out[i] = fmax(front[i], back[i]);
}

/* The finished additive chronovolume: sums / norm per channel (0 where norm is 0), clamped
 * to the window's largest opacity `alpha`, as reference.finalize does. */
__kernel void finish_additive(__global const long *acc, __global const float *alpha,
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
#endif
