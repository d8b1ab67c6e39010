"""The glTF package reader: a written .gltf/.glb -> :class:`~wrinklepipe.package.WrinklePackage`.

The one reader of glTF packages (``read_package``, ``validate-asset``, ``export``, the tests and
the output bench all read through :func:`read_wrinkled`), built on the document model: the file
is opened by :func:`wrinklepipe.gltf.document.read_document` (the one container reader, its caps
and URI confinement), images are decoded by :mod:`wrinklepipe.gltf.images` (held to
``max_pixels`` first) and accessors by :mod:`wrinklepipe.gltf.accessors`.

- The wrinkled material is the one carrying ``WRINKLEPIPE_wrinkle_maps`` (the first, when a list
  of materials was wrinkled: they carry the same block).
- The render mesh is every triangle primitive using a material with the extension
  (:func:`wrinklepipe.gltf.render_mesh.wrinkled_mesh`), so a character converted in place
  validates on its wrinkled primitives only; a single-mesh file (the demo, an OBJ source's
  output) is the same case with one primitive.
- The package's **name is the file's stem** (``demo_head.gltf`` -> ``demo_head``), whatever the
  scene or node names say: ``convert`` writes ``NAME.gltf``, and a character converted into its
  own document keeps the source's scene names, so the stem is the name the user gave it.
- The extension block maps onto :class:`~wrinklepipe.metadata.WrinkleMeta` by
  :meth:`~wrinklepipe.metadata.WrinkleMeta.from_extension` (checked by the shipped JSON Schema);
  ``weightCurves`` name the animations that play the region weights (``KHR_animation_pointer``)
  and the blendshape inputs (morph ``weights`` channels).
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import udim
from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error, plain_reason
from wrinklepipe.gltf.document import Document, read_document
from wrinklepipe.gltf.images import image_pixels, texture_source
from wrinklepipe.gltf.limits import GltfReadOptions
from wrinklepipe.gltf.render_mesh import wrinkled_mesh
from wrinklepipe.gltf.wrinkled import wrinkled_primitives
from wrinklepipe.metadata import EXTENSION, VERTEX_ID_ATTRIBUTE, WrinkleMeta
from wrinklepipe.package import PackedTexture, WeightCurves, WrinklePackage, safe_name


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
    """Load a .gltf/.glb whose material(s) carry the wrinkle extension as a package (see the
    module doc; ``options``: the reader's caps, ``max_pixels`` included).

    Raises :class:`~wrinklepipe.errors.InputError` naming the file (and JSON pointer) for
    anything malformed."""
    try:
        doc = read_document(path, options)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        # Safety net for structures the specific checks did not foresee: still one clear line.
        raise input_error(path, f"malformed glTF: {plain_reason(exc)}") from None
    return wrinkled_package(doc, Path(path).stem)


def wrinkled_package(doc: Document, name: str) -> WrinklePackage:
    """The package of a document already read (:func:`read_wrinkled` without the read: a
    caller that needs the document too opens the file once), named ``name``."""
    try:
        return _wrinkled_package(doc, name)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise input_error(doc.file, f"malformed glTF: {plain_reason(exc)}") from None


def _wrinkled_package(doc: Document, name: str) -> WrinklePackage:
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
    morph_nodes = morph_columns(doc, refs, mesh.morph_names)
    tiles = _material_tiles(doc, materials)
    if tiles:
        return _tiled_package(doc, tiles, refs, mesh, name, morph_nodes)
    return package_from_document(doc, materials[0], mesh, name, morph_nodes)


def _material_tiles(doc: Document, materials: list[int]) -> dict[int, int]:
    """``{material: tile}`` of a UDIM asset (each wrinkled material's block names its
    ``tile``), empty for one that names none; refused when some do and some do not, or two
    name one tile."""
    got: dict[int, int] = {}
    for m in materials:
        ext = doc.array("materials")[m]["extensions"][EXTENSION]
        tile = ext.get("tile") if isinstance(ext, dict) else None
        if isinstance(tile, int) and not isinstance(tile, bool) and udim.valid(tile):
            got[m] = tile
    if got and len(got) != len(materials):
        plain = [m for m in materials if m not in got]
        raise doc.err(
            f"materials {sorted(got)} are UDIM tiles but {plain} name no tile: a tiled asset "
            "gives every wrinkled material its tile",
            f"/materials/{plain[0]}/extensions/{EXTENSION}",
        )
    if len(set(got.values())) != len(got):
        raise doc.err("two wrinkled materials are the same UDIM tile", "/materials")
    return got


def _tiled_package(
    doc: Document,
    tiles: dict[int, int],
    refs: list[Any],
    mesh: Mesh,
    name: str,
    morph_nodes: dict[int, list[int]],
) -> WrinklePackage:
    """A UDIM asset written one material per tile (:mod:`wrinklepipe.gltf.package_write`):
    the render mesh with each primitive's UVs put back on its material's tile
    (:func:`wrinklepipe.udim.from_tile`), and the tiles' packages joined
    (:func:`wrinklepipe.udim.join_tiles`)."""
    uvs = np.array(mesh.uvs, np.float32, copy=True)
    for part, ref in zip(mesh.parts, refs):
        rows = slice(part.start, part.start + part.count)
        uvs[rows] = udim.from_tile(uvs[rows], tiles[ref.material])
    whole = replace(mesh, uvs=uvs)
    packages = {
        t: package_from_document(doc, m, whole, name, morph_nodes) for m, t in tiles.items()
    }
    return udim.join_tiles(packages, whole)


def _scalar(doc: Document, i: int) -> np.ndarray:
    """Accessor ``i``'s values (a SCALAR accessor as ``[count]``)."""
    a = doc.accessor(i)
    return a[:, 0] if a.ndim == 2 and a.shape[1] == 1 else a


def package_from_document(
    doc: Document, material: int, mesh: Mesh, name: str, morph_nodes: dict[int, list[int]]
) -> WrinklePackage:
    """The package the wrinkled material ``material`` of ``doc`` describes, over the render
    ``mesh``. ``morph_nodes`` maps each node whose morph-weight channel plays a curve's
    blendshape inputs to the column of ``mesh.morph_names`` of each of its targets (-1: none)."""
    mat = doc.array("materials")[material]
    ext = mat["extensions"][EXTENSION]
    pkey = f"/materials/{material}/extensions/{EXTENSION}"
    mkey = f"/materials/{material}"
    # -- textures ---------------------------------------------------------------------------
    textures: list[PackedTexture] = []
    by_image: dict[int, str] = {}
    taken: set[str] = set()

    def source(info: Any, key: str) -> int:
        if not isinstance(info, dict) or "index" not in info:
            raise doc.err("expected a textureInfo object with 'index'", key)
        return texture_source(doc, info["index"])

    def tex(info: Any, key: str, role: str) -> str:
        src = source(info, key)
        if src not in by_image:
            pixels = image_pixels(doc, src)  # refuses a missing image by its index
            img = doc.array("images")[src]
            label = safe_name(str(img.get("name") or f"image_{src}"), taken)
            textures.append(PackedTexture(label, pixels, role))
            by_image[src] = label
        return by_image[src]

    if "normalTexture" not in mat:
        raise doc.err("material has no normalTexture (the base normal map)", mkey)
    base_name = tex(mat["normalTexture"], f"{mkey}/normalTexture", "base_normal")
    _rename(textures, by_image, taken, base_name, "base_normal", doc)

    def named(info: Any, key: str, role: str) -> str:
        if role == "color":
            return tex(info, key, "state_color")
        if role != "copy":
            return tex(info, key, role)
        src = source(info, key)
        if src not in by_image:
            raise doc.err("a compressed copy of a texture the extension does not use", key)
        return by_image[src]

    colored = isinstance(ext, dict) and any(
        isinstance(st, dict) and "colorTexture" in st for st in ext.get("states") or []
    )
    if colored:  # the colour states blend over the material's base colour: read it first
        pbr = mat.get("pbrMetallicRoughness") or {}
        if not isinstance(pbr, dict) or "baseColorTexture" not in pbr:
            raise doc.err(
                "states have a colorTexture but the material has no baseColorTexture (the base "
                "colour they blend over)",
                mkey,
            )
        key = f"{mkey}/pbrMetallicRoughness/baseColorTexture"
        _rename(textures, by_image, taken, tex(pbr["baseColorTexture"], key, "base_color"),
                "base_color", doc)  # fmt: skip
    try:
        meta = WrinkleMeta.from_extension(ext, named, doc.err, pkey)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise doc.err(f"malformed extension block: {plain_reason(exc)}", pkey) from None
    if colored:
        factor = (mat.get("pbrMetallicRoughness") or {}).get("baseColorFactor", [1.0] * 4)
        meta = replace(
            meta, base_color="base_color", color_factor=tuple(float(x) for x in factor[:3])
        )
    try:
        json.dumps(meta.to_json(), allow_nan=False)
    except ValueError:
        raise doc.err("the extension block holds a NaN or infinite number", pkey) from None
    curves = _weight_curves(doc, ext, pkey, len(meta.regions), len(mesh.morph_names), morph_nodes)
    return WrinklePackage(name, mesh, textures, meta, curves)


def _rename(
    textures: list[PackedTexture],
    by_image: dict[int, str],
    taken: set[str],
    name: str,
    to: str,
    doc: Document,
) -> None:
    """Name the texture ``name`` as ``to`` (``base_normal``, ``base_color``): the name the
    package gives that role, whatever the image is called."""
    if name == to:
        return
    if to in taken:
        raise doc.err(f"an image other than the material's {to} is named {to!r}")
    for t in textures:
        if t.name == name:
            t.name = to
    taken.add(to)
    for k, v in list(by_image.items()):
        if v == name:
            by_image[k] = to


def _weight_curves(
    doc: Document,
    ext: dict[str, Any],
    pkey: str,
    n_regions: int,
    n_morphs: int,
    morph_nodes: dict[int, list[int]],
) -> list[WeightCurves]:
    """The extension's ``weightCurves``: each names a glTF animation whose
    ``KHR_animation_pointer`` channel plays the region weights, and whose morph ``weights``
    channels (on the nodes of ``morph_nodes``) play the blendshape inputs with them."""
    curves = []
    anims = doc.array("animations")
    for i, wc in enumerate(ext.get("weightCurves", [])):
        ai = wc.get("animation")
        if not isinstance(ai, int) or not 0 <= ai < len(anims):
            raise doc.err(f"animation {ai!r} does not exist", f"{pkey}/weightCurves/{i}")
        anim = anims[ai]
        pointer = [
            ch for ch in anim.get("channels", []) if ch.get("target", {}).get("path") == "pointer"
        ]
        if not pointer:
            raise doc.err("animation has no KHR_animation_pointer channel", f"/animations/{ai}")
        s = anim["samplers"][pointer[0]["sampler"]]
        times = _scalar(doc, s["input"]).astype(np.float32)
        vals = _scalar(doc, s["output"]).astype(np.float32).reshape(-1)
        morph = None
        for ch in anim.get("channels", []):
            tgt = ch.get("target", {})
            node = tgt.get("node")
            columns = morph_nodes.get(node) if isinstance(node, int) else None
            if tgt.get("path") != "weights" or columns is None:
                continue
            ms = anim["samplers"][ch["sampler"]]
            mv = _scalar(doc, ms["output"]).astype(np.float32).reshape(-1)
            n_m = len(columns)
            if not n_m or mv.size != times.size * n_m:
                raise doc.err(
                    f"morph weights: {mv.size} values for {times.size} keys x {n_m} targets",
                    f"/animations/{ai}",
                )
            if morph is None:
                morph = np.zeros((times.size, n_morphs), np.float32)
            cols = np.asarray(columns, np.int64)
            keep = cols >= 0
            morph[:, cols[keep]] = mv.reshape(times.size, n_m)[:, keep]
        if vals.size != times.size * n_regions:
            raise doc.err(
                f"animation output has {vals.size} values, expected {times.size} x {n_regions}",
                f"/animations/{ai}",
            )
        curves.append(
            WeightCurves(
                str(wc.get("name", f"curve_{i}")),
                times,
                vals.reshape(times.size, n_regions),
                morph,
            )
        )
    return curves
