/* Shared helpers of the chronocl integration kernels.
 *
 * Build options set by the host (chronocl/engine/program.py):
 *   DATA_T     element type of the brick: float, uchar, ushort or short
 *   QUANT      defined for uchar data: the per-step LUT is indexed by the raw value
 *   LUT_N      entries per step in the LUT (256 when QUANT)
 *   ENHANCE    0 none, 1 edge, 2 silhouette
 *   EARLY_EXIT defined to stop compositing once the transmittance is below 1e-6
 *
 * The brick is in xytz order: (nzb, w, ny, nx), x fastest. The output covers brick
 * rows [zcrop, zcrop + nz_out): rows outside are the gradient halo.
 * Arithmetic mirrors chronocl/reference.py so results agree to float32 rounding.
 */

#define VOX(zb, k, y, x) data[(((size_t)(zb) * w + (k)) * ny + (y)) * nx + (x)]
#define OUT_INDEX(z, y, x) (((size_t)(z) * ny + (y)) * nx + (x))

/* u = clip((v - vmin) * scale, 0, 1), in float32 exactly as the reference. */
inline float normalize_value(DATA_T v, float vmin, float scale)
{
    float u = ((float)v - vmin) * scale;
    return fmin(fmax(u, 0.0f), 1.0f);
}

/* Per-step LUT (rgb_d * rgb_t, a_d * a_t) evaluated at u with linear interpolation. */
inline float4 lut_lerp(__global const float4 *lut, float u)
{
    float x = u * (float)(LUT_N - 1);
    int i0 = min((int)x, LUT_N - 2);
    float f = x - (float)i0;
    float4 a = lut[i0];
    float4 b = lut[i0 + 1];
    return a * (1.0f - f) + b * f;
}

/* RGBA before enhancement of step k at brick voxel (x, y, zb). */
inline float4 step_rgba(__global const DATA_T *data, __global const float4 *lut, int k,
                        int x, int y, int zb, int nx, int ny, int w, float vmin, float scale)
{
#ifdef QUANT
    return lut[k * LUT_N + (int)VOX(zb, k, y, x)];
#else
    return lut_lerp(lut + k * LUT_N, normalize_value(VOX(zb, k, y, x), vmin, scale));
#endif
}

#if ENHANCE
/* One-sided difference at the borders, central inside, zero on an axis of length 1:
 * numpy.gradient with edge_order=1. `lo`, `mid`, `hi` are u at i-1, i, i+1 (clamped). */
inline float axis_gradient(float lo, float mid, float hi, int i, int n)
{
    if (n < 2) return 0.0f;
    if (i == 0) return hi - mid;
    if (i == n - 1) return mid - lo;
    return (hi - lo) * 0.5f;
}

/* Enhancement factor e of step k at brick voxel (x, y, zb); params = (k0, k1, k2, -). */
inline float enhance_factor(__global const DATA_T *data, int k, int x, int y, int zb,
                            int nx, int ny, int nzb, int w, float vmin, float scale,
                            float4 params, float4 view)
{
#define U(zz, yy, xx) normalize_value(VOX(zz, k, yy, xx), vmin, scale)
    float mid = U(zb, y, x);
    float gx = axis_gradient(U(zb, y, max(x - 1, 0)), mid, U(zb, y, min(x + 1, nx - 1)), x, nx);
    float gy = axis_gradient(U(zb, max(y - 1, 0), x), mid, U(zb, min(y + 1, ny - 1), x), y, ny);
    float gz = axis_gradient(U(max(zb - 1, 0), y, x), mid, U(min(zb + 1, nzb - 1), y, x), zb, nzb);
#undef U
    float mag = sqrt(gx * gx + gy * gy + gz * gz);
#if ENHANCE == 1
    return params.x + params.y * pow(mag, params.z);
#else
    if (mag == 0.0f) return params.x;
    float c = fabs(gx * view.x + gy * view.y + gz * view.z) / mag;
    return params.x + params.y * pow(clamp(1.0f - c, 0.0f, 1.0f), params.z);
#endif
}
#define ALPHA_OF(rgba, k) clamp((rgba).w * enhance_factor(data, k, x, y, zb, nx, ny, nzb, w, \
                                 vmin, scale, enh, view), 0.0f, 1.0f)
#else
#define ALPHA_OF(rgba, k) clamp((rgba).w, 0.0f, 1.0f)
#endif

/* The arguments every integration kernel takes, in this order. */
#define KERNEL_ARGS                                                                     \
    __global const DATA_T *data, __global const float4 *lut, __global const int *order, \
    __global const int *steps, const int nx, const int ny, const int nzb, const int w,  \
    const int zcrop, const float vmin, const float scale, const float4 enh,              \
    const float4 view

#define VOXEL_PROLOGUE                           \
    const int x = get_global_id(0);              \
    const int y = get_global_id(1);              \
    const int z = get_global_id(2);              \
    if (x >= nx || y >= ny) return;              \
    const int zb = z + zcrop;                    \
    const size_t o = OUT_INDEX(z, y, x);
