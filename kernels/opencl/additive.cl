/* additive: C = sum a_k * c_k, A = max a_k. With NORM_TIME the colour is divided per channel
 * by N = sum a_t * rgb_t (norm.xyz; a channel with N = 0 gives 0) and clamped to A here;
 * otherwise the raw sums are written and the host normalises by the volume's maximum. */
__kernel void integrate_additive(KERNEL_ARGS, const float4 norm, __global float4 *out)
{
    VOXEL_PROLOGUE
    float3 c = (float3)(0.0f);
    float a = 0.0f;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        const float4 s = step_rgba(data, lut, k, x, y, zb, nx, ny, w, vmin, scale);
        const float ak = ALPHA_OF(s, k);
        c += ak * s.xyz;
        a = fmax(a, ak);
    }
#ifdef NORM_TIME
    c = select((float3)(0.0f), c / norm.xyz, norm.xyz > 0.0f);
    c = fmin(c, (float3)(a));
#endif
    out[o] = (float4)(c, a);
}
