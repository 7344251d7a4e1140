/* Shared helpers of the chronocl integration kernels.
 *
 * Build options set by the host (chronocl/engine/opencl.py and each mode's kernel_options):
 *   VEC         voxels per work-item along x: 16 (vectorised) or 1 (x tail, enhancement)
 *   DATA_T      element type of the brick: float, uchar, ushort or short
 *   DATA_V      DATA_T with VEC lanes (e.g. uchar16; float lanes for half)
 *   HALF_DATA   DATA_T is half: loads convert with vload_half (see LOAD1)
 *   ALIGNED     every VEC-lane load and t_index store is aligned to its vector size
 *               (x width a multiple of 16, buffers 64-byte aligned): use vector pointers,
 *               which PoCL compiles to vector moves where vload16 becomes element loads
 *   QUANT       uchar data index the data LUT directly (lut holds TF(u(v)) for v = 0..255)
 *   KEY_RAW     max/min compare raw values (extreme.cl), the winning step in IDX_T lanes
 *   LUT_N       entries per channel of the data LUT
 *   CONST_COLOR the data colour is the same everywhere: skip the colour lookups
 *   COLOR_SEGS  the data colour is this many (1..8) straight pieces: evaluate them, no lookups
 *   ENHANCE     0 none, 1 edge, 2 silhouette (VEC must be 1)
 *   EARLY_EXIT  alpha: stop once every lane's transmittance is below 1e-6
 *   SKIP_EMPTY  skip steps whose lanes all map to zero data opacity (exact: they add nothing)
 *
 * The brick is in xytz order: (nzb, w, ny, nx), x fastest. A work-item integrates VEC
 * consecutive voxels starting at x0 + VEC * get_global_id(0); the output covers brick rows
 * [zcrop, zcrop + nz_out), the rest being the gradient halo. The data LUT is planar
 * (r[LUT_N], g[LUT_N], b[LUT_N], a[LUT_N]) and shared by all steps; tc[k] = (rgb_t, a_t) of
 * step k. Arithmetic follows chronocl/reference.py so results agree to float32 rounding.
 */

#pragma OPENCL FP_CONTRACT OFF

/* PoCL on x86 CPUs without AVX-512 warns "AVX vector argument of type 'float16' without
 * 'avx512f' enabled changes the ABI" (-Wpsabi) at every call taking or returning a 16-lane
 * float/int vector (convert_float16, clamp, vload16, any_lane, ...). That concerns linking
 * objects compiled for different CPUs; a kernel is built, linked with its builtins and
 * inlined for one device, so there is no ABI to change. Silence that one diagnostic. */
#if defined(__clang__) && defined(__has_warning)
#if __has_warning("-Wpsabi")
#pragma clang diagnostic ignored "-Wpsabi"
#endif
#endif

/* Sums of windows that slide by inversion, in fixed point: adding a step and later subtracting
 * the very same contribution cancels exactly, so a window never drifts. */
#define FIXED_ONE 1099511627776.0f /* 2^40 */

/* SLIDING builds hold only a mode's combine / finish kernels: one voxel per work-item, none of
 * the integrate kernels' build options. */
#ifndef SLIDING
#define VOX_INDEX(zb, k, y, x) ((((size_t)(zb) * w + (k)) * ny + (y)) * nx + (x))
#define OUT_INDEX(z, y, x) (((size_t)(z) * ny + (y)) * nx + (x))

#if VEC == 16
typedef float16 floatv;
typedef int16 intv;
#ifdef ALIGNED
#define VLOAD(p) (*(const __global DATA_V *)(p))
#define STORE_INT(v, p) (*(__global int16 *)(p) = (v))
#else
#define VLOAD(p) vload16(0, (p))
#define STORE_INT(v, p) vstore16((v), 0, (p))
#endif
#define TO_FLOAT(v) convert_float16(v)
#define TO_INT(v) convert_int16(v)
#define VABS(v) as_float16(as_int16(v) & 0x7FFFFFFF)
/* Whether any / all lanes of a comparison mask (lanes 0 or -1) are set, by OR / AND over 64-bit
 * words: PoCL's any() / all() builtins cost as much as the rest of a skipped step. */
inline int __attribute__((overloadable)) any_lane(int16 m)
{
    const ulong8 v = as_ulong8(m);
    const ulong4 a = v.lo | v.hi;
    const ulong2 b = a.lo | a.hi;
    return (b.lo | b.hi) != 0;
}
inline int __attribute__((overloadable)) any_lane(char16 m)
{
    const ulong2 v = as_ulong2(m);
    return (v.lo | v.hi) != 0;
}
inline int all_lanes(int16 m)
{
    const ulong8 v = as_ulong8(m);
    const ulong4 a = v.lo & v.hi;
    const ulong2 b = a.lo & a.hi;
    return (b.lo & b.hi) == ~0UL;
}
#define ANY(c) any_lane(c)
#define ALL(c) all_lanes(c)
#define GATHER_INT(l, i)                                                                 \
    (int16)((l)[(i).s0], (l)[(i).s1], (l)[(i).s2], (l)[(i).s3], (l)[(i).s4],            \
            (l)[(i).s5], (l)[(i).s6], (l)[(i).s7], (l)[(i).s8], (l)[(i).s9],            \
            (l)[(i).sa], (l)[(i).sb], (l)[(i).sc], (l)[(i).sd], (l)[(i).se], (l)[(i).sf])
#define GATHER(l, i)                                                                     \
    (float16)((l)[(i).s0], (l)[(i).s1], (l)[(i).s2], (l)[(i).s3], (l)[(i).s4],          \
              (l)[(i).s5], (l)[(i).s6], (l)[(i).s7], (l)[(i).s8], (l)[(i).s9],          \
              (l)[(i).sa], (l)[(i).sb], (l)[(i).sc], (l)[(i).sd], (l)[(i).se], (l)[(i).sf])
/* Interleave lane j of four planar vectors into out[o + n] (RGBA of voxel x + n). */
#define ST1(o, j, n, R_, G_, B_, A_) \
    out[(o) + n] = (float4)((R_).s##j, (G_).s##j, (B_).s##j, (A_).s##j)
#define STORE_RGBA(o, R_, G_, B_, A_)                                                    \
    do {                                                                                  \
        ST1(o, 0, 0, R_, G_, B_, A_); ST1(o, 1, 1, R_, G_, B_, A_);                       \
        ST1(o, 2, 2, R_, G_, B_, A_); ST1(o, 3, 3, R_, G_, B_, A_);                       \
        ST1(o, 4, 4, R_, G_, B_, A_); ST1(o, 5, 5, R_, G_, B_, A_);                       \
        ST1(o, 6, 6, R_, G_, B_, A_); ST1(o, 7, 7, R_, G_, B_, A_);                       \
        ST1(o, 8, 8, R_, G_, B_, A_); ST1(o, 9, 9, R_, G_, B_, A_);                       \
        ST1(o, a, 10, R_, G_, B_, A_); ST1(o, b, 11, R_, G_, B_, A_);                     \
        ST1(o, c, 12, R_, G_, B_, A_); ST1(o, d, 13, R_, G_, B_, A_);                     \
        ST1(o, e, 14, R_, G_, B_, A_); ST1(o, f, 15, R_, G_, B_, A_);                     \
    } while (0)
#elif VEC == 1
typedef float floatv;
typedef int intv;
#define VLOAD(p) (*(p))
#define TO_FLOAT(v) convert_float(v)
#define TO_INT(v) convert_int(v)
#define VABS(v) as_float(as_int(v) & 0x7FFFFFFF)
#define ANY(c) (c)
#define ALL(c) (c)
#define STORE_INT(v, p) (*(p) = (v))
#define GATHER(l, i) ((l)[(i)])
#define GATHER_INT(l, i) ((l)[(i)])
#define STORE_RGBA(o, r, g, b, a) (out[(o)] = (float4)((r), (g), (b), (a)))
#else
#error "VEC must be 16 or 1"
#endif

/* HALF_DATA: the brick travels as float16 (DATA_T half, DATA_V float lanes), converted as it is
 * loaded; LOAD1 loads one value of any brick type. */
#ifdef HALF_DATA
#undef VLOAD
#if VEC == 16
#define VLOAD(p) vload_half16(0, (p))
#else
#define VLOAD(p) vload_half(0, (p))
#endif
#define LOAD1(p) vload_half(0, (p))
#else
#define LOAD1(p) (*(p))
#endif

/* Lane-wise choice by a mask of the lanes' width: the vector ternary, which PoCL compiles to
 * a blend where its select() builtin is several times slower. */
#define SELECT(a, b, c) ((c) ? (b) : (a))

/* Lane-wise minimum, maximum, clamp and |x| by comparisons and blends. PoCL 3.0 calls its
 * 16-lane min, max, clamp, fmin, fmax and fabs out of line, through memory: a dense step spent
 * most of its time in those calls. Spelled with the variable operand first, x > c ? x : c, so
 * LLVM emits one maxps / minps per 8 lanes. On finite values they give the builtins' results
 * (a zero's sign aside, which no result can show: it only meets the LUT as position 0). */
#define VMIN(a, b) ((a) < (b) ? (a) : (b))
#define VMAX(a, b) ((a) > (b) ? (a) : (b))
#define VCLAMP(x, lo, hi) VMIN(VMAX((x), (lo)), (hi))

#if ENHANCE && VEC != 1
#error "gradient enhancement is computed one voxel per work-item (VEC=1)"
#endif

/* u = clip((v - vmin) * scale, 0, 1), in float32 exactly as the reference. */
#define NORMALIZE(v) VCLAMP((TO_FLOAT(v) - vmin) * scale, 0.0f, 1.0f)

/* Data TF of a step's values: position in the LUT, then interpolated channels. */
typedef struct {
    intv i0;   /* left LUT entry (QUANT: the raw value) */
    floatv f;  /* weight of the right entry (QUANT: unused) */
    floatv x;  /* the position itself, u * (LUT_N - 1) (QUANT: unused) */
} LutPos;

inline LutPos lut_pos_of(const floatv u)
{
    LutPos p;
    p.x = u * (float)(LUT_N - 1);
    p.i0 = VMIN(TO_INT(p.x), LUT_N - 2);
    p.f = p.x - TO_FLOAT(p.i0);
    return p;
}

#ifdef QUANT
#define LUT_CHANNEL(lut, c, p) GATHER((lut) + (c) * LUT_N, (p).i0)
#else
#define LUT_CHANNEL(lut, c, p)                                           \
    (GATHER((lut) + (c) * LUT_N, (p).i0) * (1.0f - (p).f) +              \
     GATHER((lut) + (c) * LUT_N, (p).i0 + 1) * (p).f)
#endif

/* Whether any lane of raw values can have non-zero data opacity. `cut` is the smallest raw
 * value that can (found exactly on the host: u(v) is monotone in float32 arithmetic). */
#ifdef QUANT
#define IS_LIVE(raw) ANY((raw) >= (DATA_V)((DATA_T)cut))
#else
#define IS_LIVE(raw) ANY(TO_FLOAT(raw) >= cut)
#endif

/* The LUT position of raw values (QUANT: the value itself). */
#ifdef QUANT
#define LOCATE(raw, p)          \
    (p).i0 = TO_INT(raw);       \
    (p).f = (floatv)(0.0f);     \
    (p).x = TO_FLOAT(raw);
#else
#define LOCATE(raw, p) (p) = lut_pos_of(NORMALIZE(raw));
#endif

#ifdef CONST_COLOR
/* Colour is data colour (constant, folded into tc on the host) times time colour. */
#define STEP_COLOR(lut, p, t, r, g, b) \
    r = (floatv)((t).x);               \
    g = (floatv)((t).y);               \
    b = (floatv)((t).z);
#elif COLOR_SEGS
/* The data colour is COLOR_SEGS straight pieces of the LUT (found on the host, equal to the
 * LUT's interpolation to float32 rounding): each lane picks its piece by comparisons and
 * evaluates c0 + slope * (x - x0), where looking the colour up would take six gathers. The
 * table follows the LUT in its buffer: x0[S], then c0 and slope per channel ([3][S] each). */
#define SEG_X(j) seg[(j)]
#define SEG_C(c, j) seg[COLOR_SEGS * (1 + (c)) + (j)]
#define SEG_S(c, j) seg[COLOR_SEGS * (4 + (c)) + (j)]
#define SEG_IN(j) ((p).x >= SEG_X(j))
#define SEG_PICK(j)                                         \
    if ((j) < COLOR_SEGS) {                                 \
        x0 = SELECT(x0, (floatv)(SEG_X(j)), SEG_IN(j));     \
        c0r = SELECT(c0r, (floatv)(SEG_C(0, j)), SEG_IN(j)); \
        c0g = SELECT(c0g, (floatv)(SEG_C(1, j)), SEG_IN(j)); \
        c0b = SELECT(c0b, (floatv)(SEG_C(2, j)), SEG_IN(j)); \
        sr = SELECT(sr, (floatv)(SEG_S(0, j)), SEG_IN(j));   \
        sg = SELECT(sg, (floatv)(SEG_S(1, j)), SEG_IN(j));   \
        sb = SELECT(sb, (floatv)(SEG_S(2, j)), SEG_IN(j));   \
    }
#define STEP_COLOR(lut, p, t, r, g, b)                                                   \
    {                                                                                    \
        const __global float *seg = (lut) + 4 * LUT_N;                                   \
        floatv x0 = SEG_X(0), c0r = SEG_C(0, 0), c0g = SEG_C(1, 0), c0b = SEG_C(2, 0);   \
        floatv sr = SEG_S(0, 0), sg = SEG_S(1, 0), sb = SEG_S(2, 0);                     \
        SEG_PICK(1) SEG_PICK(2) SEG_PICK(3) SEG_PICK(4) SEG_PICK(5) SEG_PICK(6) SEG_PICK(7) \
        const floatv dx = (p).x - x0;                                                    \
        r = (c0r + sr * dx) * (t).x;                                                     \
        g = (c0g + sg * dx) * (t).y;                                                     \
        b = (c0b + sb * dx) * (t).z;                                                     \
    }
#else
#define STEP_COLOR(lut, p, t, r, g, b)      \
    r = LUT_CHANNEL(lut, 0, p) * (t).x;     \
    g = LUT_CHANNEL(lut, 1, p) * (t).y;     \
    b = LUT_CHANNEL(lut, 2, p) * (t).z;
#endif

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

/* Enhancement factor e of step k at brick voxel (x, y, zb); enh = (k0, k1, k2, -). */
inline float enhance_factor(__global const DATA_T *data, int k, int x, int y, int zb, int nx,
                            int ny, int nzb, int w, float vmin, float scale, float4 enh,
                            float4 view)
{
#define U(zz, yy, xx) NORMALIZE(LOAD1(data + VOX_INDEX(zz, k, yy, xx)))
    const float mid = U(zb, y, x);
    const float gx = axis_gradient(U(zb, y, max(x - 1, 0)), mid, U(zb, y, min(x + 1, nx - 1)), x, nx);
    const float gy = axis_gradient(U(zb, max(y - 1, 0), x), mid, U(zb, min(y + 1, ny - 1), x), y, ny);
    const float gz = axis_gradient(U(max(zb - 1, 0), y, x), mid, U(min(zb + 1, nzb - 1), y, x), zb, nzb);
#undef U
    const float mag = sqrt(gx * gx + gy * gy + gz * gz);
#if ENHANCE == 1
    return enh.x + enh.y * pow(mag, enh.z);
#else
    if (mag == 0.0f) return enh.x;
    const float c = fabs(gx * view.x + gy * view.y + gz * view.z) / mag;
    return enh.x + enh.y * pow(VCLAMP(1.0f - c, 0.0f, 1.0f), enh.z);
#endif
}
#define STEP_ALPHA(lut, p, t, k) \
    VCLAMP(LUT_CHANNEL(lut, 3, p) * (t).w * \
          enhance_factor(data, k, x, y, zb, nx, ny, nzb, w, vmin, scale, enh, view), 0.0f, 1.0f)
#else
#define STEP_ALPHA(lut, p, t, k) VCLAMP(LUT_CHANNEL(lut, 3, p) * (t).w, 0.0f, 1.0f)
#endif

/* The arguments every integration kernel takes, in this order. */
#define KERNEL_ARGS                                                                        \
    __global const DATA_T *data, __global const float *lut, __global const float4 *tc,     \
    __global const int *order, __global const int *steps, const int x0, const int nx,      \
    const int ny, const int nzb, const int w, const int zcrop, const int nz_out,           \
    const float vmin, const float scale, const float cut, const float4 enh, const float4 view

#define VOXEL_PROLOGUE                                  \
    const int x = x0 + VEC * (int)get_global_id(0);     \
    const int y = get_global_id(1);                     \
    const int z = get_global_id(2);                     \
    /* padding work-items of a rounded-up launch: a lane past the row or a row past the slab */ \
    if (x + VEC > nx || y >= ny || z >= nz_out) return; \
    const int zb = z + zcrop;                           \
    const size_t o = OUT_INDEX(z, y, x);

#define RAW(k) VLOAD(data + VOX_INDEX(zb, (k), y, x))

/* Step k's colour r, g, b and opacity ak, inside a loop over the steps. With SKIP_EMPTY a step
 * whose lanes all map to zero data opacity is skipped (`continue`): every mode using this
 * gets nothing from such a step (over adds 0, no hit, sums add 0, a count does not grow). */
#ifdef SKIP_EMPTY
#define SKIP_IF_EMPTY(raw) if (!IS_LIVE(raw)) continue;
#else
#define SKIP_IF_EMPTY(raw)
#endif
#define STEP_RGBA(k, r, g, b, ak)       \
    const DATA_V raw = RAW(k);          \
    SKIP_IF_EMPTY(raw)                  \
    LutPos p;                           \
    LOCATE(raw, p)                      \
    const float4 t = tc[k];             \
    floatv r, g, b;                     \
    STEP_COLOR(lut, p, t, r, g, b)      \
    const floatv ak = STEP_ALPHA(lut, p, t, k);

/* The colour r, g, b and opacity ak of the step that won (max, min, change): the data TF at
 * `value`, the time TF of selection index `win` (lanes), and that step's enhancement. */
#ifdef CONST_COLOR
#define WINNER_COLOR(p, k4, r, g, b) \
    const floatv r = GATHER(tcf, k4), g = GATHER(tcf, (k4) + 1), b = GATHER(tcf, (k4) + 2);
#else
#define WINNER_COLOR(p, k4, r, g, b)                          \
    const floatv r = LUT_CHANNEL(lut, 0, p) * GATHER(tcf, k4); \
    const floatv g = LUT_CHANNEL(lut, 1, p) * GATHER(tcf, (k4) + 1); \
    const floatv b = LUT_CHANNEL(lut, 2, p) * GATHER(tcf, (k4) + 2);
#endif
#if ENHANCE
#define WINNER_ENHANCE(win) \
    *enhance_factor(data, (win), x, y, zb, nx, ny, nzb, w, vmin, scale, enh, view)
#else
#define WINNER_ENHANCE(win)
#endif
#define WINNER_RGBA_AT(p, win, r, g, b, ak)                             \
    const __global float *tcf = (const __global float *)tc;             \
    const intv k4 = (win) * 4;                                          \
    WINNER_COLOR(p, k4, r, g, b)                                        \
    floatv ak = VCLAMP(LUT_CHANNEL(lut, 3, p) * GATHER(tcf, k4 + 3) WINNER_ENHANCE(win), 0.0f, 1.0f);
#define WINNER_RGBA(value, win, r, g, b, ak) \
    const LutPos p = lut_pos_of(value);      \
    WINNER_RGBA_AT(p, win, r, g, b, ak)

/* The LUT position of a step again, from the `x` LOCATE gave it (QUANT: the raw value), so
 * that a step's opacity and colour come out in the same bits as in the loop. */
inline LutPos lut_pos_again(const floatv x)
{
    LutPos p;
    p.x = x;
#ifdef QUANT
    p.i0 = TO_INT(x);
    p.f = (floatv)(0.0f);
#else
    p.i0 = VMIN(TO_INT(x), LUT_N - 2);
    p.f = x - TO_FLOAT(p.i0);
#endif
    return p;
}

#endif /* SLIDING */
