/* Recolouring a window's winners on the OpenCL device of the host
 * (chronocl/render/recolour_host.py, HostRecolour): per voxel its winner's colour
 * (recolour.h), into float4 or, with RGBA8, uchar4 rounded to nearest even: the GPU path's
 * arithmetic (kernels/glsl/recolour.comp).
 * Built after recolour.h (no common.h) with K_T (the step index type), OUT_T, RUN (voxels per
 * work-item) and RGBA8. */

__kernel void recolour(__global const float *won_u, __global const K_T *won_k,
                       __global const float4 *lut, const int lut_size,
                       __global const float4 *table, const uint none_k,
                       __global OUT_T *out, const ulong n)
{
    // a run of RUN voxels per work-item: PoCL's per-item cost and the LUT gathers (which
    // keep it from vectorising across items) would otherwise dominate
    size_t start = get_global_id(0) * RUN;
    size_t end = min(start + RUN, (size_t)n);
    for (size_t i = start; i < end; ++i) {
        float4 rgba = recoloured(won_u, i, won_k[i], none_k, lut, lut_size, table);
#ifdef RGBA8
        out[i] = convert_uchar4_sat_rte(rgba * 255.0f);
#else
        out[i] = rgba;
#endif
    }
}
