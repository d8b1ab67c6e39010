"""The render pass: draw the mesh with the GLSL wrinkle model, compare with the numpy model.

The poses are those the drivers produce (:func:`wrinklepipe.drivers.poses.driver_poses`):
neutral, the expression table for ``expressions`` drivers (or none), and for other drivers'
curves the frames where each region's weight peaks, named by time (``blendshapes@1.000s``).
The mesh keeps its rest shape in every pose (every pixel compares the same surface point across
poses and with the numpy reference; a curve frame's morph weights are listed in the info). The
view is the front orthographic view fitted to the
mesh, which for a whole document is its wrinkled primitives only (other parts are left out).
For each pose the generated shaders (:mod:`wrinklepipe.shading`) render, in
one draw, a shaded image, the tangent-space normal buffer (float32) and the UV buffer. The numpy
reference (:func:`wrinklepipe.model.blend`) is evaluated at the rasterised UVs on the same
shipped texels (bilinear, clamp to edge, no mipmaps, like the GPU), so the two must agree to
within the GPU's filtering precision; a wrong colour-space tag or an unsupported format shows as
a disagreement. Wrinkles must change the render only where the source masks x weights are non-zero.

With colour states the shaders also blend colour (:mod:`wrinklepipe.shading.glsl`): the base
colour and the colour maps are uploaded as sRGB textures (the GPU decodes each texel before it
filters), the shaded image is lit with the blended albedo, and two more targets hold the albedo
and the object-space normal. The numpy colour model (:func:`wrinklepipe.model.combine_color`)
of the same shipped texels (decoded, then sampled bilinearly) gives the albedo, and lit with the
same light on the GPU's normal (:func:`shade_albedo`) the lit colour; both are compared in
CIEDE2000 (WP-RND-005).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import moderngl
import numpy as np
from scipy import ndimage

from wrinklepipe import model
from wrinklepipe.asset import Mesh
from wrinklepipe.codec import srgb
from wrinklepipe.geometry.normals import vertex_normals
from wrinklepipe.geometry.tangents import mikktspace_tangents
from wrinklepipe.metrics import DECIMALS, Budget, angle_deg, delta_e, weighted_stats
from wrinklepipe.palette import region_colours_linear
from wrinklepipe.shading import glsl
from wrinklepipe.shading.setup import MaskEntry, ShaderSetup
from wrinklepipe.validate import fidelity_pictures as fp
from wrinklepipe.validate import gl as glw
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.inputs import Texture, ValidationInput
from wrinklepipe.validate.poses import render_poses
from wrinklepipe.validate.rules_fidelity import render_fidelity

#: WP-RND-003 judges an expression only where its strongly active pixels are more than this share
#: of the render target (50 pixels at 512^2, as it was before the size followed the maps), so a
#: smaller target asks for the same screen area, not for more of it.
MIN_STRONG_SHARE = 50.0 / 512**2


def shader_setup(inp: ValidationInput) -> ShaderSetup:
    """The asset as the wrinkle shader sees it (:mod:`wrinklepipe.shading.setup`)."""
    a = inp.asset
    layers = _mask_layers(inp)
    index = {t.name: i for i, t in enumerate(layers)}
    by_region = {e.region: e for e in inp.channel_table}
    entries = []
    split = None
    for r in a.region_names:
        e = by_region[r]
        entries.append(MaskEntry(index[e.texture], int(e.channel), _split_part(e)))
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


def shade_albedo(n_obj: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """``shaders/color.glsl``'s lighting in numpy: the key light, ambient and Blinn specular on
    ``albedo`` (linear), for object-space normals ``n_obj`` ``[N, 3]`` (float32 arithmetic)."""
    f = np.float32
    light = np.array([-0.3713907, 0.5570860, 0.7427813], f)
    half = light + np.array([0.0, 0.0, 1.0], f)
    half /= np.sqrt(np.dot(half, half))
    n = np.asarray(n_obj, f)
    diffuse = np.maximum(n @ light, f(0.0))
    spec = np.maximum(n @ half, f(0.0)) ** f(48.0) * f(0.25)
    return (np.asarray(albedo, f) * (f(0.12) + f(0.88) * diffuse)[:, None] + spec[:, None]).astype(
        f
    )


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
        self.mask_layers = _mask_layers(inp)
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


def _split_part(e: object) -> int:
    """0: an unsplit region; 1 / 2: the left / right region of an lr-split channel."""
    if e.split is None:
        return 0
    return 1 if e.side == "left" else 2 if e.side == "right" else 0


def _mask_layers(inp: ValidationInput) -> list[Texture]:
    used = []
    for e in inp.channel_table:
        for name in (e.texture, e.split[0] if e.split else None):
            if name is not None and name not in used:
                used.append(name)
    return [
        inp.texture(n) for n in sorted(used, key=lambda n: [t.name for t in inp.textures].index(n))
    ]


# ------------------------------------------------------------------------------------------------
# numpy reference at the rasterised UVs


@dataclass
class Samples:
    """Shipped (and source) data sampled at the covered pixels' UVs, shared by all poses."""

    base: np.ndarray  # [N, 3]
    states: np.ndarray  # [K, N, C]
    masks: np.ndarray  # [R, N] shipped
    src_masks: np.ndarray | None  # [R, N]
    src_relief: np.ndarray | None  # [K, N] degrees between source state and base


def sample_reference(ctx: Context, uv: np.ndarray) -> Samples:
    inp, a = ctx.inp, ctx.asset
    bt = ctx.base_tex
    # filter the stored values, then decode (as the sampler and the shader do)
    base = tx.values_to_normals(tx.bilinear(ctx.values(bt), uv), tx.xy_layout(bt), ctx.flips(bt))
    states = []
    for t in inp.state_textures():
        v = tx.bilinear(ctx.values(t), uv)
        states.append(
            tx.decode_state(
                v, a.encoding, tx.xy_layout(t), a.pd_scale, t.mapping, t.bits, ctx.flips(t)
            )
        )
    sampled: dict[str, np.ndarray] = {}
    masks = []
    by_region = {e.region: e for e in inp.channel_table}

    def sample(name: str) -> np.ndarray:
        if name not in sampled:
            sampled[name] = tx.bilinear(ctx.values(inp.texture(name)), uv)
        return sampled[name]

    for r in a.region_names:
        e = by_region[r]
        m = sample(e.texture)[:, e.channel]
        part = _split_part(e)
        if part:
            s = sample(e.split[0])[:, e.split[1]]
            m = m * s if part == 1 else m * (1.0 - s)
        masks.append(m)
    src_masks = src_relief = None
    if not inp.has_source and states:
        # no source: the relief each shipped state adds at full activation
        rel = []
        for k in range(len(states)):
            w = model.combine(base, states[k][None], np.ones((1, len(uv)), np.float32), a.encoding)
            rel.append(angle_deg(w, base))
        src_relief = np.stack(rel)
    src = ctx.source_at_shipped_size
    if src is not None:
        # the source at the shipped sizes: resolution choices are WP-TEX-006's business
        src_masks = tx.bilinear(np.moveaxis(src["masks"], 0, -1), uv).T
        b = model.normalize(tx.bilinear(src["base_at_states"], uv))
        rel = []
        for s in src["states"]:
            w = model.normalize(tx.bilinear(s, uv))
            rel.append(angle_deg(w, b))
        src_relief = np.stack(rel) if rel else None
    return Samples(base, np.stack(states), np.stack(masks), src_masks, src_relief)


def _compare_colors(
    ctx: Context,
    setup: ShaderSetup,
    uv: np.ndarray,
    cov: np.ndarray,
    frames: dict[str, Frame],
    by_name: dict[str, Any],
    samples: Samples,
    info: dict[str, Any],
    where: str,
) -> list[Issue]:
    """The GPU's albedo and lit colour against the numpy colour model of the same shipped
    texels, in CIEDE2000 (WP-RND-005)."""
    colors = color_textures(ctx.inp)
    if colors is None:
        return []
    factor = np.asarray(ctx.inp.extra.get("color_factor", (1.0, 1.0, 1.0)), np.float32)

    def linear(t: Texture) -> np.ndarray | None:
        q = ctx.texels(t)
        return None if q is None else srgb.decode_texels(q[..., :3])

    base_lin = linear(colors[0])
    states_lin = [linear(t) for _, t in colors[1]]
    if base_lin is None or any(s is None for s in states_lin):
        return []
    # decode each texel, then filter (an sRGB sampler); the factor after (it is linear)
    cb = tx.bilinear(base_lin, uv) * factor
    cs = np.stack([tx.bilinear(s, uv) for s in states_lin])
    a = ctx.asset
    per_pose: dict[str, Any] = {}
    worst: tuple[str, float] | None = None
    limit = ctx.options.gpu_max_p99_delta_e
    for label, fr in frames.items():
        if fr.albedo is None or fr.object_normal is None:
            continue
        act = model.activations(samples.masks, by_name[label].weights, a.policy)
        albedo = model.combine_color(cb, cs, act[list(setup.color_states)])
        gpu_albedo = fr.albedo[cov][:, :3]
        n_obj = fr.object_normal[cov][:, :3]
        lit = np.clip(shade_albedo(n_obj, albedo), 0.0, 1.0)
        gpu_lit = np.clip(fr.color[cov][:, :3], 0.0, 1.0)
        st = {
            "albedo": _stats(delta_e(gpu_albedo, albedo).astype(np.float32)),
            "lit": _stats(delta_e(gpu_lit, lit).astype(np.float32)),
        }
        per_pose[label] = st
        p99 = max(st["albedo"]["p99"], st["lit"]["p99"])
        if p99 > limit and (worst is None or p99 > worst[1]):
            worst = (label, p99)
    info["color_vs_reference_delta_e"] = per_pose
    ctx.metrics["gpu_vs_reference_delta_e"] = per_pose
    if worst is None:
        return []
    bad = [k for k, v in per_pose.items() if max(v["albedo"]["p99"], v["lit"]["p99"]) > limit]
    return [
        make_issue(
            "WP-RND-005",
            f"{len(bad)} of {len(per_pose)} poses: the GPU's colour (albedo or lit) differs from "
            f"the numpy colour model of the same bytes by p99 over {limit:g} CIEDE2000; worst "
            f"{worst[0]}: p99 {worst[1]:.2f}",
            where,
        )
    ]


def _stats(e: np.ndarray) -> dict[str, float]:
    """The one measure's statistics of per-pixel errors, as the metrics tables show them."""
    s = weighted_stats(e)
    return {
        "mean": round(s.mean, DECIMALS),
        "p99": round(s.p99, DECIMALS),
        "max": round(s.max, DECIMALS),
    }


def _skip(reason: str, where: str) -> tuple[list[Issue], dict[str, Any], dict[str, Any]]:
    return (
        [make_issue("WP-RND-004", f"render pass skipped: {reason}", where)],
        {"skipped": reason},
        {},
    )


def can_render(ctx: Context) -> str:
    """Empty when the render pass can run on this input, else the reason it cannot."""
    inp, a = ctx.inp, ctx.asset
    if a.mesh is None or a.mesh.uvs is None:
        return "no mesh with UVs"
    if not a.regions or not a.state_names:
        return "no regions or no states"
    if a.encoding not in model.ENCODINGS or a.policy not in model.POLICIES:
        return "unknown encoding or policy"
    if a.policy == "signed" and len(a.state_names) != 2:
        return "policy 'signed' needs two states"
    if not inp.by_role("base") or ctx.values(ctx.base_tex) is None:
        return "no decodable base texture"
    sts = inp.state_textures()
    if not sts or any(t is None or ctx.values(t) is None for t in sts):
        return "a state texture is missing or undecodable"
    if len({(t.fmt, t.width, t.height, t.convention) for t in sts}) > 1:
        return "state textures differ in size, format or declared convention"
    if ctx.shipped_masks is None:
        return "the channel table or mask textures are unusable"
    splits = {e.split for e in inp.channel_table if e.split is not None}
    if len(splits) > 1:
        return "more than one split channel (lr-split layout)"
    layers = _mask_layers(inp)
    if len({(t.fmt, t.width, t.height) for t in layers}) > 1:
        return "mask textures differ in size or format"
    problems = shader_setup(inp).problems()
    if problems:
        return "; ".join(problems)
    for t in [ctx.base_tex, *sts, *layers]:
        if t.is_block and (t.width % 4 or t.height % 4):
            return f"{t.name!r} is block-compressed with a size that is not a multiple of 4"
    return ""


def render_pass(ctx: Context) -> tuple[list[Issue], dict[str, Any], dict[str, Any]]:
    """Render the poses the drivers produce (:func:`render_poses`); returns (issues, render
    info, images)."""
    inp, a, o = ctx.inp, ctx.asset, ctx.options
    where = inp.pointer("meta")
    reason = can_render(ctx)
    if reason:
        return _skip(reason, where)
    try:
        r = Renderer(inp, ctx.render_size)
    except glw.GLUnavailable as exc:
        return _skip(str(exc), where)
    except Exception as exc:  # noqa: BLE001 - a driver refusing a shader or format
        return _skip(f"{type(exc).__name__}: {str(exc).strip()[:300]}", where)
    images: dict[str, Any] = {}
    issues: list[Issue] = []
    info = dict(r.info)
    poses = render_poses(inp)
    by_name = {p.name: p for p in poses}
    info["pose_sources"] = {
        p.name: {"curve": p.curve, "time": p.time, "regions": list(p.regions), "morphs": p.morphs}
        for p in poses
        if p.curve is not None
    }
    try:
        t0 = time.perf_counter()
        frames = {}
        for pose in poses:  # the UVs are read once (the neutral pose's)
            frames[pose.name] = r.draw(pose.weights, uv=pose.name == "neutral")
        info["render_s"] = round(time.perf_counter() - t0, 4)
        plain = r.draw(None, plain=True, color=False, uv=False)
    except Exception as exc:  # noqa: BLE001 - a driver failing mid-draw: report, do not crash
        return _skip(f"{type(exc).__name__}: {str(exc).strip()[:300]}", where)
    finally:
        r.release()
    t0 = time.perf_counter()
    neutral = frames["neutral"]
    cov = neutral.covered
    if not cov.any():
        return _skip("the mesh covers no pixel of the render target", where)
    uv = neutral.uv[cov][:, :2]
    samples = sample_reference(ctx, uv)
    per_pose: dict[str, Any] = {}
    gpu_bad = []
    leaks = []
    missing = []
    n_gpu_neutral = neutral.normal[cov][:, :3]
    dilate = np.ones((5, 5), bool)
    min_strong = MIN_STRONG_SHARE * cov.size
    for label, fr in frames.items():
        w = by_name[label].weights
        ref = model.blend(samples.base, samples.states, samples.masks, w, a.encoding, a.policy)
        gpu = fr.normal[cov][:, :3]
        err = angle_deg(gpu, ref)
        st = _stats(err)
        entry: dict[str, Any] = {"gpu_vs_reference_deg": st}
        if not Budget(o.gpu_max_mean_deg, o.gpu_max_p99_deg).ok(weighted_stats(err)):
            gpu_bad.append((label, st))
        emap = np.zeros(cov.shape, np.float32)
        emap[cov] = err
        images[f"gpu_error/{label}"] = emap
        images[f"render/{label}"] = fr.color[..., :3]
        if label != "neutral":
            change = angle_deg(gpu, n_gpu_neutral)
            changed = change > o.wrinkle_deg
            masks_expected = samples.src_masks if samples.src_masks is not None else samples.masks
            act = model.activations(masks_expected, w, a.policy)
            active = np.abs(act).sum(axis=0) > 1e-4
            act_img = np.zeros(cov.shape, bool)
            act_img[cov] = active
            act_img = ndimage.binary_dilation(act_img, dilate, iterations=2)
            leak = changed & ~act_img[cov]
            n_leak = int(leak.sum())
            entry["changed_pixels"] = int(changed.sum())
            entry["leak_pixels"] = n_leak
            if n_leak > o.leak_fraction * cov.sum():
                leaks.append((label, n_leak))
            if samples.src_relief is not None and len(samples.src_relief) == len(act):
                k_rel = samples.src_relief
                full_act = act > 0.5
                strong = (full_act & (k_rel > 4.0 * o.wrinkle_deg)).any(axis=0)
                quiet = strong & (change < 0.5 * o.wrinkle_deg)
                entry["strong_pixels"] = int(strong.sum())
                entry["quiet_pixels"] = int(quiet.sum())
                if strong.sum() > min_strong and quiet.sum() > 0.25 * strong.sum():
                    missing.append((label, int(quiet.sum()), int(strong.sum())))
            cmap = np.zeros(cov.shape, np.float32)
            cmap[cov] = change
            images[f"change/{label}"] = cmap
        per_pose[label] = entry
    if r.setup.has_color:
        issues += _compare_colors(ctx, r.setup, uv, cov, frames, by_name, samples, info, where)
    plain_err = angle_deg(plain.normal[cov][:, :3], samples.base)
    info["plain_vs_reference_deg"] = _stats(plain_err)
    info["covered_pixels"] = int(cov.sum())
    info["poses"] = per_pose
    info["compare_s"] = round(time.perf_counter() - t0, 4)
    ctx.metrics["gpu_vs_reference_deg"] = {
        k: v["gpu_vs_reference_deg"] for k, v in per_pose.items()
    }
    # fidelity in screen space: the GPU render against the full-resolution source's
    gpu = {e: fr.normal[cov][:, :3] for e, fr in frames.items() if e is not None}
    f_issues, f_info = render_fidelity(ctx, uv, gpu, samples.masks)
    issues += f_issues
    for e, err in f_info.get("maps", {}).items():
        emap = np.zeros(cov.shape, np.float32)
        emap[cov] = err
        images[f"fidelity_render/{e}"] = emap
        # the full-resolution source's render beside the shipped one: blended normals per pixel
        for key, n in (("render_source", f_info["normals"][e]), ("render_shipped", gpu[e])):
            pic = np.ones(cov.shape + (3,), np.float32)
            pic[cov] = fp.normal_picture(n)
            images[f"{key}/{e}"] = pic
    # mask overlay from the UV buffer: shipped masks coloured per region over the neutral render
    overlay = np.zeros(cov.shape + (3,), np.float32)
    colors = region_colours_linear(len(a.regions))  # Tol's colour-blind-safe schemes
    overlay[cov] = np.clip(samples.masks.T @ colors, 0.0, 1.0)
    images["mask_overlay"] = 0.5 * neutral.color[..., :3] + 0.5 * overlay
    images["_region_colors"] = colors
    # crop the contact sheet to the masked area (with a margin), square
    union = np.zeros(cov.shape, bool)
    union[cov] = samples.masks.max(axis=0) > 1.0 / 255.0
    if union.any():
        ys, xs = np.nonzero(union)
        cy, cx = (ys.min() + ys.max()) / 2, (xs.min() + xs.max()) / 2
        half = int(max(ys.max() - ys.min(), xs.max() - xs.min()) * 0.6) + 4
        y0, x0 = max(int(cy) - half, 0), max(int(cx) - half, 0)
        y1, x1 = min(int(cy) + half, cov.shape[0]), min(int(cx) + half, cov.shape[1])
        info["crop"] = [int(x0), int(y0), int(x1), int(y1)]
        for k in list(images):
            if k.split("/")[0] in (
                "render",
                "gpu_error",
                "change",
                "fidelity_render",
                "render_source",
                "render_shipped",
            ):
                images[k] = images[k][y0:y1, x0:x1]
    if gpu_bad:
        worst = max(gpu_bad, key=lambda x: x[1]["p99"])
        issues.append(
            make_issue(
                "WP-RND-001",
                f"{len(gpu_bad)} of {len(frames)} poses: GPU normal buffer vs numpy reference "
                f"over {o.gpu_max_mean_deg:g} mean / {o.gpu_max_p99_deg:g} p99 degrees; worst "
                f"{worst[0]}: mean {worst[1]['mean']:.2f}, p99 {worst[1]['p99']:.2f}",
                where,
            )
        )
    if leaks:
        worst = max(leaks, key=lambda x: x[1])
        issues.append(
            make_issue(
                "WP-RND-002",
                f"{len(leaks)} expression(s) change the render where masks x weights are zero; "
                f"worst {worst[0]}: {worst[1]} pixels",
                inp.pointer("masks"),
            )
        )
    if missing:
        worst = max(missing, key=lambda x: x[1] / x[2])
        issues.append(
            make_issue(
                "WP-RND-003",
                f"{len(missing)} expression(s) show no wrinkle where the source is fully "
                f"active; worst {worst[0]}: {worst[1]} of {worst[2]} pixels unchanged",
                inp.pointer("masks"),
            )
        )
    return issues, info, images
