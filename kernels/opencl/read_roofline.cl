/* The read roofline of the benchmark: read every element of the brick once and sum it,
 * one work-item per (x, y, z) summing over the w steps, as the integration kernels read. */
__kernel void read_sum(__global const DATA_T *data, const int nx, const int ny, const int w,
                       __global float *out)
{
    const int x = get_global_id(0);
    const int y = get_global_id(1);
    const int z = get_global_id(2);
    if (x >= nx || y >= ny) return;
    float acc = 0.0f;
    for (int k = 0; k < w; ++k) acc += (float)VOX(z, k, y, x);
    out[OUT_INDEX(z, y, x)] = acc;
}
