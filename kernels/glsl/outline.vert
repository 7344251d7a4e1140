#version 330
// The volume box's edges, drawn as lines over the rendered image.
uniform mat4 view_proj;
in vec3 position;

void main()
{
    gl_Position = view_proj * vec4(position, 1.0);
}
