"""The render pass's GL side: the asset as the wrinkle shader sees it (:func:`shader_setup`),
the textures it draws (the exact shipped bytes), the front orthographic view, and the
:class:`Renderer` that draws one pose into float targets and reads them back (:class:`Frame`).
:mod:`wrinklepipe.validate.render` compares the frames with the numpy model.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import moderngl
import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.geometry.normals import vertex_normals
from wrinklepipe.geometry.tangents import mikktspace_tangents
from wrinklepipe.shading import glsl
from wrinklepipe.shading.setup import MaskEntry, ShaderSetup
from wrinklepipe.validate import gl as glw
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.inputs import Texture, ValidationInput


def shader_setup(inp: ValidationInput) -> ShaderSetup:
    """The asset as the wrinkle shader sees it (:mod:`wrinklepipe.shading.setup`)."""
    a = inp.asset
    layers = mask_layers(inp)
    index = {t.name: i for i, t in enumerate(layers)}
    by_region = {e.region: e for e in inp.channel_table}
    entries = []
    split = None
    for r in a.region_names:
        e = by_region[r]
        entries.append(MaskEntry(index[e.texture], int(e.channel), split_part(e)))
        if e.split is not None:
            split = (index[e.split[0]], int(e.split[1]))
    base = inp.by_role("base")[0]
    states = inp.state_textures()
    colors = color_textures(inp)

    return ShaderSetup(
        encoding=a.encoding,
        policy=a.policy,
        scale=float(a.pd_scale),
        state_names=tuple(a.state_names),
        region_names=tuple(a.region_names),
        region_states=tuple(tuple(int(v) for v in row) for row in a.region_state_matrix()),
        entries=tuple(entries),
        layer_names=tuple(t.name for t in layers),
        layer_channels=tuple(t.channels for t in layers),
        split=split,
        base_layout=tx.xy_layout(base),
        state_layout=tx.xy_layout(states[0]),
        state_bits=states[0].bits,
        mapping=states[0].mapping,
        base_convention=base.convention,
        state_convention=states[0].convention,
        output="opengl",
        color_states=tuple(k for k, _ in colors[1]) if colors is not None else (),
    )


def color_textures(inp: ValidationInput) -> tuple[Texture, list[tuple[int, Texture]]] | None:
    """The base colour and the colour maps ``(state index, texture)`` in state order, when the
    render pass can draw them (one size and format for the colour maps); None otherwise (the
    render then draws the normals alone, the colour rules say what is wrong)."""
    base = inp.by_role("base_color")
    found = {t.state: t for t in inp.by_role("state_color")}
    states = [(k, found[s]) for k, s in enumerate(inp.asset.state_names) if s in found]
    if not base or not states:
        return None
    if len({(t.fmt, t.width, t.height) for _, t in states}) > 1:
        return None
    for t in [base[0], *(t for _, t in states)]:
        if t.is_block and (t.width % 4 or t.height % 4):
            return None
        if len(t.data) < t.expected_size():
            return None
    return base[0], states


def ortho_front(positions: np.ndarray, aspect: float = 1.0, margin: float = 1.05) -> np.ndarray:
    """Column-major MVP of an orthographic view along -Z fitted to the mesh's bounds."""
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    c = (lo + hi) / 2.0
    half = max((hi[0] - lo[0]) / 2.0 / aspect, (hi[1] - lo[1]) / 2.0, 1e-9) * margin
    zr = max((hi[2] - lo[2]) / 2.0, 1e-9) * 1.01
    m = np.array(
        [
            [1.0 / (half * aspect), 0.0, 0.0, -c[0] / (half * aspect)],
            [0.0, 1.0 / half, 0.0, -c[1] / half],
            [0.0, 0.0, -1.0 / zr, c[2] / zr],
            [0.0, 0.0, 0.0, 1.0],
        ],
        np.float32,
    )
    return m.T.copy()


@dataclass
class Frame:
    """One pose as rendered: images are ``[H, W, C]`` float32, row 0 at the top (None: not
    read back, see :meth:`Renderer.draw`)."""

    color: np.ndarray | None
    normal: np.ndarray
    uv: np.ndarray | None
    albedo: np.ndarray | None = None  # with colour states: the blended albedo (linear)
    object_normal: np.ndarray | None = None  # ... and the object-space normal it was lit with

    @property
    def covered(self) -> np.ndarray:
        return self.normal[..., 3] > 0.5


@dataclass
class Renderer:
    """GL state for one asset: programs, the mesh and the uploaded textures."""

    inp: ValidationInput
    size: int = 512
    ctx: Any = None
    gl: glw.RawGL | None = None
    names: list[int] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)
    #: (x, y, w, h) in GL window coordinates: the box of the pixels the mesh covers, from the
    #: first image read back (None before). Every draw covers the same pixels (the geometry
    #: does not move; the split draw only partitions the triangles) and every fragment writes
    #: alpha 1 into each target, so outside the box every target holds the clear value 0.
    covered_box: tuple[int, int, int, int] | None = None

    def __post_init__(self) -> None:
        self.ctx = glw.create_context()
        try:
            self._setup()
        except Exception:
            self.release()
            raise

    # ------------------------------------------------------------------ setup
    def _setup(self) -> None:
        ctx, inp = self.ctx, self.inp
        a = inp.asset
        self.gl = glw.RawGL.load()
        self.info = {
            "renderer": ctx.info.get("GL_RENDERER", ""),
            "gl_version": ctx.version_code,
            "size": self.size,
        }
        vs = glsl.vertex_shader()
        self.mask_layers = mask_layers(inp)
        self.setup = shader_setup(inp)
        self.prog = ctx.program(
            vertex_shader=vs, fragment_shader=glsl.validator_fragment(self.setup)
        )
        self.plain = ctx.program(
            vertex_shader=vs, fragment_shader=glsl.validator_fragment(self.setup, plain=True)
        )
        mesh: Mesh = a.mesh
        normals = mesh.normals
        if normals is None:
            normals = _vertex_normals(mesh)
        tangents = mesh.tangents
        if tangents is None or np.asarray(tangents).shape != (mesh.vertex_count, 4):
            tangents = mikktspace_tangents(mesh.positions, normals, mesh.uvs, mesh.indices)
        verts = np.concatenate(
            [
                np.asarray(mesh.positions, np.float32),
                np.asarray(normals, np.float32),
                np.asarray(tangents, np.float32),
                np.asarray(mesh.uvs, np.float32),
            ],
            axis=1,
        )
        self.vbo = ctx.buffer(np.ascontiguousarray(verts).tobytes())
        self.ibo = ctx.buffer(np.ascontiguousarray(mesh.indices, np.uint32).tobytes())
        layout = (self.vbo, "3f 3f 4f 2f", "in_position", "in_normal", "in_tangent", "in_uv")
        self.vao = ctx.vertex_array(self.prog, [layout], self.ibo, index_element_size=4)
        self.vao_plain = ctx.vertex_array(self.plain, [layout], self.ibo, index_element_size=4)
        # split draws: triangles that touch a non-zero texel of a weighted mask layer get the
        # wrinkle shader, the rest the plain one (identical output where every activation is 0)
        self.indices = np.ascontiguousarray(mesh.indices, np.uint32)
        self.ibo_w = ctx.buffer(reserve=max(self.indices.nbytes, 4), dynamic=True)
        self.ibo_p = ctx.buffer(reserve=max(self.indices.nbytes, 4), dynamic=True)
        self.vao_w = ctx.vertex_array(self.prog, [layout], self.ibo_w, index_element_size=4)
        self.vao_p = ctx.vertex_array(self.plain, [layout], self.ibo_p, index_element_size=4)
        self.mvp = ortho_front(np.asarray(mesh.positions, np.float64))
        s = self.size
        self.targets = [
            ctx.renderbuffer((s, s), 4, dtype="f4") for _ in range(5 if self.setup.has_color else 3)
        ]
        self.depth = ctx.depth_renderbuffer((s, s))
        self.fbo = ctx.framebuffer(self.targets, self.depth)
        # --- textures: the exact shipped bytes
        base = inp.by_role("base")[0]
        self.base_name = glw.upload(self.gl, [base], array=False)
        self.names.append(self.base_name)
        self.base_tex = ctx.external_texture(self.base_name, (base.width, base.height), 4, 0, "f1")
        self.base_tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
        states = inp.state_textures()
        self.state_name = glw.upload(self.gl, states, array=True)
        self.names.append(self.state_name)
        self.mask_name = glw.upload(self.gl, self.mask_layers, array=True)
        self.names.append(self.mask_name)
        self.color_names: tuple[int, int] | None = None
        colors = color_textures(inp) if self.setup.has_color else None
        if colors is not None:
            cbase = glw.upload(self.gl, [colors[0]], array=False)
            self.names.append(cbase)
            cstates = glw.upload(self.gl, [t for _, t in colors[1]], array=True)
            self.names.append(cstates)
            self.color_names = (cbase, cstates)
            factor = tuple(float(x) for x in inp.extra.get("color_factor", (1.0, 1.0, 1.0)))
        for prog in (self.prog, self.plain):
            self._set(prog, "u_mvp", self.mvp.tobytes())
            self._set(prog, "u_base", 0)
            if colors is not None:
                self._set(prog, "u_color_base", 3)
                self._set(prog, "u_colors", 4)
                self._set(prog, "u_color_factor", factor)
        p = self.prog
        self._set(p, "u_states", 1)
        self._set(p, "u_masks", 2)
        self._set(p, "u_pd_scale", float(a.pd_scale))
        self._set(p, "u_used", self.setup.used_vectors().tobytes())
        self.touch = triangle_layer_touch(self.mask_layers, mesh)  # [T, L] bool

    @staticmethod
    def _set(prog: Any, name: str, value: Any) -> None:
        if name not in prog:
            return
        if isinstance(value, bytes):
            u = prog[name]
            # the compiler trims arrays to the elements used; send that many
            size = u.array_length * u.dimension * 4
            prog[name].write(value[:size])
        else:
            prog[name].value = value

    def release(self) -> None:
        if self.gl is not None and self.names:
            glw.delete(self.gl, self.names)
            self.names = []
        if self.ctx is not None:
            self.ctx.release()
            self.ctx = None

    # ------------------------------------------------------------------ drawing
    def active_triangles(self, weights: np.ndarray | None) -> np.ndarray:
        """Triangles whose UV footprint touches a non-zero texel of a layer with a weight."""
        if weights is None:
            return np.zeros(len(self.indices), bool)
        on = self.setup.groups_with_weight(weights)[: self.touch.shape[1]]
        return self.touch[:, on].any(axis=1)

    def draw(
        self,
        weights: np.ndarray | None,
        plain: bool = False,
        read: bool = True,
        split: bool = True,
        color: bool = True,
        uv: bool = True,
    ) -> Frame | None:
        """Render one pose (``weights`` ``[R, K]``, or ``[R]`` under ``signed``).

        ``plain``: the plain normal-map shader everywhere (the benchmark's baseline).
        ``split``: the wrinkle shader only on triangles a weighted mask touches (the same
        image: elsewhere every activation is 0 and the model returns the base); ``False``
        draws every triangle with the wrinkle shader. ``color`` / ``uv``: read those images
        back (each read of a float target costs as much as a draw on llvmpipe; the UVs are the
        same in every pose, the geometry does not move).
        """

        ctx = self.ctx
        self.fbo.use()
        self.fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(moderngl.DEPTH_TEST)
        ctx.disable(moderngl.CULL_FACE)
        self.base_tex.use(0)
        glw.bind(self.gl, 1, self.state_name, array=True)
        glw.bind(self.gl, 2, self.mask_name, array=True)
        if self.color_names is not None:
            glw.bind(self.gl, 3, self.color_names[0], array=False)
            glw.bind(self.gl, 4, self.color_names[1], array=True)
        if plain:
            self.vao_plain.render(moderngl.TRIANGLES)
        else:
            self._set(self.prog, "u_w", self.setup.weight_vectors(weights).tobytes())
            if not split:
                self.vao.render(moderngl.TRIANGLES)
            else:
                act = self.active_triangles(weights)
                wi, pi = self.indices[act], self.indices[~act]
                if len(wi):
                    self.ibo_w.write(wi.tobytes())
                    self.vao_w.render(moderngl.TRIANGLES, vertices=wi.size)
                if len(pi):
                    self.ibo_p.write(pi.tobytes())
                    self.vao_p.render(moderngl.TRIANGLES, vertices=pi.size)
        if not read:
            ctx.finish()
            return None
        wanted = (color, True, uv) + ((not plain, not plain) if self.setup.has_color else ())
        imgs = [self._read(i) if w else None for i, w in enumerate(wanted)]
        if self.covered_box is None:
            self.covered_box = alpha_box(imgs[1])
        return Frame(*imgs)

    def _read(self, attachment: int) -> np.ndarray:
        """One target as ``[H, W, 4]`` float32, row 0 at the top. Once the covered box is
        known, only the box is read back (each float read costs as much as a draw on
        llvmpipe); the rest is the clear value, as a whole read would give."""
        s, box = self.size, self.covered_box
        if box is None:
            raw = self.fbo.read(components=4, attachment=attachment, dtype="f4")
            return np.frombuffer(raw, np.float32).reshape(s, s, 4)[::-1].copy()
        x, y, w, h = box
        raw = self.fbo.read(viewport=box, components=4, attachment=attachment, dtype="f4")
        out = np.zeros((s, s, 4), np.float32)
        out[s - y - h : s - y, x : x + w] = np.frombuffer(raw, np.float32).reshape(h, w, 4)[::-1]
        return out


def alpha_box(image: np.ndarray) -> tuple[int, int, int, int] | None:
    """(x, y, w, h) in GL window coordinates (origin bottom-left) of the pixels with a
    non-zero alpha in ``image`` ``[H, W, 4]`` (row 0 at the top); None when there are none."""
    written = image[..., 3] != 0
    rows, cols = np.flatnonzero(written.any(axis=1)), np.flatnonzero(written.any(axis=0))
    if not len(rows):
        return None
    h = image.shape[0]
    r0, r1, c0, c1 = int(rows[0]), int(rows[-1]), int(cols[0]), int(cols[-1])
    return c0, h - 1 - r1, c1 - c0 + 1, r1 - r0 + 1


def triangle_layer_touch(layers: list[Texture], mesh: Mesh) -> np.ndarray:
    """``[T, L]``: does triangle t's UV box reach a non-zero texel of mask layer l (bilinear
    footprint included)? Summed-area tables make it one vectorised lookup per triangle."""
    uv = np.asarray(mesh.uvs, np.float64)[np.asarray(mesh.indices, np.int64)]  # [T, 3, 2]
    lo, hi = uv.min(axis=1), uv.max(axis=1)
    out = np.zeros((len(uv), len(layers)), bool)
    for i, t in enumerate(layers):
        v = tx.decode_values(t)
        h, w = v.shape[:2]
        nz = (np.abs(v).max(axis=-1) > 0).astype(np.int64)
        sat = np.zeros((h + 1, w + 1), np.int64)
        sat[1:, 1:] = nz.cumsum(0).cumsum(1)
        x0 = np.clip(np.floor(lo[:, 0] * w - 0.5), 0, w - 1).astype(np.int64)
        x1 = np.clip(np.floor(hi[:, 0] * w - 0.5) + 1, 0, w - 1).astype(np.int64)
        y0 = np.clip(np.floor(lo[:, 1] * h - 0.5), 0, h - 1).astype(np.int64)
        y1 = np.clip(np.floor(hi[:, 1] * h - 0.5) + 1, 0, h - 1).astype(np.int64)
        count = sat[y1 + 1, x1 + 1] - sat[y0, x1 + 1] - sat[y1 + 1, x0] + sat[y0, x0]
        out[:, i] = count > 0
    return out


def _vertex_normals(mesh: Mesh) -> np.ndarray:
    return vertex_normals(np.asarray(mesh.positions, np.float32), np.asarray(mesh.indices))


def split_part(e: object) -> int:
    """0: an unsplit region; 1 / 2: the left / right region of an lr-split channel."""
    if e.split is None:
        return 0
    return 1 if e.side == "left" else 2 if e.side == "right" else 0


def mask_layers(inp: ValidationInput) -> list[Texture]:
    used = []
    for e in inp.channel_table:
        for name in (e.texture, e.split[0] if e.split else None):
            if name is not None and name not in used:
                used.append(name)
    return [
        inp.texture(n) for n in sorted(used, key=lambda n: [t.name for t in inp.textures].index(n))
    ]
