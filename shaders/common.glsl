// Shared by the validator's fragment shaders (wrinklepipe.shading.glsl), inserted after the
// codec's generated decode functions (wrinklepipe.codec.shaders.decode_source("glsl")).

// Tangent space -> object space with the mesh's tangent frame (bitangent = cross(N, T) * w).
vec3 to_object(vec3 n_ts, vec3 normal, vec4 tangent) {
    vec3 N = normalize(normal);
    vec3 T = tangent.xyz - N * dot(N, tangent.xyz);
    float tl = length(T);
    T = tl > 1e-12 ? T / tl : vec3(1.0, 0.0, 0.0);
    vec3 B = cross(N, T) * (tangent.w < 0.0 ? -1.0 : 1.0);
    return normalize(T * n_ts.x + B * n_ts.y + N * n_ts.z);
}

// A simple fixed light: key light from the upper left front, a little ambient, Blinn specular.
vec3 shade(vec3 n_obj) {
    const vec3 L = vec3(-0.3713907, 0.5570860, 0.7427813);  // normalize(-0.4, 0.6, 0.8)
    const vec3 V = vec3(0.0, 0.0, 1.0);
    const vec3 albedo = vec3(0.80, 0.62, 0.52);
    float diffuse = max(dot(n_obj, L), 0.0);
    vec3 H = normalize(L + V);
    float spec = pow(max(dot(n_obj, H), 0.0), 48.0) * 0.25;
    return albedo * (0.12 + 0.88 * diffuse) + vec3(spec);
}
