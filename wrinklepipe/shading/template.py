"""The wrinkle model as shader text: one template, emitted as GLSL, HLSL or Godot shading language.

The core is a block of statements (so it can sit inside an Unreal Custom node, which allows no
function definitions) written in the common subset of GLSL, HLSL and Godot's shading language;
:func:`emit` translates the few spellings that differ (``vec4`` / ``float4``, ``mix`` / ``lerp``).
It is specialised at compile time by ``#define`` (:func:`defines`, as engines do with material
permutations) and reads everything through hooks the target defines:

``WP_BASE()``      the base normal texel (vec4, stored values in [0, 1])
``WP_STATE(k)``    the texel of wrinkle state ``k`` (only fetched where its activation is not 0)
``WP_MASK(l)``     the texel of mask texture ``l`` (vec4; single-channel textures in ``.r``)
``WP_W(i)``        weight vector ``i`` of the flat weight array (:mod:`wrinklepipe.shading.setup`)
``WP_USED(g)``     lanes of mask group ``g`` that hold a region (``renormalize`` only)
``WP_REGION_COLOR(i)``  optional: the colour of group lane ``i`` (a region overlay, ``wp_regions``)
``WP_COLOR_BASE()``  with colour states: the base colour in linear light (vec3; an sRGB sampler
                   decodes, the target applies its factor)
``WP_COLOR(c)``    with colour states: colour map ``c`` in linear light (vec3), only fetched where
                   its state is active; ``WP_COLOR_STATE(c)`` (a define) is its state
``WP_DECODE_*``    texel decoding: the codec's generated functions
                   (:func:`wrinklepipe.codec.shaders.decode_source`: ``wp_normal``, ``wp_pd``,
                   ``wp_diff_rgb``), so a layout or value mapping cannot differ from the writer's

It leaves ``wp_n`` (the unit tangent-space normal, in the output's green convention) and
``wp_activity`` (``sum_k |a_k|``) in scope, and with colour states (``core(color=True)``)
``wp_color``: ``clamp(C_B + sum_k a_k (C_k - C_B), 0, 1)`` in linear light, the base colour
itself where no colour state is active (:func:`wrinklepipe.model.combine_color`). The maths is
:mod:`wrinklepipe.model`'s, line for line:

``s_k = sum_r M_r w_{r,k}``, ``a_k = policy(s_k)``, ``N = combine(B, {W_k, a_k}, encoding)``,
with the base returned unchanged where no state is active.
"""

from __future__ import annotations

import re

from wrinklepipe.codec.layouts import LAYOUT_IDS
from wrinklepipe.codec.shaders import decode_source
from wrinklepipe.shading.setup import GATHERS, ShaderSetup

LANGS: tuple[str, ...] = ("glsl", "hlsl", "gdshader")

ENCODING_IDS = {"pd": 0, "diff": 1, "full": 2, "composite": 3}
POLICY_IDS = {"clamp01": 0, "signed": 1, "additive": 2, "renormalize": 3, "lerp": 4}

CONSTANTS = """\
#define WP_ENC_PD 0
#define WP_ENC_DIFF 1
#define WP_ENC_FULL 2
#define WP_ENC_COMPOSITE 3
#define WP_POL_CLAMP01 0
#define WP_POL_SIGNED 1
#define WP_POL_ADDITIVE 2
#define WP_POL_RENORMALIZE 3
#define WP_POL_LERP 4
#define WP_GATHER_CHANNELS 0
#define WP_GATHER_LAYERS 1
#define WP_GATHER_SPLIT 2
"""

#: Hooks onto the decode functions (a target may route them elsewhere, e.g. a struct's methods).
DECODE_HOOKS = """\
// A map in the other green convention than the output has its decoded y negated (every
// encoding is symmetric under y -> -y, so this is exact whatever the value mapping).
#if WP_FLIP_BASE
#define WP_FLIP_B vec3(1.0, -1.0, 1.0)
#else
#define WP_FLIP_B vec3(1.0, 1.0, 1.0)
#endif
#if WP_FLIP_STATES
#define WP_FLIP_S vec3(1.0, -1.0, 1.0)
#else
#define WP_FLIP_S vec3(1.0, 1.0, 1.0)
#endif
#ifndef WP_DECODE_BASE
#define WP_DECODE_BASE(t) (wp_normal(t, WP_BASE_LAYOUT) * WP_FLIP_B)
#endif
#ifndef WP_DECODE_STATE_NORMAL
#define WP_DECODE_STATE_NORMAL(t) (wp_normal(t, WP_STATE_LAYOUT) * WP_FLIP_S)
#endif
#ifndef WP_DECODE_PD
#define WP_DECODE_PD(t) (wp_pd(t, WP_STATE_LAYOUT, WP_MAPPING, WP_STATE_BITS, WP_SCALE) * WP_FLIP_S.xy)
#endif
#ifndef WP_DECODE_DIFF
#define WP_DECODE_DIFF(t) (wp_diff_rgb(t, WP_MAPPING, WP_STATE_BITS, WP_SCALE) * WP_FLIP_S)
#endif
"""  # noqa: E501

CORE = """\
// wrinklepipe core: s_k = sum_r M_r w_rk; a_k = policy(s_k); N = combine(B, {W_k, a_k}).
vec3 wp_n;
float wp_activity;
vec3 wp_regions = vec3(0.0, 0.0, 0.0);  // sum_r M_r colour_r where WP_REGION_COLOR is defined
{
    vec4 wp_s[4];
    wp_s[0] = vec4(0.0, 0.0, 0.0, 0.0);
    wp_s[1] = wp_s[0];
    wp_s[2] = wp_s[0];
    wp_s[3] = wp_s[0];
    float wp_total = 0.0;
#if WP_GATHER == WP_GATHER_SPLIT
    float wp_sp = WP_MASK(WP_SPLIT_LAYER)[WP_SPLIT_CHANNEL];
#endif
    WP_LOOP for (int wp_g = 0; wp_g < WP_NUM_GROUPS; ++wp_g) {
#if WP_GATHER == WP_GATHER_LAYERS
        int wp_l = 4 * wp_g;
        vec4 wp_m = vec4(WP_MASK(wp_l).x,
                         wp_l + 1 < WP_NUM_LAYERS ? WP_MASK(wp_l + 1).x : 0.0,
                         wp_l + 2 < WP_NUM_LAYERS ? WP_MASK(wp_l + 2).x : 0.0,
                         wp_l + 3 < WP_NUM_LAYERS ? WP_MASK(wp_l + 3).x : 0.0);
#elif WP_GATHER == WP_GATHER_SPLIT
        int wp_part = wp_g - 3 * (wp_g / 3);
        vec4 wp_m = WP_MASK(wp_g / 3) * (wp_part == 0 ? 1.0 : (wp_part == 1 ? wp_sp : 1.0 - wp_sp));
#else
        vec4 wp_m = WP_MASK(wp_g);
#endif
#if WP_POLICY == WP_POL_RENORMALIZE
        wp_total += dot(wp_m, WP_USED(wp_g));
#endif
#ifdef WP_REGION_COLOR
        int wp_c = 4 * wp_g;
        wp_regions += wp_m.x * WP_REGION_COLOR(wp_c) + wp_m.y * WP_REGION_COLOR(wp_c + 1);
        wp_regions += wp_m.z * WP_REGION_COLOR(wp_c + 2) + wp_m.w * WP_REGION_COLOR(wp_c + 3);
#endif
        WP_LOOP for (int wp_q = 0; wp_q < WP_QUADS; ++wp_q) {
            int wp_i = 4 * (wp_g * WP_QUADS + wp_q);
            wp_s[wp_q] += wp_m.x * WP_W(wp_i) + wp_m.y * WP_W(wp_i + 1)
                        + wp_m.z * WP_W(wp_i + 2) + wp_m.w * WP_W(wp_i + 3);
        }
    }
    vec4 wp_a[4];
#if WP_POLICY == WP_POL_SIGNED
    float wp_sig = clamp(wp_s[0].x, -1.0, 1.0);
    wp_a[0] = vec4(max(-wp_sig, 0.0), max(wp_sig, 0.0), 0.0, 0.0);
    wp_a[1] = vec4(0.0, 0.0, 0.0, 0.0);
    wp_a[2] = wp_a[1];
    wp_a[3] = wp_a[1];
#elif WP_POLICY == WP_POL_ADDITIVE
    wp_a[0] = wp_s[0];
    wp_a[1] = wp_s[1];
    wp_a[2] = wp_s[2];
    wp_a[3] = wp_s[3];
#else
#if WP_POLICY == WP_POL_RENORMALIZE
    float wp_div = max(wp_total, 1.0);
#else
    float wp_div = 1.0;
#endif
    wp_a[0] = clamp(wp_s[0] / wp_div, 0.0, 1.0);
    wp_a[1] = clamp(wp_s[1] / wp_div, 0.0, 1.0);
    wp_a[2] = clamp(wp_s[2] / wp_div, 0.0, 1.0);
    wp_a[3] = clamp(wp_s[3] / wp_div, 0.0, 1.0);
#if WP_POLICY == WP_POL_LERP
    float wp_sum = dot(wp_a[0] + wp_a[1] + wp_a[2] + wp_a[3], vec4(1.0, 1.0, 1.0, 1.0));
    if (wp_sum > 1.0) {
        wp_a[0] /= wp_sum;
        wp_a[1] /= wp_sum;
        wp_a[2] /= wp_sum;
        wp_a[3] /= wp_sum;
    }
#endif
#endif
    wp_activity = dot(abs(wp_a[0]) + abs(wp_a[1]) + abs(wp_a[2]) + abs(wp_a[3]),
                      vec4(1.0, 1.0, 1.0, 1.0));
    vec3 wp_b = WP_DECODE_BASE(WP_BASE());
#if WP_ENCODING == WP_ENC_PD
    vec3 wp_acc = vec3(wp_b.xy / max(wp_b.z, 1e-12), 1.0);
#else
    vec3 wp_acc = wp_b;
#endif
    WP_LOOP for (int wp_k = 0; wp_k < WP_NUM_STATES; ++wp_k) {
        float wp_ak = wp_a[wp_k / 4][wp_k - 4 * (wp_k / 4)];
        if (wp_ak != 0.0) {
            vec4 wp_t = WP_STATE(wp_k);
#if WP_ENCODING == WP_ENC_PD
            wp_acc.xy += wp_ak * WP_DECODE_PD(wp_t);
#elif WP_ENCODING == WP_ENC_DIFF
            wp_acc += wp_ak * WP_DECODE_DIFF(wp_t);
#elif WP_ENCODING == WP_ENC_FULL
            wp_acc += wp_ak * (WP_DECODE_STATE_NORMAL(wp_t) - wp_b);
#else
            vec3 wp_w = WP_DECODE_STATE_NORMAL(wp_t);
            wp_acc.xy += wp_ak * wp_w.xy;
            wp_acc.z *= 1.0 + wp_ak * (wp_w.z - 1.0);
#endif
        }
    }
    wp_n = wp_activity == 0.0 ? wp_b : normalize(wp_acc);
}
"""

#: The colour block (inserted at the end of the core's scope, where the activations are): the
#: colour model of :func:`wrinklepipe.model.combine_color`, line for line.
COLOR_BLOCK = """\
    // colour: C = clamp(C_B + sum_k a_k (C_k - C_B), 0, 1) in linear light, same activations
    vec3 wp_cb = WP_COLOR_BASE();
    vec3 wp_cacc = wp_cb;
    WP_LOOP for (int wp_c = 0; wp_c < WP_NUM_COLORS; ++wp_c) {
        int wp_ck = WP_COLOR_STATE(wp_c);
        float wp_ca = wp_a[wp_ck / 4][wp_ck - 4 * (wp_ck / 4)];
        if (wp_ca != 0.0) {
            wp_cacc += wp_ca * (WP_COLOR(wp_c) - wp_cb);
        }
    }
    wp_color = clamp(wp_cacc, 0.0, 1.0);
"""

_HLSL_WORDS = {
    "vec2": "float2",
    "vec3": "float3",
    "vec4": "float4",
    "ivec2": "int2",
    "ivec3": "int3",
    "ivec4": "int4",
    "mat4": "float4x4",
    "mix": "lerp",
    "fract": "frac",
    "inversesqrt": "rsqrt",
}
_WORD = re.compile(r"\b(" + "|".join(_HLSL_WORDS) + r")\b")


def emit(text: str, lang: str) -> str:
    """``text`` (the GLSL spelling) in ``lang``: ``glsl``, ``hlsl`` or ``gdshader``."""
    if lang not in LANGS:
        raise ValueError(f"unknown shader language {lang!r}; expected one of {', '.join(LANGS)}")
    if lang == "hlsl":
        return _WORD.sub(lambda m: _HLSL_WORDS[m.group(1)], text)
    return text


def float_literal(x: float) -> str:
    """A float literal every shading language reads the same (``0.25``, ``1.0``, ``1e-05``)."""
    s = repr(float(x))
    return s if any(c in s for c in ".en") else s + ".0"


def defines(setup: ShaderSetup) -> dict[str, str]:
    """The ``#define`` values that specialise the core for one asset."""
    split_layer, split_channel = setup.split or (0, 0)
    return {
        "WP_ENCODING": str(ENCODING_IDS[setup.encoding]),
        "WP_POLICY": str(POLICY_IDS[setup.policy]),
        "WP_SCALE": float_literal(setup.scale),
        "WP_NUM_STATES": str(setup.n_states),
        "WP_NUM_LAYERS": str(setup.n_layers),
        "WP_NUM_GROUPS": str(setup.n_groups),
        "WP_QUADS": str(setup.quads),
        "WP_NUM_WEIGHTS": str(setup.n_weight_vectors),
        "WP_GATHER": str(GATHERS.index(setup.gather)),
        "WP_SPLIT_LAYER": str(split_layer),
        "WP_SPLIT_CHANNEL": str(split_channel),
        "WP_BASE_LAYOUT": str(LAYOUT_IDS[setup.base_layout]),
        "WP_STATE_LAYOUT": str(LAYOUT_IDS[setup.state_layout]),
        "WP_STATE_BITS": str(setup.state_bits),
        "WP_MAPPING": str(setup.mapping),
        "WP_FLIP_BASE": str(int(setup.base_convention != setup.output)),
        "WP_FLIP_STATES": str(int(setup.state_convention != setup.output)),
        **_color_defines(setup),
    }


def _color_defines(setup: ShaderSetup) -> dict[str, str]:
    """``WP_NUM_COLORS`` and ``WP_COLOR_STATE(c)``, the state of colour map ``c`` (a chain of
    conditionals, constant-folded once loops unroll); nothing without colour states."""
    if not setup.has_color:
        return {}
    ks = list(setup.color_states)
    chain = "".join(f"(c) == {c} ? {k} : " for c, k in enumerate(ks[:-1])) + str(ks[-1])
    return {"WP_NUM_COLORS": str(len(ks)), "WP_COLOR_STATE(c)": f"({chain})"}


def define_block(values: dict[str, str]) -> str:
    return "".join(f"#define {k} {v}\n" for k, v in values.items())


def core(lang: str, loop: str = "", color: bool = False) -> str:
    """The core statement block in ``lang`` (``loop``: an attribute put before every loop, such
    as HLSL's ``[unroll]``); ``color``: with the colour block (``wp_color``)."""
    text = CORE
    if color:
        text = text.replace("float wp_activity;\n", "float wp_activity;\nvec3 wp_color;\n", 1)
        assert text.endswith("}\n")
        text = text[: -len("}\n")] + COLOR_BLOCK + "}\n"
    text = text.replace("WP_LOOP ", f"{loop} " if loop else "")
    return emit(text, lang)


def functions(lang: str) -> str:
    """Constants, the codec's decode functions and the decode hooks, in ``lang`` (global scope).

    Godot's shading language reads the GLSL spelling of the decode functions."""
    decode = decode_source("hlsl" if lang == "hlsl" else "glsl")
    return emit(CONSTANTS, lang) + decode + emit(DECODE_HOOKS, lang)
