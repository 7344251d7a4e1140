/* A winner's colour, prepended to recolour_bricks.cl (program.source(name, common="recolour.h"),
 * followed by rgba8.h, whose rgba8() writes it). */

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
