/* first_hit: the first step in the order whose opacity exceeds the threshold supplies the
 * voxel: (a_k * c_k, a_k) and t_index = s_k; none: (0, 0, 0, 0) and -1. */
#ifndef SLIDING
__kernel void integrate_first_hit(KERNEL_ARGS, const float threshold, __global float4 *out,
                                  __global int *t_index)
{
    VOXEL_PROLOGUE
    /* The loop needs only each step's opacity (its colour goes unused and is not computed):
     * it keeps the hit's LUT position and step, and the hit is coloured once, after it. */
    floatv hx = 0.0f;
    intv hk = -1;
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        STEP_POSITION(k, p)
        const intv open_ = hk < 0;
        THRESHOLD_TEST(p, k, open_, pass)
        const intv take = open_ & pass;
        hx = SELECT(hx, p.x, take);
        hk = SELECT(hk, (intv)(k), take);
        if (ALL(hk >= 0)) break;
    }
    const intv none = hk < 0;
    const intv win = VMAX(hk, 0);
    const LutPos q = lut_pos_again(hx);
    WINNER_RGBA_AT(q, win, r, g, b, ak)
    const floatv zero = 0.0f;
    STORE_RGBA(o, SELECT(ak * r, zero, none), SELECT(ak * g, zero, none),
               SELECT(ak * b, zero, none), SELECT(ak, zero, none));
    STORE_INT(SELECT(GATHER_INT(steps, win), (intv)(-1), none), t_index + o);
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
