"""Render an engine's shader text with the validator's GL layer and compare it with numpy.

HLSL goes through ``glslangValidator -D`` (its HLSL front end) to SPIR-V and ``spirv-cross
--version 330`` back to GLSL 330; GLSL is used as is. The program draws a full-screen triangle in
UV space (pixel (x, y) samples uv = ((x + .5) / N, (y + .5) / N)), with the shipped texture
bytes uploaded by :mod:`wrinklepipe.validate.gl` (exactly as the render pass does), and writes
the tangent-space normal to a float32 target. The reference is ``wrinklepipe.model.blend`` on
the same texels sampled bilinearly at the same UVs (``validate.render.sample_reference``).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import model
from wrinklepipe.metrics import angle_deg
from wrinklepipe.validate import ValidateOptions, renderer
from wrinklepipe.validate import gl as glw
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.inputs import ValidationInput
from wrinklepipe.validate.render import sample_reference

TOOLS = ("glslangValidator", "spirv-cross")


def missing_tools() -> str:
    """Empty when the HLSL -> GLSL chain is installed, else what is missing."""
    gone = [t for t in TOOLS if shutil.which(t) is None]
    return ", ".join(gone)


def hlsl_to_glsl(source: str, stage: str = "frag", entry: str = "main") -> str:
    """HLSL -> SPIR-V (glslang's HLSL front end) -> GLSL 330 (spirv-cross)."""
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / f"shader.{stage}.hlsl"
        spv = Path(tmp) / "shader.spv"
        src.write_text(source, encoding="utf-8")
        r = subprocess.run(
            ["glslangValidator", "-D", "-V", "-S", stage, "-e", entry, str(src), "-o", str(spv)],
            capture_output=True,
            text=True,
        )
        if r.returncode:
            raise AssertionError(f"glslang rejected the HLSL:\n{r.stdout}{r.stderr}")
        r = subprocess.run(
            ["spirv-cross", "--version", "330", "--no-420pack-extension", str(spv)],
            capture_output=True,
            text=True,
        )
        if r.returncode:
            raise AssertionError(f"spirv-cross failed:\n{r.stdout}{r.stderr}")
        return r.stdout


def glsl_compiles(source: str, stage: str = "frag") -> str:
    """glslang's verdict on GLSL ``source`` (empty: compiles)."""
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / f"shader.{stage}"
        src.write_text(source, encoding="utf-8")
        r = subprocess.run(["glslangValidator", str(src)], capture_output=True, text=True)
        return "" if r.returncode == 0 else r.stdout + r.stderr


def region_weights(inp: ValidationInput, expr: str | None) -> np.ndarray:
    """One weight per region for an expression at full amount (None: neutral)."""
    a = inp.asset
    w = np.zeros(len(a.regions), np.float32)
    for r, v in (a.expressions.get(expr, {}) if expr else {}).items():
        if r in a.region_names:
            w[a.region_names.index(r)] += np.float32(v)
    return w


class UVRenderer:
    """A GLSL 330 fragment program drawn over UV space, textures bound by sampler name."""

    def __init__(self, size: int = 96) -> None:
        import moderngl

        self.moderngl = moderngl
        self.ctx = glw.create_context()
        self.gl = glw.RawGL.load()
        self.size = size
        self.names: list[int] = []
        self.target = self.ctx.renderbuffer((size, size), 4, dtype="f4")
        self.fbo = self.ctx.framebuffer([self.target])
        self.vao_empty: Any = None

    def release(self) -> None:
        glw.delete(self.gl, self.names)
        self.ctx.release()

    def upload(self, textures: list, array: bool) -> int:
        name = glw.upload(self.gl, textures, array=array)
        self.names.append(name)
        return name

    def program(self, fragment: str) -> Any:
        varying = re.search(r"^in vec2 (\w+);", fragment, re.M)
        assert varying, "the fragment shader reads no vec2 UV varying"
        vs = (
            "#version 330\n"
            f"out vec2 {varying.group(1)};\n"
            "void main() {\n"
            "    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);\n"
            f"    {varying.group(1)} = p;\n"
            "    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);\n"
            "}\n"
        )
        return self.ctx.program(vertex_shader=vs, fragment_shader=fragment)

    def draw(
        self,
        prog: Any,
        samplers: dict[str, tuple[int, bool]],
        blocks: dict[str, bytes] | None = None,
        uniforms: dict[str, bytes] | None = None,
    ) -> np.ndarray:
        """Render once; ``samplers``: uniform name -> (GL texture, is array); ``blocks``: uniform
        block name -> std140 bytes; ``uniforms``: plain uniform arrays -> bytes. Returns
        ``[N, N, 4]`` float32, row 0 at v = 0."""
        ctx = self.ctx
        unit = 0
        for name, (tex, array) in samplers.items():
            glw.bind(self.gl, unit, tex, array)
            prog[name].value = unit
            unit += 1
        bufs = []
        for i, (name, data) in enumerate((blocks or {}).items()):
            buf = ctx.buffer(data)
            prog[name].binding = i
            buf.bind_to_uniform_block(i)
            bufs.append(buf)
        for name, data in (uniforms or {}).items():
            if name in prog:
                u = prog[name]
                prog[name].write(data[: u.array_length * u.dimension * 4])
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0)
        vao = ctx.vertex_array(prog, [])
        vao.render(self.moderngl.TRIANGLES, vertices=3)
        raw = self.fbo.read(components=4, dtype="f4")
        for b in bufs:
            b.release()
        vao.release()
        return np.frombuffer(raw, np.float32).reshape(self.size, self.size, 4).copy()

    def uvs(self) -> np.ndarray:
        return uv_grid(self.size)


def uv_grid(size: int) -> np.ndarray:
    """The UV of every pixel centre of a ``size`` x ``size`` UV-space render, row 0 at v = 0."""
    c = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(c, c, indexing="xy")
    return np.stack([u.ravel(), v.ravel()], axis=-1)


def samples(inp: ValidationInput, uv: np.ndarray) -> Any:
    """The shipped texels bilinearly sampled at ``uv`` (what every pose's reference uses)."""
    return sample_reference(Context(inp, ValidateOptions()), uv)


def blend(inp: ValidationInput, s: Any, expr: str | None) -> np.ndarray:
    """The numpy model of one expression on sampled texels ``s`` -> ``[N, 3]``."""
    a = inp.asset
    w = Context(inp, ValidateOptions()).weights(expr)
    return model.blend(s.base, s.states, s.masks, w, a.encoding, a.policy)


def compare(image: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    n = image.reshape(-1, 4)[:, :3].astype(np.float64)
    n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    err = angle_deg(n, ref)
    return {
        "mean": float(err.mean()),
        "p99": float(np.percentile(err, 99)),
        "max": float(err.max()),
    }


def mask_layers(inp: ValidationInput) -> list:
    return renderer.mask_layers(inp)
