"""The engine shaders blend colour as the numpy colour model does: Unreal's Custom node (its
additional output ``Color``), Unity's Custom Function (``Color``) through HLSL -> glslang ->
SPIR-V -> spirv-cross -> GLSL 330, and Godot's shader core as GLSL, rendered on llvmpipe with
the colour maps uploaded as sRGB textures, against :func:`wrinklepipe.model.combine_color` on
the same shipped texels (decoded, then sampled bilinearly) at the same UVs: CIEDE2000 p99 <= 1.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import shader_harness as h

from wrinklepipe import model
from wrinklepipe.codec import srgb
from wrinklepipe.demo import demo_asset
from wrinklepipe.metrics import delta_e
from wrinklepipe.shading import godot, hlsl
from wrinklepipe.validate import gl as glw
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.renderer import color_textures, shader_setup
from wrinklepipe.validate.ship import ShipOptions, ship_asset

pytestmark = pytest.mark.gpu
SIZE = 96


@pytest.fixture(scope="module")
def gpu():
    gone = h.missing_tools()
    if gone:
        pytest.skip(f"{gone} not installed (Debian glslang-tools / spirv-cross; ci/bootstrap.sh)")
    try:
        r = h.UVRenderer(SIZE)
    except glw.GLUnavailable as exc:
        pytest.skip(f"no OpenGL: {exc}")
    yield r
    r.release()


@functools.cache
def shipped():
    """The demo with colour states (8-bit PNG texels), its expressions' reference colours."""
    inp = ship_asset(demo_asset(64, color=True, mesh_resolution=(48, 32)), ShipOptions(False))
    uv = h.uv_grid(SIZE)
    s = h.samples(inp, uv)
    base_t, states_t = color_textures(inp)
    lin = [srgb.decode_texels(np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, -1))
           for t in [base_t, *(t for _, t in states_t)]]  # fmt: skip
    cb = tx.bilinear(lin[0][..., :3], uv)
    cs = np.stack([tx.bilinear(x[..., :3], uv) for x in lin[1:]])
    setup = shader_setup(inp)
    refs = {}
    for expr in [None, *sorted(inp.asset.expressions)]:
        w = h.region_weights(inp, expr)[:, None] * inp.asset.region_state_matrix()
        act = model.activations(s.masks, w, inp.asset.policy)[list(setup.color_states)]
        refs[expr] = model.combine_color(cb, cs, act)
    return inp, setup, refs


def _draw(gpu, prog, samplers, **kw) -> np.ndarray:
    """Draw with the samplers the program uses (the colour output alone leaves the normal's
    textures unused: the compiler drops them)."""
    return gpu.draw(prog, {k: v for k, v in samplers.items() if k in prog}, **kw)


def _check(image: np.ndarray, ref: np.ndarray, what: str) -> None:
    got = image.reshape(-1, 4)[:, :3]
    err = delta_e(got, ref)
    assert float(np.percentile(err, 99)) <= 1.0, (what, float(err.mean()), float(err.max()))


def test_a_flush_changes_the_colour():
    inp, _, refs = shipped()
    moved = delta_e(refs["anger"], refs[None])
    assert float(moved.max()) > 5.0  # the flushed glabella is visibly redder


# ------------------------------------------------------------------------------------------------
# Unreal


def unreal_color_material(nodes: hlsl.UnrealNodes) -> tuple[str, list[str]]:
    """The pixel shader Unreal would build around the Custom nodes (emulated), returning the
    wrinkle node's additional output Color; and the Texture2D names it declares."""
    params, args, textures = [], [], []
    n_regions = len(nodes.region_inputs)
    scalars = {n for n, _ in nodes.region_inputs}
    for name, _ in nodes.wrinkle.inputs:
        if name == "UV":
            params.append("MaterialFloat2 UV")
            args.append("i.uv")
        elif name == "Decode":
            params.append("MaterialFloat Decode")
            args.append("d")
        elif name == "BaseColor":
            params.append("MaterialFloat3 BaseColor")
            args.append(
                "BaseColorMap.SampleGrad(BaseColorMapSampler, i.uv, ddx(i.uv), ddy(i.uv)).rgb"
            )
        elif name in scalars:
            params.append(f"MaterialFloat {name}")
            r = [n for n, _ in nodes.region_inputs].index(name)
            args.append(f"WPRegionWeights[{r // 4}].{'xyzw'[r % 4]}")
        else:
            params.append(f"Texture2D {name}, SamplerState {name}Sampler")
            args.append(f"{name}, {name}Sampler")
            textures.append(name)
    decl = "".join(
        f"Texture2D {t};\nSamplerState {t}Sampler;\n" for t in [*textures, "BaseColorMap"]
    )
    src = (
        "#define MaterialFloat float\n#define MaterialFloat2 float2\n"
        "#define MaterialFloat3 float3\n"
        "#define Texture2DSampleGrad(Tex, Sampler, UV, DDX, DDY) \\\n"
        "    Tex.SampleGrad(Sampler, UV, DDX, DDY)\n"
        "struct FMaterialPixelParameters { float4 SvPosition; };\n"
        + decl
        + f"cbuffer WPHarness {{ float4 WPRegionWeights[{(n_regions + 3) // 4}]; }};\n"
        + "MaterialFloat CustomExpression0(FMaterialPixelParameters Parameters)\n{\n"
        + nodes.decode.code
        + "\n}\n"
        + "MaterialFloat3 CustomExpression1(FMaterialPixelParameters Parameters, "
        + ", ".join(params)
        + ", inout MaterialFloat3 Color)\n{\n"
        + nodes.wrinkle.code
        + "\n}\n"
        + "struct PSIn { float4 pos : SV_Position; float2 uv : TEXCOORD0; };\n"
        + "float4 main(PSIn i) : SV_Target0\n{\n"
        + "    FMaterialPixelParameters p;\n    p.SvPosition = i.pos;\n"
        + "    MaterialFloat d = CustomExpression0(p);\n"
        + "    MaterialFloat3 Color = MaterialFloat3(0.0, 0.0, 0.0);\n"
        + f"    CustomExpression1(p, {', '.join(args)}, Color);\n"
        + "    return float4(Color, 1.0);\n}\n"
    )
    return src, textures


def test_unreal_custom_node_blends_the_colour(gpu):
    inp, setup, refs = shipped()
    nodes = hlsl.unreal_nodes(setup)
    assert nodes.wrinkle.additional_outputs == (("Color", "CMOT Float3"),)
    src, names = unreal_color_material(nodes)
    prog = gpu.program(h.hlsl_to_glsl(src))
    base_t, states_t = color_textures(inp)
    by_name = {"Base": inp.by_role("base")[0], "BaseColorMap": base_t}
    by_name |= {f"State{k}": t for k, t in enumerate(inp.state_textures())}
    by_name |= {f"Mask{k}": t for k, t in enumerate(h.mask_layers(inp))}
    by_name |= {f"Color{c}": t for c, (_, t) in enumerate(states_t)}
    samplers = {
        f"SPIRV_Cross_Combined{n}{n}Sampler": (gpu.upload([by_name[n]], array=False), False)
        for n in [*names, "BaseColorMap"]
    }
    for expr, ref in refs.items():
        w = h.region_weights(inp, expr)
        pad = np.zeros(((len(w) + 3) // 4) * 4, np.float32)
        pad[: len(w)] = w
        img = _draw(gpu, prog, samplers, blocks={"WPHarness": pad.tobytes()})
        _check(img, ref, ("unreal", expr))


# ------------------------------------------------------------------------------------------------
# Unity

UNITY_PRELUDE = """\
#define SAMPLE_TEXTURE2D_GRAD(textureName, samplerName, coord2, dpdx, dpdy) \\
    textureName.SampleGrad(samplerName, coord2, dpdx, dpdy)
#define SAMPLE_TEXTURE2D_ARRAY_GRAD(textureName, samplerName, coord2, index, dpdx, dpdy) \\
    textureName.SampleGrad(samplerName, float3(coord2, index), dpdx, dpdy)
struct UnitySamplerState { SamplerState samplerstate; };
struct UnityTexture2D { Texture2D tex; SamplerState samplerstate; float4 texelSize;
                        float4 scaleTranslate; };
struct UnityTexture2DArray { Texture2DArray tex; SamplerState samplerstate; };
Texture2D _BaseMap;
Texture2DArray _States;
Texture2DArray _Masks;
Texture2D _BaseColorMap;
Texture2DArray _Colors;
SamplerState sampler_BaseMap;
"""

UNITY_MAIN = """\
struct PSIn { float4 pos : SV_Position; float2 uv : TEXCOORD0; };
float4 main(PSIn i) : SV_Target0
{
    UnityTexture2D b; b.tex = _BaseMap; b.samplerstate = sampler_BaseMap;
    b.texelSize = float4(0, 0, 0, 0); b.scaleTranslate = float4(1, 1, 0, 0);
    UnityTexture2DArray s; s.tex = _States; s.samplerstate = sampler_BaseMap;
    UnityTexture2DArray m; m.tex = _Masks; m.samplerstate = sampler_BaseMap;
    UnityTexture2DArray c; c.tex = _Colors; c.samplerstate = sampler_BaseMap;
    UnitySamplerState ss; ss.samplerstate = sampler_BaseMap;
    float3 baseColor = _BaseColorMap.SampleGrad(sampler_BaseMap, i.uv, ddx(i.uv), ddy(i.uv)).rgb;
    float3 n;
    float a;
    float3 color;
    WrinkleNormal_float(i.uv, b, s, m, baseColor, c, ss, n, a, color);
    return float4(color, a);
}
"""


def test_unity_custom_function_blends_the_colour(gpu):
    inp, setup, refs = shipped()
    glsl = h.hlsl_to_glsl(UNITY_PRELUDE + hlsl.unity_file(setup) + UNITY_MAIN)
    prog = gpu.program(glsl)
    block = next(b for b in ("_Globals", "_Global", "type_Globals") if b in glsl)
    base_t, states_t = color_textures(inp)
    samplers = {
        "SPIRV_Cross_Combined_BaseMapsampler_BaseMap": (
            gpu.upload([inp.by_role("base")[0]], array=False), False),
        "SPIRV_Cross_Combined_Statessampler_BaseMap": (
            gpu.upload(inp.state_textures(), array=True), True),
        "SPIRV_Cross_Combined_Maskssampler_BaseMap": (
            gpu.upload(h.mask_layers(inp), array=True), True),
        "SPIRV_Cross_Combined_BaseColorMapsampler_BaseMap": (
            gpu.upload([base_t], array=False), False),
        "SPIRV_Cross_Combined_Colorssampler_BaseMap": (
            gpu.upload([t for _, t in states_t], array=True), True),
    }  # fmt: skip
    for expr, ref in refs.items():
        wv = setup.weight_vectors(h.region_weights(inp, expr))
        data = np.concatenate([wv.ravel(), setup.used_vectors().ravel()]).astype(np.float32)
        img = _draw(gpu, prog, samplers, blocks={block: data.tobytes()})
        _check(img, ref, ("unity", expr))


# ------------------------------------------------------------------------------------------------
# Godot


def test_godot_shader_core_blends_the_colour(gpu):
    inp, setup, refs = shipped()
    shader = godot.godot_shader(setup)
    assert "ALBEDO = wp_color;" in shader and "wp_colors : source_color" in shader
    glsl = (
        "#version 330\n"
        + godot.section(shader, godot.GLOBAL_BEGIN, godot.GLOBAL_END)
        + "in vec2 UV;\n"
        "uniform sampler2D wp_base;\n"
        "uniform sampler2DArray wp_states;\n"
        "uniform sampler2DArray wp_masks;\n"
        "uniform sampler2D wp_albedo;\n"
        "uniform vec3 wp_albedo_factor;\n"
        "uniform sampler2DArray wp_colors;\n"
        f"uniform vec4 wp_w[{setup.n_weight_vectors}];\n"
        f"uniform vec4 wp_used[{setup.n_groups}];\n"
        "layout(location = 0) out vec4 out_color;\n"
        "void main() {\n"
        "    vec2 wp_uv = UV;\n"
        "    vec2 wp_dx = dFdx(UV);\n"
        "    vec2 wp_dy = dFdy(UV);\n"
        + godot.section(shader, godot.BODY_BEGIN, godot.BODY_END)
        + "    out_color = vec4(wp_color, wp_activity);\n"
        "}\n"
    )
    assert h.glsl_compiles(glsl) == ""
    prog = gpu.program(glsl)
    base_t, states_t = color_textures(inp)
    samplers = {
        "wp_base": (gpu.upload([inp.by_role("base")[0]], array=False), False),
        "wp_states": (gpu.upload(inp.state_textures(), array=True), True),
        "wp_masks": (gpu.upload(h.mask_layers(inp), array=True), True),
        "wp_albedo": (gpu.upload([base_t], array=False), False),
        "wp_colors": (gpu.upload([t for _, t in states_t], array=True), True),
    }
    one = np.ones(3, np.float32).tobytes()
    for expr, ref in refs.items():
        wv = setup.weight_vectors(h.region_weights(inp, expr))
        img = _draw(
            gpu,
            prog,
            samplers,
            uniforms={
                "wp_w": wv.tobytes(),
                "wp_used": setup.used_vectors().tobytes(),
                "wp_albedo_factor": one,
            },
        )
        _check(img, ref, ("godot", expr))
