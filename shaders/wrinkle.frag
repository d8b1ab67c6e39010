#version 330
// The wrinkle model of wrinklepipe/model.py for every encoding and policy (DESIGN.md section 1):
//   s_k = sum_r M_r w_{r,k}     masks packed four to a layer: s += W_layer * mask_layer
//   a_k = policy(s_k)
//   N   = combine(B, {W_k, a_k}, encoding)
// Specialised at compile time (as engines do with material permutations): the renderer
// prepends #defines for ENCODING, POLICY, NUM_STATES (1..8), NUM_LAYERS (1..16) and
// BASE_LAYOUT / STATE_LAYOUT (WP_LAYOUT_RGB, _RG, _AG of the codec), STATE_BITS (8, 16, 0 for
// float) and MAPPING_VERSION (the asset's value mapping), BASE_FLIP_Y / STATE_FLIP_Y (maps
// declared DirectX), LR_SPLIT / SPLIT_LAYER / SPLIT_CHANNEL (lr-split masks). Stored values are
// decoded by the codec's generated functions (wrinklepipe.codec.shaders).
// Outputs: 0 shaded colour, 1 tangent-space normal (w = 1 where covered), 2 UV (z = sum |a_k|).
#define ENC_PD 0
#define ENC_DIFF 1
#define ENC_FULL 2
#define ENC_COMPOSITE 3
#define POL_CLAMP01 0
#define POL_SIGNED 1
#define POL_ADDITIVE 2
#define POL_RENORMALIZE 3
#define POL_LERP 4
#ifndef ENCODING
#define ENCODING ENC_PD
#endif
#ifndef POLICY
#define POLICY POL_CLAMP01
#endif
#ifndef NUM_STATES
#define NUM_STATES 2
#endif
#ifndef NUM_LAYERS
#define NUM_LAYERS 2
#endif
#ifndef BASE_LAYOUT
#define BASE_LAYOUT 1
#endif
#ifndef STATE_LAYOUT
#define STATE_LAYOUT 1
#endif
#ifndef STATE_BITS
#define STATE_BITS 8
#endif
#ifndef MAPPING_VERSION
#define MAPPING_VERSION 1
#endif
#ifndef BASE_FLIP_Y
#define BASE_FLIP_Y 0
#endif
#ifndef STATE_FLIP_Y
#define STATE_FLIP_Y 0
#endif
#ifndef LR_SPLIT
#define LR_SPLIT 0
#endif
#ifndef SPLIT_LAYER
#define SPLIT_LAYER 0
#endif
#ifndef SPLIT_CHANNEL
#define SPLIT_CHANNEL 3
#endif
#define MAX_LAYERS 16

//#include common.glsl

in vec3 v_normal;
in vec4 v_tangent;
in vec2 v_uv;

uniform sampler2D u_base;
uniform sampler2DArray u_states;
uniform sampler2DArray u_masks;
uniform float u_pd_scale;  // pd: slope range of the stored values; diff: gain
uniform mat4 u_wlo[MAX_LAYERS];  // weights of states 0..3: column c = mask channel c
uniform mat4 u_whi[MAX_LAYERS];  // weights of states 4..7
uniform vec4 u_used[MAX_LAYERS];  // 1 for channels that hold a region (renormalize)
#if LR_SPLIT
// lr-split layout (2009 blog): a left/right pair shares a channel c; the split channel s is 1 on
// the character's left, so M_left = c * s, M_right = c * (1 - s). Centre regions use u_wlo.
uniform mat4 u_wlo_l[MAX_LAYERS];
uniform mat4 u_whi_l[MAX_LAYERS];
uniform mat4 u_wlo_r[MAX_LAYERS];
uniform mat4 u_whi_r[MAX_LAYERS];
uniform vec4 u_used_l[MAX_LAYERS];
uniform vec4 u_used_r[MAX_LAYERS];
#endif

layout(location = 0) out vec4 out_color;
layout(location = 1) out vec4 out_normal;
layout(location = 2) out vec4 out_uv;

void main() {
    vec4 s_lo = vec4(0.0);
    vec4 s_hi = vec4(0.0);
    float total = 0.0;
#if LR_SPLIT
    float sp = textureLod(u_masks, vec3(v_uv, float(SPLIT_LAYER)), 0.0)[SPLIT_CHANNEL];
#endif
    for (int l = 0; l < NUM_LAYERS; ++l) {
        vec4 m = textureLod(u_masks, vec3(v_uv, float(l)), 0.0);
        total += dot(m, u_used[l]);
        s_lo += u_wlo[l] * m;
#if NUM_STATES > 4
        s_hi += u_whi[l] * m;
#endif
#if LR_SPLIT
        total += sp * dot(m, u_used_l[l]) + (1.0 - sp) * dot(m, u_used_r[l]);
        s_lo += sp * (u_wlo_l[l] * m) + (1.0 - sp) * (u_wlo_r[l] * m);
#if NUM_STATES > 4
        s_hi += sp * (u_whi_l[l] * m) + (1.0 - sp) * (u_whi_r[l] * m);
#endif
#endif
    }
    vec4 a_lo;
    vec4 a_hi;
#if POLICY == POL_SIGNED
    float sig = clamp(s_lo.x, -1.0, 1.0);
    a_lo = vec4(max(-sig, 0.0), max(sig, 0.0), 0.0, 0.0);
    a_hi = vec4(0.0);
#elif POLICY == POL_ADDITIVE
    a_lo = s_lo;
    a_hi = s_hi;
#else
#if POLICY == POL_RENORMALIZE
    float div = max(total, 1.0);
#else
    float div = 1.0;
#endif
    a_lo = clamp(s_lo / div, 0.0, 1.0);
    a_hi = clamp(s_hi / div, 0.0, 1.0);
#if POLICY == POL_LERP
    float lsum = dot(a_lo, vec4(1.0)) + dot(a_hi, vec4(1.0));
    if (lsum > 1.0) {
        a_lo /= lsum;
        a_hi /= lsum;
    }
#endif
#endif

    vec3 B = wp_normal(textureLod(u_base, v_uv, 0.0), BASE_LAYOUT);
#if BASE_FLIP_Y
    B.y = -B.y;  // declared DirectX (+Y down): read as +Y
#endif
#if ENCODING == ENC_PD
    vec2 d = B.xy / max(B.z, 1e-12);
#elif ENCODING == ENC_COMPOSITE
    vec2 xy = B.xy;
    float z = B.z;
#else
    vec3 acc = B;
#endif
    for (int k = 0; k < NUM_STATES; ++k) {
        float ak = k < 4 ? a_lo[k] : a_hi[k - 4];
        if (ak == 0.0) continue;  // a GPU skips the fetch for a whole wave; exact (a = 0 adds 0)
        vec4 c = textureLod(u_states, vec3(v_uv, float(k)), 0.0);
#if STATE_FLIP_Y
        const vec3 fy = vec3(1.0, -1.0, 1.0);  // declared DirectX: y flips after decoding
#else
        const vec3 fy = vec3(1.0);
#endif
#if ENCODING == ENC_PD
        d += ak * fy.xy * wp_pd(c, STATE_LAYOUT, MAPPING_VERSION, STATE_BITS, u_pd_scale);
#elif ENCODING == ENC_DIFF
        // u_pd_scale is the diff gain
        acc += ak * fy * wp_diff_rgb(c, MAPPING_VERSION, STATE_BITS, u_pd_scale);
#elif ENCODING == ENC_FULL
        acc += ak * (fy * wp_normal(c, STATE_LAYOUT) - B);
#else
        vec3 W = fy * wp_normal(c, STATE_LAYOUT);
        xy += ak * W.xy;
        z *= 1.0 + ak * (W.z - 1.0);
#endif
    }
#if ENCODING == ENC_PD
    vec3 N = normalize(vec3(d, 1.0));
#elif ENCODING == ENC_COMPOSITE
    vec3 N = normalize(vec3(xy, z));
#else
    vec3 N = normalize(acc);
#endif
    out_color = vec4(shade(to_object(N, v_normal, v_tangent)), 1.0);
    out_normal = vec4(N, 1.0);
    out_uv = vec4(v_uv, dot(abs(a_lo), vec4(1.0)) + dot(abs(a_hi), vec4(1.0)), 1.0);
}
