/* What a sliding window's leaf compares (chronocl/modes: `leaf_value`), from steps resident on
 * the device (chronocl/engine/device_steps.py), so a GPU's leaves never travel: max/min compare
 * the raw value of the leaf's step, change the change between its two steps. Built with
 * SLIDING and DATA_T, the steps' type (HALF_DATA: half, loaded with vload_half). A leaf's step
 * k lies at base[k] + z * zstride + (y * X + x); one voxel per work-item, `plane` = Y * X. The
 * arithmetic is chronocl/core/values.py's, in float32, so the bits agree with the host's. */

#ifdef HALF_DATA
#define LOAD(p) vload_half(0, (p))
#else
#define LOAD(p) convert_float(*(p))
#endif

#define AT(k) (data + base[k] + (size_t)(i / plane) * zstride + i % plane)

/* The raw value of the leaf's last step, as float (Extreme.leaf_value). */
__kernel void leaf_raw(__global const DATA_T *data, __global const long *base, const long zstride,
                       const long plane, const int last, __global float *out)
{
    const size_t i = get_global_id(0);
    out[i] = LOAD(AT(last));
}

/* |clip(v1) - clip(v0)| of the leaf's last two steps, clipped to [lo, hi] (Change.leaf_value). */
__kernel void leaf_change(__global const DATA_T *data, __global const long *base,
                          const long zstride, const long plane, const int last,
                          __global float *out, const float lo, const float hi)
{
    const size_t i = get_global_id(0);
    const float a = fmin(fmax(LOAD(AT(last - 1)), lo), hi);
    const float b = fmin(fmax(LOAD(AT(last)), lo), hi);
    out[i] = fabs(b - a);
}
