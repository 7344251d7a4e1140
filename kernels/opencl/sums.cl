/* Fixed-point window sums of the modes that slide by inversion (additive, mean, count): a step
 * enters with sign +1 and leaves with sign -1, exactly. Built with SLIDING and CHANNELS, the
 * number of leading RGBA channels summed. */

/* acc (CHANNELS longs per voxel) += sign * fixed(the first CHANNELS channels of a raw partial). */
__kernel void fixed_add(__global const float4 *step, __global long *acc, const int sign)
{
    const size_t i = get_global_id(0);
    const float4 s = step[i];
    const float c[4] = {s.x, s.y, s.z, s.w};
    for (int j = 0; j < CHANNELS; ++j) {
        const long f = convert_long_rtz(c[j] * FIXED_ONE);
        acc[CHANNELS * i + j] += sign > 0 ? f : -f;
    }
}
