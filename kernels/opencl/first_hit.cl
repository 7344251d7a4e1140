/* first_hit: the first step in the order whose opacity exceeds the threshold supplies the
 * voxel: (a_k * c_k, a_k) and t_index = s_k; none: (0, 0, 0, 0) and -1. */
#ifndef SLIDING
/* The loop needs only each step's opacity (its colour goes unused and is not computed): it
 * keeps the hit's LUT position hx and step hk (-1: none yet), and the hit is coloured once,
 * after it. */
typedef struct {
    floatv hx;
    intv hk;
} Hit;
#define HIT_INIT(s) s.hx = 0.0f; s.hk = -1;
#define HIT_STEP(s, k)                                  \
    {                                                   \
        STEP_POSITION(k, p)                             \
        const intv open_ = s.hk < 0;                    \
        THRESHOLD_TEST(p, k, open_, pass)               \
        const intv take = open_ & pass;                 \
        s.hx = SELECT(s.hx, p.x, take);                 \
        s.hk = SELECT(s.hk, (intv)(k), take);           \
    }
#define HIT_DONE(s) ALL((s).hk >= 0)
#define HIT_FINISH(s)                                                              \
    {                                                                              \
        const intv none = s.hk < 0;                                                \
        const intv win = VMAX(s.hk, 0);                                            \
        const LutPos q = lut_pos_again(s.hx);                                      \
        WINNER_RGBA_AT(q, win, r, g, b, ak)                                        \
        const floatv zero = 0.0f;                                                  \
        STORE_RGBA(o, SELECT(ak * r, zero, none), SELECT(ak * g, zero, none),      \
                   SELECT(ak * b, zero, none), SELECT(ak, zero, none));            \
        STORE_INT(SELECT(STEP_AT(win), (intv)(-1), none), t_index + o);            \
    }

__kernel void integrate_first_hit(KERNEL_ARGS, const float threshold, __global out_t *out,
                                  __global int *t_index)
{
    VECTOR_BODY(Hit, 0, HIT_INIT, HIT_STEP, HIT_DONE, HIT_FINISH)
}

#if VEC == 16
__kernel void integrate_first_hit_rows(KERNEL_ARGS, const float threshold, __global out_t *out,
                                       __global int *t_index, ROWS_ARGS(Hit))
{
    ROWS_BODY(Hit, 0, HIT_INIT, HIT_STEP, HIT_DONE, HIT_FINISH)
}
#endif
#else
/* Combining the partials of two consecutive runs of steps, `front` integrated first
 * (chronocl/modes/first_hit.py `combine` is the oracle). One voxel per work-item. */

__kernel void combine_first(__global const float4 *front, __global const int *front_t,
                            __global const float4 *back, __global const int *back_t,
                            __global colour_t *out, __global int *out_t, ELEMENT_ARGS)
{
    ELEMENT(i);
    const int keep = front_t[i] >= 0;
    out[i] = COLOUR(keep ? front[i] : back[i]);
    out_t[i] = keep ? front_t[i] : back_t[i];
}
#endif
