/* first_hit: the first step in the order whose opacity exceeds the threshold supplies the
 * voxel: (a_k * c_k, a_k) and t_index = s_k; none: (0, 0, 0, 0) and -1. */
__kernel void integrate_first_hit(KERNEL_ARGS, const float threshold, __global float4 *out,
                                  __global int *t_index)
{
    VOXEL_PROLOGUE
    float4 hit = (float4)(0.0f);
    int step = -1;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        const float4 s = step_rgba(data, lut, k, x, y, zb, nx, ny, w, vmin, scale);
        const float ak = ALPHA_OF(s, k);
        if (ak > threshold) {
            hit = (float4)(ak * s.xyz, ak);
            step = steps[k];
            break;
        }
    }
    out[o] = hit;
    t_index[o] = step;
}
