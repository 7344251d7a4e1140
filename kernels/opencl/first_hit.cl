/* first_hit: the first step in the order whose opacity exceeds the threshold supplies the
 * voxel: (a_k * c_k, a_k) and t_index = s_k; none: (0, 0, 0, 0) and -1. */
#ifndef SLIDING
__kernel void integrate_first_hit(KERNEL_ARGS, const float threshold, __global float4 *out,
                                  __global int *t_index)
{
    VOXEL_PROLOGUE
    floatv hr = 0.0f, hg = 0.0f, hb = 0.0f, ha = 0.0f;
    intv hit = -1;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        STEP_RGBA(k, r, g, b, ak)
        const intv take = (hit < 0) & (ak > threshold);
        hr = SELECT(hr, ak * r, take);
        hg = SELECT(hg, ak * g, take);
        hb = SELECT(hb, ak * b, take);
        ha = SELECT(ha, ak, take);
        hit = SELECT(hit, (intv)(steps[k]), take);
        if (ALL(hit >= 0)) break;
    }
    STORE_RGBA(o, hr, hg, hb, ha);
    STORE_INT(hit, t_index + o);
}
#else
/* Combining the partials of two consecutive runs of steps, `front` integrated first
 * (chronocl/modes/first_hit.py `combine` is the oracle). One voxel per work-item. */

__kernel void combine_first(__global const float4 *front, __global const int *front_t,
                            __global const float4 *back, __global const int *back_t,
                            __global float4 *out, __global int *out_t)
{
    const size_t i = get_global_id(0);
    const int keep = front_t[i] >= 0;
    out[i] = keep ? front[i] : back[i];
    out_t[i] = keep ? front_t[i] : back_t[i];
}
#endif
