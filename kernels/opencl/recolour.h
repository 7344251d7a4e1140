/* A winner's colour and its RGBA8, prepended to recolour_bricks.cl
 * (program.source(name, common="recolour.h")). */

/* The data TF's LUT at the winner's value u (lerped as lut_lerp32 does) times the time TF of its
 * step k, premultiplied, as kernels/glsl/recolour.comp computes it; zero where the voxel has no
 * winner (k == none_k, its u not read). */

inline float4 recoloured(__global const float *won_u, const size_t i, const uint k,
                         const uint none_k, __global const float4 *lut, const int lut_size,
                         __global const float4 *table)
{
    if (k == none_k) return (float4)(0.0f);
    float x = won_u[i] * (float)(lut_size - 1);
    int i0 = min((int)x, lut_size - 2);
    float f = x - (float)i0;
    float4 d = lut[i0] * (1.0f - f) + lut[i0 + 1] * f;
    float4 t = table[k];
    float a = clamp(d.w * t.w, 0.0f, 1.0f);
    return (float4)(a * (d.xyz * t.xyz), a);
}

/* RGBA8 of a colour: round(v * 255) to nearest even, clamped to 0..255, the display conversion's
 * rule and the bytes of common.h's TO_RGBA8 (convert_uchar4_sat_rte) for every float, NaN
 * included (tests/test_recolour.py). Clamped, then rounded by adding and taking away 2^23
 * (exact below it; separate statements, so no contraction), then truncated: PoCL's rte
 * conversion ran at half the speed of rint(), and rint() (which also handles signs and
 * magnitudes that cannot occur here) took 315 ms where this takes 219 (512^3, AVX2). */
inline uchar4 rgba8(const float4 rgba)
{
    float4 y = clamp(rgba * 255.0f, 0.0f, 255.0f);
    y = y + 8388608.0f;
    y = y - 8388608.0f;
    return convert_uchar4(y);
}
