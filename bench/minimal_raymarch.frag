#version 330
// The benchmark's baseline: a minimal raymarcher (fixed step of one voxel, front-to-back,
// no opacity correction, no early termination, no jitter, no clip plane).
uniform sampler3D volume;
uniform mat4 inv_view_proj;
uniform vec3 box_min;
uniform vec3 box_max;
uniform float step_world;
uniform int max_steps;
in vec2 ndc;
out vec4 frag_color;

void main()
{
    vec4 near = inv_view_proj * vec4(ndc, -1.0, 1.0);
    vec4 far = inv_view_proj * vec4(ndc, 1.0, 1.0);
    vec3 origin = near.xyz / near.w;
    vec3 dir = normalize(far.xyz / far.w - origin);
    vec3 t0 = (box_min - origin) / dir;
    vec3 t1 = (box_max - origin) / dir;
    vec3 tmin = min(t0, t1);
    vec3 tmax = max(t0, t1);
    float t_enter = max(max(tmin.x, tmin.y), max(tmin.z, 0.0));
    float t_exit = min(min(tmax.x, tmax.y), tmax.z);
    vec4 acc = vec4(0.0);
    for (int i = 0; i < max_steps; ++i) {
        float t = t_enter + (float(i) + 0.5) * step_world;
        if (t >= t_exit) break;
        vec4 s = texture(volume, (origin + t * dir - box_min) / (box_max - box_min));
        acc += (1.0 - acc.a) * s;
    }
    frag_color = acc;
}
