"""The generated GLSL and HLSL decode functions, rendered, equal the codec's numpy decode.

Every function of :mod:`wrinklepipe.codec.shaders` is evaluated by the GPU (moderngl on EGL;
llvmpipe here) on textures holding every 8-bit value (and a spread of 16-bit ones plus the
special texels 0, 1, c - 1, c, c + 1, top), read back from a float32 target and compared with
:func:`wrinklepipe.codec.decode_sampled` (the same float32 arithmetic). The HLSL text is
compiled by glslangValidator to SPIR-V and back to GLSL 330 by spirv-cross, then rendered the
same way, so a typing or swizzle slip in either language shows as a number.
"""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest

from wrinklepipe import codec
from wrinklepipe.codec.shaders import FUNCTIONS, decode_source
from wrinklepipe.validate import gl as glw
from wrinklepipe.validate.inputs import Texture

pytestmark = pytest.mark.gpu

N = 16  # 16 x 16 texels: every 8-bit value once per channel

_VS = """#version 330
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
"""

# (id, expression in the texel `c`, numpy twin)
_CASES = [
    ("normal_rgb", "vec4(wp_normal_rgb(c), 0.0)"),
    ("normal_rg", "vec4(wp_normal_rg(c), 0.0)"),
    ("normal_ag", "vec4(wp_normal_ag(c), 0.0)"),
    ("normal_dispatch_ag", "vec4(wp_normal(c, WP_LAYOUT_AG), 0.0)"),
    ("pd_rg", "vec4(wp_pd_rg(c, VERSION, BITS, SCALE), 0.0, 0.0)"),
    ("pd_ag", "vec4(wp_pd_ag(c, VERSION, BITS, SCALE), 0.0, 0.0)"),
    ("pd_dispatch_rg", "vec4(wp_pd(c, WP_LAYOUT_RG, VERSION, BITS, SCALE), 0.0, 0.0)"),
    ("diff_rgb", "vec4(wp_diff_rgb(c, VERSION, BITS, SCALE), 0.0)"),
    ("signed", "vec4(wp_signed(c.r, VERSION, BITS), wp_signed2(c.ga, VERSION, BITS), 0.0)"),
    ("signed3", "vec4(wp_signed3(c.rgb, VERSION, BITS), 0.0)"),
    ("pd_to_normal", "vec4(wp_pd_to_normal(wp_pd_rg(c, VERSION, BITS, SCALE)), 0.0)"),
]


def _numpy(case: str, v: np.ndarray, version: int, bits: int, scale: float) -> np.ndarray:
    """The codec's numpy decode of sampled values ``v`` [N, N, 4] for one case -> [N, N, 4]."""
    ds = codec.decode_sampled
    if case.startswith("normal"):
        lay = {"normal_rgb": "rgb", "normal_rg": "rg"}.get(case, "ag")
        out = ds("full", v, lay, bits=bits)
    elif case.startswith("pd_to"):
        out = codec.to_normal("pd", ds("pd", v, "rg", bits=bits, param=scale, version=version))
    elif case.startswith("pd"):
        lay = "ag" if case == "pd_ag" else "rg"
        out = ds("pd", v, lay, bits=bits, param=scale, version=version)
    elif case == "diff_rgb":
        out = ds("diff", v, "rgb", bits=bits, param=scale, version=version)
    else:
        m = codec.mapping(version)
        if case == "signed":
            out = m.decode_unorm(v[..., [0, 1, 3]], bits)
        else:
            out = m.decode_unorm(v[..., :3], bits)
    pad = np.zeros(out.shape[:-1] + (4 - out.shape[-1],), np.float32)
    return np.concatenate([out, pad], axis=-1)


def _texels(bits: int) -> np.ndarray:
    rng = np.random.default_rng(bits)
    if bits == 8:
        ch = [rng.permutation(256) for _ in range(4)]
        return np.stack(ch, -1).reshape(N, N, 4).astype(np.uint8)
    special = [0, 1, 32767, 32768, 32769, 65535]
    vals = rng.integers(0, 65536, (N * N, 4))
    vals[: len(special)] = np.array(special)[:, None]
    return vals.reshape(N, N, 4).astype(np.uint16)


@pytest.fixture(scope="module")
def gl():
    try:
        ctx = glw.create_context()
        raw = glw.RawGL.load()
    except glw.GLUnavailable as exc:
        pytest.skip(f"no OpenGL: {exc}")
    rb = ctx.renderbuffer((N, N), 4, dtype="f4")
    fbo = ctx.framebuffer([rb])
    yield ctx, raw, fbo
    fbo.release()
    rb.release()
    ctx.release()


def _render(gl, fragment: str, q: np.ndarray) -> np.ndarray:
    ctx, raw, fbo = gl
    fmt = "rgba8" if q.dtype == np.uint8 else "rgba16"
    data = q.astype("<u2").tobytes() if q.dtype == np.uint16 else q.tobytes()
    name = glw.upload(raw, [Texture("t", "base", fmt, N, N, data)], array=False)
    try:
        prog = ctx.program(vertex_shader=_VS, fragment_shader=fragment)
        glw.bind(raw, 0, name, array=False)  # the one sampler (spirv-cross renames it) is unit 0
        fbo.use()
        ctx.viewport = (0, 0, N, N)
        vao = ctx.vertex_array(prog, [])
        vao.render(vertices=3)
        out = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(N, N, 4)
        vao.release()
        prog.release()
        err = raw.get_error()
        assert err == 0, f"GL error 0x{err:04X}"
    finally:
        glw.delete(raw, [name])
    return out


def _glsl(expr: str, version: int, bits: int, scale: float) -> str:
    return (
        "#version 330\n"
        + decode_source("glsl")
        + f"#define VERSION {version}\n#define BITS {bits}\n#define SCALE {scale!r}\n"
        + "uniform sampler2D u_tex;\nout vec4 o;\n"
        + "void main() {\n    vec4 c = texelFetch(u_tex, ivec2(gl_FragCoord.xy), 0);\n"
        + f"    o = {expr};\n}}\n"
    )


def _hlsl_to_glsl(expr: str, version: int, bits: int, scale: float, tmp_path) -> str:
    hexpr = expr.replace("vec4(", "float4(")
    src = (
        decode_source("hlsl")
        + f"#define VERSION {version}\n#define BITS {bits}\n#define SCALE {scale!r}\n"
        + "Texture2D<float4> u_tex : register(t0);\n"
        + "float4 main(float4 pos : SV_Position) : SV_Target {\n"
        + "    float4 c = u_tex.Load(int3(int2(pos.xy), 0));\n"
        + f"    return {hexpr};\n}}\n"
    )
    hl = tmp_path / "decode.hlsl"
    spv = tmp_path / "decode.spv"
    hl.write_text(src)
    subprocess.run(
        ["glslangValidator", "-D", "-V", "-S", "frag", "-e", "main", "--auto-map-bindings"]
        + ["-o", str(spv), str(hl)],
        check=True,
        capture_output=True,
    )
    out = subprocess.run(
        ["spirv-cross", "--version", "330", "--no-es", str(spv)],
        check=True,
        capture_output=True,
        text=True,
    )
    return out.stdout


def test_function_list_is_what_the_source_defines():
    for lang in ("glsl", "hlsl"):
        text = decode_source(lang)
        for fn in FUNCTIONS:
            assert f" {fn}(" in text, (lang, fn)
        assert decode_source(lang) == text  # deterministic
    with pytest.raises(ValueError, match="language"):
        decode_source("metal")


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("version", [1, 2])
def test_glsl_decode_equals_numpy(gl, version, bits):
    q = _texels(bits)
    v = q.astype(np.float64) / ((1 << bits) - 1)
    scale = 0.375
    for case, expr in _CASES:
        got = _render(gl, _glsl(expr, version, bits, scale), q)
        want = _numpy(case, v, version, bits, scale)
        np.testing.assert_allclose(got, want, atol=2e-6, err_msg=f"{case} v{version} {bits}")


def test_glsl_flat_pd_texel_is_exactly_up(gl):
    """A centred v2 texel is a zero slope on the GPU too (to float32 precision)."""
    q = np.full((N, N, 4), 128, np.uint8)
    got = _render(gl, _glsl(_CASES[-1][1], 2, 8, 1.0), q)
    assert np.abs(got[..., :2]).max() < 1e-6 and np.abs(got[..., 2] - 1).max() < 1e-6


@pytest.mark.skipif(
    shutil.which("glslangValidator") is None or shutil.which("spirv-cross") is None,
    reason="glslang-tools / spirv-cross missing: run ci/bootstrap.sh",
)
@pytest.mark.parametrize("version", [1, 2])
def test_hlsl_decode_equals_numpy(gl, version, tmp_path):
    bits, scale = 8, 0.375
    q = _texels(bits)
    v = q.astype(np.float64) / 255
    for case, expr in _CASES:
        got = _render(gl, _hlsl_to_glsl(expr, version, bits, scale, tmp_path), q)
        want = _numpy(case, v, version, bits, scale)
        np.testing.assert_allclose(got, want, atol=2e-6, err_msg=f"hlsl {case} v{version}")
