"""Tangent-space normal maps baked from high-resolution meshes into a low mesh's UV layout.

What a baker (xNormal, Marmoset Toolbag, Substance, Blender) does, in the frame the pipeline
ships:

- **Samples.** The low mesh's UV layout at ``size`` x ``size`` with ``supersample`` x
  ``supersample`` samples per texel (:func:`wrinklepipe.geometry.uv_samples.uv_samples`); at
  each, the low surface point ``P`` and its frame, interpolated barycentrically from the
  vertices exactly as the shaders do (``shaders/common.glsl``): ``N = normalize(normal)``,
  ``T = normalize(tangent.xyz - N (N . tangent.xyz))``, ``B = cross(N, T) * sign(tangent.w)``.
  The tangents are the mesh's own (MikkTSpace where convert computes them), so a map baked
  here decodes on the shipped mesh to the sculpt's normal.
- **Rays.** From the cage point ``P + d N`` towards ``-N`` over ``2 d``: the first surface of
  the high mesh within ``d`` of the low surface, outside or inside (``d``: ``max_distance``;
  ``None`` measures it: twice the 99.9th percentile of the distance from the low surface to
  the high one along ``+-N``, on the samples of a 256 x 256 map, at least 1e-4 of the low
  mesh's size). Ray casting is Embree's (``embreex``), single precision.
- **The sculpt's normal** at the hit: its vertex normals interpolated with the hit's
  barycentrics and normalised (the file's normals; a mesh without them gets area-weighted
  vertex normals, as sculpting tools export smooth shading). In the frame:
  ``n_ts = (n . T, n . B, n . N)``, OpenGL green (+Y).
- **Texels.** The mean of a texel's samples that hit, normalised (the supersampling is the
  anti-aliasing). Covered texels no sample of which hit are flat ``(0, 0, 1)`` and counted.
  Then edge padding: ``padding`` texels beyond the UV islands take the nearest island texel's
  normal (:func:`~wrinklepipe.geometry.uv_samples.pad_islands`); farther texels are flat.

Every high mesh is baked with the same samples, frames and rays (one sampling, one frame): a
high mesh identical to another bakes to identical bytes. The map is baked in tiles of
:data:`TILE` x :data:`TILE` texels and each tile's samples in chunks of
:data:`~wrinklepipe.geometry.uv_samples.CHUNK_SAMPLES`, so the working set is bounded whatever
the map's size; the maps themselves are float32 ``[size, size, 3]``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.normals import vertex_normals
from wrinklepipe.geometry.uv_samples import UvSamples, interpolate, pad_islands, tiles, uv_samples

NAME = "bake"
#: Texels per side of the tiles the map is baked in: the working set is a tile's samples
#: (``TILE^2 supersample^2``), whatever the map's size.
TILE = 1024


@dataclass(frozen=True)
class BakeOptions:
    """Options of :func:`bake_normal_maps`.

    size: maps are ``size`` x ``size`` texels.
    supersample: samples per texel per axis (anti-aliasing; 2 = 4 samples a texel).
    max_distance: ray distance ``d`` either side of the low surface, mesh units; None: measured.
    padding: texels of edge padding beyond UV islands; None: ``max(2, size // 128)``.
    """

    size: int = 2048
    supersample: int = 2
    max_distance: float | None = None
    padding: int | None = None

    @property
    def padding_px(self) -> int:
        return self.padding if self.padding is not None else max(2, self.size // 128)


@dataclass
class HighMesh:
    """A high-resolution mesh to bake: positions ``[V, 3]``, triangles ``[T, 3]``, unit vertex
    normals ``[V, 3]`` (None: area-weighted ones are computed) and a name for messages."""

    positions: np.ndarray
    indices: np.ndarray
    normals: np.ndarray | None = None
    name: str = "high"


class RayScene:
    """Embree's BVH over one triangle mesh; :meth:`first_hit` casts rays (float32)."""

    def __init__(self, positions: np.ndarray, indices: np.ndarray) -> None:
        self.scene = rtcore_scene.EmbreeScene()
        tri = np.ascontiguousarray(indices, dtype=np.int32).reshape(-1, 3)
        pos = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
        TriangleMesh(self.scene, pos, tri)

    def first_hit(
        self, origins: np.ndarray, directions: np.ndarray, distance: np.ndarray | float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per ray: the triangle hit first within ``distance`` (-1: none), the hit's
        barycentrics ``u``, ``v`` (the point is ``(1-u-v) p0 + u p1 + v p2``) and distance."""
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        dist = np.broadcast_to(np.asarray(distance, dtype=np.float32), (len(o),))
        res = self.scene.run(o, d, dists=np.ascontiguousarray(dist), output=1)
        return (
            np.asarray(res["primID"], np.int64),
            np.asarray(res["u"], np.float64),
            np.asarray(res["v"], np.float64),
            np.asarray(res["tfar"], np.float64),
        )


@dataclass
class BakeResult:
    """Baked maps ``[size, size, 3]`` float32 unit tangent-space normals (one per high mesh, in
    order, glTF UV convention), the covered texels, per high mesh the samples and the covered
    texels with no hit, the ray distance used and notes."""

    maps: list[np.ndarray]
    covered: np.ndarray
    samples: int
    missed_samples: list[int]
    missed_texels: list[int]
    max_distance: float
    notes: list[str] = field(default_factory=list)


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.sqrt((v * v).sum(axis=-1, keepdims=True))
    ok = n[..., 0] > 1e-12
    return v / np.where(ok[..., None], n, 1), ok


def vertex_frames(low: Mesh) -> np.ndarray:
    """The per-vertex data a sample's frame is interpolated from: ``[V, 10]`` float32, position,
    normal and tangent (xyz, w) side by side (one gather per corner)."""
    return np.ascontiguousarray(
        np.concatenate(
            [
                np.asarray(low.positions, np.float32),
                np.asarray(low.normals, np.float32),
                np.asarray(low.tangents, np.float32),
            ],
            axis=1,
        )
    )


def sample_frames(
    low: Mesh, samples: UvSamples, part: slice, per_vertex: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per sample of ``part``: the low surface point ``P`` and the shipped frame ``T``, ``B``,
    ``N`` (``[S, 3]`` float32 each; see the module doc). ``per_vertex``: :func:`vertex_frames`
    of ``low``, when the caller has it."""
    pv = vertex_frames(low) if per_vertex is None else per_vertex
    x = interpolate(samples, low.indices, pv, part)
    p = x[:, 0:3]
    n, _ = _unit(x[:, 3:6])
    t = x[:, 6:9] - n * (n * x[:, 6:9]).sum(axis=1, keepdims=True)
    t, ok = _unit(t)
    t[~ok] = (1.0, 0.0, 0.0)  # as the shader's fallback
    b = np.cross(n, t)
    b[x[:, 9] < 0.0] *= -1.0
    return p, t, b, n


def _high_normals(h: HighMesh) -> tuple[np.ndarray, list[str]]:
    if h.normals is not None:
        n, ok = _unit(np.asarray(h.normals, np.float64))
        if ok.all():
            return n, []
    n = vertex_normals(np.asarray(h.positions, np.float32), np.asarray(h.indices))
    return n.astype(np.float64), [f"{h.name}: computed area-weighted vertex normals"]


def auto_distance(low: Mesh, scenes: Sequence[RayScene], size_of_mesh: float) -> float:
    """Twice the 99.9th percentile of the low-to-high distance along ``+-N`` (see the module
    doc), over every high mesh, on the samples of a 256 x 256 map (at most 65 536)."""
    samples = uv_samples(low.uvs, low.indices, 256, 1)
    p, _, _, n = sample_frames(low, samples, slice(None))
    far = 0.1 * size_of_mesh
    found = []
    for scene in scenes:
        best = np.full(len(p), np.inf)
        for sign in (1.0, -1.0):
            tri, _, _, t = scene.first_hit(p, sign * n, far)
            best = np.where(tri >= 0, np.minimum(best, t), best)
        hit = best[np.isfinite(best)]
        if len(hit):
            found.append(float(np.quantile(hit, 0.999)))
    floor = 1e-4 * size_of_mesh
    return max(2.0 * max(found, default=0.0), floor)


def bake_normal_maps(
    low: Mesh, highs: Sequence[HighMesh], options: BakeOptions | None = None
) -> BakeResult:
    """Bake every high mesh onto ``low``'s UV layout (see the module doc). ``low`` needs UVs,
    normals and tangents (:func:`wrinklepipe.pipeline.prepare.prepare_mesh` gives them)."""
    o = options or BakeOptions()
    src = low.name
    if low.uvs is None or low.normals is None or low.tangents is None:
        raise input_error(src, "the low mesh needs UVs, normals and tangents to bake onto")
    if o.size < 4 or o.supersample < 1:
        raise input_error("<arguments>", f"size must be >= 4, got {o.size}", "--size")
    if o.max_distance is not None and not (np.isfinite(o.max_distance) and o.max_distance > 0):
        raise input_error("<arguments>", "the ray distance must be a positive number")
    notes: list[str] = []
    scenes = []
    normals = []
    for h in highs:
        if len(h.indices) == 0:
            raise input_error(h.name, "the mesh has no triangles")
        scenes.append(RayScene(h.positions, h.indices))
        n, more = _high_normals(h)
        normals.append(n)
        notes += more
    hi_idx = [np.asarray(h.indices, np.int32).reshape(-1, 3) for h in highs]
    p = np.asarray(low.positions, np.float64)
    size_of_mesh = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    d = o.max_distance or auto_distance(low, scenes, size_of_mesh)
    size = o.size
    flat = np.array([0.0, 0.0, 1.0], np.float32)
    maps = [np.empty((size, size, 3), np.float32) for _ in highs]
    got = [np.zeros((size, size), bool) for _ in highs]
    covered = np.zeros((size, size), bool)
    missed = [0 for _ in highs]
    total = 0
    per_vertex = vertex_frames(low)
    for r0, r1, c0, c1 in tiles(size, TILE):
        samples = uv_samples(low.uvs, low.indices, size, o.supersample, window=(r0, r1, c0, c1))
        th, tw = r1 - r0, c1 - c0
        total += samples.count
        local = (samples.texel // size - r0) * tw + (samples.texel % size - c0)
        covered[r0:r1, c0:c1] = np.bincount(local, minlength=th * tw).reshape(th, tw) > 0
        sums = [np.zeros((th * tw, 3)) for _ in highs]
        hits = [np.zeros(th * tw) for _ in highs]
        for part in samples.chunks():
            pp, t, b, n = sample_frames(low, samples, part, per_vertex)
            origins = pp + np.float32(d) * n
            back = -n
            lt = local[part]
            for k, (scene, hn) in enumerate(zip(scenes, normals)):
                tri, u, v, _ = scene.first_hit(origins, back, 2.0 * d)
                ok = tri >= 0
                missed[k] += int(len(ok) - ok.sum())
                if not ok.any():
                    continue
                sel = slice(None) if ok.all() else ok
                hi_tri = hi_idx[k][tri[sel]]
                uo = u[sel, None].astype(np.float32)
                vo = v[sel, None].astype(np.float32)
                nh = hn[hi_tri[:, 0]] * (1.0 - uo - vo)
                nh += hn[hi_tri[:, 1]] * uo
                nh += hn[hi_tri[:, 2]] * vo
                nh, _ = _unit(nh)
                # samples come texel by texel: add into the chunk's texel range only
                tx = lt[sel]
                t0 = int(tx[0])
                span = int(tx[-1]) - t0 + 1
                rel = tx - t0
                for c, axis in enumerate((t, b, n)):
                    comp = (nh * axis[sel]).sum(axis=1)
                    sums[k][t0 : t0 + span, c] += np.bincount(rel, comp, minlength=span)
                hits[k][t0 : t0 + span] += np.bincount(rel, minlength=span)
        for k in range(len(highs)):
            img, ok = _unit(sums[k] / np.maximum(hits[k], 1.0)[:, None])
            has = (hits[k] > 0) & ok
            img[~has] = flat
            maps[k][r0:r1, c0:c1] = img.reshape(th, tw, 3)
            got[k][r0:r1, c0:c1] = has.reshape(th, tw)
    if total == 0:
        raise input_error(src, f"the UV layout covers no texel at {size}^2")
    missed_tex = []
    for k, h in enumerate(highs):
        missed_tex.append(int((covered & ~got[k]).sum()))
        inward = float(np.median(maps[k][got[k]][:, 2])) if got[k].any() else 1.0
        if inward < 0:
            notes.append(
                f"{h.name}: the sculpt's normals point into the surface (reversed winding?)"
            )
        maps[k] = pad_islands(maps[k], covered, o.padding_px, fill=flat)
    return BakeResult(maps, covered, total, missed, missed_tex, float(d), notes)
