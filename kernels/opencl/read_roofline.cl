/* The read roofline of the benchmark: read every element of the brick once and sum it, a
 * work-item per VEC voxels along x summing over the w steps, as the integration kernels read. */
__kernel void read_sum(__global const DATA_T *data, const int nx, const int ny, const int w,
                       __global float *out)
{
    const int x = VEC * (int)get_global_id(0);
    const int y = get_global_id(1);
    const int z = get_global_id(2);
    const int zb = z;
    floatv acc = 0.0f;
    for (int k = 0; k < w; ++k) acc += TO_FLOAT(RAW(k));
#if VEC == 16
    vstore16(acc, 0, out + OUT_INDEX(z, y, x));
#else
    out[OUT_INDEX(z, y, x)] = acc;
#endif
}
