/* RGBA8, the display format (chronocl/render/upload.py's "f1"): round(v * 255) to nearest even,
 * clamped to 0..255, the host conversion's rule, written by one rule for every kernel: the
 * integrate kernels' final store (common.h's STORE_RGBA) and the recolouring (recolour.h). The
 * program builder puts it after either header, before the kernel file (chronocl/engine/program.py
 * `source`).
 *
 * Clamped, then rounded by adding and taking away 2^23 (exact below it; separate statements, so
 * no contraction), then truncated. It gives the bytes of convert_uchar*_sat_rte for every float,
 * NaN included (clamp's fmax takes NaN to 0; tests/test_recolour.py), and PoCL's rte conversion
 * ran at half its speed: recolouring 512^3 took 315 ms with rint() and 219 with this (AVX2). */

inline uchar4 rgba8(const float4 v)
{
    float4 y = clamp(v * 255.0f, 0.0f, 255.0f);
    y = y + 8388608.0f;
    y = y - 8388608.0f;
    return convert_uchar4(y);
}

/* The combine kernels' colour output (built SLIDING): float32, or, built OUT8, RGBA8 by the rule
 * above, for a sliding window's last combine, its value shown as it is (the partials its stacks
 * keep stay float32; chronocl/integration/interactive/slider.py `Combine.last`). */
#ifdef OUT8
typedef uchar4 colour_t;
#define COLOUR(v) rgba8(v)
#else
typedef float4 colour_t;
#define COLOUR(v) (v)
#endif

/* Sixteen lanes of one channel at once: the store of the integrate kernels built RGBA8 at VEC 16
 * (after common.h, whose pragma keeps PoCL's -Wpsabi note on 16-lane calls quiet). */
#if defined(RGBA8) && VEC == 16
inline uchar16 bytes16(const float16 v)
{
    float16 y = clamp(v * 255.0f, 0.0f, 255.0f);
    y = y + 8388608.0f;
    y = y - 8388608.0f;
    return convert_uchar16(y);
}
#endif
