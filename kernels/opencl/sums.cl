/* Fixed-point window sums of the modes that slide by inversion (additive, mean, count): a step
 * enters with sign +1 and leaves with sign -1, exactly. Built with SLIDING and CHANNELS, the
 * number of leading RGBA channels summed. */

/* acc (CHANNELS longs per voxel) += sign * fixed(the first CHANNELS channels of a raw partial). */
__kernel void fixed_add(__global const float4 *step, __global long *acc, const int sign,
                        ELEMENT_ARGS)
{
    ELEMENT(i);
    const float4 s = step[i];
    const float c[4] = {s.x, s.y, s.z, s.w};
    for (int j = 0; j < CHANNELS; ++j) {
        const long f = convert_long_rtz(c[j] * FIXED_ONE);
        acc[CHANNELS * i + j] += sign > 0 ? f : -f;
    }
}

/* The opacity of a raw partial alone: what an inverting mode that aggregates it (additive's
 * largest opacity) slides, taken on the device. */
__kernel void alpha_of(__global const float4 *step, __global float *alpha)
{
    const size_t i = get_global_id(0);
    alpha[i] = step[i].w;
}

/* The largest of n sums, in two passes: work-item g keeps the largest of elements g, g + G, ...
 * (G work-items), and the host takes the largest of those G (additive's normalisation). */
__kernel void max_sums(__global const long *acc, const long n, __global long *out)
{
    const size_t g = get_global_id(0), stride = get_global_size(0);
    long m = LONG_MIN;
    for (size_t i = g; i < (size_t)n; i += stride)
        m = max(m, acc[i]);
    out[g] = m;
}
