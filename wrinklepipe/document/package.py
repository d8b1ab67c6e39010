"""A written glTF -> :class:`~wrinklepipe.io.package.WrinklePackage`, whole documents included.

The wrinkled material is the one carrying ``WRINKLEPIPE_wrinkle_maps`` (the first, when a list
of materials was wrinkled: they carry the same block); the render mesh is every triangle
primitive using a material with the extension (:func:`wrinklepipe.document.render_mesh.
wrinkled_mesh`), so a character converted in place validates on its wrinkled primitives only.
A single-mesh file (the demo, an OBJ source's output) is the same case with one primitive. The
extension block maps to the package by :func:`wrinklepipe.io.gltf_read.package_from_gltf`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wrinklepipe.document.images import image_pixels
from wrinklepipe.document.model import Document, read_document
from wrinklepipe.document.render_mesh import wrinkled_mesh
from wrinklepipe.document.wrinkled import VERTEX_ID_ATTRIBUTE, wrinkled_primitives
from wrinklepipe.errors import input_error, plain_reason
from wrinklepipe.io.gltf_read import GltfReadOptions, package_from_gltf
from wrinklepipe.io.package import EXTENSION, WrinklePackage


def wrinkled_materials(doc: Document) -> list[int]:
    """Indices of the materials that carry the wrinkle extension."""
    return [
        i
        for i, m in enumerate(doc.array("materials"))
        if isinstance(m, dict) and EXTENSION in (m.get("extensions") or {})
    ]


def morph_columns(doc: Document, refs: list, names: tuple[str, ...]) -> dict[int, list[int]]:
    """Each node instancing a wrinkled mesh with targets -> the render-mesh morph column of
    each of its targets (-1 when the render mesh has no such name)."""
    out: dict[int, list[int]] = {}
    for mesh in dict.fromkeys(r.mesh for r in refs):
        targets = doc.target_names(mesh)
        if not targets:
            continue
        cols = [names.index(t) if t in names else -1 for t in targets]
        for node in doc.mesh_nodes(mesh):
            out.setdefault(node, cols)
    return out


def read_wrinkled(path: str | Path, options: GltfReadOptions | None = None) -> WrinklePackage:
    """Load a .gltf/.glb whose material(s) carry the wrinkle extension as a package.

    Raises :class:`~wrinklepipe.errors.InputError` naming the file (and JSON pointer) for
    anything malformed."""
    try:
        return _read_wrinkled(path, options)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        # Safety net for structures the specific checks did not foresee: still one clear line.
        raise input_error(path, f"malformed glTF: {plain_reason(exc)}") from None


def _read_wrinkled(path: str | Path, options: GltfReadOptions | None) -> WrinklePackage:
    doc = read_document(path, options)
    materials = wrinkled_materials(doc)
    if not materials:
        raise doc.err(f"no material carries {EXTENSION}: not a wrinklepipe asset", "/materials")
    refs = wrinkled_primitives(doc, materials)
    ext = doc.array("materials")[materials[0]]["extensions"][EXTENSION]
    vid = ext.get("vertexIdAttribute", VERTEX_ID_ATTRIBUTE) if isinstance(ext, dict) else ""
    for r in refs:
        attrs = doc.primitive(r).get("attributes", {})
        for need in ("POSITION", "NORMAL", "TANGENT", "TEXCOORD_0", vid):
            if need not in attrs:
                raise doc.err(f"wrinkled primitive has no {need} attribute", r.pointer)
    mesh = wrinkled_mesh(doc, refs)

    def image(i: int) -> tuple[str, np.ndarray]:
        img = doc.array("images")[i] if 0 <= i < len(doc.array("images")) else {}
        return str(img.get("name") or f"image_{i}"), image_pixels(doc, i)

    def accessor(i: int) -> np.ndarray:
        a = doc.accessor(i)
        return a[:, 0] if a.ndim == 2 and a.shape[1] == 1 else a

    return package_from_gltf(
        doc.gltf,
        materials[0],
        mesh,
        image,
        accessor,
        doc.err,
        Path(path).stem,
        morph_columns(doc, refs, mesh.morph_names),
    )
