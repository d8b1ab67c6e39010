#version 330
// A plain normal-mapped surface: the baseline the wrinkle shader's cost is measured against.
//#include common.glsl

in vec3 v_normal;
in vec4 v_tangent;
in vec2 v_uv;

uniform sampler2D u_base;
#ifndef BASE_LAYOUT
#define BASE_LAYOUT 1
#endif
#ifndef BASE_FLIP_Y
#define BASE_FLIP_Y 0
#endif

layout(location = 0) out vec4 out_color;
layout(location = 1) out vec4 out_normal;
layout(location = 2) out vec4 out_uv;

void main() {
    vec3 N = wp_normal(textureLod(u_base, v_uv, 0.0), BASE_LAYOUT);
#if BASE_FLIP_Y
    N.y = -N.y;  // declared DirectX (+Y down): read as +Y
#endif
    out_color = vec4(shade(to_object(N, v_normal, v_tangent)), 1.0);
    out_normal = vec4(N, 1.0);
    out_uv = vec4(v_uv, 0.0, 1.0);
}
