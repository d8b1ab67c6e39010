// The validator's lighting of a colour (inserted after common.glsl when the asset has colour
// states): the same key light, ambient and Blinn specular as shade(), on a given albedo in
// linear light (wrinklepipe.validate.render.shade_albedo is its numpy twin).
vec3 shade_albedo(vec3 n_obj, vec3 albedo) {
    const vec3 L = vec3(-0.3713907, 0.5570860, 0.7427813);  // normalize(-0.4, 0.6, 0.8)
    const vec3 V = vec3(0.0, 0.0, 1.0);
    float diffuse = max(dot(n_obj, L), 0.0);
    vec3 H = normalize(L + V);
    float spec = pow(max(dot(n_obj, H), 0.0), 48.0) * 0.25;
    return albedo * (0.12 + 0.88 * diffuse) + vec3(spec);
}
