/* change: the largest change between consecutive selected steps (k >= 1 in the brick's time
 * order, visited in integration order; ties: first in the order) supplies the voxel, coloured
 * by the data TF at δ and the time TF of s_k: (a * c, a), t_index = s_k. One step:
 * (0, 0, 0, 0) and -1. Changes are compared as d = |clip(v_k) - clip(v_{k-1})| on the values
 * clipped to [lo, hi]; the winner's δ = min(d * scale, 1) (chronocl/modes/change.py). Built
 * without QUANT: the LUT is interpolated at δ. TIME_ORDER: 1 forward, 2 backward, 0 any order
 * (through `order`). CHANGE_BYTES: uchar data whose clipped values are whole numbers,
 * compared in byte lanes.
 * Sliding windows combine pairs of steps with extreme.cl's combine_extreme. */
#define CLIPPED(v) VCLAMP(TO_FLOAT(v), lo, hi)

/* forward order: a strictly larger change takes the lead; backward: an equal one too, so the
 * latest of equal changes (first in its order) wins. */
#if TIME_ORDER == 1
#define TAKES >
#else
#define TAKES >=
#endif

__kernel void integrate_change(KERNEL_ARGS, const float lo, const float hi,
                               __global out_t *out, __global int *t_index,
                               __global float *won_u, __global uchar *won_k)
{
    VOXEL_PROLOGUE
    if (w < 2) { /* one step: nothing changed */
        STORE_RGBA(o, (floatv)(0.0f), (floatv)(0.0f), (floatv)(0.0f), (floatv)(0.0f));
        STORE_INT((intv)(-1), t_index + o);
        STORE_WINNERS(o, (floatv)(0.0f), (intv)(NO_WINNER))
        STREAM_FENCE
        return;
    }
    TIME_TABLE_LOAD
#if defined(CHANGE_BYTES) && VEC == 16
    /* Walk the steps in time; clipped values, differences and the winning step stay in byte
     * lanes (the host checked that lo and hi clip bytes to whole numbers). */
    const uchar16 lo8 = (uchar16)((uchar)VCLAMP(lo, 0.0f, 255.0f));
    const uchar16 hi8 = (uchar16)((uchar)VCLAMP(hi, 0.0f, 255.0f));
#define CLIPPED8(v) VCLAMP((v), lo8, hi8)
    DATA_V prev = CLIPPED8(RAW(1));
    const uchar16 first = CLIPPED8(RAW(0));
    uchar16 best_d = VMAX(prev, first) - VMIN(prev, first);
    uchar16 best_k8 = (uchar16)(1);
    for (int k = 2; k < w; ++k) {
        const DATA_V v = CLIPPED8(RAW(k));
        const uchar16 d = VMAX(v, prev) - VMIN(v, prev);
        prev = v;
        const char16 take = d TAKES best_d;
        best_d = SELECT(best_d, d, take);
        best_k8 = SELECT(best_k8, (uchar16)((uchar)k), take);
    }
    const floatv best = convert_float16(best_d);
    const intv kk = convert_int16(best_k8);
#elif TIME_ORDER
    floatv prev = CLIPPED(RAW(1));
    floatv best = VABS(prev - CLIPPED(RAW(0)));
    intv kk = (intv)(1);
    for (int k = 2; k < w; ++k) {
        const floatv c = CLIPPED(RAW(k));
        const floatv d = VABS(c - prev);
        prev = c;
        const intv take = d TAKES best;
        best = SELECT(best, d, take);
        kk = SELECT(kk, (intv)(k), take);
    }
#else
    floatv best = 0.0f;
    intv kk = -1;
    for (int i = 0; i < w; ++i) {
        const int k = ORDER_AT(i);
        if (k == 0) continue;
        const floatv d = VABS(CLIPPED(RAW(k)) - CLIPPED(RAW(k - 1)));
        const intv take = (kk < 0) | (d > best);
        best = SELECT(best, d, take);
        kk = SELECT(kk, (intv)(k), take);
    }
#endif
    const floatv delta = VMIN(best * scale, 1.0f);
    WINNER_RGBA(delta, kk, r, g, b, ak)
    STORE_RGBA(o, ak * r, ak * g, ak * b, ak);
    STORE_INT(STEP_AT(kk), t_index + o);
    STORE_WINNERS(o, delta, kk)
    STREAM_FENCE
}

#if VEC == 16
/* The rows kernel (CPU devices, common.h's ROWS_BODY): the same walks, the state of a vector
 * between groups of steps in local memory, so the same bits. TIME_ORDER walks the steps in
 * time (k = 2..w-1 after the first pair, whatever the order's direction: only TAKES tells
 * them apart); any other order visits order[i], taking k >= 1. */
#if TIME_ORDER
#undef ORDER_AT
#define ORDER_AT(i) (i)
#define CHANGE_FROM 2
#else
#define CHANGE_FROM 0
#endif
#ifdef CHANGE_BYTES
typedef struct {
    uchar16 prev, best, kk;
} Change;
#define LO8 ((uchar16)((uchar)VCLAMP(lo, 0.0f, 255.0f)))
#define HI8 ((uchar16)((uchar)VCLAMP(hi, 0.0f, 255.0f)))
#define CHANGE_INIT(s)                                            \
    {                                                             \
        const uchar16 first_ = VCLAMP(RAW(0), LO8, HI8);          \
        s.prev = VCLAMP(RAW(1), LO8, HI8);                        \
        s.best = VMAX(s.prev, first_) - VMIN(s.prev, first_);     \
        s.kk = (uchar16)(1);                                      \
    }
#define CHANGE_STEP(s, k)                                         \
    {                                                             \
        const uchar16 v_ = VCLAMP(RAW(k), LO8, HI8);              \
        const uchar16 d_ = VMAX(v_, s.prev) - VMIN(v_, s.prev);   \
        s.prev = v_;                                              \
        const char16 take_ = d_ TAKES s.best;                     \
        s.best = SELECT(s.best, d_, take_);                       \
        s.kk = SELECT(s.kk, (uchar16)((uchar)(k)), take_);        \
    }
#define CHANGE_BEST(s) convert_float16(s.best)
#define CHANGE_K(s) convert_int16(s.kk)
#else
typedef struct {
    floatv prev, best;
    intv kk;
} Change;
#if TIME_ORDER
#define CHANGE_INIT(s)                                  \
    s.prev = CLIPPED(RAW(1));                           \
    s.best = VABS(s.prev - CLIPPED(RAW(0)));            \
    s.kk = (intv)(1);
#define CHANGE_STEP(s, k)                               \
    {                                                   \
        const floatv c_ = CLIPPED(RAW(k));              \
        const floatv d_ = VABS(c_ - s.prev);            \
        s.prev = c_;                                    \
        const intv take_ = d_ TAKES s.best;             \
        s.best = SELECT(s.best, d_, take_);             \
        s.kk = SELECT(s.kk, (intv)(k), take_);          \
    }
#else
#define CHANGE_INIT(s)  \
    s.best = 0.0f;      \
    s.kk = -1;
#define CHANGE_STEP(s, k)                                                   \
    if ((k) == 0) continue;                                                 \
    {                                                                       \
        const floatv d_ = VABS(CLIPPED(RAW(k)) - CLIPPED(RAW((k) - 1)));    \
        const intv take_ = (s.kk < 0) | (d_ > s.best);                      \
        s.best = SELECT(s.best, d_, take_);                                 \
        s.kk = SELECT(s.kk, (intv)(k), take_);                              \
    }
#endif
#define CHANGE_BEST(s) (s.best)
#define CHANGE_K(s) (s.kk)
#endif
#define CHANGE_FINISH(s)                                       \
    {                                                          \
        const intv kk = CHANGE_K(s);                           \
        const floatv delta = VMIN(CHANGE_BEST(s) * scale, 1.0f); \
        WINNER_RGBA(delta, kk, r, g, b, ak)                    \
        STORE_RGBA(o, ak * r, ak * g, ak * b, ak);             \
        STORE_INT(STEP_AT(kk), t_index + o);                   \
        STORE_WINNERS(o, delta, kk)                            \
    }

__kernel void integrate_change_rows(KERNEL_ARGS, const float lo, const float hi,
                                    __global out_t *out, __global int *t_index,
                                    __global float *won_u, __global uchar *won_k,
                                    ROWS_ARGS(Change))
{
    if (w < 2) { /* one step: nothing changed */
        ROWS_PROLOGUE
        FOR_BLOCK(v) {
            BLOCK_VOXEL(v)
            const size_t o = OUT_INDEX(z, y, x);
            STORE_RGBA(o, (floatv)(0.0f), (floatv)(0.0f), (floatv)(0.0f), (floatv)(0.0f));
            STORE_INT((intv)(-1), t_index + o);
            STORE_WINNERS(o, (floatv)(0.0f), (intv)(NO_WINNER))
        }
        STREAM_FENCE
        return;
    }
    ROWS_BODY(Change, CHANGE_FROM, CHANGE_INIT, CHANGE_STEP, NEVER_DONE, CHANGE_FINISH)
}
#endif
