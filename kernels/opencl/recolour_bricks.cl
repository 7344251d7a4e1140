/* Recolouring brick by brick on the OpenCL device of the host
 * (chronocl/render/recolour/bricks.py, BrickRecolourer): per brick a summary of its winners,
 * then the bricks that may be coloured recoloured into RGBA8 (a winner's colour: recolour.h),
 * with their opacity peaks and occupied box. Built after recolour.h (no common.h) with K_T
 * (the step index type) and BRICK (the brick side, chronocl/render/brick_grid.py's). Each run
 * is over one z-span of whole rows of bricks as a volume of its own (nz its planes, brick
 * indices and box z from its first): a brick reads only its own voxels, so the host puts the
 * spans' results together as the whole volume's. */

#define B BRICK
// The voxel range of brick `b` (x fastest), clamped to the volume.
#define BRICK_RANGE(b)                                                                    \
    int bx = (b) % gx, by = ((b) / gx) % gy, bz = (b) / (gx * gy);                         \
    int x0 = bx * B, y0 = by * B, z0 = bz * B;                                             \
    int x1 = min(x0 + B, nx), y1 = min(y0 + B, ny), z1 = min(z0 + B, nz);

__kernel void summarise(__global const float *won_u, __global const K_T *won_k,
                        const uint none_k, const int nx, const int ny, const int nz,
                        const int gx, const int gy, __global float *umin,
                        __global float *umax, __global ulong *steps)
{
    int b = get_global_id(0);
    BRICK_RANGE(b)
    float lo = INFINITY, hi = -INFINITY;
    ulong mask = 0;
    for (int z = z0; z < z1; ++z)
        for (int y = y0; y < y1; ++y) {
            size_t row = ((size_t)z * ny + y) * nx;
            for (int x = x0; x < x1; ++x) {
                uint k = won_k[row + x];
                if (k == none_k) continue;
                float u = won_u[row + x];
                lo = fmin(lo, u);
                hi = fmax(hi, u);
                mask |= 1UL << min(k, 63u);
            }
        }
    umin[b] = lo;
    umax[b] = hi;
    steps[b] = mask;
}

// Per run of listed bricks (consecutive along x, `runs`: where each starts in `list`): their
// voxels recoloured, row by row along x, and what the grid and the occupied box need of each:
// in `peaks` (27 a brick) the largest opacity byte over each of its parts [cz][cy][cx], a
// class per axis (0: the low face's voxels, 1: all, 2: the high face's), in `box` the box of
// its voxels whose byte is > 0 (x, y, z lows, then highs; -1: none).
__kernel void recolour(__global const float *won_u, __global const K_T *won_k,
                       __global const float4 *lut, const int lut_size,
                       __global const float4 *table, const uint none_k,
                       __global uchar4 *out, __global const int *list,
                       __global const int *runs, const int nx, const int ny, const int nz,
                       const int gx, const int gy, __global uchar *peaks, __global int *box)
{
    int p0 = runs[get_global_id(0)], p1 = runs[get_global_id(0) + 1];
    BRICK_RANGE(list[p0])
    for (int p = p0; p < p1; ++p)
        for (int j = 0; j < 27; ++j) {
            peaks[27 * p + j] = 0;
            if (j < 6) box[6 * p + j] = j < 3 ? INT_MAX : -1;
        }
    for (int z = z0; z < z1; ++z)
        for (int y = y0; y < y1; ++y) {
            size_t row = ((size_t)z * ny + y) * nx;
            int xe = min(x0 + (p1 - p0) * B, nx);
            // the whole run's row in one loop (several times faster than brick by brick:
            // the compiler vectorises it), then its bricks' opacities from the cache
            for (int x = x0; x < xe; ++x) {
                size_t i = row + x;
                out[i] = rgba8(recoloured(won_u, i, won_k[i], none_k, lut, lut_size, table));
            }
            for (int p = p0; p < p1; ++p) {
                int xs = x0 + (p - p0) * B, xb = min(xs + B, nx);
                uint rowmax = 0, first = out[row + xs].w, last = out[row + xb - 1].w;
#ifdef __ENDIAN_LITTLE__
                // the largest uint32 has the largest opacity (its top byte): vector loads
                __global const uint *word = (__global const uint *)out + row;
                for (int x = xs; x < xb; ++x)
                    rowmax = max(rowmax, word[x]);
                rowmax >>= 24;
#else
                for (int x = xs; x < xb; ++x)
                    rowmax = max(rowmax, (uint)out[row + x].w);
#endif
                int lox = xb, hix = -1;
                for (int x = xs; rowmax > 0 && x < xb; ++x)
                    if (out[row + x].w > 0) {
                        lox = min(lox, x);
                        hix = x;
                    }
                // the row is in class 1 of y and z, and in 0 or 2 on a face
                uint part[3] = {first, rowmax, last};
                for (int cz = 0; cz < 3; ++cz) {
                    if ((cz == 0 && z != z0) || (cz == 2 && z != z1 - 1)) continue;
                    for (int cy = 0; cy < 3; ++cy) {
                        if ((cy == 0 && y != y0) || (cy == 2 && y != y1 - 1)) continue;
                        __global uchar *s = peaks + 27 * p + 9 * cz + 3 * cy;
                        for (int cx = 0; cx < 3; ++cx) s[cx] = max((uint)s[cx], part[cx]);
                    }
                }
                if (rowmax > 0) {
                    __global int *c = box + 6 * p;
                    c[0] = min(c[0], lox); c[3] = max(c[3], hix);
                    c[1] = min(c[1], y); c[4] = max(c[4], y);
                    c[2] = min(c[2], z); c[5] = max(c[5], z);
                }
            }
        }
}
