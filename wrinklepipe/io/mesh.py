"""Mesh ingest by file extension -> :class:`wrinklepipe.asset.Mesh`.

- :func:`load_meshes` returns one Mesh per glTF triangle primitive (per node instance), per USD
  ``Mesh`` prim, or per OBJ object/group.
- :func:`load_mesh` merges them into ONE Mesh (what the wrinkle pipeline wants for a face):
  indices are offset, morph targets are unioned by name (a part without a target gets zero
  deltas), skins are unioned by joint name, and an attribute only some parts have is filled
  (UVs 0, normals computed, tangents dropped so they are recomputed) and noted.

Both triangulate, keep the vertex splits that UV seams and hard edges need, skip degenerate
triangles with a counted note, and give meshes without UVs an xatlas layout (noted).
Bad input raises :class:`wrinklepipe.errors.InputError` naming the file (and key).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import xatlas

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.io.mesh_gltf import GltfMeshOptions, read_gltf_meshes
from wrinklepipe.io.mesh_obj import read_obj_meshes
from wrinklepipe.io.mesh_usd import UsdMeshOptions, read_usd_meshes

SUFFIXES = {
    ".gltf": "gltf",
    ".glb": "gltf",
    ".usd": "usd",
    ".usda": "usd",
    ".usdc": "usd",
    ".usdz": "usd",
    ".obj": "obj",
}


@dataclass(frozen=True)
class LoadOptions:
    """Options of :func:`load_mesh` / :func:`load_meshes`.

    generate_uvs: give meshes without UVs an xatlas layout (default True; noted).
    bake_transforms: glTF/USD: apply node / prim world transforms to non-skinned meshes.
    usd_time: USD time code to read points at (default: the default time).
    """

    generate_uvs: bool = True
    bake_transforms: bool = True
    usd_time: float | None = None


def load_meshes(path: str | Path, options: LoadOptions | None = None) -> list[Mesh]:
    """Every mesh part of ``path`` as its own triangulated :class:`Mesh`."""
    opts = options or LoadOptions()
    p = Path(path)
    kind = SUFFIXES.get(p.suffix.lower())
    if kind is None:
        raise input_error(p, f"unknown mesh format {p.suffix!r}; use one of {sorted(SUFFIXES)}")
    if not p.is_file():
        raise input_error(p, "file not found")
    if kind == "gltf":
        meshes = read_gltf_meshes(p, GltfMeshOptions(bake_transforms=opts.bake_transforms))
    elif kind == "usd":
        meshes = read_usd_meshes(
            p, UsdMeshOptions(bake_transforms=opts.bake_transforms, time=opts.usd_time)
        )
    else:
        meshes = read_obj_meshes(p)
    if opts.generate_uvs:
        meshes = [ensure_uvs(m) if m.uvs is None else m for m in meshes]
    return meshes


def load_mesh(path: str | Path, options: LoadOptions | None = None) -> Mesh:
    """All parts of ``path`` merged into one :class:`Mesh` (see the module doc)."""
    meshes = load_meshes(path, options)
    if len(meshes) == 1:
        return meshes[0]
    merged = merge_meshes(meshes)
    merged.name = Path(path).stem
    return merged


def merge_meshes(meshes: list[Mesh]) -> Mesh:
    """Concatenate meshes into one (indices offset; morphs by name; skins by joint name)."""
    notes: list[str] = [f"merged {len(meshes)} parts: {', '.join(m.name for m in meshes)}"]
    for m in meshes:
        notes.extend(f"{m.name}: {n}" for n in m.notes)
    counts = [m.vertex_count for m in meshes]
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    pos = np.concatenate([m.positions for m in meshes]).astype(np.float32)
    idx = np.concatenate([m.indices.astype(np.int64) + o for m, o in zip(meshes, offsets)])

    def cat(get: str, width: int, fill: float) -> np.ndarray | None:
        have = [getattr(m, get) is not None for m in meshes]
        if not any(have):
            return None
        if not all(have):
            notes.append(f"{get}: missing on {have.count(False)} part(s), filled with {fill}")
        return np.concatenate(
            [
                getattr(m, get) if getattr(m, get) is not None else np.full((c, width), fill)
                for m, c in zip(meshes, counts)
            ]
        ).astype(np.float32)

    uvs = cat("uvs", 2, 0.0)
    colors = cat("colors", 4, 1.0)
    normals = None
    if all(m.normals is not None for m in meshes):
        normals = np.concatenate([m.normals for m in meshes]).astype(np.float32)
    elif any(m.normals is not None for m in meshes):
        notes.append("normals missing on some parts: dropped (recomputed downstream)")
    tangents = None
    if all(m.tangents is not None for m in meshes):
        tangents = np.concatenate([m.tangents for m in meshes]).astype(np.float32)
    elif any(m.tangents is not None for m in meshes):
        notes.append("tangents missing on some parts: dropped (recomputed downstream)")

    names: list[str] = []
    for m in meshes:
        names.extend(n for n in m.morph_names if n not in names)
    deltas = None
    if names:
        deltas = np.zeros((len(names), len(pos), 3), np.float32)
        for m, o, c in zip(meshes, offsets, counts):
            for k, n in enumerate(m.morph_names):
                deltas[names.index(n), o : o + c] = m.morph_deltas[k]

    joint_names: list[str] = []
    for m in meshes:
        joint_names.extend(n for n in m.joint_names if n not in joint_names)
    joints = weights = ibm = None
    if joint_names and all(m.joints is not None for m in meshes):
        joints = np.concatenate(
            [
                np.array([joint_names.index(n) for n in m.joint_names], np.int64)[m.joints]
                for m in meshes
            ]
        )
        weights = np.concatenate([m.skin_weights for m in meshes]).astype(np.float32)
        ibm = np.zeros((len(joint_names), 4, 4), np.float32)
        for m in meshes:
            src = (
                m.inverse_bind
                if m.inverse_bind is not None
                else np.eye(4)[None].repeat(len(m.joint_names), 0)
            )
            for k, n in enumerate(m.joint_names):
                ibm[joint_names.index(n)] = src[k]
    elif joint_names:
        notes.append("skin on only some parts: dropped the skin")
        joint_names = []

    vertex_ids = None
    if all(m.vertex_ids is not None for m in meshes):
        notes.append("per-part vertex IDs dropped on merge (recompute over the merged mesh)")
    return Mesh(
        positions=pos,
        indices=idx.astype(np.uint32),
        uvs=uvs,
        normals=normals,
        tangents=tangents,
        morph_names=tuple(names),
        morph_deltas=deltas,
        joints=joints,
        skin_weights=weights,
        joint_names=tuple(joint_names),
        inverse_bind=ibm,
        vertex_ids=vertex_ids,
        colors=colors,
        name="merged",
        notes=notes,
    )


def ensure_uvs(mesh: Mesh) -> Mesh:
    """Give a mesh without UVs an xatlas parametrisation (splits vertices along chart seams;
    every per-vertex attribute follows). Noted in ``mesh.notes``."""
    if mesh.uvs is not None:
        return mesh

    vmap, idx, uvs = xatlas.parametrize(
        np.ascontiguousarray(mesh.positions, np.float32),
        np.ascontiguousarray(mesh.indices, np.uint32),
    )
    vmap = vmap.astype(np.int64)

    def take(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else np.ascontiguousarray(a[vmap])

    note = (
        f"generated UVs with xatlas ({len(vmap)} vertices from {mesh.vertex_count};"
        f" {len(vmap) - mesh.vertex_count} added along chart seams)"
    )
    if mesh.tangents is not None:
        note += "; supplied tangents dropped (recompute them for the new UVs)"
    return replace(
        mesh,
        positions=take(mesh.positions),
        indices=idx.astype(np.uint32),
        uvs=uvs.astype(np.float32),
        normals=take(mesh.normals),
        tangents=None,
        morph_deltas=None if mesh.morph_deltas is None else mesh.morph_deltas[:, vmap],
        joints=take(mesh.joints),
        skin_weights=take(mesh.skin_weights),
        vertex_ids=take(mesh.vertex_ids),
        colors=take(mesh.colors),
        notes=[*mesh.notes, note],
    )
