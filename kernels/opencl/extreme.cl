/* max / min: the step holding the extreme normalised value (ties: first in the order) supplies
 * the voxel, coloured by its TF: (a * c, a), t_index = s_k*. IS_MIN selects min. */
__kernel void integrate_extreme(KERNEL_ARGS, __global float4 *out, __global int *t_index)
{
    VOXEL_PROLOGUE
    int best_k = order[0];
    float best = normalize_value(VOX(zb, best_k, y, x), vmin, scale);
    for (int i = 1; i < w; ++i) {
        const int k = order[i];
        const float u = normalize_value(VOX(zb, k, y, x), vmin, scale);
#ifdef IS_MIN
        const int better = u < best;
#else
        const int better = u > best;
#endif
        best = better ? u : best;
        best_k = better ? k : best_k;
    }
    const float4 s = step_rgba(data, lut, best_k, x, y, zb, nx, ny, w, vmin, scale);
    const float ak = ALPHA_OF(s, best_k);
    out[o] = (float4)(ak * s.xyz, ak);
    t_index[o] = steps[best_k];
}
