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
 *   TF_SEGS     the data TF is this many (1..8) straight pieces (0: none): the colour, unless
 *               constant, is evaluated from them, no lookups
 *   SEG_ALPHA   opacity in the pieces: 1 evaluated from them; 2 (threshold modes) deciding
 *               the lanes far from the threshold, the others looked up exactly (THRESHOLD_TEST)
 *   ENHANCE     0 none, 1 edge, 2 silhouette (VEC must be 1)
 *   EARLY_EXIT  alpha: stop once every lane's transmittance is below 1e-6
 *   SKIP_EMPTY  skip steps whose lanes all lie below `cut`, where data opacity is 0 (or, in
 *               first_hit and count, cannot exceed the threshold): exact, they add nothing
 *   STEP_GROUP  steps a block of rows runs before its state goes back to local memory (8)
 *   TIME_TABLE  a rows kernel of a mode with t_index, at most 32 steps: the winner's time colour
 *               and step may come from register tables (PERMUTE_TIME)
 *
 * The brick is in xytz order: (nzb, w, ny, nx), x fastest, or with SLOTS its steps lie apart
 * (VOX_INDEX below). A work-item integrates VEC
 * consecutive voxels starting at x0 + VEC * get_global_id(0), or, in a mode's `_rows` kernel
 * (CPU devices), a block of rows (BLOCK_STEPS below); the output covers brick rows
 * [zcrop, zcrop + nz_out), the rest being the gradient halo. The data LUT is planar
 * (r[LUT_N], g[LUT_N], b[LUT_N], a[LUT_N]) and shared by all steps; tc[k] = (rgb_t, a_t) of
 * step k. Arithmetic follows chronocl/reference.py so results agree to float32 rounding
 * (`madd` contracts a few sums to one rounding).
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
 * the integrate kernels' build options. They are launched over whole work-groups of one size
 * (chronocl/engine/elementwise.py: a driver compiles a kernel once per work-group size, not
 * once per volume), so each takes the voxel count `n_items` last and the items past it return. */
#define ELEMENT_ARGS const ulong n_items
#define ELEMENT(i)                      \
    const size_t i = get_global_id(0); \
    if (i >= n_items) return
#ifndef SLIDING
#ifdef SLOTS
/* The steps are not stacked but read where they lie (chronocl.data.bricks.SlotBrick): brick
 * step k's first row starts at step_base[k], and its rows are zstride elements apart. */
#define VOX_INDEX(zb, k, y, x) (step_base[k] + (size_t)(zb) * zstride + (size_t)(y) * nx + (x))
#else
#define VOX_INDEX(zb, k, y, x) ((((size_t)(zb) * w + (k)) * ny + (y)) * nx + (x))
#endif
#define OUT_INDEX(z, y, x) (((size_t)(z) * ny + (y)) * nx + (x))

/* Stores of whole aligned vectors of the output, which the kernel writes once and never reads:
 * non-temporal where the compiler has them (PoCL), so a CPU writes the lines without reading
 * them in first; alpha ran 1.2x faster, max 1.05x, at 10 x 256^3 float32 on an AVX2 EPYC. */
#if defined(__has_builtin)
#if __has_builtin(__builtin_nontemporal_store)
#define STREAM_STORE(v, p) __builtin_nontemporal_store((v), (p))
/* x86 orders non-temporal stores only at a fence: each work-item that made them (aligned
 * 16-lane builds) fences them before it ends, so whoever reads the output after the kernel
 * sees all of it. */
#if __has_builtin(__builtin_ia32_sfence) && VEC == 16 && defined(ALIGNED)
#define STREAM_FENCE __builtin_ia32_sfence();
#endif
#endif
#endif
#ifndef STREAM_STORE
#define STREAM_STORE(v, p) (*(p) = (v))
#endif
#ifndef STREAM_FENCE
#define STREAM_FENCE
#endif

#if VEC == 16
typedef float16 floatv;
typedef int16 intv;
#ifdef ALIGNED
#define VLOAD(p) (*(const __global DATA_V *)(p))
#define STORE_INT(v, p) STREAM_STORE((v), (__global int16 *)(p))
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
#if defined(__has_builtin)
#if __has_builtin(__builtin_shufflevector)
#define SHUFFLE_STORE
#endif
#endif
/* The x86 paths this build may take (ISA_AVX512, ISA_AVX2): those the compiler's target has,
 * unless the host lowers them with CPU_PATHS (1: AVX2 as on a CPU without AVX-512; 0: neither,
 * the portable gathers), so that every variant the CPU can run is built and compared with the
 * others on whatever CPU runs the suite (chronocl/engine/defines.py CPU_PATHS). */
#if defined(__AVX512F__) && (!defined(CPU_PATHS) || CPU_PATHS >= 2)
#define ISA_AVX512
#endif
#if defined(__AVX2__) && (!defined(CPU_PATHS) || CPU_PATHS >= 1)
#define ISA_AVX2
#endif
#ifdef SHUFFLE_STORE
/* Two vectors of 2, 4 or 8 lanes as one of twice as many. */
#define CAT2(a, b) __builtin_shufflevector(a, b, 0, 1, 2, 3)
#define CAT4(a, b) __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7)
#define CAT8(a, b) __builtin_shufflevector(a, b, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15)
/* Interleave four planar vectors into the RGBA of 16 voxels at dst with two rounds of lane
 * shuffles and four 64-byte stores, where the per-voxel float4 stores below build each float4
 * from four lanes (5 % faster max, 10 % additive). Clang's shuffle builtin, where the OpenCL
 * compiler has it (PoCL, NVIDIA's); else the float4 stores. */
#define ZIP_LO 0, 16, 1, 17, 2, 18, 3, 19, 4, 20, 5, 21, 6, 22, 7, 23
#define ZIP_HI 8, 24, 9, 25, 10, 26, 11, 27, 12, 28, 13, 29, 14, 30, 15, 31
#define PAIRS_LO 0, 1, 16, 17, 2, 3, 18, 19, 4, 5, 20, 21, 6, 7, 22, 23
#define PAIRS_HI 8, 9, 24, 25, 10, 11, 26, 27, 12, 13, 28, 29, 14, 15, 30, 31
#ifdef ALIGNED
#define STORE16(v, i, p) STREAM_STORE((v), ((__global float16 *)(p)) + (i))
#else
#define STORE16(v, i, p) vstore16((v), (i), (__global float *)(p))
#endif
inline void store_rgba16(__global float4 *dst, const float16 r, const float16 g,
                         const float16 b, const float16 a)
{
    const float16 rg_lo = __builtin_shufflevector(r, g, ZIP_LO);
    const float16 rg_hi = __builtin_shufflevector(r, g, ZIP_HI);
    const float16 ba_lo = __builtin_shufflevector(b, a, ZIP_LO);
    const float16 ba_hi = __builtin_shufflevector(b, a, ZIP_HI);
    STORE16(__builtin_shufflevector(rg_lo, ba_lo, PAIRS_LO), 0, dst);
    STORE16(__builtin_shufflevector(rg_lo, ba_lo, PAIRS_HI), 1, dst);
    STORE16(__builtin_shufflevector(rg_hi, ba_hi, PAIRS_LO), 2, dst);
    STORE16(__builtin_shufflevector(rg_hi, ba_hi, PAIRS_HI), 3, dst);
}
#define STORE_RGBA(o, R_, G_, B_, A_) store_rgba16(out + (o), (R_), (G_), (B_), (A_))
#else
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
#endif
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

/* RGBA8: integrate kernels write the display format itself (rgba8.h's rule, the recolouring's
 * too), a quarter of float32's bytes and nothing left to convert on the host. Only a final
 * result is written so: partials and the combine / finish kernels stay float32. */
#ifdef RGBA8
typedef uchar4 out_t;
#undef STORE_RGBA
#define TO_RGBA8(v) rgba8(v)
#if VEC == 16
#define ST8(o, j, n) out[(o) + n] = (uchar4)(r8_.s##j, g8_.s##j, b8_.s##j, a8_.s##j)
#define STORE_RGBA(o, R_, G_, B_, A_)                                                    \
    do {                                                                                  \
        const uchar16 r8_ = bytes16(R_);                                             \
        const uchar16 g8_ = bytes16(G_);                                             \
        const uchar16 b8_ = bytes16(B_);                                             \
        const uchar16 a8_ = bytes16(A_);                                             \
        ST8(o, 0, 0); ST8(o, 1, 1); ST8(o, 2, 2); ST8(o, 3, 3);                           \
        ST8(o, 4, 4); ST8(o, 5, 5); ST8(o, 6, 6); ST8(o, 7, 7);                           \
        ST8(o, 8, 8); ST8(o, 9, 9); ST8(o, a, 10); ST8(o, b, 11);                         \
        ST8(o, c, 12); ST8(o, d, 13); ST8(o, e, 14); ST8(o, f, 15);                       \
    } while (0)
#else
#define STORE_RGBA(o, r, g, b, a) (out[(o)] = TO_RGBA8((float4)((r), (g), (b), (a))))
#endif
#else
typedef float4 out_t;
#endif

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

/* x clamped to [0, 1]. A function, not VCLAMP: with the bound value written twice LLVM turns
 * the outer comparison into mask arithmetic (seven instructions per 8 lanes, not two). */
inline floatv clamp_unit(const floatv x)
{
    const floatv m = VMAX(x, 0.0f);
    return VMIN(m, 1.0f);
}

/* a * b + c with one rounding where the device fuses them (FMA): the data TF's pieces and the
 * sums through time, which compute more than they read on a CPU. Elsewhere the file keeps
 * contraction off, so a result follows the reference's rounding step by step. (fma() itself
 * is called out of line for 16 lanes in PoCL 3.0, several times slower than the two.) */
inline floatv madd(const floatv a, const floatv b, const floatv c)
{
#pragma OPENCL FP_CONTRACT ON
    return a * b + c;
}

/* u = clip((v - vmin) * scale, 0, 1), in float32 exactly as the reference. */
#define NORMALIZE(v) clamp_unit((TO_FLOAT(v) - vmin) * scale)

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
#elif VEC == 16 && defined(SHUFFLE_STORE) && defined(ISA_AVX2) && !defined(ISA_AVX512)
/* Entries i and i + 1 of every lane in one 8-byte load each, split into the left and the
 * right entries by shuffles: a quarter of the operations of two 16-lane gathers as AVX2 builds
 * them (scalar loads and inserts), the same values, so the same bits. Only where measured: on
 * AVX2 CPUs; AVX-512 has gathers of its own (there, shuffled loads of the time colours ran
 * slower than gathers: docs/engine.md). */
#define LUT_PAIR(j) vload2(0, l + i.s##j)
inline float16 lut_lerp(const __global float *l, const int16 i, const float16 f)
{
    const float16 lo = CAT8(CAT4(CAT2(LUT_PAIR(0), LUT_PAIR(1)), CAT2(LUT_PAIR(2), LUT_PAIR(3))),
                            CAT4(CAT2(LUT_PAIR(4), LUT_PAIR(5)), CAT2(LUT_PAIR(6), LUT_PAIR(7))));
    const float16 hi = CAT8(CAT4(CAT2(LUT_PAIR(8), LUT_PAIR(9)), CAT2(LUT_PAIR(a), LUT_PAIR(b))),
                            CAT4(CAT2(LUT_PAIR(c), LUT_PAIR(d)), CAT2(LUT_PAIR(e), LUT_PAIR(f))));
    const float16 left = __builtin_shufflevector(lo, hi, 0, 2, 4, 6, 8, 10, 12, 14, 16, 18,
                                                 20, 22, 24, 26, 28, 30);
    const float16 right = __builtin_shufflevector(lo, hi, 1, 3, 5, 7, 9, 11, 13, 15, 17, 19,
                                                  21, 23, 25, 27, 29, 31);
    return left * (1.0f - f) + right * f;
}
#define LUT_CHANNEL(lut, c, p) lut_lerp((lut) + (c) * LUT_N, (p).i0, (p).f)
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

#if TF_SEGS
/* The data TF as TF_SEGS straight pieces of the LUT (found on the host, equal to the LUT's
 * interpolation to float32 rounding), where looking a channel up takes two 16-lane gathers.
 * A position's run through piece j is x - x0_j clamped to [0, the piece's length], and a
 * channel is c0 + sum_j slope_j * run_j: no lane picks a piece, and no term is larger than
 * the channel's change over its piece (no cancellation). The table follows the LUT in its
 * buffer: x0[S], then per step k (W of them) and channel (r g b a) the value at 0 and the
 * S slopes, times step k's time colour and opacity (chronocl/engine/tables.py `tf_segments`).
 * `PIECES(p, k)` declares the runs h0..h7 and step k's row; channels a build does not use
 * cost nothing (the compiler drops them). */
#define SEG_X(j) seg[(j)]
#define SEG_ROW(k) (seg + TF_SEGS + (k) * 4 * (TF_SEGS + 1))
#define SEG_C(c) segk[(c) * (TF_SEGS + 1)]
#define SEG_S(c, j) segk[(c) * (TF_SEGS + 1) + 1 + (j)]
#define RUN(p, j)                                                                        \
    const floatv h##j = (j) >= TF_SEGS ? (floatv)(0.0f)                                  \
                      : (j) + 1 == TF_SEGS ? VMAX((p).x - SEG_X(j), 0.0f)                \
                      : VCLAMP((p).x - SEG_X(j), 0.0f, SEG_X((j) + 1) - SEG_X(j));
#define PIECES(p, k)                                                                     \
    const __global float *seg = lut + 4 * LUT_N;                                         \
    const __global float *segk = SEG_ROW(k);                                             \
    RUN(p, 0) RUN(p, 1) RUN(p, 2) RUN(p, 3) RUN(p, 4) RUN(p, 5) RUN(p, 6) RUN(p, 7)
#define TERM(c, j, acc) ((j) < TF_SEGS ? madd((floatv)(SEG_S(c, j)), h##j, acc) : (acc))
#define TERMS_FROM(c, base)                                                              \
    TERM(c, 7, TERM(c, 6, TERM(c, 5, TERM(c, 4, TERM(c, 3, TERM(c, 2, TERM(c, 1,         \
         TERM(c, 0, (floatv)(base)))))))))
#define PIECE_OF(c) TERMS_FROM(c, SEG_C(c))
#define CH_r 0
#define CH_g 1
#define CH_b 2
#define CH_a 3
/* Channel c (r, g, b or a) of the data TF times the time TF of the step PIECES took. */
#define PIECE(c) PIECE_OF(CH_##c)
/* How far a threshold test trusts the pieces' opacity: twice the error the host allows them
 * (chronocl/engine/tables.py `opacity_error`, at most 5e-6). */
#define SEG_MARGIN 1e-5f
#else
#define PIECES(p, k)
#endif

#ifdef CONST_COLOR
/* Colour is data colour (constant, folded into tc on the host) times time colour. */
#define STEP_COLOR(lut, p, t, r, g, b) \
    r = (floatv)((t).x);               \
    g = (floatv)((t).y);               \
    b = (floatv)((t).z);
#elif TF_SEGS
#define STEP_COLOR(lut, p, t, r, g, b) \
    r = PIECE(r);                      \
    g = PIECE(g);                      \
    b = PIECE(b);
#else
#define STEP_COLOR(lut, p, t, r, g, b)      \
    r = LUT_CHANNEL(lut, 0, p) * (t).x;     \
    g = LUT_CHANNEL(lut, 1, p) * (t).y;     \
    b = LUT_CHANNEL(lut, 2, p) * (t).z;
#endif

/* A step's data opacity times its time opacity: from the pieces, or looked up. */
#if TF_SEGS && SEG_ALPHA == 1
#define TIMED_ALPHA(lut, p, t) PIECE(a)
#else
#define TIMED_ALPHA(lut, p, t) (LUT_CHANNEL(lut, 3, p) * (t).w)
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
inline float enhance_factor(__global const DATA_T *data, __global const long *step_base,
                            long zstride, int k, int x, int y, int zb, int nx, int ny, int nzb,
                            int w, float vmin, float scale, float4 enh, float4 view)
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
    VCLAMP(TIMED_ALPHA(lut, p, t) * \
          enhance_factor(data, step_base, zstride, k, x, y, zb, nx, ny, nzb, w, vmin, scale, enh, view), 0.0f, 1.0f)
#else
#define STEP_ALPHA(lut, p, t, k) clamp_unit(TIMED_ALPHA(lut, p, t))
#endif

/* The arguments every integration kernel takes, in this order: declared for the host in
 * chronocl/engine/kernel_args.py (INTEGRATE), which sets them by name; a mode's kernels follow
 * them with the mode's extras, `out` (and `t_index`) and, for `_rows`, ROWS_ARGS.
 * tests/test_kernel_args.py checks every kernel against the declaration. */
#define KERNEL_ARGS                                                                        \
    __global const DATA_T *data, __global const float *lut, __global const float4 *tc,     \
    __global const int *order, __global const int *steps, __global const long *step_base, \
    const long zstride, const int x0, const int nx,                                        \
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

/* The brick step integrated i-th. ORDER_FORWARD / ORDER_BACKWARD: the host found the order to
 * be the brick's steps in turn or reversed (forward and backward orders over a window), so no
 * step index is loaded and the compiler steps the addresses instead of multiplying each one out
 * (max ran 15 % faster). Otherwise order[i]. */
#if defined(ORDER_FORWARD)
#define ORDER_AT(i) (i)
#elif defined(ORDER_BACKWARD)
#define ORDER_AT(i) (w - 1 - (i))
#else
#define ORDER_AT(i) order[i]
#endif

/* Steps `from`..w-1 of the order into a mode's state s: STEP(s, k) each (which may `continue`
 * past a step), stopping once DONE(s). */
#define STEPS(s, from, to, STEP, DONE)  \
    for (int i = (from); i < (to); ++i) { \
        const int k = ORDER_AT(i);      \
        STEP(s, k)                      \
        if (DONE(s)) break;             \
    }
#define NEVER_DONE(s) 0

/* Blocks of rows (CPU devices; chronocl/engine/opencl.py `_row_blocks`). A mode's `_rows`
 * kernel takes `rows` rows of `nvec` vectors each (from x0) per work-item and runs the steps
 * in the outer loop, STEP_GROUP at a time: each step of the block is then a few runs of
 * consecutive memory, which a CPU's prefetchers stream, where one work-item per vector reads
 * w places a step apart. The mode's state waits in local memory between groups (cache
 * resident); each vector does the very arithmetic of the per-vector kernel, so the results
 * are the same bits. */
#ifndef STEP_GROUP
#define STEP_GROUP 8
#endif
/* The state of the modes that sum or composite colour: planar RGBA of one vector. */
typedef struct {
    floatv r, g, b, a;
} Rgba;
#define RGBA_ZERO(s) s.r = s.g = s.b = s.a = 0.0f;
#define ROWS_ARGS(T) const int rows, const int nvec, __local T *st /* kernel_args.ROWS */
#define ROWS_PROLOGUE                            \
    const int y0 = rows * (int)get_global_id(0); \
    const int z = get_global_id(1);              \
    if (y0 >= ny || z >= nz_out) return;         \
    const int zb = z + zcrop;                    \
    const int nv = min(rows, ny - y0) * nvec;
#define FOR_BLOCK(v) for (int v = 0; v < nv; ++v)
/* Vector v of the block: its row y and first voxel x. */
#define BLOCK_VOXEL(v)                           \
    const int y = y0 + (v) / nvec;               \
    const int x = x0 + VEC * ((v) % nvec);
/* The groups of steps, the last of which finishes each vector right after its steps (FINISH
 * writes voxel o): its arithmetic then overlaps the loads of the next vector's steps, where a
 * pass of its own left memory idle (alpha, max, first_hit and count about 1.07x faster on an
 * AVX2 EPYC; mixed on an AVX-512 one, docs/engine.md). A block with no step to run (from >= w)
 * only finishes. */
#define BLOCK_STEPS(T, from, STEP, DONE, FINISH)                         \
    for (int i0 = (from);; i0 += STEP_GROUP) {                           \
        const int last_ = i0 + STEP_GROUP >= w;                          \
        FOR_BLOCK(v) {                                                   \
            BLOCK_VOXEL(v)                                               \
            T s = st[v];                                                 \
            if (i0 < w && !DONE(s)) {                                    \
                STEPS(s, i0, min(w, i0 + STEP_GROUP), STEP, DONE)        \
            }                                                            \
            if (last_) {                                                 \
                const size_t o = OUT_INDEX(z, y, x);                     \
                FINISH(s)                                                \
            } else {                                                     \
                st[v] = s;                                               \
            }                                                            \
        }                                                                \
        if (last_) break;                                                \
    }

/* The bodies of a mode's two kernels, from its state type T and macros: INIT(s) (from the
 * first step where `from` is 1), STEP(s, k), DONE(s) and FINISH(s) (which writes voxel o). */
#define VECTOR_BODY(T, from, INIT, STEP, DONE, FINISH) \
    VOXEL_PROLOGUE                                     \
    TIME_TABLE_LOAD                                    \
    T s;                                               \
    INIT(s)                                            \
    STEPS(s, from, w, STEP, DONE)                      \
    FINISH(s)                                          \
    STREAM_FENCE
#define ROWS_BODY(T, from, INIT, STEP, DONE, FINISH) \
    ROWS_PROLOGUE                                    \
    TIME_TABLE_LOAD                                  \
    FOR_BLOCK(v) {                                   \
        BLOCK_VOXEL(v)                               \
        INIT(st[v])                                  \
    }                                                \
    BLOCK_STEPS(T, from, STEP, DONE, FINISH)        \
    STREAM_FENCE

/* Step k's colour r, g, b and opacity ak, inside a loop over the steps. With SKIP_EMPTY a step
 * whose lanes all map to zero data opacity is skipped (`continue`): every mode using this
 * gets nothing from such a step (over adds 0, no hit, sums add 0, a count does not grow). */
#ifdef SKIP_EMPTY
#define SKIP_IF_EMPTY(raw) if (!IS_LIVE(raw)) continue;
#else
#define SKIP_IF_EMPTY(raw)
#endif
/* Step k's LUT position p, inside a loop over the steps (SKIP_EMPTY: `continue` past it). */
#define STEP_POSITION(k, p)             \
    const DATA_V raw = RAW(k);          \
    SKIP_IF_EMPTY(raw)                  \
    LutPos p;                           \
    LOCATE(raw, p)
#define STEP_RGBA(k, r, g, b, ak)       \
    STEP_POSITION(k, p)                 \
    const float4 t = tc[k];             \
    PIECES(p, k)                        \
    floatv r, g, b;                     \
    STEP_COLOR(lut, p, t, r, g, b)      \
    const floatv ak = STEP_ALPHA(lut, p, t, k);

/* `pass`: the lanes of step k whose opacity exceeds `threshold`, exactly as the LUT gives it.
 * With SEG_ALPHA 2 the pieces' opacity (within SEG_MARGIN / 2 of the exact one; the host keeps
 * time opacities at most 1 and gradient enhancement off) decides every lane at least
 * SEG_MARGIN below the threshold or more than SEG_MARGIN above it, and the exact opacity is
 * looked up only when a lane of `open_` lies between; a step no lane of `open_` can pass is
 * skipped (`continue`). */
#if TF_SEGS && SEG_ALPHA == 2
#define THRESHOLD_TEST(p, k, open_, pass)                              \
    PIECES(p, k)                                                       \
    const floatv near_ = TERMS_FROM(CH_a, SEG_C(CH_a) - threshold);   \
    const intv can_ = (open_) & (near_ > -SEG_MARGIN);                 \
    if (!ANY(can_)) continue;                                          \
    intv pass = near_ > SEG_MARGIN;                                    \
    if (ANY(can_ & ~pass)) {                                           \
        const float4 t = tc[k];                                        \
        pass = STEP_ALPHA(lut, p, t, k) > threshold;                   \
    }
#else
#define THRESHOLD_TEST(p, k, open_, pass) \
    PIECES(p, k)                          \
    const float4 t = tc[k];               \
    const intv pass = STEP_ALPHA(lut, p, t, k) > threshold;
#endif

/* The time TF and step of the winning step `win` (lanes of brick step indices): TIME_AT(c, win)
 * is channel c (0..3: r g b a) of tc[win], STEP_AT(win) is steps[win]. By default each is a
 * 16-lane gather. PERMUTE_TIME (a rows kernel on an AVX-512 or AVX2 CPU, with the host's
 * TIME_TABLE: at most 32 steps) keeps tc and steps as planar 32-entry tables in registers,
 * loaded once per block of rows, and looks a vector up with one two-table permute (512:
 * vpermi2ps; max ran 8-13 % faster) or a few one-table permutes and blends (256: vpermps)
 * where a gather takes 16 loads. Portable OpenCL has no lane permute by variable indices
 * (PoCL's shuffle2 ran at 0.8 of the gathers' speed), hence the x86 builtins, and the gathers
 * wherever they are missing. All give the same bits. The permutes read an index's low 5 bits,
 * so the host sets TIME_TABLE only for rows kernels of at most 32 steps, and only for modes
 * whose kernels load the tables (TIME_TABLE_LOAD). */
#if VEC == 16 && defined(TIME_TABLE) && defined(ISA_AVX512) && defined(__has_builtin)
#if __has_builtin(__builtin_ia32_vpermi2varps512)
#define PERMUTE_TIME 512
#endif
#endif
#if VEC == 16 && defined(TIME_TABLE) && !defined(PERMUTE_TIME) && defined(ISA_AVX2) && \
    defined(__has_builtin)
#if __has_builtin(__builtin_ia32_permvarsf256) && __has_builtin(__builtin_shufflevector)
#define PERMUTE_TIME 256
#endif
#endif
#if PERMUTE_TIME == 512
typedef float v16sf_ __attribute__((vector_size(64)));
typedef int v16si_ __attribute__((vector_size(64)));
/* Entry i (lanes, 0..31) of the 32 entries lo[0..15], hi[0..15]. */
inline float16 lookup32(const float16 lo, const float16 hi, const int16 i, const int w)
{
    return as_float16(__builtin_ia32_vpermi2varps512((v16sf_)lo, (v16si_)i, (v16sf_)hi));
}
#elif PERMUTE_TIME == 256
/* AVX2 (no AVX-512): vpermps looks 8 lanes up in one 8-entry quarter of the table by an
 * index's low 3 bits; bits 3 and 4 choose among the quarters, of which only those below w
 * are permuted (w is the same for every work-item: the branches cost nothing). 3-7 vector
 * operations per 8 lanes where a gather takes 8 loads, 8 inserts and the index extractions:
 * max ran about 1.3x faster at 10 x 256^3 float32 on a 2-core AMD EPYC without AVX-512. */
typedef float v8sf_ __attribute__((vector_size(32)));
typedef int v8si_ __attribute__((vector_size(32)));
#define LANES_LO 0, 1, 2, 3, 4, 5, 6, 7
#define LANES_HI 8, 9, 10, 11, 12, 13, 14, 15
inline float8 permute8(const float8 table, const int8 i)
{
    return as_float8(__builtin_ia32_permvarsf256((v8sf_)table, (v8si_)i));
}
inline float8 lookup32_8(const float16 lo, const float16 hi, const int8 i, const int w)
{
    const float8 q0 = permute8(__builtin_shufflevector(lo, lo, LANES_LO), i);
    if (w <= 8) return q0;
    const float8 a = SELECT(q0, permute8(__builtin_shufflevector(lo, lo, LANES_HI), i), (i & 8) != 0);
    if (w <= 16) return a;
    const float8 q2 = permute8(__builtin_shufflevector(hi, hi, LANES_LO), i);
    const float8 b = SELECT(q2, permute8(__builtin_shufflevector(hi, hi, LANES_HI), i), (i & 8) != 0);
    return SELECT(a, b, (i & 16) != 0);
}
/* Entry i (lanes, 0..31) of the 32 entries lo[0..15], hi[0..15]. */
inline float16 lookup32(const float16 lo, const float16 hi, const int16 i, const int w)
{
    return __builtin_shufflevector(lookup32_8(lo, hi, i.lo, w), lookup32_8(lo, hi, i.hi, w),
                                   LANES_LO, LANES_HI);
}
#endif
#ifdef PERMUTE_TIME
typedef struct {
    float16 t0lo, t0hi, t1lo, t1hi, t2lo, t2hi, t3lo, t3hi; /* channel c of tc[0..31] */
    float16 slo, shi;                                        /* steps[0..31], as bits */
} TimeTable;
/* Entries past w - 1 repeat the last: no lane reads beyond the tables, none looks them up. */
inline TimeTable time_table(__global const float4 *tc, __global const int *steps, const int w)
{
    const __global float *tcf = (const __global float *)tc;
    const int16 lane = (int16)(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);
    const int16 lo = min(lane, w - 1) * 4, hi = min(lane + 16, w - 1) * 4;
    TimeTable t;
    t.t0lo = GATHER(tcf, lo), t.t0hi = GATHER(tcf, hi);
    t.t1lo = GATHER(tcf, lo + 1), t.t1hi = GATHER(tcf, hi + 1);
    t.t2lo = GATHER(tcf, lo + 2), t.t2hi = GATHER(tcf, hi + 2);
    t.t3lo = GATHER(tcf, lo + 3), t.t3hi = GATHER(tcf, hi + 3);
    t.slo = as_float16(GATHER_INT(steps, lo / 4));
    t.shi = as_float16(GATHER_INT(steps, hi / 4));
    return t;
}
#define TIME_TABLE_LOAD const TimeTable tt_ = time_table(tc, steps, w);
#define TIME_AT(c, win) lookup32(tt_.t##c##lo, tt_.t##c##hi, (win), w)
#define STEP_AT(win) as_int16(lookup32(tt_.slo, tt_.shi, (win), w))
#else
#define TIME_TABLE_LOAD
#define TIME_AT(c, win) GATHER((const __global float *)tc, (win) * 4 + (c))
#define STEP_AT(win) GATHER_INT(steps, (win))
#endif

/* All four channels of the winner's time TF: tr, tg, tb, ta. Without register tables (a
 * per-vector kernel, or more than 32 steps), on AVX2 CPUs without AVX-512, each lane's tc[win]
 * is one 16-byte load and four lanes at a time are transposed by shuffles, where four gathers
 * take 64 loads and 64 inserts. */
#if VEC == 16 && !defined(PERMUTE_TIME) && defined(SHUFFLE_STORE) && defined(ISA_AVX2) && \
    !defined(ISA_AVX512)
typedef struct {
    float16 r, g, b, a;
} TimeRgba;
#define LOW_PAIRS(a, b) __builtin_shufflevector(a, b, 0, 4, 1, 5)
#define HIGH_PAIRS(a, b) __builtin_shufflevector(a, b, 2, 6, 3, 7)
#define LOW_HALVES(a, b) __builtin_shufflevector(a, b, 0, 1, 4, 5)
#define HIGH_HALVES(a, b) __builtin_shufflevector(a, b, 2, 3, 6, 7)
/* Channels r, g, b, a of four float4 as four float4 (one lane each). */
#define TRANSPOSE4(t0, t1, t2, t3, r, g, b, a)                           \
    const float4 r = LOW_HALVES(LOW_PAIRS(t0, t1), LOW_PAIRS(t2, t3));   \
    const float4 g = HIGH_HALVES(LOW_PAIRS(t0, t1), LOW_PAIRS(t2, t3));  \
    const float4 b = LOW_HALVES(HIGH_PAIRS(t0, t1), HIGH_PAIRS(t2, t3)); \
    const float4 a = HIGH_HALVES(HIGH_PAIRS(t0, t1), HIGH_PAIRS(t2, t3));
#define CAT16(a, b, c, d) CAT8(CAT4(a, b), CAT4(c, d))
inline TimeRgba time_rgba(__global const float4 *tc, const int16 i)
{
    TRANSPOSE4(tc[i.s0], tc[i.s1], tc[i.s2], tc[i.s3], r0, g0, b0, a0)
    TRANSPOSE4(tc[i.s4], tc[i.s5], tc[i.s6], tc[i.s7], r1, g1, b1, a1)
    TRANSPOSE4(tc[i.s8], tc[i.s9], tc[i.sa], tc[i.sb], r2, g2, b2, a2)
    TRANSPOSE4(tc[i.sc], tc[i.sd], tc[i.se], tc[i.sf], r3, g3, b3, a3)
    TimeRgba t;
    t.r = CAT16(r0, r1, r2, r3);
    t.g = CAT16(g0, g1, g2, g3);
    t.b = CAT16(b0, b1, b2, b3);
    t.a = CAT16(a0, a1, a2, a3);
    return t;
}
#define TIME_RGBA(win, tr, tg, tb, ta)        \
    const TimeRgba trgba_ = time_rgba(tc, (win)); \
    const floatv tr = trgba_.r, tg = trgba_.g, tb = trgba_.b, ta = trgba_.a;
#else
#define TIME_RGBA(win, tr, tg, tb, ta) \
    const floatv tr = TIME_AT(0, win), tg = TIME_AT(1, win), tb = TIME_AT(2, win), ta = TIME_AT(3, win);
#endif

/* The colour r, g, b and opacity ak of the step that won (max, min, change): the data TF at
 * `value`, the time TF of selection index `win` (lanes), and that step's enhancement. */
#ifdef CONST_COLOR
#define WINNER_COLOR(p, r, g, b) const floatv r = tr_, g = tg_, b = tb_;
#else
#define WINNER_COLOR(p, r, g, b)                       \
    const floatv r = LUT_CHANNEL(lut, 0, p) * tr_;     \
    const floatv g = LUT_CHANNEL(lut, 1, p) * tg_;     \
    const floatv b = LUT_CHANNEL(lut, 2, p) * tb_;
#endif
#if ENHANCE
#define WINNER_ENHANCE(win) \
    *enhance_factor(data, step_base, zstride, (win), x, y, zb, nx, ny, nzb, w, vmin, scale, enh, view)
#else
#define WINNER_ENHANCE(win)
#endif
#define WINNER_RGBA_AT(p, win, r, g, b, ak)                             \
    TIME_RGBA(win, tr_, tg_, tb_, ta_)                                  \
    WINNER_COLOR(p, r, g, b)                                            \
    floatv ak = VCLAMP(LUT_CHANNEL(lut, 3, p) * ta_ WINNER_ENHANCE(win), 0.0f, 1.0f);
#define WINNER_RGBA(value, win, r, g, b, ak) \
    const LutPos p = lut_pos_of(value);      \
    WINNER_RGBA_AT(p, win, r, g, b, ak)

/* A winning mode's winners (WINNERS: the host asked for them, its `won_u` and `won_k` outputs
 * given): each voxel's u and its winner's index into the window's steps, as the viewer's
 * recolouring takes them (chronocl/integration/interactive/winners.py), so that a first TF
 * edit gathers nothing (NO_WINNER: a voxel no step won). Without WINNERS the outputs are
 * null and nothing is stored. */
#define NO_WINNER 255
#ifdef WINNERS
#if VEC == 16
#define STORE_WINNERS(o, u, win)                    \
    vstore16((u), 0, won_u + (o));                  \
    vstore16(convert_uchar16(win), 0, won_k + (o));
#else
#define STORE_WINNERS(o, u, win) \
    won_u[(o)] = (u);            \
    won_k[(o)] = (uchar)(win);
#endif
#else
#define STORE_WINNERS(o, u, win)
#endif

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
