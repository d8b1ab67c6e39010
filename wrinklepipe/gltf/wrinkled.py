"""The wrinkled part of a source document: the named material(s) and the primitives using them.

- :func:`select_materials`: the manifest's ``material`` (a name or a list) -> material indices.
  Omitted: the document's only material. Every bad case is one clear
  :class:`~wrinklepipe.errors.InputError` that lists the materials and the primitives that use
  them: an unknown name, an ambiguous one (two materials share it), an omitted name with several
  materials, a named material no primitive uses.
- :func:`wrinkled_primitives`: the primitives whose material is wrinkled (only they get
  tangents, vertex IDs, mask lookups, side checks, dynamic weights, framing).
- :func:`add_wrinkle_attributes`: gives each wrinkled primitive MikkTSpace ``TANGENT`` where it
  has none (or invalid ones), a ``TEXCOORD_n`` front projection where it has no UVs (noted), and
  ``_WRINKLE_VERTEX_ID`` (FLOAT, spatial-hash IDs shared across all wrinkled primitives, computed
  on their rest-pose world positions). Only new accessors are added; nothing else changes.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.errors import input_error
from wrinklepipe.geometry.normals import vertex_normals
from wrinklepipe.geometry.tangents import mikktspace_tangents_report
from wrinklepipe.geometry.vertex_ids import compute_vertex_ids
from wrinklepipe.gltf.document import ARRAY_BUFFER, Document, PrimitiveRef
from wrinklepipe.gltf.scene import node_world_matrices, primitive_triangles, rest_positions
from wrinklepipe.metadata import VERTEX_ID_ATTRIBUTE
from wrinklepipe.names import did_you_mean, plural

#: Largest integer a float32 holds exactly (vertex IDs are FLOAT accessors).
MAX_FLOAT_ID = 1 << 24


def material_listing(doc: Document) -> str:
    """``'Grey' (Foot.L/0, Torso/0, ...); 'Main' (...)``: every material and its primitives."""
    parts = []
    for i in range(len(doc.array("materials"))):
        prims = [
            f"{doc.mesh_name(r.mesh)}/{r.primitive}" for r in doc.primitives() if r.material == i
        ]
        parts.append(f"{doc.material_name(i)!r} ({', '.join(prims) or 'no primitive'})")
    return "; ".join(parts) or "none"


def select_materials(
    doc: Document, wanted: str | list[str] | None, manifest: str | Path = ""
) -> list[int]:
    """Material indices the manifest's ``material`` names (see the module doc)."""
    file = str(manifest or doc.file)
    mats = doc.array("materials")
    names = [doc.material_name(i) for i in range(len(mats))]
    if wanted is None:
        if len(mats) == 1:
            chosen = [0]
        else:
            raise input_error(
                file,
                f"{doc.path.name} has {len(mats)} materials; name the wrinkled one with "
                f'material = "NAME" (materials: {material_listing(doc)})',
                "material",
            )
    else:
        chosen = []
        for k, name in enumerate([wanted] if isinstance(wanted, str) else list(wanted)):
            hits = [i for i, n in enumerate(names) if n == name]
            key = "material" if isinstance(wanted, str) else f"material[{k}]"
            if not hits:
                raise input_error(
                    file,
                    f"no material {name!r} in {doc.path.name}{did_you_mean(name, names)} "
                    f"(materials: {material_listing(doc)})",
                    key,
                )
            if len(hits) > 1:
                raise input_error(
                    file,
                    f"material name {name!r} is ambiguous in {doc.path.name}: materials "
                    f"{', '.join(map(str, hits))} share it (materials: {material_listing(doc)})",
                    key,
                )
            if hits[0] not in chosen:
                chosen.append(hits[0])
    used = {r.material for r in doc.primitives()}
    for i in chosen:
        if i not in used:
            raise input_error(
                file,
                f"material {names[i]!r} is used by no primitive of {doc.path.name}; nothing "
                f"would be wrinkled (materials: {material_listing(doc)})",
                "material",
            )
    return chosen


def wrinkled_primitives(doc: Document, materials: list[int]) -> list[PrimitiveRef]:
    """The triangle primitives whose material is one of ``materials``, in document order."""
    return [
        r
        for r in doc.primitives()
        if r.material in materials and int(doc.primitive(r).get("mode", 4)) in (4, 5, 6)
    ]


def mesh_listing(doc: Document, materials: list[int]) -> str:
    """``'Head' (nodes 'Head'; primitives 1)``: the meshes with primitives of ``materials``."""
    parts = []
    for mi in range(len(doc.array("meshes"))):
        prims = [r.primitive for r in doc.primitives() if r.mesh == mi and r.material in materials]
        if prims:
            nodes = ", ".join(repr(doc.node_name(n)) for n in doc.mesh_nodes(mi)) or "no node"
            parts.append(
                f"{doc.mesh_name(mi)!r} (nodes {nodes}; primitives {', '.join(map(str, prims))})"
            )
    return "; ".join(parts) or "none"


def _mesh_and_node_names(doc: Document, refs: list[PrimitiveRef]) -> list[str]:
    """The names of the meshes of ``refs`` and of the nodes instancing them."""
    out = []
    for mesh in dict.fromkeys(r.mesh for r in refs):
        out.append(doc.mesh_name(mesh))
        out += [doc.node_name(n) for n in doc.mesh_nodes(mesh)]
    return out


def restrict_to_meshes(
    doc: Document,
    refs: list[PrimitiveRef],
    names: tuple[str, ...] | list[str],
    materials: list[int],
    manifest: str | Path = "",
) -> list[PrimitiveRef]:
    """The primitives of ``refs`` whose mesh, or a node instancing it, is named in ``names``.

    A name that matches no mesh or node with a wrinkled-material primitive is one clear
    :class:`~wrinklepipe.errors.InputError` listing the meshes (and nodes) that have one."""
    file = str(manifest or doc.file)
    keep: set[int] = set()
    mats = ", ".join(repr(doc.material_name(m)) for m in materials)
    for k, name in enumerate(names):
        hits = {
            r.mesh
            for r in refs
            if doc.mesh_name(r.mesh) == name
            or any(doc.node_name(n) == name for n in doc.mesh_nodes(r.mesh))
        }
        if not hits:
            raise input_error(
                file,
                f"no mesh or node {name!r} in {doc.path.name} has a primitive using {mats}"
                f"{did_you_mean(name, _mesh_and_node_names(doc, refs))} "
                f"(meshes using it: {mesh_listing(doc, materials)})",
                f"meshes[{k}]",
            )
        keep |= hits
    return [r for r in refs if r.mesh in keep]


def clone_shared_materials(
    doc: Document, refs: list[PrimitiveRef]
) -> tuple[list[PrimitiveRef], list[int], list[str]]:
    """Give the wrinkled primitives their own copy of a material other primitives also use.

    The clone (every property and extension of the source material, named ``"NAME
    (wrinkled)"``) is appended to ``materials``; only the wrinkled primitives point at it, so
    the rest of the document is unchanged. Returns the updated refs, the wrinkled material
    indices and notes."""
    wrinkled = {(r.mesh, r.primitive) for r in refs}
    materials = list(dict.fromkeys(r.material for r in refs if r.material is not None))
    clones: dict[int, int] = {}
    notes: list[str] = []
    for m in materials:
        others = [
            r for r in doc.primitives() if r.material == m and (r.mesh, r.primitive) not in wrinkled
        ]
        if not others:
            continue
        mat: dict[str, Any] = copy.deepcopy(doc.array("materials")[m])
        mat["name"] = f"{doc.material_name(m)} (wrinkled)"
        doc.gltf["materials"].append(mat)
        clones[m] = len(doc.gltf["materials"]) - 1
        notes.append(
            f"material {doc.material_name(m)!r} is shared with {plural(len(others), 'primitive')} "
            "outside "
            f"the wrinkled meshes: cloned as {mat['name']!r} (materials[{clones[m]}]) for the "
            "wrinkled primitives; the others keep the original"
        )
    out = []
    for r in refs:
        if r.material in clones:
            doc.primitive(r)["material"] = clones[r.material]
            r = PrimitiveRef(r.mesh, r.primitive, clones[r.material])
        out.append(r)
    return out, [clones.get(m, m) for m in materials], notes


#: Properties of the material convert creates for a document without any (the demo's look).
DEFAULT_MATERIAL: dict[str, Any] = {
    "pbrMetallicRoughness": {
        "baseColorFactor": [0.8, 0.62, 0.52, 1.0],
        "metallicFactor": 0.0,
        "roughnessFactor": 0.55,
    },
}


@dataclass
class Selection:
    """What gets wrinkled: material indices (clones included) and their triangle primitives."""

    materials: list[int]
    refs: list[PrimitiveRef]
    notes: list[str] = field(default_factory=list)
    #: clone -> the source's material it copies (messages name the material the user named)
    origin: dict[int, int] = field(default_factory=dict)


def select_wrinkled(
    doc: Document,
    material: str | list[str] | None,
    meshes: tuple[str, ...] | list[str] = (),
    manifest: str | Path = "",
    name: str = "",
) -> Selection:
    """The manifest's ``material`` (+ optional ``meshes`` restriction) -> a :class:`Selection`.

    A document without materials (and no ``material`` named) gets one, ``NAME_skin``, for its
    triangle primitives without a material (noted). Shared materials are cloned for a
    restricted set of primitives (:func:`clone_shared_materials`)."""
    notes: list[str] = []
    if material is None and not doc.array("materials"):
        mat = {"name": f"{name or doc.path.stem}_skin", **copy.deepcopy(DEFAULT_MATERIAL)}
        doc.gltf["materials"] = [mat]
        for r in doc.primitives():
            if r.material is None and int(doc.primitive(r).get("mode", 4)) in (4, 5, 6):
                doc.primitive(r)["material"] = 0
        notes.append(f"the document has no material: added {mat['name']!r} for its primitives")
    chosen = select_materials(doc, material, manifest)
    refs = wrinkled_primitives(doc, chosen)
    origin: dict[int, int] = {}
    if meshes:
        refs = restrict_to_meshes(doc, refs, meshes, chosen, manifest)
        source = {(r.mesh, r.primitive): r.material for r in refs}
        refs, chosen, n = clone_shared_materials(doc, refs)
        origin = {
            r.material: source[(r.mesh, r.primitive)]
            for r in refs
            if r.material != source[(r.mesh, r.primitive)]
        }
        notes += n
    return Selection(chosen, refs, notes, origin)


@dataclass
class WrinkledPart:
    """One wrinkled primitive as the pipeline's maths sees it (rest-pose world space)."""

    ref: PrimitiveRef
    positions: np.ndarray  # [V, 3] float64 rest-pose world positions
    triangles: np.ndarray  # [T, 3] int64
    uvs: np.ndarray  # [V, 2] float32 (glTF convention)
    vertex_ids: np.ndarray  # [V] int64, shared across the parts
    notes: list[str] = field(default_factory=list)


def _valid_tangents(t: np.ndarray, n: np.ndarray | None) -> bool:
    if t.shape[1] != 4 or not np.isfinite(t).all():
        return False
    length = np.linalg.norm(t[:, :3], axis=1)
    if np.any(np.abs(length - 1) > 1e-2) or np.any(np.abs(np.abs(t[:, 3]) - 1) > 1e-3):
        return False
    if n is not None and np.any(np.abs(np.einsum("ij,ij->i", t[:, :3], n)) > 0.1):
        return False
    return True


def front_projection_uvs(positions: np.ndarray) -> np.ndarray:
    """UVs from the front (+Z) view: u along +X, v down along -Y, over the bounds (uniform
    scale, centred), so the whole wrinkled area maps into [0, 1]^2 without splitting vertices."""
    p = np.asarray(positions, np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    span = float(max(hi[0] - lo[0], hi[1] - lo[1], 1e-12))
    c = (lo + hi) / 2
    u = 0.5 + (p[:, 0] - c[0]) / span
    v = 0.5 - (p[:, 1] - c[1]) / span
    return np.stack([u, v], axis=1).astype(np.float32)


def add_wrinkle_attributes(doc: Document, refs: list[PrimitiveRef]) -> list[WrinkledPart]:
    """Add TANGENT (where missing or invalid), TEXCOORD (where missing) and the shared
    ``_WRINKLE_VERTEX_ID`` to each wrinkled primitive (new accessors only)."""

    worlds = node_world_matrices(doc)
    world = [rest_positions(doc, r, worlds=worlds) for r in refs]
    counts = [len(p) for p in world]
    if not refs:
        return []
    ids_all = compute_vertex_ids(np.concatenate(world), source=doc.file)
    if int(ids_all.max(initial=0)) >= MAX_FLOAT_ID:
        raise doc.err(f"more than {MAX_FLOAT_ID} distinct wrinkled positions (FLOAT IDs)")
    ids = np.split(ids_all, np.cumsum(counts)[:-1])
    projected = front_projection_uvs(np.concatenate(world))
    uv_parts = np.split(projected, np.cumsum(counts)[:-1])
    parts: list[WrinkledPart] = []
    for r, wp, vid, puv in zip(refs, world, ids, uv_parts):
        prim = doc.primitive(r)
        attrs = prim["attributes"]
        notes: list[str] = []
        tri = primitive_triangles(doc, r)
        local = doc.accessor(attrs["POSITION"]).astype(np.float64)
        normals = doc.accessor(attrs["NORMAL"]).astype(np.float64) if "NORMAL" in attrs else None
        if normals is None:
            normals = vertex_normals(local.astype(np.float32), tri.astype(np.uint32))
            attrs["NORMAL"] = doc.add_accessor(np.asarray(normals, np.float32), ARRAY_BUFFER)
            notes.append("added area-weighted NORMAL")
        if "TEXCOORD_0" in attrs:
            uvs = doc.accessor(attrs["TEXCOORD_0"]).astype(np.float32)
        else:
            uvs = puv
            attrs["TEXCOORD_0"] = doc.add_accessor(uvs, ARRAY_BUFFER)
            notes.append(
                "no UVs: added TEXCOORD_0 as the front (+Z) projection of the wrinkled "
                "primitives' rest-pose bounds (no vertex split)"
            )
        tangents = doc.accessor(attrs["TANGENT"]) if "TANGENT" in attrs else None
        if tangents is None or not _valid_tangents(tangents, normals):
            t, rep = mikktspace_tangents_report(
                local.astype(np.float32), np.asarray(normals, np.float32), uvs, tri
            )
            attrs["TANGENT"] = doc.add_accessor(t, ARRAY_BUFFER)
            what = "replaced invalid TANGENT with" if tangents is not None else "added"
            zero = rep.degenerate_uv_triangles
            notes.append(
                f"{what} MikkTSpace TANGENT" + (f" ({zero} zero-UV-area triangles)" if zero else "")
            )
        attrs[VERTEX_ID_ATTRIBUTE] = doc.add_accessor(vid.astype(np.float32), ARRAY_BUFFER)
        notes.append(f"added {VERTEX_ID_ATTRIBUTE} (shared across the wrinkled primitives)")
        notes += _custom_attribute_notes(doc, attrs)
        parts.append(WrinkledPart(r, wp, tri, uvs, vid, notes))
    return parts


def _custom_attribute_notes(doc: Document, attrs: dict[str, Any]) -> list[str]:
    """A note when the primitive's custom (``_``) attributes, the source's beside the added
    SCALAR FLOAT vertex IDs, are not all SCALAR FLOAT: Blender 5's glTF importer drops
    non-FLOAT custom attributes and fails on a primitive whose custom attributes mix shapes."""
    accessors = doc.gltf.get("accessors", [])
    other = {
        k: (accessors[i].get("type"), accessors[i].get("componentType"))
        for k, i in attrs.items()
        if k.startswith("_")
        and k != VERTEX_ID_ATTRIBUTE
        and isinstance(i, int)
        and 0 <= i < len(accessors)
    }
    odd = sorted(k for k, (t, c) in other.items() if (t, c) != ("SCALAR", 5126))
    if not odd:
        return []
    return [
        f"the source's custom attributes {', '.join(odd)} are not SCALAR FLOAT like "
        f"{VERTEX_ID_ATTRIBUTE}: Blender 5's glTF importer fails on (or drops) them"
    ]


TEXTURE_TRANSFORM = "KHR_texture_transform"


def material_normal_texture(
    doc: Document,
    materials: list[int],
    manifest: str | Path = "",
    origin: dict[int, int] | None = None,
) -> dict[str, Any]:
    """The ``normalTexture`` the wrinkled materials share, when it is to be the base map.

    Refused, each with one message: a material without one, materials with different ones,
    a ``KHR_texture_transform`` on it or ``texCoord`` other than 0 (masks and states are laid
    out on TEXCOORD_0 without a transform), a ``scale`` other than 1 (the wrinkle shaders read
    the base unscaled). Messages name the source's material (``origin`` maps a clone made for
    a ``meshes`` restriction back to it)."""
    file = str(manifest or doc.file)
    origin = origin or {}
    infos = []
    for m in materials:
        info = doc.array("materials")[m].get("normalTexture")
        name = doc.material_name(origin.get(m, m))
        if not isinstance(info, dict) or not isinstance(info.get("index"), int):
            raise input_error(
                file,
                f"base is omitted but the wrinkled material {name!r} of {doc.path.name} has no "
                'normalTexture; name the base normal map with base = "FILE"',
                "base",
            )
        where = f"{doc.path.name} /materials/{origin.get(m, m)}/normalTexture"
        if TEXTURE_TRANSFORM in (info.get("extensions") or {}):
            raise input_error(
                file,
                f"{where} (the base) has {TEXTURE_TRANSFORM}; wrinkle masks and states are "
                "looked up on untransformed TEXCOORD_0: bake the transform into the UVs or give "
                'base = "FILE"',
                "base",
            )
        if info.get("texCoord", 0) != 0:
            raise input_error(
                file,
                f"{where} (the base) uses TEXCOORD_{info['texCoord']}; wrinkle maps use TEXCOORD_0",
                "base",
            )
        if info.get("scale", 1.0) != 1.0:
            raise input_error(
                file,
                f"{where} (the base) has scale {info['scale']}; the wrinkle shaders read the base "
                'unscaled: bake the scale into the map or give base = "FILE"',
                "base",
            )
        infos.append(info)
    if any(i["index"] != infos[0]["index"] for i in infos):
        raise input_error(
            file,
            "base is omitted but the wrinkled materials use different normal textures ("
            + ", ".join(
                f"{doc.material_name(origin.get(m, m))!r}: texture {i['index']}"
                for m, i in zip(materials, infos)
            )
            + '); name the base normal map with base = "FILE"',
            "base",
        )
    return infos[0]


def material_base_color(
    doc: Document, materials: list[int], manifest: str | Path = ""
) -> tuple[dict[str, Any], tuple[float, float, float]]:
    """The ``baseColorTexture`` the wrinkled materials share and their ``baseColorFactor``'s RGB,
    when they are the base colour of colour states (no ``base_color`` in the manifest).

    Refused, each with one message: a material without one, materials with different ones
    (texture or factor), a ``KHR_texture_transform`` on it or a ``texCoord`` other than 0 (the
    states' colour maps are looked up on TEXCOORD_0 without a transform)."""
    file = str(manifest or doc.file)
    found = []
    for m in materials:
        mat = doc.array("materials")[m]
        pbr = mat.get("pbrMetallicRoughness") if isinstance(mat, dict) else None
        pbr = pbr if isinstance(pbr, dict) else {}
        info = pbr.get("baseColorTexture")
        name = doc.material_name(m)
        if not isinstance(info, dict) or not isinstance(info.get("index"), int):
            raise input_error(
                file,
                f"the states have colour maps but the wrinkled material {name!r} of "
                f"{doc.path.name} has no baseColorTexture to blend them over; name the base "
                'colour map with base_color = "FILE"',
                "base_color",
            )
        where = f"{doc.path.name} /materials/{m}/pbrMetallicRoughness/baseColorTexture"
        if TEXTURE_TRANSFORM in (info.get("extensions") or {}):
            raise input_error(
                file,
                f"{where} (the base colour) has {TEXTURE_TRANSFORM}; the states' colour maps are "
                "looked up on untransformed TEXCOORD_0: bake the transform into the UVs or give "
                'base_color = "FILE"',
                "base_color",
            )
        if info.get("texCoord", 0) != 0:
            raise input_error(
                file,
                f"{where} (the base colour) uses TEXCOORD_{info['texCoord']}; the states' colour "
                "maps use TEXCOORD_0",
                "base_color",
            )
        factor = pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0])
        rgb = tuple(float(x) for x in factor[:3])
        found.append((m, info, rgb))
    first = found[0]
    if any(i["index"] != first[1]["index"] or f != first[2] for _, i, f in found):
        raise input_error(
            file,
            "the wrinkled materials have different base colours ("
            + ", ".join(
                f"{doc.material_name(m)!r}: texture {i['index']}, factor {list(f)}"
                for m, i, f in found
            )
            + '); name the base colour map with base_color = "FILE"',
            "base_color",
        )
    return first[1], first[2]  # type: ignore[return-value]
