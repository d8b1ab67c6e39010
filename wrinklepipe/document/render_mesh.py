"""The render mesh of a document's wrinkled primitives: what the wrinkle maths and validator see.

:func:`wrinkled_mesh` reads the wrinkled primitives (and only them) into one
:class:`~wrinklepipe.asset.Mesh`, with the convention of :mod:`wrinklepipe.io.mesh_gltf`:
non-skinned primitives are baked into world space by the first node that instances them;
skinned ones stay in their bind space (the node transform of a skinned mesh is ignored by the
spec; the skin's joints, weights and inverse bind matrices come along). Several primitives are
merged by :func:`wrinklepipe.io.mesh_merge.merge_meshes` (morph targets unioned by name, skins by
joint name); ``Mesh.parts`` maps every vertex run back to its primitive, vertex order kept.
Degenerate triangles are left out of the render mesh (counted); the document is not touched.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.asset import Mesh, MeshPart
from wrinklepipe.document.model import Document, PrimitiveRef
from wrinklepipe.document.scene import node_world_matrices, primitive_triangles
from wrinklepipe.document.wrinkled import VERTEX_ID_ATTRIBUTE
from wrinklepipe.io.mesh_gltf import bake_world, drop_degenerate
from wrinklepipe.io.mesh_merge import merge_meshes

BIAS_ATTRIBUTE = "_WRINKLE_BIAS"


def _attr(
    doc: Document, ref: PrimitiveRef, name: str, widths: tuple[int, ...], n: int
) -> np.ndarray | None:
    attrs = doc.primitive(ref).get("attributes", {})
    if name not in attrs:
        return None
    a = doc.accessor(attrs[name], normalize=name != "JOINTS_0")
    key = f"{ref.pointer}/attributes/{name}"
    if len(a) != n or a.shape[1] not in widths:
        raise doc.err(f"{name} has {len(a)} x {a.shape[1]} values, POSITION has {n}", key)
    return a


def _skin(doc: Document, skin: int) -> tuple[tuple[str, ...], np.ndarray]:
    s = doc.array("skins")[skin]
    joints = [int(j) for j in s.get("joints", [])]
    names = tuple(doc.node_name(j) for j in joints)
    if "inverseBindMatrices" in s:
        m = doc.accessor(s["inverseBindMatrices"]).astype(np.float32)
        if m.shape != (len(joints), 16):
            raise doc.err("inverseBindMatrices count differs from joints", f"/skins/{skin}")
        ibm = np.ascontiguousarray(m.reshape(-1, 4, 4).transpose(0, 2, 1))
    else:
        ibm = np.tile(np.eye(4, dtype=np.float32), (len(joints), 1, 1))
    return names, ibm


def primitive_mesh(
    doc: Document, ref: PrimitiveRef, worlds: dict[int, np.ndarray] | None = None
) -> Mesh:
    """One primitive as a :class:`Mesh` (see the module doc), named ``mesh`` or ``mesh/i``."""
    worlds = worlds if worlds is not None else node_world_matrices(doc)
    prim = doc.primitive(ref)
    attrs = prim.get("attributes", {})
    if "POSITION" not in attrs:
        raise doc.err("primitive has no POSITION attribute", ref.pointer + "/attributes")
    pos = doc.accessor(attrs["POSITION"]).astype(np.float32)
    n = len(pos)
    if not np.isfinite(pos).all():
        raise doc.err("positions are NaN or infinite", f"{ref.pointer}/attributes/POSITION")
    tris, degenerate = drop_degenerate(pos, primitive_triangles(doc, ref))
    notes = [f"skipped {degenerate} degenerate triangle(s)"] if degenerate else []
    vid = _attr(doc, ref, VERTEX_ID_ATTRIBUTE, (1,), n)
    ids = None
    if vid is not None:
        v = vid[:, 0].astype(np.float64)
        if np.any(v != np.rint(v)) or np.any(v < 0):
            raise doc.err(
                "vertex IDs must be non-negative integers",
                f"{ref.pointer}/attributes/{VERTEX_ID_ATTRIBUTE}",
            )
        ids = v.astype(np.int64)
    names = doc.target_names(ref.mesh)
    deltas = []
    for t, tgt in enumerate(prim.get("targets", [])):
        if "POSITION" in tgt:
            d = doc.accessor(tgt["POSITION"]).astype(np.float32)
            if d.shape != (n, 3):
                raise doc.err(
                    f"morph target has {len(d)} deltas for {n} vertices",
                    f"{ref.pointer}/targets/{t}/POSITION",
                )
        else:
            d = np.zeros((n, 3), np.float32)
        deltas.append(d)
    mesh_json = doc.array("meshes")[ref.mesh]
    label = doc.mesh_name(ref.mesh)
    mesh = Mesh(
        positions=pos,
        indices=tris.astype(np.uint32),
        uvs=_f32(_attr(doc, ref, "TEXCOORD_0", (2,), n)),
        normals=_f32(_attr(doc, ref, "NORMAL", (3,), n)),
        tangents=_f32(_attr(doc, ref, "TANGENT", (4,), n)),
        morph_names=tuple(names[: len(deltas)]),
        morph_deltas=np.stack(deltas) if deltas else None,
        vertex_ids=ids,
        colors=_f32(_attr(doc, ref, BIAS_ATTRIBUTE, (4,), n)),
        name=f"{label}/{ref.primitive}" if len(mesh_json.get("primitives", [])) > 1 else label,
        notes=notes,
    )
    nodes = doc.mesh_nodes(ref.mesh)
    node = next((i for i in nodes if i in worlds), nodes[0] if nodes else None)
    node_json = doc.array("nodes")[node] if node is not None else {}
    joints = _attr(doc, ref, "JOINTS_0", (4,), n)
    weights = _attr(doc, ref, "WEIGHTS_0", (4,), n)
    if "skin" in node_json and joints is not None and weights is not None:
        mesh.joint_names, mesh.inverse_bind = _skin(doc, int(node_json["skin"]))
        mesh.joints = joints.astype(np.int64)
        mesh.skin_weights = weights.astype(np.float32)
        if mesh.joints.size and mesh.joints.max() >= len(mesh.joint_names):
            raise doc.err("JOINTS_0 index past the skin's joints", f"{ref.pointer}/attributes")
    elif node is not None and not np.allclose(worlds.get(node, np.eye(4)), np.eye(4)):
        if abs(np.linalg.det(worlds[node][:3, :3])) < 1e-30:
            raise doc.err("the node's world transform is singular", f"/nodes/{node}")
        bake_world(mesh, worlds[node])  # the ingest reader's bake: one
    mesh.parts = (MeshPart(mesh.name, ref.pointer, 0, n, node),)
    return mesh


def _f32(a: np.ndarray | None) -> np.ndarray | None:
    return None if a is None else np.ascontiguousarray(a, np.float32)


def wrinkled_mesh(doc: Document, refs: list[PrimitiveRef], name: str = "") -> Mesh:
    """The wrinkled primitives ``refs`` as one render mesh (see the module doc)."""
    if not refs:
        raise doc.err("no wrinkled primitive (no triangle primitive uses the wrinkled material)")
    worlds = node_world_matrices(doc)
    parts = [primitive_mesh(doc, r, worlds) for r in refs]
    if len(parts) == 1:
        return parts[0]
    merged = merge_meshes(parts)
    if all(p.vertex_ids is not None for p in parts):
        merged.vertex_ids = np.concatenate([p.vertex_ids for p in parts])
        merged.notes = [n for n in merged.notes if not n.startswith("per-part vertex IDs")]
    starts = np.concatenate([[0], np.cumsum([p.vertex_count for p in parts])[:-1]])
    merged.parts = tuple(
        MeshPart(p.name, p.parts[0].pointer, int(s), p.vertex_count, p.parts[0].node)
        for p, s in zip(parts, starts)
    )
    merged.name = name or "+".join(dict.fromkeys(doc.mesh_name(r.mesh) for r in refs))
    return merged
