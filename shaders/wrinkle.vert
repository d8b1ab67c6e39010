#version 330
// Shared vertex shader of the validator's render pass (wrinkle.frag and plain_normal.frag).
// Object space is world space; u_mvp is an orthographic front view fitted to the mesh.
in vec3 in_position;
in vec3 in_normal;
in vec4 in_tangent;  // xyz: tangent (MikkTSpace), w: handedness +-1
in vec2 in_uv;       // glTF convention: v = 0 at the top of the image

uniform mat4 u_mvp;

out vec3 v_normal;
out vec4 v_tangent;
out vec2 v_uv;

void main() {
    v_normal = in_normal;
    v_tangent = in_tangent;
    v_uv = in_uv;
    gl_Position = u_mvp * vec4(in_position, 1.0);
}
