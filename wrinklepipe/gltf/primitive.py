"""THE per-primitive glTF reader: one primitive of a glTF JSON tree and its accessors ->
:class:`wrinklepipe.asset.Mesh`, for both glTF mesh readers.

:func:`read_primitive` reads one primitive of any :class:`GltfSource`: a file opened by
:class:`wrinklepipe.gltf.read.GltfFile` (mesh ingest, :func:`wrinklepipe.gltf.meshes.
read_gltf_meshes`) or the pass-through :class:`wrinklepipe.gltf.document.Document` (the
render mesh of a source or a package, :mod:`wrinklepipe.gltf.render_mesh`). What it reads:
POSITION (VEC3, finite), NORMAL, TANGENT, TEXCOORD_0, a colour attribute (``COLOR_0``, VEC3
given alpha 1; or a package's ``_WRINKLE_BIAS``: :class:`PrimitiveOptions`), JOINTS_0 /
WEIGHTS_0 with the instancing node's skin (joint names: the nodes' names, ``node<i>`` when
unnamed; inverse bind matrices: identity when the skin has none, per the spec), the
``_WRINKLE_VERTEX_ID`` attribute, and morph targets (POSITION deltas; names from
``mesh.extras.targetNames``, else ``target_<i>``). :func:`read_instance` adds the node: a
node with a skin keeps the bind space (the spec ignores a skinned mesh's node transform); any
other instance is baked into world space (positions, normals, tangents, morph deltas; a
mirroring matrix flips the winding).

- Accessors come through the source (:func:`wrinklepipe.gltf.accessors.read_accessor`, the one
  accessor reader: component types, strides, sparse, ``normalized`` integers as floats);
  indices and JOINTS_0 are never normalized (the spec forbids it).
- Modes TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN (strips and fans unrolled, noted); every
  index must name a vertex.
- Degenerate triangles (a repeated index or zero area) are left out, counted in the notes;
  a primitive may be left with none (valid glTF): the caller decides.
- ``strict`` (:class:`PrimitiveOptions`): a malformed optional part (vertex IDs, a morph
  target of the wrong length or with non-finite deltas) is an error naming the pointer;
  otherwise it is left out and noted.

Everything else malformed is an :class:`~wrinklepipe.errors.InputError` naming the file and
the JSON pointer.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import InputError
from wrinklepipe.geometry.polygons import drop_degenerate
from wrinklepipe.metadata import BIAS_ATTRIBUTE, BIAS_CHANNEL_ATTRIBUTES, VERTEX_ID_ATTRIBUTE
from wrinklepipe.names import noun, plural

#: Modes read as triangles: TRIANGLES, TRIANGLE_STRIP, TRIANGLE_FAN.
TRIANGLE_MODES = (4, 5, 6)


class GltfSource(Protocol):
    """What :func:`read_primitive` reads a glTF through: the JSON tree, its accessors decoded
    as ``[count, components]`` (``normalize``: normalized integers as floats), and the error
    naming the file and JSON pointer. :class:`wrinklepipe.gltf.read.GltfFile` and
    :class:`wrinklepipe.gltf.document.Document` are both one."""

    gltf: dict[str, Any]

    def accessor(self, i: Any, normalize: bool = True) -> np.ndarray: ...

    def err(self, message: str, key: str = "") -> InputError: ...


@dataclass(frozen=True)
class PrimitiveOptions:
    """Options of :func:`read_primitive`.

    colors: the attribute read into ``Mesh.colors`` (``COLOR_0``, VEC3 gets alpha 1; a
        wrinkle package's render mesh reads its ``_WRINKLE_BIAS``: the four SCALAR channels
        ``_WRINKLE_BIAS_R``..``_A`` it writes, or one VEC3/VEC4 attribute as written before).
    strict: a malformed optional part (``_WRINKLE_VERTEX_ID``, a morph target of the wrong
        length or with non-finite deltas) is an error; otherwise (mesh ingest of any file) it
        is left out and noted.
    """

    colors: str = "COLOR_0"
    strict: bool = False


@dataclass(frozen=True)
class Skin:
    """A glTF skin as a mesh carries it: joint names, inverse bind matrices ``[J, 4, 4]``."""

    index: int
    names: tuple[str, ...]
    inverse_bind: np.ndarray  # [J, 4, 4] float32, column vectors


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
    q = _vec(node, "rotation", [0, 0, 0, 1], 4)
    s = _vec(node, "scale", [1, 1, 1], 3)
    return trs_matrices(t[None], q[None], s[None])[0]


def trs_matrices(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``[F, 4, 4]`` (column vectors) of translations ``[F, 3]``, unit quaternions ``[F, 4]``
    (x, y, z, w) and scales ``[F, 3]``: T R S, as glTF composes a node."""
    x, y, z, w = q.T
    r = np.empty((len(q), 3, 3))
    r[:, 0] = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], 1)
    r[:, 1] = np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], 1)
    r[:, 2] = np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], 1)
    m = np.tile(np.eye(4), (len(q), 1, 1))
    m[:, :3, :3] = r * s[:, None, :]
    m[:, :3, 3] = t
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


def json_type(v: Any) -> str:
    """The JSON name of a value's type (for messages)."""
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, (int, float)):
        return "a number"
    return {str: "a string", list: "an array", dict: "an object"}.get(type(v), "null")


def node_name(gltf: dict[str, Any], i: int) -> str:
    """A node's name (``node<i>`` when unnamed): how a joint is named."""
    nodes = gltf.get("nodes", [])
    node = nodes[i] if isinstance(nodes, list) and 0 <= i < len(nodes) else {}
    name = node.get("name") if isinstance(node, dict) else None
    return str(name) if name else f"node{i}"


def target_names(gltf: dict[str, Any], mesh: int) -> list[str]:
    """Morph target names of a mesh (``extras.targetNames``; ``target_<i>`` for the rest), one
    per target of its primitive with the most."""
    m = gltf["meshes"][mesh]
    n = max((len(p.get("targets", [])) for p in m.get("primitives", [])), default=0)
    names = (m.get("extras") or {}).get("targetNames", []) if isinstance(m, dict) else []
    names = names if isinstance(names, list) else []
    return [str(names[i]) if i < len(names) else f"target_{i}" for i in range(n)]


def read_skin(src: GltfSource, index: int) -> Skin:
    """Skin ``index``: its joints' node names and inverse bind matrices (identity when the
    skin has none, per the spec)."""
    skins = src.gltf.get("skins", [])
    if not isinstance(index, int) or not 0 <= index < len(skins):
        raise src.err(f"skin {index} does not exist", "/skins")
    s = skins[index]
    joints = [int(j) for j in s.get("joints", [])]
    names = tuple(node_name(src.gltf, j) for j in joints)
    if "inverseBindMatrices" in s:
        m = src.accessor(s["inverseBindMatrices"]).astype(np.float32)
        if m.shape != (len(joints), 16):
            raise src.err("inverseBindMatrices count differs from joints", f"/skins/{index}")
        ibm = np.ascontiguousarray(m.reshape(-1, 4, 4).transpose(0, 2, 1))  # column-major
    else:
        ibm = np.tile(np.eye(4, dtype=np.float32), (len(joints), 1, 1))
    return Skin(index, names, ibm)


def primitive_triangles(src: GltfSource, mesh: int, prim: int) -> np.ndarray:
    """``[T, 3]`` int64 vertex indices of a triangle primitive (strips and fans unrolled; no
    triangles for another mode); every index must name a vertex."""
    key = f"/meshes/{mesh}/primitives/{prim}"
    p = src.gltf["meshes"][mesh]["primitives"][prim]
    n = len(src.accessor(p["attributes"]["POSITION"]))
    if "indices" in p:  # never normalized (the spec forbids it)
        idx = src.accessor(p["indices"], normalize=False)[:, 0].astype(np.int64)
    else:
        idx = np.arange(n, dtype=np.int64)
    if len(idx) and (idx.min() < 0 or idx.max() >= n):
        raise src.err(f"indices out of range 0..{n - 1} (max {int(idx.max())})", key + "/indices")
    mode = int(p.get("mode", 4))
    if mode not in TRIANGLE_MODES:
        return np.zeros((0, 3), np.int64)
    return triangulate(mode, idx)


def read_primitive(
    src: GltfSource,
    mesh: int,
    prim: int,
    options: PrimitiveOptions | None = None,
    skin: Skin | None = None,
) -> Mesh:
    """Primitive ``prim`` of mesh ``mesh`` as a :class:`Mesh` in the mesh's own space (see
    the module doc), named ``<mesh name>`` or ``<mesh name>/<prim>``; with the ``skin`` of
    the node that instances it when it has JOINTS_0 and WEIGHTS_0. An
    :class:`~wrinklepipe.errors.InputError` names the file and JSON pointer of anything
    malformed."""
    opts = options or PrimitiveOptions()
    key = f"/meshes/{mesh}/primitives/{prim}"
    gm = src.gltf["meshes"][mesh]
    p = gm["primitives"][prim]
    attrs = p.get("attributes", {})
    if not isinstance(attrs, dict):
        raise src.err(f"attributes must be an object, got {json_type(attrs)}", key)
    if "POSITION" not in attrs:
        raise src.err("primitive has no POSITION attribute", key + "/attributes")
    pos = src.accessor(attrs["POSITION"]).astype(np.float32)
    if pos.shape[1] != 3:
        raise src.err("POSITION must be VEC3", key + "/attributes/POSITION")
    nv = len(pos)
    bad = ~np.isfinite(pos).all(axis=1)
    if bad.any():
        v = int(np.flatnonzero(bad)[0])
        raise src.err(
            f"{plural(int(bad.sum()), 'position')} {noun(int(bad.sum()), 'is', 'are')} NaN or "
            f"infinite (first: vertex {v})",
            key + "/attributes/POSITION",
        )
    notes: list[str] = []

    def attr(name: str, width: tuple[int, ...], normalize: bool = True) -> np.ndarray | None:
        if name not in attrs:
            return None
        a = src.accessor(attrs[name], normalize)
        if len(a) != nv or a.shape[1] not in width:
            raise src.err(
                f"{name} has {len(a)} x {a.shape[1]} values, POSITION has {nv}",
                f"{key}/attributes/{name}",
            )
        return a

    mode = int(p.get("mode", 4))
    if mode not in TRIANGLE_MODES:
        raise src.err(f"primitive mode {mode} is not triangles", key + "/mode")
    tris = primitive_triangles(src, mesh, prim)
    if mode != 4:
        notes.append(f"triangulated a {'strip' if mode == 5 else 'fan'}")
    tris, n_degen = drop_degenerate(pos, tris)
    if n_degen:
        notes.append(f"skipped {plural(n_degen, 'degenerate triangle')}")

    normals = attr("NORMAL", (3,))
    tangents = attr("TANGENT", (4,))
    uvs = attr("TEXCOORD_0", (2,))
    colors = attr(opts.colors, (3, 4))
    if colors is None and opts.colors == BIAS_ATTRIBUTE:
        colors = bias_channels(attrs, lambda name: attr(name, (1,)), src.err, key)
    if colors is not None and colors.shape[1] == 3:
        colors = np.concatenate([colors, np.ones((nv, 1), colors.dtype)], axis=1)
    joints = attr("JOINTS_0", (4,), normalize=False)  # joint indices, never normalized
    weights = attr("WEIGHTS_0", (4,))
    vertex_ids = _vertex_ids(src, attrs, nv, key, opts, notes)
    names = target_names(src.gltf, mesh)
    targets = p.get("targets", [])
    deltas, tnames = _morph_targets(src, targets, names, nv, key, opts, notes)
    given = (gm.get("extras") or {}).get("targetNames")
    if isinstance(given, list) and given and len(given) != len(targets):
        notes.append(f"extras.targetNames has {len(given)} names for {len(targets)} targets")
    label = gm.get("name") or f"mesh{mesh}"
    out = Mesh(
        positions=pos,
        indices=tris.astype(np.uint32),
        uvs=_f32(uvs),
        normals=_f32(normals),
        tangents=_f32(tangents),
        morph_names=tuple(tnames),
        morph_deltas=np.stack(deltas) if deltas else None,
        vertex_ids=vertex_ids,
        colors=_f32(colors),
        name=f"{label}/{prim}" if len(gm.get("primitives", [])) > 1 else str(label),
        notes=notes,
    )
    if skin is not None and joints is not None and weights is not None:
        j = joints.astype(np.int64)
        if j.max(initial=0) >= len(skin.names):
            raise src.err("JOINTS_0 index past the skin's joints", key + "/attributes/JOINTS_0")
        out.joints = j
        out.skin_weights = weights.astype(np.float32)
        out.joint_names = skin.names
        out.inverse_bind = skin.inverse_bind
    return out


def _f32(a: np.ndarray | None) -> np.ndarray | None:
    return None if a is None else np.ascontiguousarray(a, np.float32)


def _vertex_ids(
    src: GltfSource,
    attrs: dict[str, Any],
    nv: int,
    key: str,
    opts: PrimitiveOptions,
    notes: list[str],
) -> np.ndarray | None:
    """The ``_WRINKLE_VERTEX_ID`` attribute: one non-negative integer per vertex."""
    if VERTEX_ID_ATTRIBUTE not in attrs:
        return None
    a = src.accessor(attrs[VERTEX_ID_ATTRIBUTE])
    v = a[:, 0].astype(np.float64)
    if a.shape == (nv, 1) and np.all(v == np.rint(v)) and np.all(v >= 0):
        return v.astype(np.int64)
    if opts.strict:
        raise src.err(
            "vertex IDs must be one non-negative integer per vertex",
            f"{key}/attributes/{VERTEX_ID_ATTRIBUTE}",
        )
    notes.append(f"ignored {VERTEX_ID_ATTRIBUTE} (not one non-negative integer per vertex)")
    return None


def bias_channels(
    attrs: dict[str, Any],
    read: Any,
    err: Any,
    key: str,
) -> np.ndarray | None:
    """The bias ``[V, 4]`` from its per-channel attributes (``_WRINKLE_BIAS_R``..``_A``, each
    read by ``read(name)`` as ``[V, 1]``), or None when the primitive has none of them; some
    but not all of them is an error (``err(message, pointer)``)."""
    have = [n for n in BIAS_CHANNEL_ATTRIBUTES if n in attrs]
    if not have:
        return None
    if len(have) != len(BIAS_CHANNEL_ATTRIBUTES):
        missing = ", ".join(n for n in BIAS_CHANNEL_ATTRIBUTES if n not in attrs)
        raise err(f"the bias lacks {missing} (it is written as four channels)", key + "/attributes")
    return np.concatenate([read(n) for n in BIAS_CHANNEL_ATTRIBUTES], axis=1)


def _morph_targets(
    src: GltfSource,
    targets: list[dict[str, Any]],
    names: list[str],
    nv: int,
    key: str,
    opts: PrimitiveOptions,
    notes: list[str],
) -> tuple[list[np.ndarray], list[str]]:
    """The POSITION deltas ``[V, 3]`` of every target and their names (a target without
    POSITION: zeros)."""
    deltas, kept = [], []
    for ti, tgt in enumerate(targets):
        name = names[ti]
        if "POSITION" not in tgt:
            d = np.zeros((nv, 3), np.float32)
        else:
            d = src.accessor(tgt["POSITION"]).astype(np.float32)
            if d.shape != (nv, 3) or not np.isfinite(d).all():
                what = f"{d.shape[0]} x {d.shape[1]} deltas for {nv} vertices" + (
                    "" if np.isfinite(d).all() else " or non-finite values"
                )
                if opts.strict:
                    raise src.err(f"morph target has {what}", f"{key}/targets/{ti}/POSITION")
                notes.append(f"skipped morph target {name!r}: {what}")
                continue
        deltas.append(d)
        kept.append(name)
    return deltas, kept


def read_instance(
    src: GltfSource,
    mesh: int,
    prim: int,
    node: int | None,
    world: np.ndarray,
    bake: bool = True,
    options: PrimitiveOptions | None = None,
) -> tuple[Mesh, str | None]:
    """Primitive ``prim`` of mesh ``mesh`` as node ``node`` (world matrix ``world``)
    instances it: with the node's skin (bind space, the node transform ignored, as the spec
    says), or, with ``bake``, baked into world space. Returns the mesh and what was done
    (``"skinned"``, ``"baked"`` or None)."""
    n = src.gltf["nodes"][node] if node is not None else {}
    skin = read_skin(src, int(n["skin"])) if "skin" in n else None
    m = read_primitive(src, mesh, prim, options, skin)
    if skin is not None:
        return m, "skinned" if m.joints is not None else None
    if not bake or np.allclose(world, np.eye(4)):
        return m, None
    try:
        bake_world(m, world)
    except ValueError:
        raise src.err("the node's world transform is singular", f"/nodes/{node}") from None
    return m, "baked"


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
