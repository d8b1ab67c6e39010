"""Combine-function snippets shipped with an engine export (PD encoding)."""

from __future__ import annotations

HLSL = """// wrinklepipe: base normal + PD wrinkle states (encoding "pd", policy "{policy}").
// Inputs are the raw texture samples (values in [0, 1]); returns a unit tangent-space normal
// in this engine's convention ({convention}). SCALE = {scale}.
static const float SCALE = {scale};
// z is rebuilt from x, y, so a two-channel (BC5) base works too.
float3 WrinkleNormal(float2 baseSample, float2 stateSamples[{k}], float activation[{k}])
{{
    float2 bxy = baseSample * 2.0 - 1.0;
    float bz = sqrt(saturate(1.0 - dot(bxy, bxy)));
    float2 d = bxy / max(bz, 1e-6);
    [unroll] for (int k = 0; k < {k}; ++k)
        d += activation[k] * (stateSamples[k] * (2.0 * SCALE) - SCALE);
    return normalize(float3(d, 1.0));
}}
"""

GLSL = """// wrinklepipe: base normal + PD wrinkle states (encoding "pd", policy "{policy}").
// Inputs are raw texture samples in [0, 1]; returns a unit tangent-space normal (+Y).
const float SCALE = {scale};
vec3 wrinkle_normal(vec2 base_sample, vec2 state_samples[{k}], float activation[{k}]) {{
    vec2 bxy = base_sample * 2.0 - 1.0;
    float bz = sqrt(clamp(1.0 - dot(bxy, bxy), 0.0, 1.0));
    vec2 d = bxy / max(bz, 1e-6);
    for (int k = 0; k < {k}; ++k)
        d += activation[k] * (state_samples[k] * (2.0 * SCALE) - SCALE);
    return normalize(vec3(d, 1.0));
}}
"""
