/* change: the largest |u(s_k) - u(s_{k-1})| between consecutive selected steps (k >= 1 in the
 * brick's time order, visited in integration order; ties: first in the order) supplies the
 * voxel, coloured by the data TF at that change and the time TF of s_k: (a * c, a),
 * t_index = s_k. One step: (0, 0, 0, 0) and -1. Built without QUANT: the LUT is interpolated at
 * the change. TIME_ORDER: 1 forward, 2 backward, 0 any order (through `order`). Sliding
 * windows combine pairs of steps with extreme.cl's combine_extreme. */
__kernel void integrate_change(KERNEL_ARGS, __global float4 *out, __global int *t_index)
{
    VOXEL_PROLOGUE
    intv best_k = -1;
    floatv best = 0.0f;
#if TIME_ORDER
    /* forward (1) or backward (2) order: walk the steps in time, each value normalised once;
     * backward takes ties too, so the latest of equal changes (first in its order) wins. */
    best = -1.0f; /* below any change, so step 1 always takes the lead */
    floatv prev = NORMALIZE(RAW(0));
    for (int k = 1; k < w; ++k) {
        const floatv u = NORMALIZE(RAW(k));
        const floatv d = fabs(u - prev);
        prev = u;
#if TIME_ORDER == 1
        const intv better = d > best;
#else
        const intv better = d >= best;
#endif
        best = SELECT(best, d, better);
        best_k = SELECT(best_k, (intv)(k), better);
    }
    best = fmax(best, 0.0f); /* one step: no change (the lanes are cleared below) */
#else
    for (int i = 0; i < w; ++i) {
        const int k = order[i];
        if (k == 0) continue;
        const floatv d = fabs(NORMALIZE(RAW(k)) - NORMALIZE(RAW(k - 1)));
        const intv better = (best_k < 0) | (d > best);
        best = SELECT(best, d, better);
        best_k = SELECT(best_k, (intv)(k), better);
    }
#endif
    const intv none = best_k < 0;
    const intv kk = max(best_k, 0);
    WINNER_RGBA(best, kk, r, g, b, ak)
    ak = SELECT(ak, (floatv)(0.0f), none);
    STORE_RGBA(o, ak * r, ak * g, ak * b, ak);
    STORE_INT(SELECT(GATHER_INT(steps, kk), (intv)(-1), none), t_index + o);
}
