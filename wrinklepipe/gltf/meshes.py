"""glTF 2.0 / GLB mesh ingest: every triangle primitive of a file, per instance ->
:class:`wrinklepipe.asset.Mesh`; and a node pose sampled from the file's animation (with the
one keyframe sampler, :mod:`wrinklepipe.geometry.keyframes`).

A file is opened by :class:`wrinklepipe.gltf.read.GltfFile` and every primitive read by
:func:`wrinklepipe.gltf.primitive.read_instance` (the one per-primitive reader, which the
document model's render mesh uses too): one mesh per triangle primitive per node that
instances it (meshes no node uses: once, in their own space), non-skinned instances baked into
world space when ``bake_transforms``. What ingest adds to the per-primitive reader:

- ``KHR_mesh_quantization``: decoded (quantised attributes are plain accessors; the
  dequantising node transform is applied by the bake), noted.
- ``EXT_meshopt_compression`` / ``KHR_meshopt_compression`` / ``KHR_draco_mesh_compression``:
  decoded (noted) by the document model's decoder, which :class:`~wrinklepipe.gltf.read.
  GltfFile` reads a compressed file through; data that does not decode is a one-line error
  naming the file and the extension.
- ``KHR_texture_basisu`` and other texture/material extensions: textures are not part of mesh
  ingest, so they are ignored (noted); any other required extension is refused.
- POINTS and LINES primitives, and primitives whose triangles are all degenerate, are skipped
  and counted in the notes; a file left with none is an error.
- A morph target of the wrong length, or a malformed ``_WRINKLE_VERTEX_ID``, is left out and
  noted (the per-primitive reader's non-strict mode): any file is ingested as far as it can be.

Container, buffer and URI safety come from :mod:`wrinklepipe.gltf.container` (through
:mod:`wrinklepipe.gltf.read`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.keyframes import sample_channel
from wrinklepipe.gltf.animation import WIDTHS, morph_tracks, read_channels
from wrinklepipe.gltf.decompress import DRACO, MESHOPT
from wrinklepipe.gltf.primitive import (
    TRIANGLE_MODES,
    GltfSource,
    json_type,
    node_name,
    read_instance,
    target_names,
    world_matrices,
)
from wrinklepipe.gltf.read import GltfFile, GltfReadOptions
from wrinklepipe.names import plural

#: Required extensions that do not change geometry (textures/materials/lights): ignored.
_HARMLESS_PREFIXES = ("KHR_materials_", "KHR_texture_", "EXT_texture_", "KHR_lights_")
#: Required extensions mesh ingest decodes (compressed geometry: by the document's decoder,
#: which drops their names from the tree; one left there compressed nothing).
_SUPPORTED = {"KHR_mesh_quantization"}
_COMPRESSION = {DRACO, *MESHOPT}


@dataclass(frozen=True)
class GltfMeshOptions:
    """Options of :func:`read_gltf_meshes`.

    bake_transforms: apply each non-skinned instance's node world matrix (default True).
    """

    bake_transforms: bool = True


def check_extensions(r: GltfFile) -> list[str]:
    """Note the decoded and ignored extensions; refuse any other required one (by name)."""
    notes = [f"decoded {name}" for name in r.decoded]
    for name in r.gltf.get("extensionsRequired", []):
        if name in _COMPRESSION:
            continue
        if name in _SUPPORTED:
            notes.append(f"decoded {name}")
        elif name.startswith(_HARMLESS_PREFIXES):
            notes.append(f"ignored {name} (textures and materials are not part of mesh ingest)")
        else:
            raise r.err(f"required extension {name} is not supported", "/extensionsRequired")
    return notes


def read_gltf_meshes(path: str | Path, options: GltfMeshOptions | None = None) -> list[Mesh]:
    """One :class:`Mesh` per triangle primitive per instance (meshes no node uses: once, local).

    Raises :class:`InputError` naming the file and JSON pointer for anything malformed.
    """
    try:
        return _read_gltf_meshes(path, options)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        # Safety net for structures the specific checks did not foresee: still one clear line.
        del exc  # Python's wording ("'list' object has no attribute") helps nobody
        raise input_error(
            path,
            "malformed glTF: a member has the wrong type or is missing (the Khronos glTF "
            "validator names the exact place)",
        ) from None


def _objects(r: GltfSource, value: Any, key: str) -> list[dict[str, Any]]:
    """``value`` as an array of JSON objects, or a message naming the first that is not one."""
    if not isinstance(value, list):
        raise r.err(f"must be an array of objects, got {json_type(value)}", key)
    for i, v in enumerate(value):
        if not isinstance(v, dict):
            raise r.err(f"must be an object, got {json_type(v)}", f"{key}/{i}")
    return value


def _read_gltf_meshes(path: str | Path, options: GltfMeshOptions | None = None) -> list[Mesh]:
    opts = options or GltfMeshOptions()
    r = GltfFile(Path(path), GltfReadOptions())
    doc = r.gltf
    file_notes = check_extensions(r)
    meshes = _objects(r, doc.get("meshes", []), "/meshes")
    nodes = _objects(r, doc.get("nodes", []), "/nodes")
    try:
        worlds = world_matrices(doc)
    except ValueError as exc:
        raise r.err(str(exc), "/nodes") from None
    instances: list[tuple[int, int | None]] = []  # (mesh index, node index)
    used = set()
    for ni in sorted(worlds):
        if "mesh" in nodes[ni]:
            instances.append((int(nodes[ni]["mesh"]), ni))
            used.add(int(nodes[ni]["mesh"]))
    instances += [(mi, None) for mi in range(len(meshes)) if mi not in used]
    out: list[Mesh] = []
    skipped_modes = faceless = 0
    for mi, ni in instances:
        if not 0 <= mi < len(meshes):
            raise r.err(f"node uses mesh {mi}, which does not exist", f"/nodes/{ni}/mesh")
        prims = _objects(r, meshes[mi].get("primitives", []), f"/meshes/{mi}/primitives")
        world = worlds.get(ni, np.eye(4)) if ni is not None else np.eye(4)
        for pi, prim in enumerate(prims):
            if int(prim.get("mode", 4)) not in TRIANGLE_MODES:
                skipped_modes += 1
                continue
            mesh, placed = read_instance(r, mi, pi, ni, world, opts.bake_transforms)
            if mesh.triangle_count == 0:
                faceless += 1
                continue
            mesh.notes[:0] = file_notes
            if placed == "baked":
                mesh.notes.append(f"baked the world transform of node {ni}")
            elif placed == "skinned":
                mesh.notes.append(f"skin {nodes[ni]['skin']}: {len(mesh.joint_names)} joints")
            out.append(mesh)
    if skipped_modes and out:
        out[0].notes.append(f"skipped {plural(skipped_modes, 'point/line primitive')}")
    if faceless and out:
        out[0].notes.append(
            f"skipped {plural(faceless, 'primitive')} whose triangles are all degenerate"
        )
    if not out and faceless:
        raise r.err("every triangle is degenerate (zero area or a repeated index)", "/meshes")
    if not out:
        raise r.err("no triangle primitives (the file has no faces)", "/meshes")
    return out


def gltf_joint_world_matrices(
    path: str | Path, mesh: Mesh, time: float | None = None
) -> np.ndarray:
    """World matrices ``[J, 4, 4]`` of ``mesh``'s joints, at rest or at ``time`` (seconds) of
    the file's first animation (STEP, LINEAR with slerp for rotations, CUBICSPLINE)."""
    return gltf_joint_world_matrices_at(path, mesh, [time])[0]


def gltf_joint_world_matrices_at(
    path: str | Path, mesh: Mesh, times: Sequence[float | None]
) -> np.ndarray:
    """World matrices ``[F, J, 4, 4]`` of ``mesh``'s joints at each of ``times`` (None: the
    rest pose), reading the file once."""
    r = GltfFile(Path(path), GltfReadOptions())
    doc = r.gltf
    if any(t is not None for t in times) and not doc.get("animations"):
        raise r.err("the file has no animation to sample", "/animations")
    rest_nodes = [dict(n) for n in doc.get("nodes", [])]
    channels = [  # the one channel reader (gltf/animation), the node paths of the first animation
        (c.node, c.path, c.times, c.values, c.interpolation)
        for c in (read_channels(r, 0, tuple(WIDTHS)) if doc.get("animations") else [])
    ]
    names_to_node = {}
    for s in doc.get("skins", []):
        for j in s.get("joints", []):
            nm = node_name(doc, j)
            names_to_node.setdefault(nm, j)
    missing = [n for n in mesh.joint_names if n not in names_to_node]
    if missing:
        raise input_error(str(path), f"joints {missing} are not nodes of the file")
    out = []
    for time in times:  # per frame: a few matrix products per node
        nodes = [dict(n) for n in rest_nodes]
        if time is not None:
            for node, path_, t_in, vals, interp in channels:
                nodes[node][path_] = sample_channel(t_in, vals, float(time), interp, path_).tolist()
                nodes[node].pop("matrix", None)
        worlds = world_matrices({**doc, "nodes": nodes})
        out.append(np.stack([worlds.get(names_to_node[n], np.eye(4)) for n in mesh.joint_names]))
    return np.stack(out)


def gltf_animation_times(path: str | Path) -> np.ndarray:
    """Sorted key times (seconds) of the file's first animation, over all its channels."""
    r = GltfFile(Path(path), GltfReadOptions())
    anims = r.gltf.get("animations") or []
    if not anims:
        raise r.err("the file has no animation", "/animations")
    keys = [
        r.accessor(s["input"])[:, 0].astype(np.float64)
        for i, s in enumerate(anims[0].get("samplers", []))
    ]
    return np.unique(np.concatenate(keys)) if keys else np.zeros(1)


def gltf_morph_weights(path: str | Path, mesh: Mesh, time: float) -> dict[str, float]:
    """Morph-target weights at ``time`` (seconds) of the first animation's ``weights`` channels
    (else the node's / mesh's default ``weights``), by target name, for targets ``mesh`` has."""
    r = GltfFile(Path(path), GltfReadOptions())
    doc = r.gltf
    if not doc.get("animations"):
        raise r.err("the file has no animation to sample", "/animations")
    nodes = doc.get("nodes", [])
    meshes = doc.get("meshes", [])
    # the one reader of weights channels (gltf/animation, as the drivers are given them); a
    # node's last channel wins
    channels = {t.node: t for t in morph_tracks(r, 0)}
    out: dict[str, float] = {}
    for ni, node in enumerate(nodes):
        if "mesh" not in node or not 0 <= int(node["mesh"]) < len(meshes):
            continue
        gm = meshes[int(node["mesh"])]
        n_t = max((len(p.get("targets", [])) for p in gm.get("primitives", [])), default=0)
        if not n_t:
            continue
        names = target_names(doc, int(node["mesh"]))
        w = np.asarray(node.get("weights", gm.get("weights", [0.0] * n_t)), dtype=np.float64)
        tr = channels.get(ni)
        if tr is not None:
            w = sample_channel(tr.times, tr.values, float(time), tr.interpolation, "weights")
        for name, value in zip(names, w):
            if name in mesh.morph_names:
                out.setdefault(name, float(value))
    return out
