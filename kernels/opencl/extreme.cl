/* max / min: the step holding the extreme normalised value (ties: first in the order) supplies
 * the voxel, coloured by its TF at that value and that step's time position: (a * c, a),
 * t_index = s_k*. IS_MIN selects min. Built without QUANT: the LUT is interpolated at u.
 *
 * The loop compares a key instead of u = clamp(t, 0, 1), t = (v - vmin) * scale:
 *   KEY_RAW   the raw values, in the data's lanes (the host checked that u is strictly
 *             increasing on the values strictly between zlo and zhi, 0 at or below zlo and 1 at
 *             or above zhi), the winning step in lanes as narrow (IDX_T: uchar or ushort);
 *   otherwise t unclamped (zlo = 0, zhi = 1), the winning step in int lanes.
 * Both order the steps as u does, ties included, where the winner's key lies strictly between
 * zlo and zhi. Beyond, u is 0 or 1 and ties: on the side the comparison runs from (max: u = 0,
 * min: u = 1) every step ties, so the first in the order wins; on the side it runs to (max:
 * u = 1, min: u = 0) the first step in the order that lies there wins, found by a second pass
 * over the steps where some lane needs it. */
#ifndef SLIDING
#ifdef IS_MIN
#define IS_BETTER <
#define BEHIND(kf) ((kf) >= zhi)
#define AHEAD(kf) ((kf) <= zlo)
#else
#define IS_BETTER >
#define BEHIND(kf) ((kf) <= zlo)
#define AHEAD(kf) ((kf) >= zhi)
#endif

#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#ifdef KEY_RAW
#define KEY(raw) (raw)
#define KEY_FLOAT(key) TO_FLOAT(key)
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
#define KEY(raw) ((TO_FLOAT(raw) - vmin) * scale)
#define KEY_FLOAT(key) (key)
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

#ifdef KEY_RAW
#define UNIT_OF_KEY(key) NORMALIZE(key)
#else
#define UNIT_OF_KEY(key) clamp_unit(key)
#endif

/* The winner: `win` from the best key and its step, then a second pass over the steps where
 * some lane lies beyond zhi (max) / zlo (min); the voxel's colour and t_index. */
#define BEST_FINISH(s)                                                              \
    {                                                                               \
        const int first = ORDER_AT(0);                                              \
        const floatv kf = KEY_FLOAT(s.best);                                        \
        intv win = SELECT(TO_INT(s.best_k), (intv)(first), BEHIND(kf));             \
        const intv ahead = AHEAD(kf);                                               \
        if (ANY(ahead)) {                                                           \
            intv todo = ahead;                                                      \
            for (int i = 0; i < w; ++i) {                                           \
                const int k = ORDER_AT(i);                                          \
                const intv hit = todo & AHEAD(KEY_FLOAT(KEY(RAW(k))));              \
                win = SELECT(win, (intv)(k), hit);                                  \
                todo &= ~hit;                                                       \
                if (!ANY(todo)) break;                                              \
            }                                                                       \
        }                                                                           \
        const floatv u = UNIT_OF_KEY(s.best);                                       \
        WINNER_RGBA(u, win, r, g, b, ak)                                            \
        STORE_RGBA(o, ak * r, ak * g, ak * b, ak);                                  \
        STORE_INT(STEP_AT(win), t_index + o);                                       \
    }

__kernel void integrate_extreme(KERNEL_ARGS, const float zlo, const float zhi,
                                __global out_t *out, __global int *t_index)
{
    VECTOR_BODY(Best, 1, BEST_INIT, BEST_STEP, NEVER_DONE, BEST_FINISH)
}

#if VEC == 16
__kernel void integrate_extreme_rows(KERNEL_ARGS, const float zlo, const float zhi,
                                     __global out_t *out, __global int *t_index,
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
                              __global float4 *out, __global int *out_t, __global float *out_v,
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
    out[i] = keep ? front[i] : back[i];
    out_t[i] = keep ? front_t[i] : back_t[i];
    out_v[i] = keep ? a : b;
}
#endif
