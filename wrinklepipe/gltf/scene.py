"""Where a document's primitives are in the scene: node world matrices and rest-pose positions.

A primitive's *rest-pose world positions* are what a viewer shows with no animation playing: the
default morph weights applied (``node.weights``, else ``mesh.weights``), then the node's world
matrix, or for a skinned node the skin at its rest pose (``sum_k w_k J_world[j_k] IBM[j_k] p``;
the node's own transform is ignored, as the spec says). Framing and the geometry comparisons of
compressed files use them.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.gltf.document import Document, PrimitiveRef
from wrinklepipe.gltf.primitive import primitive_triangles as gltf_triangles
from wrinklepipe.gltf.primitive import read_skin, world_matrices


def node_world_matrices(doc: Document) -> dict[int, np.ndarray]:
    """World matrix (float64 ``[4, 4]``, column vectors) of every node reachable from a scene."""
    try:
        return world_matrices(doc.gltf)
    except ValueError as exc:
        raise doc.err(str(exc), "/nodes") from None


def default_morph_weights(doc: Document, node: int | None, mesh: int) -> np.ndarray:
    """The morph weights a viewer uses without animation (node's, else mesh's, else zeros)."""
    n_targets = len(doc.target_names(mesh))
    w = None
    if node is not None:
        w = doc.array("nodes")[node].get("weights")
    if w is None:
        w = doc.array("meshes")[mesh].get("weights")
    out = np.zeros(n_targets, np.float64)
    if isinstance(w, list):
        vals = np.asarray(w[:n_targets], np.float64)
        out[: len(vals)] = vals
    return out


def rest_positions(
    doc: Document,
    ref: PrimitiveRef,
    node: int | None = None,
    worlds: dict[int, np.ndarray] | None = None,
) -> np.ndarray:
    """``[V, 3]`` float64 rest-pose world positions of a primitive as instanced by ``node``
    (default: the first node that instances its mesh; none: the mesh's own space)."""
    prim = doc.primitive(ref)
    attrs = prim.get("attributes", {})
    key = ref.pointer + "/attributes"
    if "POSITION" not in attrs:
        raise doc.err("primitive has no POSITION attribute", key)
    p = doc.accessor(attrs["POSITION"]).astype(np.float64)
    if node is None:
        nodes = doc.mesh_nodes(ref.mesh)
        node = nodes[0] if nodes else None
    weights = default_morph_weights(doc, node, ref.mesh)
    for t, w in enumerate(weights):
        tgt = prim.get("targets", [])
        if w and t < len(tgt) and "POSITION" in tgt[t]:
            p = p + w * doc.accessor(tgt[t]["POSITION"]).astype(np.float64)
    if node is None:
        return p
    worlds = worlds if worlds is not None else node_world_matrices(doc)
    n = doc.array("nodes")[node]
    if "skin" in n and "JOINTS_0" in attrs and "WEIGHTS_0" in attrs:
        return _skinned(doc, int(n["skin"]), attrs, p, worlds)
    m = worlds.get(node, np.eye(4))
    return p @ m[:3, :3].T + m[:3, 3]


def _skinned(
    doc: Document,
    skin_index: int,
    attrs: dict[str, int],
    p: np.ndarray,
    worlds: dict[int, np.ndarray],
) -> np.ndarray:
    joints = [int(j) for j in doc.array("skins")[skin_index].get("joints", [])]
    ibm = read_skin(doc, skin_index).inverse_bind.astype(np.float64)  # the one skin reader
    jm = np.stack([worlds.get(j, np.eye(4)) for j in joints]) @ ibm  # [J, 4, 4]
    out = np.zeros_like(p)
    k = 0
    while f"JOINTS_{k}" in attrs and f"WEIGHTS_{k}" in attrs:
        j = doc.accessor(attrs[f"JOINTS_{k}"], normalize=False).astype(np.int64)
        w = doc.accessor(attrs[f"WEIGHTS_{k}"]).astype(np.float64)
        if j.size and (j.min() < 0 or j.max() >= len(joints)):
            raise doc.err("JOINTS index past the skin's joints", f"/skins/{skin_index}")
        for c in range(4):
            m = jm[j[:, c]]  # [V, 4, 4]
            out += w[:, c : c + 1] * (np.einsum("vij,vj->vi", m[:, :3, :3], p) + m[:, :3, 3])
        k += 1
    return out


def primitive_triangles(doc: Document, ref: PrimitiveRef) -> np.ndarray:
    """``[T, 3]`` int64 vertex indices of a triangle primitive (strips and fans unrolled):
    :func:`wrinklepipe.gltf.primitive.primitive_triangles`, the one triangle reader."""
    return gltf_triangles(doc, ref.mesh, ref.primitive)
