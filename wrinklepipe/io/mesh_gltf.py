"""glTF 2.0 / GLB mesh ingest: every triangle primitive -> :class:`wrinklepipe.asset.Mesh`.

What is read: POSITION, NORMAL, TANGENT, TEXCOORD_0, COLOR_0, JOINTS_0/WEIGHTS_0, the
``_WRINKLE_VERTEX_ID`` attribute, morph targets (POSITION deltas; names from
``mesh.extras.targetNames``), the skin of the node that instances the mesh (joint names,
inverse bind matrices) and that node's world transform.

- Accessors (:mod:`wrinklepipe.io.accessors`, the one accessor reader): any component type,
  ``normalized`` integers decoded per the spec (signed: ``max(c / MAX, -1)``), sparse
  accessors, byte strides. This makes ``KHR_mesh_quantization``
  work (quantised attributes are plain accessors; the dequantising node transform is applied).
- ``EXT_meshopt_compression``: the compressed views are not decoded (no well-kept PyPI decoder);
  when the extension is *required* the file is refused with a message naming it, otherwise the
  uncompressed fallback data is read. ``KHR_draco_mesh_compression`` required: refused likewise.
- ``KHR_texture_basisu`` and other texture/material extensions: textures are not part of mesh
  ingest, so they are ignored (noted).
- Primitive modes TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN are read (strips and fans are
  triangulated); POINTS and LINES primitives are skipped and counted in the notes.
- Non-skinned instances are baked into world space (positions, normals, tangents, morph deltas)
  when ``bake_transforms``; skinned meshes stay in their bind space, as the spec says the node
  transform of a skinned mesh is ignored.

Container, buffer and URI safety come from :mod:`wrinklepipe.document.container` (through
:mod:`wrinklepipe.io.gltf_read`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.io.accessors import read_accessor
from wrinklepipe.io.gltf_read import GltfFile, GltfReadOptions

#: Required extensions that do not change geometry (textures/materials/lights): ignored.
_HARMLESS_PREFIXES = ("KHR_materials_", "KHR_texture_", "EXT_texture_", "KHR_lights_")
_SUPPORTED = {"KHR_mesh_quantization"}
_REFUSED = {
    "EXT_meshopt_compression": "meshopt-compressed buffer views (EXT_meshopt_compression) cannot"
    " be decoded: no well-kept PyPI decoder; re-export without meshopt (gltfpack without -c)",
    "KHR_meshopt_compression": "meshopt-compressed buffer views (KHR_meshopt_compression) cannot"
    " be decoded: no well-kept PyPI decoder; re-export without meshopt",
    "KHR_draco_mesh_compression": "Draco-compressed primitives (KHR_draco_mesh_compression) are"
    " not decoded; re-export without Draco",
}


@dataclass(frozen=True)
class GltfMeshOptions:
    """Options of :func:`read_gltf_meshes`.

    bake_transforms: apply each non-skinned instance's node world matrix (default True).
    """

    bake_transforms: bool = True


class _MeshFile(GltfFile):
    """The safe container reader; accessors through :func:`wrinklepipe.io.accessors.
    read_accessor` (sparse, normalized, strides), refusing required meshopt views."""

    def typed(self, i: Any, key: str) -> np.ndarray:
        """Accessor ``i`` as a 2-D array ``[count, width]`` (normalized ints -> float32)."""
        return read_accessor(self.doc, i, self._view_bytes, self.err)

    def _view_bytes(self, view_i: Any) -> tuple[bytes, int]:
        views = self.doc.get("bufferViews", [])
        if isinstance(view_i, int) and 0 <= view_i < len(views):
            ext = views[view_i].get("extensions", {})
            for name in ("EXT_meshopt_compression", "KHR_meshopt_compression"):
                if name in ext and name in self.doc.get("extensionsRequired", []):
                    raise self.err(_REFUSED[name], f"/bufferViews/{view_i}")
        return self.view(view_i)


def _vec(node: dict[str, Any], key: str, default: list[float], n: int) -> np.ndarray:
    v = node.get(key, default)
    try:
        a = np.asarray(v, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (n,) or not np.isfinite(a).all():
        raise ValueError(f"{key} must be {n} finite numbers")
    return a


def node_matrix(node: dict[str, Any]) -> np.ndarray:
    """Local matrix of a node (column vectors); ValueError for malformed TRS / matrix."""
    if "matrix" in node:
        return _vec(node, "matrix", [], 16).reshape(4, 4).T  # column-major
    t = _vec(node, "translation", [0, 0, 0], 3)
    x, y, z, w = _vec(node, "rotation", [0, 0, 0, 1], 4)
    s = _vec(node, "scale", [1, 1, 1], 3)
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    m = np.eye(4)
    m[:3, :3] = r * s
    m[:3, 3] = t
    return m


def _int_list(v: Any) -> list[int]:
    if not isinstance(v, list) or not all(isinstance(c, int) for c in v):
        raise ValueError("must be a list of integers")
    return v


def world_matrices(doc: dict[str, Any]) -> dict[int, np.ndarray]:
    """World matrix of every node reachable from the scenes (or all roots if no scenes).

    Raises ValueError (with the node) for malformed nodes; the callers turn it into an
    InputError naming the file."""
    nodes = doc.get("nodes", [])
    if not isinstance(nodes, list) or not all(isinstance(n, dict) for n in nodes):
        raise ValueError("nodes must be a list of objects")
    children: set[int] = set()
    for i, n in enumerate(nodes):
        try:
            children.update(_int_list(n.get("children", [])))
        except ValueError as exc:
            raise ValueError(f"nodes[{i}].children {exc}") from None
    roots: list[int] = []
    for sc in doc.get("scenes", []):
        roots.extend(_int_list(sc.get("nodes", [])) if isinstance(sc, dict) else [])
    if not roots:
        roots = [i for i in range(len(nodes)) if i not in children]
    out: dict[int, np.ndarray] = {}
    stack = [(int(r), np.eye(4)) for r in roots]
    while stack:  # a walk over the node hierarchy (nodes, not vertices)
        i, parent = stack.pop()
        if i in out or not 0 <= i < len(nodes):
            continue
        try:
            out[i] = parent @ node_matrix(nodes[i])
        except ValueError as exc:
            raise ValueError(f"nodes[{i}]: {exc}") from None
        stack.extend((int(c), out[i]) for c in nodes[i].get("children", []))
    return out


def triangulate(mode: int, idx: np.ndarray) -> np.ndarray:
    if mode == 4:
        return idx[: len(idx) // 3 * 3].reshape(-1, 3)
    if mode == 5:  # strip: (i, i+1, i+2), every other one flipped
        n = len(idx) - 2
        if n <= 0:
            return np.zeros((0, 3), np.int64)
        k = np.arange(n)
        a, b, c = idx[k], idx[k + 1], idx[k + 2]
        odd = k % 2 == 1
        return np.stack([np.where(odd, b, a), np.where(odd, a, b), c], axis=1)
    if mode == 6:  # fan
        n = len(idx) - 2
        if n <= 0:
            return np.zeros((0, 3), np.int64)
        k = np.arange(n)
        return np.stack([np.full(n, idx[0]), idx[k + 1], idx[k + 2]], axis=1)
    raise ValueError(mode)


def check_extensions(r: GltfFile) -> list[str]:
    """Refuse required extensions that change geometry and are not decoded; note the rest."""
    notes = []
    for name in r.doc.get("extensionsRequired", []):
        if name in _REFUSED:
            raise r.err(_REFUSED[name], "/extensionsRequired")
        if name in _SUPPORTED:
            notes.append(f"decoded {name}")
        elif name.startswith(_HARMLESS_PREFIXES):
            notes.append(f"ignored {name} (textures and materials are not part of mesh ingest)")
        else:
            raise r.err(f"required extension {name} is not supported", "/extensionsRequired")
    for name in r.doc.get("extensionsUsed", []):
        if name in _REFUSED and name not in r.doc.get("extensionsRequired", []):
            notes.append(f"{name} used but not required: read the uncompressed fallback data")
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


def _objects(r: _MeshFile, value: Any, key: str) -> list[dict[str, Any]]:
    """``value`` as an array of JSON objects, or a message naming the first that is not one."""
    if not isinstance(value, list):
        raise r.err(f"must be an array of objects, got {json_type(value)}", key)
    for i, v in enumerate(value):
        if not isinstance(v, dict):
            raise r.err(f"must be an object, got {json_type(v)}", f"{key}/{i}")
    return value


def json_type(v: Any) -> str:
    """The JSON name of a value's type (for messages)."""
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, (int, float)):
        return "a number"
    return {str: "a string", list: "an array", dict: "an object"}.get(type(v), "null")


def _read_gltf_meshes(path: str | Path, options: GltfMeshOptions | None = None) -> list[Mesh]:
    opts = options or GltfMeshOptions()
    r = _MeshFile(Path(path), GltfReadOptions())
    doc = r.doc
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
    skipped_modes = 0
    for mi, ni in instances:
        if not 0 <= mi < len(meshes):
            raise r.err(f"node uses mesh {mi}, which does not exist", f"/nodes/{ni}/mesh")
        gm = meshes[mi]
        names = list((gm.get("extras") or {}).get("targetNames", []))
        node = nodes[ni] if ni is not None else {}
        skin = _read_skin(r, int(node["skin"])) if "skin" in node else None
        world = worlds.get(ni, np.eye(4)) if ni is not None else np.eye(4)
        for pi, prim in enumerate(
            _objects(r, gm.get("primitives", []), f"/meshes/{mi}/primitives")
        ):
            mode = int(prim.get("mode", 4))
            if mode not in (4, 5, 6):
                skipped_modes += 1
                continue
            mesh = _read_primitive(r, mi, pi, prim, names, skin)
            mesh.notes[:0] = file_notes
            if skin is None and opts.bake_transforms and not np.allclose(world, np.eye(4)):
                try:
                    mesh = bake_world(mesh, world)
                except ValueError:
                    raise r.err("the node's world transform is singular", f"/nodes/{ni}") from None
                mesh.notes.append(f"baked the world transform of node {ni}")
            label = gm.get("name") or f"mesh{mi}"
            mesh.name = f"{label}/{pi}" if len(gm.get("primitives", [])) > 1 else str(label)
            out.append(mesh)
    if skipped_modes and out:
        out[0].notes.append(f"skipped {skipped_modes} point/line primitive(s)")
    if not out:
        raise r.err("no triangle primitives (the file has no faces)", "/meshes")
    return out


def _read_skin(r: _MeshFile, si: int) -> dict[str, Any]:
    skins = r.doc.get("skins", [])
    if not 0 <= si < len(skins):
        raise r.err(f"skin {si} does not exist", "/skins")
    s = skins[si]
    nodes = r.doc.get("nodes", [])
    joints = [int(j) for j in s.get("joints", [])]
    names = tuple(
        str(nodes[j].get("name") or f"joint{j}") if 0 <= j < len(nodes) else f"joint{j}"
        for j in joints
    )
    ibm = None
    if "inverseBindMatrices" in s:
        m = r.typed(s["inverseBindMatrices"], f"/skins/{si}/inverseBindMatrices")
        if m.shape != (len(joints), 16):
            raise r.err("inverseBindMatrices count differs from joints", f"/skins/{si}")
        ibm = m.reshape(-1, 4, 4).transpose(0, 2, 1).astype(np.float32)  # column-major
    return {"names": names, "ibm": ibm, "nodes": joints, "index": si}


def _read_primitive(
    r: _MeshFile,
    mi: int,
    pi: int,
    prim: dict[str, Any],
    names: list[str],
    skin: dict[str, Any] | None,
) -> Mesh:
    key = f"/meshes/{mi}/primitives/{pi}"
    attrs = prim.get("attributes", {})
    if "POSITION" not in attrs:
        raise r.err("primitive has no POSITION attribute", key + "/attributes")
    pos = r.typed(attrs["POSITION"], key + "/attributes/POSITION").astype(np.float32)
    if pos.shape[1] != 3:
        raise r.err("POSITION must be VEC3", key + "/attributes/POSITION")
    nv = len(pos)
    bad = ~np.isfinite(pos).all(axis=1)
    if bad.any():
        v = int(np.flatnonzero(bad)[0])
        raise r.err(
            f"{int(bad.sum())} position(s) are NaN or infinite (first: vertex {v})",
            key + "/attributes/POSITION",
        )
    notes: list[str] = []

    def attr(name: str, width: tuple[int, ...]) -> np.ndarray | None:
        if name not in attrs:
            return None
        a = r.typed(attrs[name], f"{key}/attributes/{name}")
        if len(a) != nv or a.shape[1] not in width:
            raise r.err(
                f"{name} has {len(a)} x {a.shape[1]} values, POSITION has {nv}",
                f"{key}/attributes/{name}",
            )
        return a

    if "indices" in prim:
        idx = r.typed(prim["indices"], key + "/indices")[:, 0].astype(np.int64)
    else:
        idx = np.arange(nv, dtype=np.int64)
    if len(idx) and (idx.min() < 0 or idx.max() >= nv):
        raise r.err(f"indices out of range 0..{nv - 1} (max {int(idx.max())})", key + "/indices")
    tris = triangulate(int(prim.get("mode", 4)), idx)
    if int(prim.get("mode", 4)) != 4:
        notes.append(f"triangulated a {'strip' if prim.get('mode') == 5 else 'fan'}")
    if len(tris) == 0:
        raise r.err("primitive has no triangles", key)
    tris, n_degen = drop_degenerate(pos, tris)
    if n_degen:
        notes.append(f"skipped {n_degen} degenerate (zero-area or repeated-index) triangle(s)")
    if len(tris) == 0:
        raise r.err("every triangle of the primitive is degenerate", key)

    normals = attr("NORMAL", (3,))
    tangents = attr("TANGENT", (4,))
    uvs = attr("TEXCOORD_0", (2,))
    colors = attr("COLOR_0", (3, 4))
    if colors is not None and colors.shape[1] == 3:
        colors = np.concatenate([colors, np.ones((nv, 1), colors.dtype)], axis=1)
    joints = attr("JOINTS_0", (4,))
    weights = attr("WEIGHTS_0", (4,))
    vid = attrs.get("_WRINKLE_VERTEX_ID")
    vertex_ids = None
    if vid is not None:
        v = r.typed(vid, key + "/attributes/_WRINKLE_VERTEX_ID")[:, 0].astype(np.float64)
        if len(v) == nv and np.all(v == np.rint(v)) and np.all(v >= 0):
            vertex_ids = v.astype(np.int64)
        else:
            notes.append("ignored _WRINKLE_VERTEX_ID (not one non-negative integer per vertex)")

    deltas = []
    tnames = []
    skipped_targets = 0
    for ti, tgt in enumerate(prim.get("targets", [])):
        tname = str(names[ti]) if ti < len(names) else f"target_{ti}"
        if "POSITION" not in tgt:
            d = np.zeros((nv, 3), np.float32)
        else:
            d = r.typed(tgt["POSITION"], f"{key}/targets/{ti}/POSITION").astype(np.float32)
            if d.shape != (nv, 3) or not np.isfinite(d).all():
                skipped_targets += 1
                notes.append(
                    f"skipped morph target {tname!r}: {d.shape[0]} x {d.shape[1]} deltas for"
                    f" {nv} vertices" + ("" if np.isfinite(d).all() else " or non-finite values")
                )
                continue
        deltas.append(d)
        tnames.append(tname)
    if names and len(names) != len(prim.get("targets", [])):
        notes.append(
            f"extras.targetNames has {len(names)} names for {len(prim.get('targets', []))} targets"
        )

    mesh = Mesh(
        positions=pos,
        indices=tris.astype(np.uint32),
        uvs=None if uvs is None else uvs.astype(np.float32),
        normals=None if normals is None else normals.astype(np.float32),
        tangents=None if tangents is None else tangents.astype(np.float32),
        morph_names=tuple(tnames),
        morph_deltas=np.stack(deltas) if deltas else None,
        vertex_ids=vertex_ids,
        colors=None if colors is None else colors.astype(np.float32),
        notes=notes,
    )
    if skin is not None and joints is not None and weights is not None:
        j = joints.astype(np.int64)
        if j.max(initial=0) >= len(skin["names"]):
            raise r.err("JOINTS_0 index past the skin's joints", key + "/attributes/JOINTS_0")
        mesh.joints = j
        mesh.skin_weights = weights.astype(np.float32)
        mesh.joint_names = skin["names"]
        mesh.inverse_bind = skin["ibm"]
        mesh.notes.append(f"skin {skin['index']}: {len(skin['names'])} joints")
    return mesh


def drop_degenerate(positions: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, int]:
    """Remove triangles with repeated indices or zero area; return (kept, removed count)."""
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(tris, dtype=np.int64)
    rep = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
    tri = p[t]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    keep = ~rep & (area2 > 0)
    return t[keep], int((~keep).sum())


def bake_world(mesh: Mesh, m: np.ndarray) -> Mesh:
    """Apply world matrix ``m`` to positions, normals, tangents and morph deltas (in place;
    a mirrored instance flips triangle winding); ValueError for a singular matrix."""
    lin = m[:3, :3]
    if abs(np.linalg.det(lin)) < 1e-30:
        raise ValueError("singular transform")
    mesh.positions = (mesh.positions.astype(np.float64) @ lin.T + m[:3, 3]).astype(np.float32)
    if mesh.morph_deltas is not None:
        mesh.morph_deltas = (mesh.morph_deltas.astype(np.float64) @ lin.T).astype(np.float32)
    nrm_m = np.linalg.inv(lin).T
    if mesh.normals is not None:
        n = mesh.normals.astype(np.float64) @ nrm_m.T
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30)
        mesh.normals = n.astype(np.float32)
    if mesh.tangents is not None:
        t = mesh.tangents[:, :3].astype(np.float64) @ lin.T
        t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-30)
        w = mesh.tangents[:, 3:] * np.sign(np.linalg.det(lin) or 1.0)
        mesh.tangents = np.concatenate([t, w], axis=1).astype(np.float32)
    if np.linalg.det(lin) < 0:  # mirrored instance: keep counter-clockwise front faces
        mesh.indices = mesh.indices[:, [0, 2, 1]].copy()
    return mesh


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
    r = _MeshFile(Path(path), GltfReadOptions())
    doc = r.doc
    if any(t is not None for t in times) and not doc.get("animations"):
        raise r.err("the file has no animation to sample", "/animations")
    rest_nodes = [dict(n) for n in doc.get("nodes", [])]
    channels = []
    for ci, ch in enumerate((doc.get("animations") or [{}])[0].get("channels", [])):
        tgt = ch.get("target", {})
        path_ = tgt.get("path")
        if path_ not in ("translation", "rotation", "scale") or "node" not in tgt:
            continue
        smp = doc["animations"][0]["samplers"][ch["sampler"]]
        key = f"/animations/0/channels/{ci}"
        t_in = r.typed(smp["input"], key)[:, 0].astype(np.float64)
        vals = r.typed(smp["output"], key).astype(np.float64)
        interp = smp.get("interpolation", "LINEAR")
        if interp == "CUBICSPLINE":
            vals = vals.reshape(len(t_in), 3, -1)
        channels.append((int(tgt["node"]), path_, t_in, vals, interp))
    names_to_node = {}
    for s in doc.get("skins", []):
        for j in s.get("joints", []):
            nm = str(rest_nodes[j].get("name") or f"joint{j}")
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
    r = _MeshFile(Path(path), GltfReadOptions())
    anims = r.doc.get("animations") or []
    if not anims:
        raise r.err("the file has no animation", "/animations")
    keys = [
        r.typed(s["input"], f"/animations/0/samplers/{i}")[:, 0].astype(np.float64)
        for i, s in enumerate(anims[0].get("samplers", []))
    ]
    return np.unique(np.concatenate(keys)) if keys else np.zeros(1)


def gltf_morph_weights(path: str | Path, mesh: Mesh, time: float) -> dict[str, float]:
    """Morph-target weights at ``time`` (seconds) of the first animation's ``weights`` channels
    (else the node's / mesh's default ``weights``), by target name, for targets ``mesh`` has."""
    r = _MeshFile(Path(path), GltfReadOptions())
    doc = r.doc
    if not doc.get("animations"):
        raise r.err("the file has no animation to sample", "/animations")
    nodes = doc.get("nodes", [])
    meshes = doc.get("meshes", [])
    out: dict[str, float] = {}
    for ni, node in enumerate(nodes):
        if "mesh" not in node or not 0 <= int(node["mesh"]) < len(meshes):
            continue
        gm = meshes[int(node["mesh"])]
        n_t = max((len(p.get("targets", [])) for p in gm.get("primitives", [])), default=0)
        if not n_t:
            continue
        names = list((gm.get("extras") or {}).get("targetNames", []))
        names = [str(names[i]) if i < len(names) else f"target_{i}" for i in range(n_t)]
        w = np.asarray(node.get("weights", gm.get("weights", [0.0] * n_t)), dtype=np.float64)
        for ai, anim in enumerate(doc.get("animations", [])[:1]):
            for ci, ch in enumerate(anim.get("channels", [])):
                tgt = ch.get("target", {})
                if tgt.get("path") != "weights" or tgt.get("node") != ni:
                    continue
                smp = anim["samplers"][ch["sampler"]]
                key = f"/animations/{ai}/channels/{ci}"
                t_in = r.typed(smp["input"], key)[:, 0].astype(np.float64)
                vals = r.typed(smp["output"], key).astype(np.float64).reshape(-1)
                interp = smp.get("interpolation", "LINEAR")
                shape = (len(t_in), 3, n_t) if interp == "CUBICSPLINE" else (len(t_in), n_t)
                w = sample_channel(
                    t_in,
                    vals.reshape(shape),
                    float(time),
                    interp,
                    "weights",
                )
        for name, value in zip(names, w):
            if name in mesh.morph_names:
                out.setdefault(name, float(value))
    return out


def slerp(q0: np.ndarray, q1: np.ndarray, a: float) -> np.ndarray:
    """Spherical linear interpolation of unit quaternions (the shorter arc), as glTF specifies."""
    q0 = np.asarray(q0, np.float64)
    q1 = np.asarray(q1, np.float64)
    d = float(np.dot(q0, q1))
    if d < 0.0:
        q1, d = -q1, -d
    if d > 0.9995:  # nearly parallel: lerp is exact to float precision
        q = (1 - a) * q0 + a * q1
    else:
        theta = np.arccos(d)
        q = (np.sin((1 - a) * theta) * q0 + np.sin(a * theta) * q1) / np.sin(theta)
    return q / np.linalg.norm(q)


def sample_channel(t: np.ndarray, v: np.ndarray, time: float, interp: str, path: str) -> np.ndarray:
    """Sample a glTF animation channel at ``time`` (:func:`sample_channel_at` at one time)."""
    return sample_channel_at(t, v, np.array([time], np.float64), interp, path)[0]


def _slerp_rows(q0: np.ndarray, q1: np.ndarray, a: np.ndarray) -> np.ndarray:
    """:func:`slerp` of quaternion rows ``[F, 4]`` by ``a`` ``[F]``."""
    d = np.sum(q0 * q1, axis=1)
    q1 = np.where(d[:, None] < 0, -q1, q1)
    d = np.abs(d)
    near = d > 0.9995
    theta = np.arccos(np.clip(d, -1.0, 1.0))
    sin = np.where(near, 1.0, np.sin(theta))
    w0 = np.where(near, 1 - a, np.sin((1 - a) * theta) / sin)
    w1 = np.where(near, a, np.sin(a * theta) / sin)
    q = w0[:, None] * q0 + w1[:, None] * q1
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def sample_channel_at(
    t: np.ndarray, v: np.ndarray, times: np.ndarray, interp: str, path: str
) -> np.ndarray:
    """Sample a glTF animation channel at ``times`` -> ``[F, C]``, per the glTF 2.0 spec
    (Appendix C).

    ``v`` is ``[N, C]`` for STEP / LINEAR and ``[N, 3, C]`` (in-tangent, value, out-tangent)
    for CUBICSPLINE. LINEAR rotations slerp; cubic rotations are normalised. Times outside the
    keys clamp to the first / last value.
    """
    vals = v[:, 1] if interp == "CUBICSPLINE" else v
    times = np.asarray(times, np.float64)
    if len(t) == 1:
        return np.repeat(vals[:1], len(times), axis=0).astype(np.float64)
    k = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
    td = t[k + 1] - t[k]
    a = np.clip((times - t[k]) / np.where(td > 0, td, 1.0), 0.0, 1.0)
    if interp == "STEP":
        out = vals[k].astype(np.float64)
    elif interp == "CUBICSPLINE":
        a2, a3 = a * a, a * a * a
        out = (
            (2 * a3 - 3 * a2 + 1)[:, None] * v[k, 1]
            + (td * (a3 - 2 * a2 + a))[:, None] * v[k, 2]
            + (-2 * a3 + 3 * a2)[:, None] * v[k + 1, 1]
            + (td * (a3 - a2))[:, None] * v[k + 1, 0]
        )
        if path == "rotation":
            out /= np.linalg.norm(out, axis=1, keepdims=True)
    elif path == "rotation":
        out = _slerp_rows(vals[k].astype(np.float64), vals[k + 1].astype(np.float64), a)
    else:
        out = (1 - a)[:, None] * vals[k] + a[:, None] * vals[k + 1]
    out[times <= t[0]] = vals[0]
    out[times >= t[-1]] = vals[-1]
    return out
