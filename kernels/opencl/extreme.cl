/* max / min: the step holding the extreme raw value v (ties: first in the order) supplies the
 * voxel, coloured by its TF at u = clamp((v - vmin) * scale, 0, 1) and that step's time
 * position: (a * c, a), t_index = s_k*. IS_MIN selects min. Built without QUANT: the LUT is
 * interpolated at u. The winner does not depend on the data TF or its range: t_index answers
 * "when did this voxel peak" (DESIGN.md).
 *
 * The loop compares a key per lane:
 *   KEY_RAW   the raw values in the data's lanes (integer data whose steps fit IDX_T, uchar or
 *             ushort, the winning step in lanes as narrow);
 *   otherwise the values as float (exact for every type the device reads), steps in int lanes. */
#ifndef SLIDING
#ifdef IS_MIN
#define IS_BETTER <
#else
#define IS_BETTER >
#endif

#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#ifdef KEY_RAW
#define KEY(raw) (raw)
#if VEC == 16
typedef DATA_V keyv;
typedef CAT(IDX_T, 16) idxv;
#define IDX(k) ((idxv)((IDX_T)(k)))
#else
typedef DATA_T keyv;
typedef int idxv;
#define IDX(k) (k)
#endif
#else
#define KEY(raw) TO_FLOAT(raw)
typedef floatv keyv;
typedef intv idxv;
#define IDX(k) ((idxv)(k))
#endif

/* The best key so far and its step (ties keep the step integrated first). */
typedef struct {
    keyv best;
    idxv best_k;
} Best;
#define BEST_INIT(s)                  \
    s.best = KEY(RAW(ORDER_AT(0)));   \
    s.best_k = IDX(ORDER_AT(0));
#define BEST_STEP(s, k)                                        \
    {                                                          \
        const keyv v_ = KEY(RAW(k));                           \
        s.best_k = SELECT(s.best_k, IDX(k), v_ IS_BETTER s.best); \
        s.best = SELECT(s.best, v_, v_ IS_BETTER s.best);      \
    }

/* The voxel's colour at u of the winning value and its t_index. */
#define BEST_FINISH(s)                                 \
    {                                                  \
        const intv win = TO_INT(s.best_k);             \
        const floatv u = NORMALIZE(s.best);            \
        WINNER_RGBA(u, win, r, g, b, ak)               \
        STORE_RGBA(o, ak * r, ak * g, ak * b, ak);     \
        STORE_INT(STEP_AT(win), t_index + o);          \
        STORE_WINNERS(o, u, win)                       \
    }

__kernel void integrate_extreme(KERNEL_ARGS, __global out_t *out, __global int *t_index,
                                __global float *won_u, __global uchar *won_k)
{
    VECTOR_BODY(Best, 1, BEST_INIT, BEST_STEP, NEVER_DONE, BEST_FINISH)
}

#if VEC == 16
__kernel void integrate_extreme_rows(KERNEL_ARGS, __global out_t *out, __global int *t_index,
                                     __global float *won_u, __global uchar *won_k,
                                     ROWS_ARGS(Best))
{
    ROWS_BODY(Best, 1, BEST_INIT, BEST_STEP, NEVER_DONE, BEST_FINISH)
}
#endif
#else
/* Combining the partials of two consecutive runs of steps, `front` integrated first
 * (chronocl/modes/extreme.py `combine` is the oracle). One voxel per work-item. */

/* Ties keep the front: the step integrated first wins, as in integrate_extreme. */
__kernel void combine_extreme(__global const float4 *front, __global const int *front_t,
                              __global const float *front_v, __global const float4 *back,
                              __global const int *back_t, __global const float *back_v,
                              __global colour_t *out, __global int *out_t, __global float *out_v,
                              ELEMENT_ARGS)
{
    ELEMENT(i);
    const float a = front_v[i], b = back_v[i];
#ifdef IS_MIN
    const int beats = b < a;
#else
    const int beats = b > a;
#endif
    const int keep = front_t[i] >= 0 && !(beats && back_t[i] >= 0);
    out[i] = COLOUR(keep ? front[i] : back[i]);
    out_t[i] = keep ? front_t[i] : back_t[i];
    out_v[i] = keep ? a : b;
}
#endif
