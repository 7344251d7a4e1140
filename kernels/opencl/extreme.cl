/* max / min: the step holding the extreme normalised value (ties: first in the order) supplies
 * the voxel, coloured by its TF at that value and that step's time position: (a * c, a),
 * t_index = s_k*. IS_MIN selects min. Built without QUANT: the LUT is interpolated at u.
 * RAW_ORDER compares raw values (the host checked that u(v) is strictly increasing). */
#ifndef SLIDING
#ifdef IS_MIN
#define IS_BETTER <
#else
#define IS_BETTER >
#endif

__kernel void integrate_extreme(KERNEL_ARGS, __global float4 *out, __global int *t_index)
{
    VOXEL_PROLOGUE
    const int first = order[0];
    intv best_k = first;
#if defined(RAW_ORDER) && VEC == 16
    /* uchar data, w <= 256: compare bytes and keep the winning step index in byte lanes too,
     * so the loop never widens its lane masks. */
    DATA_V best_raw = RAW(first);
    uchar16 best_k8 = (uchar16)((uchar)first);
    for (int i = 1; i < w; ++i) {
        const int k = order[i];
        const DATA_V v = RAW(k);
        const char16 take = v IS_BETTER best_raw;
        best_k8 = SELECT(best_k8, (uchar16)((uchar)k), take);
        best_raw = SELECT(best_raw, v, take);
    }
    best_k = convert_int16(best_k8);
    const floatv best = NORMALIZE(best_raw);
#elif defined(RAW_ORDER)
    DATA_V best_raw = RAW(first);
    for (int i = 1; i < w; ++i) {
        const int k = order[i];
        const DATA_V v = RAW(k);
        const int take = v IS_BETTER best_raw;
        best_k = take ? k : best_k;
        best_raw = take ? v : best_raw;
    }
    const floatv best = NORMALIZE(best_raw);
#else
    floatv best = NORMALIZE(RAW(first));
    for (int i = 1; i < w; ++i) {
        const int k = order[i];
        const floatv u = NORMALIZE(RAW(k));
        const intv better = u IS_BETTER best;
        best = SELECT(best, u, better);
        best_k = SELECT(best_k, (intv)(k), better);
    }
#endif
    WINNER_RGBA(best, best_k, r, g, b, ak)
    STORE_RGBA(o, ak * r, ak * g, ak * b, ak);
    STORE_INT(GATHER_INT(steps, best_k), t_index + o);
}
#else
/* Combining the partials of two consecutive runs of steps, `front` integrated first
 * (chronocl/modes/extreme.py `combine` is the oracle). One voxel per work-item. */

/* Ties keep the front: the step integrated first wins, as in integrate_extreme. */
__kernel void combine_extreme(__global const float4 *front, __global const int *front_t,
                              __global const float *front_v, __global const float4 *back,
                              __global const int *back_t, __global const float *back_v,
                              __global float4 *out, __global int *out_t, __global float *out_v)
{
    const size_t i = get_global_id(0);
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
