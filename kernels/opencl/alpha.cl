/* alpha: front-to-back `over` through time, premultiplied; the first step in the order is in
 * front. C += (1 - A) * a_k * c_k; A += (1 - A) * a_k. */
__kernel void integrate_alpha(KERNEL_ARGS, __global float4 *out)
{
    VOXEL_PROLOGUE
    float3 c = (float3)(0.0f);
    float a = 0.0f;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        const float4 s = step_rgba(data, lut, k, x, y, zb, nx, ny, w, vmin, scale);
        const float ak = ALPHA_OF(s, k);
        const float t = (1.0f - a) * ak;
        c += t * s.xyz;
        a += t;
#ifdef EARLY_EXIT
        /* What the remaining steps could add is at most the transmittance 1 - a. */
        if (1.0f - a < 1e-6f) break;
#endif
    }
    out[o] = (float4)(c, a);
}
