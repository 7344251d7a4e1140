/* alpha: front-to-back `over` through time, premultiplied; the first step in the order is in
 * front. C += (1 - A) * a_k * c_k; A += (1 - A) * a_k. */
#ifndef SLIDING
__kernel void integrate_alpha(KERNEL_ARGS, __global float4 *out)
{
    VOXEL_PROLOGUE
    floatv cr = 0.0f, cg = 0.0f, cb = 0.0f, ca = 0.0f;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        STEP_RGBA(k, r, g, b, ak)
        const floatv tk = (1.0f - ca) * ak;
        cr += tk * r;
        cg += tk * g;
        cb += tk * b;
        ca += tk;
#ifdef EARLY_EXIT
        /* What the remaining steps could add is at most the transmittance 1 - A. */
        if (ALL(1.0f - ca < 1e-6f)) break;
#endif
    }
    STORE_RGBA(o, cr, cg, cb, ca);
}
#else
/* Combining the partials of two consecutive runs of steps, `front` integrated first
 * (chronocl/modes/alpha.py `combine` is the oracle). One voxel per work-item. */

__kernel void combine_over(__global const float4 *front, __global const float4 *back,
                           __global float4 *out)
{
    const size_t i = get_global_id(0);
    const float4 f = front[i];
    out[i] = f + (1.0f - f.w) * back[i];
}
#endif
