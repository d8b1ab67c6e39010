"""The render mesh of a document's wrinkled primitives: what the wrinkle maths and validator see.

:func:`wrinkled_mesh` reads the wrinkled primitives (and only them) into one
:class:`~wrinklepipe.asset.Mesh`, with the convention of :mod:`wrinklepipe.gltf.meshes`:
non-skinned primitives are baked into world space by the first node that instances them;
skinned ones stay in their bind space (the node transform of a skinned mesh is ignored by the
spec; the skin's joints, weights and inverse bind matrices come along). Several primitives are
merged by :func:`wrinklepipe.geometry.merge.merge_meshes` (morph targets unioned by name, skins by
joint name); ``Mesh.parts`` maps every vertex run back to its primitive, vertex order kept.
Degenerate triangles are left out of the render mesh (counted); the document is not touched.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.asset import Mesh, MeshPart
from wrinklepipe.geometry.merge import merge_meshes
from wrinklepipe.gltf.document import Document, PrimitiveRef
from wrinklepipe.gltf.primitive import PrimitiveOptions, read_instance
from wrinklepipe.gltf.scene import node_world_matrices
from wrinklepipe.metadata import BIAS_ATTRIBUTE

#: How the render mesh reads a primitive: the package's bias into ``Mesh.colors``; vertex IDs
#: and morph targets must be whole (ingest gave the wrinkled primitives their IDs).
OPTIONS = PrimitiveOptions(colors=BIAS_ATTRIBUTE, strict=True)


def primitive_mesh(
    doc: Document, ref: PrimitiveRef, worlds: dict[int, np.ndarray] | None = None
) -> Mesh:
    """One primitive as a :class:`Mesh` (see the module doc), named ``mesh`` or ``mesh/i``:
    :func:`wrinklepipe.gltf.primitive.read_instance`, the reader mesh ingest uses, as the first
    node that instances it."""
    worlds = worlds if worlds is not None else node_world_matrices(doc)
    nodes = doc.mesh_nodes(ref.mesh)
    node = next((i for i in nodes if i in worlds), nodes[0] if nodes else None)
    world = worlds.get(node, np.eye(4)) if node is not None else np.eye(4)
    mesh, _ = read_instance(doc, ref.mesh, ref.primitive, node, world, options=OPTIONS)
    mesh.parts = (MeshPart(mesh.name, ref.pointer, 0, mesh.vertex_count, node),)
    return mesh


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
