"""Render a MaterialX document with the GLSL MaterialX's own generator writes (moderngl, EGL).

:func:`render_output` generates the vertex and pixel shaders of one nodegraph output
(``MaterialX.PyMaterialXGenGlsl``, the standard libraries' implementations), draws them over
texture space (a quad whose texture coordinate 0 is MaterialX's ``st``, i.e. USD's: (0, 0) at
the image's bottom left), with each image of the document read from its file (OpenImageIO,
alpha kept unassociated, uploaded as float bottom row first as OpenGL expects, linear
filtering, clamped, no mipmaps) and the
graph's float inputs set as uniforms. It returns the output per pixel, row ``i`` at glTF
``v = (i + 0.5) / N`` (``v = 1 - t``), as tests/shader_harness.py's renders are.
"""

from __future__ import annotations

from pathlib import Path

import MaterialX as mx
import MaterialX.PyMaterialXGenGlsl as mx_glsl
import MaterialX.PyMaterialXGenShader as mx_gen
import numpy as np
import OpenImageIO as oiio

from wrinklepipe.shading import materialx as wmx
from wrinklepipe.validate import gl as glw


def generate(doc: mx.Document, element: mx.Element) -> tuple[str, str]:
    """(vertex, pixel) GLSL of ``element`` (an output or a material node) of ``doc``."""
    gen = mx_glsl.GlslShaderGenerator.create()
    # colour management as hosts set it up: sRGB colour maps converted to the linear working
    # space (images without a colour space are data and left alone)
    cms = mx_gen.DefaultColorManagementSystem.create(gen.getTarget())
    cms.loadLibrary(wmx.library())
    gen.setColorManagementSystem(cms)
    ctx = mx_gen.GenContext(gen)
    ctx.getOptions().targetColorSpaceOverride = "lin_rec709"
    ctx.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    shader = gen.generate("wrinkle", element, ctx)
    return shader.getSourceCode(mx_gen.VERTEX_STAGE), shader.getSourceCode(mx_gen.PIXEL_STAGE)


def with_library(doc: mx.Document) -> mx.Document:
    out = mx.createDocument()
    out.copyContentFrom(doc)
    out.importLibrary(wmx.library())
    return out


def _texture(ctx, path: Path):
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # data, not premultiplied colour
    inp = oiio.ImageInput.open(str(path), config)
    spec = inp.spec()
    bits16 = spec.format.basetype == oiio.UINT16
    px = inp.read_image(0, 0, 0, spec.nchannels, oiio.UINT16 if bits16 else oiio.UINT8)
    inp.close()
    # the UNORM values as float32 (v / 255, v / 65535: what a UNORM texture holds), so the
    # bilinear filter runs in float (llvmpipe filters 8-bit textures in 8-bit fixed point);
    # OpenGL's first row is the image's bottom (st t = 0)
    values = px[::-1].astype(np.float32) / (65535.0 if bits16 else 255.0)
    tex = ctx.texture((spec.width, spec.height), spec.nchannels, values.tobytes(), dtype="f4")
    tex.repeat_x = tex.repeat_y = False
    tex.filter = (ctx.LINEAR, ctx.LINEAR)
    return tex


def render_output(
    doc: mx.Document, folder: Path, output: str, weights: list[dict[str, float]], size: int
) -> list[np.ndarray]:
    """Render nodegraph output ``output`` of ``doc`` (files relative to ``folder``) once per
    uniform set in ``weights`` -> one ``[size, size, 4]`` float32 image each."""
    import moderngl

    full = with_library(doc)
    graph = full.getNodeGraph(wmx.NODEGRAPH)
    vs, ps = generate(full, graph.getOutput(output))
    ctx = glw.create_context()
    try:
        prog = ctx.program(vertex_shader=vs, fragment_shader=ps)
        quad = np.array(  # x, y, z, s, t: two triangles over clip space and st's unit square
            [[-1, -1, 0, 0, 0], [1, -1, 0, 1, 0], [1, 1, 0, 1, 1]]
            + [[-1, -1, 0, 0, 0], [1, 1, 0, 1, 1], [-1, 1, 0, 0, 1]],
            np.float32,
        )
        vbo = ctx.buffer(quad.tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f 2f", "i_position", "i_texcoord_0")])
        textures = []
        unit = 0
        for inp in graph.getInputs():
            if inp.getType() == "filename" and inp.getName() in prog:
                tex = _texture(ctx, folder / inp.getValueString())
                tex.use(unit)
                prog[inp.getName()].value = unit
                textures.append(tex)
                unit += 1
        target = ctx.renderbuffer((size, size), 4, dtype="f4")
        fbo = ctx.framebuffer([target])
        images = []
        for uniforms in weights:
            for name, value in uniforms.items():
                if name in prog:
                    prog[name].value = float(value)
            fbo.use()
            fbo.clear(0.0, 0.0, 0.0, 0.0)
            vao.render(moderngl.TRIANGLES)
            raw = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32)
            images.append(raw.reshape(size, size, 4)[::-1].copy())  # row i: v = (i + 0.5) / N
        return images
    finally:
        ctx.release()
