#version 430
// Recolour a chronovolume of max, min, first_hit or change without integrating again
// (chronocl/render/recolour/gl.py): each voxel keeps the value u that won it and the index k of
// the winning step; its premultiplied RGBA is the data TF at u (a LUT, linear between
// entries, as the OpenCL kernels evaluate it) times the time TF of step k (one texel per
// window step), written into the texture the raycaster samples. The same pass finds the
// occupied box (voxels whose stored opacity is > 0) and the brick grid of empty-space
// skipping (chronocl/render/brick_grid.py: per B^3 brick grown by a voxel, the largest
// stored opacity in 0..255; only whether it is 0 matters to the raycaster).
//
// One invocation per x-row and no barriers: llvmpipe runs barrier-free groups far faster,
// and a row needs one atomic per occupied brick it reaches, not one per voxel.

layout(local_size_x = 8, local_size_y = 1, local_size_z = 1) in;

uniform sampler3D won_u;        // R32F: the winning value
uniform usampler3D won_k;       // R8UI / R16UI: the winning step's index, none_k: none
uniform sampler2D data_lut;     // (lut_size, 1) RGBA32F
uniform sampler2D step_table;   // (W, 1) RGBA32F: rgb_t, a_t per window step
uniform int lut_size;
uniform uint none_k;
uniform ivec3 dims;             // voxels along x, y, z
uniform bool unorm8;            // the texture is RGBA8: opacity stored as round(a * 255)
uniform int brick;              // voxels along a brick's side
uniform ivec3 grid_dims;        // bricks along x, y, z

layout(OUT_FORMAT, binding = 0) writeonly uniform image3D rgba_out;
layout(std430, binding = 1) buffer Bounds { int lo[3]; int hi[3]; };
layout(std430, binding = 2) buffer Grid { uint grid[]; };

// The stored opacity in 0..255 as brick_grid.py reads it: RGBA8's byte (0 at a * 255 <= 0.5,
// as numpy's rint of the integrated path), float's ceil(a * 255).
uint stored(float a)
{
    if (unorm8) return a * 255.0 > 0.5 ? uint(a * 255.0 + 0.5) : 0u;
    return uint(ceil(a * 255.0));
}

// A value of x-brick bx to every brick the row (y, z) reaches: a row is in the grown range
// of its own brick and, on a brick's edge, of the neighbour's.
void flush(int bx, int y, int z, uint v)
{
    if (v == 0u) return;
    int by0 = (y % brick == 0 && y > 0) ? y / brick - 1 : y / brick;
    int by1 = min((y % brick == brick - 1) ? y / brick + 1 : y / brick, grid_dims.y - 1);
    int bz0 = (z % brick == 0 && z > 0) ? z / brick - 1 : z / brick;
    int bz1 = min((z % brick == brick - 1) ? z / brick + 1 : z / brick, grid_dims.z - 1);
    for (int bz = bz0; bz <= bz1; ++bz)
        for (int by = by0; by <= by1; ++by)
            atomicMax(grid[(bz * grid_dims.y + by) * grid_dims.x + bx], v);
}

void main()
{
    int y = int(gl_GlobalInvocationID.x), z = int(gl_GlobalInvocationID.y);
    if (y >= dims.y || z >= dims.z) return;
    int first = dims.x, last = -1;
    uint run = 0u;   // largest stored opacity of the current x-brick so far, its grown edge too
    uint prev = 0u;  // the previous voxel's
    for (int x = 0; x < dims.x; ++x) {
        ivec3 p = ivec3(x, y, z);
        uint k = texelFetch(won_k, p, 0).r;
        vec4 rgba = vec4(0.0);
        if (k != none_k) {
            float v = texelFetch(won_u, p, 0).r * float(lut_size - 1);
            int i0 = min(int(v), lut_size - 2);
            float f = v - float(i0);
            vec4 d = texelFetch(data_lut, ivec2(i0, 0), 0) * (1.0 - f)
                   + texelFetch(data_lut, ivec2(i0 + 1, 0), 0) * f;
            vec4 t = texelFetch(step_table, ivec2(int(k), 0), 0);
            float a = clamp(d.a * t.a, 0.0, 1.0);
            rgba = vec4(a * (d.rgb * t.rgb), a);
        }
        imageStore(rgba_out, p, rgba);
        uint q = stored(rgba.a);
        if (q > 0u) {
            first = min(first, x);
            last = x;
        }
        if (x > 0 && x % brick == 0) {  // x is the voxel after the last brick: flush it
            flush(x / brick - 1, y, z, max(run, q));
            run = prev;                  // and the voxel before the new one starts it
        }
        run = max(run, q);
        prev = q;
    }
    flush((dims.x - 1) / brick, y, z, run);
    if (last >= 0) {
        atomicMin(lo[0], first); atomicMax(hi[0], last);
        atomicMin(lo[1], y); atomicMax(hi[1], y);
        atomicMin(lo[2], z); atomicMax(hi[2], z);
    }
}
