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

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wrinklepipe.document.model import ARRAY_BUFFER, Document, PrimitiveRef
from wrinklepipe.document.scene import node_world_matrices, primitive_triangles, rest_positions
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.normals import vertex_normals

VERTEX_ID_ATTRIBUTE = "_WRINKLE_VERTEX_ID"
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
                f"{doc.path.name} has {len(mats)} materials; name the wrinkled one(s) with "
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
                    f"no material {name!r} in {doc.path.name} (materials: {material_listing(doc)})",
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
    from wrinklepipe.geometry.tangents import mikktspace_tangents_report
    from wrinklepipe.geometry.vertex_ids import compute_vertex_ids

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
        parts.append(WrinkledPart(r, wp, tri, uvs, vid, notes))
    return parts
