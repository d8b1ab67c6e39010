"""Several mesh parts -> one :class:`wrinklepipe.asset.Mesh` (what the wrinkle pipeline wants
for a face): indices offset, morph targets unioned by name (a part without a target gets zero
deltas), skins unioned by joint name, an attribute only some parts have filled (UVs 0) or
dropped (normals, tangents: recomputed downstream), each noted."""

from __future__ import annotations

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.names import plural


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
            notes.append(
                f"{get}: missing on {plural(have.count(False), 'part')}, filled with {fill}"
            )
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
