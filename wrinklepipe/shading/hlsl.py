"""HLSL targets of the template: Unreal material Custom nodes and a Unity Shader Graph file.

**Unreal** (:func:`unreal_nodes`). A Custom node's code becomes the body of a generated function
(``CustomExpressionN(FMaterialPixelParameters Parameters, <inputs>)``), so it cannot define
functions. The codec's decode functions therefore go into a first node, ``WP_Decode``, whose code
closes its own body and defines them at global scope (the usual Custom-node idiom); its float
output feeds the ``Decode`` input of the second node, ``WP_Wrinkle``, so Unreal emits it first.
``WP_Wrinkle`` takes the UV, the base, state and mask textures (Texture Object inputs; their
samplers are ``<name>Sampler``) and one scalar input per region weight (named after the region,
driven by material parameters or animation curves of the same name), builds the weight array
from the slot table and runs the core. Output: the tangent-space normal in Unreal's convention
(DirectX, -Y), ready for the material's Normal input.

**Unity** (:func:`unity_file`). A Shader Graph Custom Function file (``File`` mode, function
``WrinkleNormal``, float precision) taking the UV, the base map, the states and masks as
``Texture2DArray`` and a sampler; the weight array ``_WrinkleWeights`` (and ``_WrinkleUsed``) are
global arrays set from script (``WrinkleWeights.cs``, :mod:`wrinklepipe.export`). Output: the
tangent-space normal (+Y), for the graph's Normal (Tangent Space) block.

Both sample with explicit gradients (``ddx``/``ddy`` of the UV taken once) because the state
fetches sit in a branch that skips states whose activation is 0.

With colour states (``setup.has_color``) both also blend colour with the same activations:
Unreal's ``WP_Wrinkle`` takes ``BaseColor`` (the material's base colour, linear: its Base
Color texture sampled as Color, times its tint) and one Texture Object ``Color<c>`` per colour
map (sampled as Color, i.e. sRGB), and writes the blended colour to its additional output
``Color`` (for the material's Base Color); Unity's function takes ``BaseColor`` and the colour
maps as an sRGB ``Texture2DArray`` ``Colors`` and outputs ``Color``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from wrinklepipe.codec.shaders import decode_source
from wrinklepipe.names import unique_name
from wrinklepipe.shading import template as tpl
from wrinklepipe.shading.setup import ShaderSetup

#: Texture inputs a material may take (Unreal's limit with shared samplers).
UNREAL_MAX_TEXTURES = 128


def identifier(name: str, taken: set[str], prefix: str = "") -> str:
    """An HLSL identifier made from ``name`` (letters, digits, ``_``), unique within ``taken``."""
    stem = prefix + (re.sub(r"[^A-Za-z0-9_]", "_", name) or "x")
    if stem[0].isdigit():
        stem = "_" + stem
    return unique_name(stem, taken)


@dataclass(frozen=True)
class CustomNode:
    """One Unreal Custom node: its description, output type, inputs and code."""

    description: str
    output: str  # "CMOT Float1" | "CMOT Float3"
    inputs: tuple[tuple[str, str], ...]  # (name, what to connect)
    code: str
    #: (name, type) of Unreal's additional outputs, set in the code by name (colour: "Color")
    additional_outputs: tuple[tuple[str, str], ...] = ()


@dataclass(frozen=True)
class UnrealNodes:
    """The two Custom nodes of the Unreal wrinkle material function."""

    decode: CustomNode
    wrinkle: CustomNode
    region_inputs: tuple[tuple[str, str], ...]  # (input name, region name)


def _chain(name: str, count: int, sample: str) -> str:
    """``((i) == 0 ? sample(name0) : (i) == 1 ? ...)``: constant-folded once loops unroll."""
    parts = [f"(i) == {k} ? {sample.format(t=f'{name}{k}')} : " for k in range(count - 1)]
    last = sample.format(t=f"{name}{count - 1}")
    return "(" + "".join(parts) + last + ")"


def _weight_glue(setup: ShaderSetup, names: list[str], lang_float4: str = "float4") -> str:
    """HLSL statements that fill ``wp_w`` from the region inputs ``names`` (slot table) and
    declare ``wp_used``."""
    lines = [
        f"{lang_float4} wp_w[WP_NUM_WEIGHTS];",
        "[unroll] for (int wp_z = 0; wp_z < WP_NUM_WEIGHTS; ++wp_z)",
        f"    wp_w[wp_z] = {lang_float4}(0.0, 0.0, 0.0, 0.0);",
    ]
    for name, slots in zip(names, setup.slots(), strict=True):
        for s in slots:
            lines.append(f"wp_w[{s // 4}].{'xyzw'[s % 4]} = {name};")
    used = setup.used_vectors()
    vals = ", ".join(
        f"{lang_float4}({', '.join(tpl.float_literal(v) for v in row)})" for row in used
    )
    lines.append(f"const {lang_float4} wp_used[WP_NUM_GROUPS] = {{ {vals} }};")
    return "\n".join(lines) + "\n"


def unreal_nodes(setup: ShaderSetup) -> UnrealNodes:
    """The Unreal Custom nodes for ``setup`` (textures and output in DirectX convention)."""
    n_colors = len(setup.color_states)
    n_tex = 1 + setup.n_states + setup.n_layers + n_colors
    if n_tex > UNREAL_MAX_TEXTURES:
        raise ValueError(
            f"{n_tex} textures (base, {setup.n_states} states, {setup.n_layers} masks, {n_colors} "
            f"colour maps); an Unreal material takes at most {UNREAL_MAX_TEXTURES}"
        )
    decode_code = (
        "return 0.0;\n}\n"
        "// wrinklepipe: the codec's decode functions at global scope (this node's body closes\n"
        "// above and reopens below), used by the WP_Wrinkle node.\n"
        + decode_source("hlsl")
        + "float WP_DecodeEnd_() {\nreturn 0.0;"
    )
    decode = CustomNode("WP_Decode", "CMOT Float1", (), decode_code)
    taken = {"UV", "Base", "Decode", "Parameters"}
    taken |= {f"State{k}" for k in range(setup.n_states)}
    taken |= {f"Mask{k}" for k in range(setup.n_layers)}
    if n_colors:
        taken |= {"BaseColor", "Color"} | {f"Color{c}" for c in range(n_colors)}
    region_inputs = tuple((identifier(r, taken), r) for r in setup.region_names)
    grad = "Texture2DSampleGrad({t}, {t}Sampler, UV, wp_dx, wp_dy)"
    hooks = (
        "#define WP_BASE() Texture2DSampleGrad(Base, BaseSampler, UV, wp_dx, wp_dy)\n"
        f"#define WP_STATE(i) {_chain('State', setup.n_states, grad)}\n"
        f"#define WP_MASK(i) {_chain('Mask', setup.n_layers, grad)}\n"
        "#define WP_W(i) wp_w[i]\n"
        "#define WP_USED(g) wp_used[g]\n"
        "#define WP_LOOP [unroll]\n"
    )
    if n_colors:
        hooks += (
            "#define WP_COLOR_BASE() BaseColor\n"
            f"#define WP_COLOR(i) ({_chain('Color', n_colors, grad)}).rgb\n"
        )
    body = (
        "// wrinklepipe: the wrinkle model (wrinklepipe.model), generated by wrinklepipe.shading.\n"
        "// Returns the tangent-space normal (Unreal convention) for the material's Normal.\n"
        + tpl.define_block(tpl.defines(setup))
        + tpl.emit(tpl.CONSTANTS + tpl.DECODE_HOOKS, "hlsl")
        + "float2 wp_dx = ddx(UV);\nfloat2 wp_dy = ddy(UV);\n"
        + hooks
        + _weight_glue(setup, [n for n, _ in region_inputs])
        + tpl.core("hlsl", "[unroll]", color=bool(n_colors))
        + ("Color = wp_color;\n" if n_colors else "")
        + "return wp_n;\n"
    )
    states, layers = setup.state_names, setup.layer_names
    inputs = (
        ("UV", "TexCoord[0]"),
        ("Base", "the base normal texture (Texture Object)"),
        *((f"State{k}", f"wrinkle state {s} (Texture Object)") for k, s in enumerate(states)),
        *((f"Mask{k}", f"mask texture {n} (Texture Object)") for k, n in enumerate(layers)),
        *((n, f"weight of region {r} (scalar parameter)") for n, r in region_inputs),
        *(
            (
                ("BaseColor", "the material's base colour (Base Color texture as Color x tint)"),
                *(
                    (f"Color{c}", f"colour map of state {states[k]} (Texture Object, sRGB)")
                    for c, k in enumerate(setup.color_states)
                ),
            )
            if n_colors
            else ()
        ),
        ("Decode", "the WP_Decode node's output"),
    )
    extra = (("Color", "CMOT Float3"),) if n_colors else ()
    wrinkle = CustomNode("WP_Wrinkle", "CMOT Float3", inputs, body, extra)
    return UnrealNodes(decode, wrinkle, region_inputs)


UNITY_FUNCTION = "WrinkleNormal"

#: Unity stores a NormalMap-type texture in its platform's normal-map encoding: x in alpha (and
#: r = 1) for DXT5nm-style, x in red (a = 1) for BC5 or RGB. ``x = r * a`` reads both, as Unity's
#: ``UnpackNormalmapRGorAG`` does; y is green in all of them.
UNITY_NORMAL_READ = (
    "// Unity's NormalMap encodings: x in alpha (DXT5nm-style) or in red (BC5 / RGB); x = r * a\n"
    "float4 wp_unity_normal_xy(float4 c) { return float4(c.r * c.a, c.g, 0.0, 1.0); }\n"
)


def unity_file(setup: ShaderSetup, guard: str = "WRINKLEPIPE_WRINKLE") -> str:
    """The Shader Graph Custom Function file (``.hlsl``) for ``setup``."""
    guard = re.sub(r"[^A-Za-z0-9_]", "_", guard).upper() + "_INCLUDED"
    # a two-channel base is Unity's NormalMap import: read x as r * a, like UnpackNormal
    base_read = "wp_unity_normal_xy" if setup.base_layout == "rg" else ""
    if setup.has_color:
        return _unity_color_file(setup, guard, base_read)
    return (
        "// wrinklepipe: the wrinkle model (wrinklepipe.model) as a Shader Graph Custom Function,\n"
        f"// generated by wrinklepipe.shading. Custom Function node: Type File, Name "
        f"{UNITY_FUNCTION}, Precision Float.\n"
        "// Inputs: UV (Vector 2), BaseMap (Texture 2D), States (Texture 2D Array), Masks\n"
        "// (Texture 2D Array), Sampler (Sampler State). Outputs: NormalTS (Vector 3), Activity\n"
        "// (Float). _WrinkleWeights / _WrinkleUsed are set by the WrinkleWeights component.\n"
        f"#ifndef {guard}\n#define {guard}\n"
        + tpl.define_block(tpl.defines(setup))
        + tpl.functions("hlsl")
        + UNITY_NORMAL_READ
        + "float4 _WrinkleWeights[WP_NUM_WEIGHTS];\n"
        + "float4 _WrinkleUsed[WP_NUM_GROUPS];\n\n"
        + f"void {UNITY_FUNCTION}_float(float2 UV, UnityTexture2D BaseMap, UnityTexture2DArray "
        "States,\n    UnityTexture2DArray Masks, UnitySamplerState Sampler, out float3 NormalTS, "
        "out float Activity)\n{\n"
        "    float2 wp_dx = ddx(UV);\n    float2 wp_dy = ddy(UV);\n"
        f"#define WP_BASE() {base_read}(SAMPLE_TEXTURE2D_GRAD(BaseMap.tex, Sampler.samplerstate, "
        "UV, wp_dx, wp_dy))\n"
        "#define WP_STATE(k) SAMPLE_TEXTURE2D_ARRAY_GRAD(States.tex, Sampler.samplerstate, UV, "
        "(k), wp_dx, wp_dy)\n"
        "#define WP_MASK(l) SAMPLE_TEXTURE2D_ARRAY_GRAD(Masks.tex, Sampler.samplerstate, UV, "
        "(l), wp_dx, wp_dy)\n"
        "#define WP_W(i) _WrinkleWeights[i]\n#define WP_USED(g) _WrinkleUsed[g]\n"
        "#define WP_LOOP [loop]\n"
        + tpl.core("hlsl", "WP_LOOP")
        + "    NormalTS = wp_n;\n    Activity = wp_activity;\n"
        "#undef WP_BASE\n#undef WP_STATE\n#undef WP_MASK\n#undef WP_W\n#undef WP_USED\n"
        "#undef WP_LOOP\n}\n\n"
        + f"void {UNITY_FUNCTION}_half(float2 UV, UnityTexture2D BaseMap, UnityTexture2DArray "
        "States,\n    UnityTexture2DArray Masks, UnitySamplerState Sampler, out half3 NormalTS, "
        "out half Activity)\n{\n"
        "    float3 n;\n    float a;\n"
        f"    {UNITY_FUNCTION}_float(UV, BaseMap, States, Masks, Sampler, n, a);\n"
        "    NormalTS = n;\n    Activity = a;\n}\n"
        f"#endif  // {guard}\n"
    )


def _unity_color_file(setup: ShaderSetup, guard: str, base_read: str) -> str:
    """:func:`unity_file` with colour states: ``BaseColor`` and the sRGB ``Colors`` array in,
    the blended ``Color`` out."""
    sig_in = (
        "float2 UV, UnityTexture2D BaseMap, UnityTexture2DArray States,\n"
        "    UnityTexture2DArray Masks, float3 BaseColor, UnityTexture2DArray Colors,\n"
        "    UnitySamplerState Sampler"
    )
    return (
        "// wrinklepipe: the wrinkle model (wrinklepipe.model) as a Shader Graph Custom Function,\n"
        f"// generated by wrinklepipe.shading. Custom Function node: Type File, Name "
        f"{UNITY_FUNCTION}, Precision Float.\n"
        "// Inputs: UV (Vector 2), BaseMap (Texture 2D), States (Texture 2D Array), Masks\n"
        "// (Texture 2D Array), BaseColor (Vector 3: the base colour, linear), Colors (Texture 2D\n"
        "// Array, sRGB: the colour maps), Sampler (Sampler State). Outputs: NormalTS (Vector 3),\n"
        "// Activity (Float), Color (Vector 3: the blended base colour, linear).\n"
        "// _WrinkleWeights / _WrinkleUsed are set by the WrinkleWeights component.\n"
        f"#ifndef {guard}\n#define {guard}\n"
        + tpl.define_block(tpl.defines(setup))
        + tpl.functions("hlsl")
        + UNITY_NORMAL_READ
        + "float4 _WrinkleWeights[WP_NUM_WEIGHTS];\n"
        + "float4 _WrinkleUsed[WP_NUM_GROUPS];\n\n"
        + f"void {UNITY_FUNCTION}_float({sig_in},\n"
        "    out float3 NormalTS, out float Activity, out float3 Color)\n{\n"
        "    float2 wp_dx = ddx(UV);\n    float2 wp_dy = ddy(UV);\n"
        f"#define WP_BASE() {base_read}(SAMPLE_TEXTURE2D_GRAD(BaseMap.tex, Sampler.samplerstate, "
        "UV, wp_dx, wp_dy))\n"
        "#define WP_STATE(k) SAMPLE_TEXTURE2D_ARRAY_GRAD(States.tex, Sampler.samplerstate, UV, "
        "(k), wp_dx, wp_dy)\n"
        "#define WP_MASK(l) SAMPLE_TEXTURE2D_ARRAY_GRAD(Masks.tex, Sampler.samplerstate, UV, "
        "(l), wp_dx, wp_dy)\n"
        "#define WP_COLOR_BASE() BaseColor\n"
        "#define WP_COLOR(c) SAMPLE_TEXTURE2D_ARRAY_GRAD(Colors.tex, Sampler.samplerstate, UV, "
        "(c), wp_dx, wp_dy).rgb\n"
        "#define WP_W(i) _WrinkleWeights[i]\n#define WP_USED(g) _WrinkleUsed[g]\n"
        "#define WP_LOOP [loop]\n"
        + tpl.core("hlsl", "WP_LOOP", color=True)
        + "    NormalTS = wp_n;\n    Activity = wp_activity;\n    Color = wp_color;\n"
        "#undef WP_BASE\n#undef WP_STATE\n#undef WP_MASK\n#undef WP_COLOR_BASE\n"
        "#undef WP_COLOR\n#undef WP_W\n#undef WP_USED\n#undef WP_LOOP\n}\n\n"
        + f"void {UNITY_FUNCTION}_half({sig_in},\n"
        "    out half3 NormalTS, out half Activity, out half3 Color)\n{\n"
        "    float3 n;\n    float a;\n    float3 c;\n"
        f"    {UNITY_FUNCTION}_float(UV, BaseMap, States, Masks, BaseColor, Colors, Sampler, n, a, "
        "c);\n"
        "    NormalTS = n;\n    Activity = a;\n    Color = c;\n}\n"
        f"#endif  // {guard}\n"
    )
