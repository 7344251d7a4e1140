#version 330
// Raycast a chronovolume: premultiplied RGBA in a 3D texture, composited front to back.
//
// Rays come from unprojecting the fragment at the near and far planes (orthographic or
// perspective alike) and are clipped to the volume box and, optionally, to a slicing plane.
// Samples are taken every `step_world` along the ray; a sample's opacity, defined for a
// path of `unit_world` (one voxel), is corrected for the step: a' = 1 - (1 - a)^(step/unit),
// and its premultiplied colour scaled alike. Early termination once A > 1 - 1/512 (less than
// half an 8-bit step can still be added).
//
// With `skip_empty`, rays jump across the empty bricks of a brick grid (max opacity per B^3
// brick, grown by a voxel: chronocl/render/brick_grid.py) onto the same sample phase, so the
// picture equals the unskipped one. With COUNT_SAMPLES defined (bench/render_skip.py, the
// tests) the output is (samples taken, brick grid reads) per ray, for a float framebuffer.
//
// With SHADING defined (the raycaster prepends it; chronocl/render/shading.py), each sample's
// colour is lit before compositing: Blinn-Phong with a headlight, the normal being the
// negated opacity gradient by central differences one voxel apart. Without it this is the
// unshaded shader, unchanged.

uniform sampler3D volume;
uniform mat4 inv_view_proj;   // clip space -> world
uniform vec3 box_min;         // world-space corners of the volume box (texture mapping)
uniform vec3 box_max;
uniform vec3 hit_min;         // corners of the occupied part (opacity > 0, grown by a voxel):
uniform vec3 hit_max;         // rays only march there
uniform float step_world;     // sampling distance along the ray
uniform float unit_world;     // the length an opacity value refers to (one voxel)
uniform int max_steps;
uniform bool jitter;          // offset each ray's first sample by a per-pixel random fraction
uniform bool clip_enabled;
uniform vec4 clip_plane;      // world-space plane n.x + d; the side where it is >= 0 is kept
uniform vec3 background;
uniform bool skip_empty;      // jump across empty bricks of the brick grid
uniform sampler3D bricks;     // the brick grid: max opacity per brick (R8, texelFetch)
uniform float brick_voxels;   // voxels along a brick's side
uniform ivec3 brick_count;    // bricks along x, y, z
#ifdef SHADING
uniform vec3 texel;           // one voxel in texture coordinates (1 / size per axis)
uniform vec3 grad_scale;      // texture differences -> opacity change per unit_world length
uniform float ambient;
uniform float diffuse;
uniform float specular;
uniform float shininess;
#endif

in vec2 ndc;
out vec4 frag_color;

#ifdef SHADING
// The sample's premultiplied colour lit from the eye (light and view both along -dir).
// Where the opacity is nearly constant the normal is noise: blend back to the flat colour.
vec3 shade(vec3 tex, vec4 s, vec3 dir)
{
    vec3 dx = vec3(texel.x, 0.0, 0.0);
    vec3 dy = vec3(0.0, texel.y, 0.0);
    vec3 dz = vec3(0.0, 0.0, texel.z);
    vec3 g = vec3(
        texture(volume, tex + dx).a - texture(volume, tex - dx).a,
        texture(volume, tex + dy).a - texture(volume, tex - dy).a,
        texture(volume, tex + dz).a - texture(volume, tex - dz).a) * grad_scale;
    float len = length(g);
    float weight = smoothstep(0.002, 0.02, len);
    if (weight <= 0.0) return s.rgb;
    vec3 n = -g / len;
    float nl = abs(dot(n, -dir));   // two-sided: inner walls of a shell are lit too
    vec3 lit = s.rgb * (ambient + diffuse * nl) + vec3(specular * pow(nl, shininess) * s.a);
    return mix(s.rgb, min(lit, vec3(s.a)), weight);
}
#endif

float hash(vec2 p)
{
    return fract(sin(dot(p, vec2(12.9898, 78.233))) * 43758.5453);
}

void main()
{
    vec4 near = inv_view_proj * vec4(ndc, -1.0, 1.0);
    vec4 far = inv_view_proj * vec4(ndc, 1.0, 1.0);
    vec3 origin = near.xyz / near.w;
    vec3 dir = normalize(far.xyz / far.w - origin);

    // Slab test against the occupied box.
    vec3 inv = 1.0 / dir;
    vec3 t0 = (hit_min - origin) * inv;
    vec3 t1 = (hit_max - origin) * inv;
    vec3 tmin = min(t0, t1);
    vec3 tmax = max(t0, t1);
    float t_enter = max(max(tmin.x, tmin.y), max(tmin.z, 0.0));
    float t_exit = min(min(tmax.x, tmax.y), tmax.z);

    if (clip_enabled) {
        float denom = dot(clip_plane.xyz, dir);
        float side = dot(clip_plane.xyz, origin) + clip_plane.w;
        if (abs(denom) < 1e-12) {
            if (side < 0.0) t_exit = -1.0;
        } else {
            float t_plane = -side / denom;
            if (denom > 0.0) t_enter = max(t_enter, t_plane);
            else t_exit = min(t_exit, t_plane);
        }
    }

    vec4 acc = vec4(0.0);
#ifdef COUNT_SAMPLES
    float samples = 0.0;   // volume samples taken
    float lookups = 0.0;   // brick grid reads
#endif
    if (t_exit > t_enter) {
        float offset = jitter ? hash(gl_FragCoord.xy) : 0.5;
        float ratio = step_world / unit_world;
        vec3 size = box_max - box_min;
        float t_first = t_enter + offset * step_world;
        // Sample k sits at t_first + k * step_world whether bricks are skipped or not, so a
        // skip lands on the same samples the unskipped loop takes (the same picture).
        vec3 dims = vec3(textureSize(volume, 0));
        vec3 vdir = dir / size * dims;           // voxels per unit of t
        ivec3 last_brick = ivec3(-1);
        bool brick_empty = false;
        int hops = brick_count.x + brick_count.y + brick_count.z + 3;  // bricks a ray can cross
        int k = 0;
        for (int i = 0; i < max_steps; ++i) {
            float t = t_first + float(k) * step_world;
            if (k >= max_steps || t >= t_exit) break;
            vec3 tex = (origin + t * dir - box_min) / size;
            if (skip_empty) {
                // Empty-space skipping: a brick whose grid value is 0 holds no sample with
                // opacity > 0 (chronocl/render/brick_grid.py); jump to the first sample past
                // its exit (slab test in voxel units), brick after brick, then take one
                // sample: every pass of the outer loop samples once, so neighbouring rays
                // (which the GPU or llvmpipe runs in lockstep) stay in step.
                bool done = false;
                for (int j = 0; j < hops; ++j) {
                    vec3 p = tex * dims;
                    ivec3 b = clamp(ivec3(floor(p / brick_voxels)), ivec3(0), brick_count - 1);
                    if (b != last_brick) {
                        last_brick = b;
                        brick_empty = texelFetch(bricks, b, 0).r == 0.0;
#ifdef COUNT_SAMPLES
                        lookups += 1.0;
#endif
                    }
                    if (!brick_empty) break;
                    vec3 bound = (vec3(b) + step(0.0, vdir)) * brick_voxels;
                    vec3 dt = mix(vec3(1e30), (bound - p) / vdir, notEqual(vdir, vec3(0.0)));
                    float t_out = t + min(min(dt.x, dt.y), dt.z);
                    k = max(k + 1, int(ceil((t_out - t_first) / step_world)));
                    t = t_first + float(k) * step_world;
                    if (k >= max_steps || t >= t_exit) {
                        done = true;
                        break;
                    }
                    tex = (origin + t * dir - box_min) / size;
                }
                if (done) break;
            }
#ifdef COUNT_SAMPLES
            samples += 1.0;
#endif
            vec4 s = texture(volume, tex);
            if (s.a > 0.0) {
#ifdef SHADING
                s.rgb = shade(tex, s, dir);
#endif
                float a = 1.0 - pow(max(1.0 - s.a, 0.0), ratio);
                acc.rgb += (1.0 - acc.a) * s.rgb * (a / s.a);
                acc.a += (1.0 - acc.a) * a;
                if (acc.a > 1.0 - 1.0 / 512.0) break;
            }
            ++k;
        }
    }
#ifdef COUNT_SAMPLES
    frag_color = vec4(samples, lookups, 0.0, 1.0);
#else
    frag_color = vec4(acc.rgb + (1.0 - acc.a) * background, 1.0);
#endif
}
