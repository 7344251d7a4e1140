/* The winners of a window gathered on the OpenCL device (chronocl/engine/gather.py,
 * on_device): each voxel's step index from the chronovolume's t_index and its value read from
 * that step alone. Built alone (no common.h) with K_T (the step index type), V_T (the raw
 * values' type) and, in change mode, CHANGE. */

// The winners' step index (into the window; none: none_k) from t_index (the selected step, -1:
// none) through `table` (step + 1 -> index: gather.index_table, on_host's too), then
// their value u (0 where none): the window's
// steps go in chunks of up to 8 (p1..p8 the chunk's steps, p0 the step before the first, which
// change reads; `winner_u`). Every voxel's k and u are written here: the host's arrays come
// uninitialised.
__kernel void window_index(__global const int *t_index, __global const K_T *table,
                           __global K_T *won_k, __global float *won_u)
{
    size_t i = get_global_id(0);
    won_k[i] = table[t_index[i] + 1];
    won_u[i] = 0.0f;
}

// A winner's u from its value v (change: and b, the value of the step before it), normalised
// as chronocl.core.values does (change: the clipped difference, scaled).
inline float winner_u(const float v, const float b, const float lo, const float hi,
                      const float scale)
{
#ifdef CHANGE
    return min(fabs(clamp(v, lo, hi) - clamp(b, lo, hi)) * scale, 1.0f);
#else
    return clamp((v - lo) * scale, 0.0f, 1.0f);
#endif
}

// The window's steps as views of one block (the window manager's slots: each step's z rows
// `sz` elements apart, a row's Y x X contiguous, each step at its element offset `offs[k]`):
// per z row (global id 1) and voxel of the row (id 0), its k as window_index finds it and its
// value read where it lies, in one pass (t_index read once, k written once, no division).
__kernel void gather_block(__global const int *t_index, __global const K_T *table,
                           __global K_T *won_k, __global float *won_u,
                           __global const V_T *block, __global const long *offs, const long sz,
                           const uint none_k, const float lo, const float hi, const float scale)
{
    const size_t r = get_global_id(0), z = get_global_id(1);
    const size_t i = z * get_global_size(0) + r;
    uint k = table[t_index[i] + 1];
    won_k[i] = k;
#ifdef CHANGE
    if (k == none_k || k == 0) {  // the window's first step starts no change (as `gather`)
#else
    if (k == none_k) {
#endif
        won_u[i] = 0.0f;
        return;
    }
    const long at = (long)z * sz + (long)r;
    const float v = (float)block[offs[k] + at];
#ifdef CHANGE
    won_u[i] = winner_u(v, (float)block[offs[k - 1] + at], lo, hi, scale);
#else
    won_u[i] = winner_u(v, v, lo, hi, scale);
#endif
}

// Value j (0..7) of a chunk's eight step pointers at voxel i.
inline float pick(const uint j, const size_t i, __global const V_T *a0, __global const V_T *a1,
                  __global const V_T *a2, __global const V_T *a3, __global const V_T *a4,
                  __global const V_T *a5, __global const V_T *a6, __global const V_T *a7)
{
    switch (j) {
        case 0: return (float)a0[i];
        case 1: return (float)a1[i];
        case 2: return (float)a2[i];
        case 3: return (float)a3[i];
        case 4: return (float)a4[i];
        case 5: return (float)a5[i];
        case 6: return (float)a6[i];
        default: return (float)a7[i];
    }
}

__kernel void gather(__global const K_T *won_k, __global float *won_u,
                     const uint base, const uint count,
                     __global const V_T *p0, __global const V_T *p1, __global const V_T *p2,
                     __global const V_T *p3, __global const V_T *p4, __global const V_T *p5,
                     __global const V_T *p6, __global const V_T *p7, __global const V_T *p8,
                     const float lo, const float hi, const float scale)
{
    size_t i = get_global_id(0);
    uint k = won_k[i];
    if (k < base || k >= base + count) return;
    const float v = pick(k - base, i, p1, p2, p3, p4, p5, p6, p7, p8);
#ifdef CHANGE
    won_u[i] = winner_u(v, pick(k - base, i, p0, p1, p2, p3, p4, p5, p6, p7), lo, hi, scale);
#else
    won_u[i] = winner_u(v, v, lo, hi, scale);
#endif
}
