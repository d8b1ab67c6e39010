"""Add a package's wrinkle data to a source document (what convert writes for a glTF source).

What is added, and nothing else is changed:

- the package's textures as PNG images (``textures/NAME.png`` beside a .gltf, embedded in a
  .glb), each with a texture and one shared sampler; the base map only when the manifest names
  one (then the wrinkled material's ``normalTexture`` points at it); when the base is the
  material's own ``normalTexture``, that texture is used as it is;
- ``WRINKLEPIPE_wrinkle_maps`` on each wrinkled material (:func:`~wrinklepipe.gltf.package_write.
  extension_block`, textures by index);
- one animation per weight curve (:func:`~wrinklepipe.gltf.package_write.curve_animations`): the
  region weights through ``KHR_animation_pointer`` at each wrinkled material, and a blendshapes
  driver's morph weights on the nodes instancing the wrinkled meshes;
- ``extensionsUsed`` entries for both extensions (never ``extensionsRequired``).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from wrinklepipe.gltf.document import Document, PrimitiveRef
from wrinklepipe.gltf.package_read import morph_columns
from wrinklepipe.gltf.package_write import (
    POINTER_EXTENSION,
    MorphChannel,
    curve_animations,
    extension_block,
    weights_pointer,
)
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, png_bytes
from wrinklepipe.metadata import EXTENSION
from wrinklepipe.package import WrinklePackage, safe_name

#: The sampler of the added textures (bilinear, trilinear mips, clamped: masks end at the UVs).
SAMPLER = {"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}


@dataclass(frozen=True)
class WrinkleTarget:
    """Where the wrinkle data goes: the wrinkled materials and primitives, the texture that
    is the base when the manifest names none (the material's own normalTexture), and likewise
    the base colour's (the material's own baseColorTexture) when states carry colour."""

    materials: tuple[int, ...]
    refs: tuple[PrimitiveRef, ...]
    base_texture: int | None = None
    base_color_texture: int | None = None


def _free_uri(doc: Document, stem: str) -> str:
    taken = {f.uri.lower() for f in doc.images.values()}
    taken |= {str(i.get("uri", "")).lower() for i in doc.array("images")}
    uri, k = f"textures/{stem}.png", 1
    while uri.lower() in taken:
        k += 1
        uri = f"textures/{stem}_{k}.png"
    return uri


def add_wrinkle_maps(
    doc: Document, target: WrinkleTarget, pkg: WrinklePackage, png_level: int = DEFAULT_PNG_LEVEL
) -> list[str]:
    """Add ``pkg``'s textures (PNGs at zlib ``png_level``), extension and weight animations to
    ``doc`` (see the module doc); return notes on what changed in the wrinkled materials."""
    notes: list[str] = []
    sampler = doc.add_sampler(dict(SAMPLER))
    tex_index: dict[str, int] = {}
    for t in pkg.textures:
        if t.role == "base_normal" and target.base_texture is not None:
            tex_index[t.name] = target.base_texture
            continue
        if t.role == "base_color" and target.base_color_texture is not None:
            tex_index[t.name] = target.base_color_texture
            continue
        stem = safe_name(t.name)
        image = doc.add_image(
            png_bytes(t.pixels, png_level), "image/png", t.name, _free_uri(doc, stem)
        )
        tex_index[t.name] = doc.add_texture(image, sampler, t.name)
    ext = extension_block(pkg.meta, tex_index)
    first = len(doc.array("animations"))
    mesh_names = tuple(pkg.mesh.morph_names)
    morphs = [
        MorphChannel(node, np.asarray(cols, np.int64))
        for node, cols in sorted(morph_columns(doc, list(target.refs), mesh_names).items())
    ]

    def accessor(a: np.ndarray, minmax: bool) -> int:
        return doc.add_accessor(np.asarray(a, np.float32), minmax=minmax)

    animations = curve_animations(
        pkg.curves,
        len(pkg.meta.regions),
        accessor,
        [weights_pointer(m) for m in target.materials],
        morphs,
        doc.file,
    )
    for a in animations:
        doc.add_animation(a)
    if animations:
        ext["weightCurves"] = [
            {"name": c.name, "animation": first + i} for i, c in enumerate(pkg.curves)
        ]
    for m in target.materials:
        mat = doc.gltf["materials"][m]
        if target.base_texture is None:
            if "normalTexture" in mat:
                notes.append(
                    f"material {mat.get('name', m)!r}: normalTexture (texture "
                    f"{mat['normalTexture'].get('index')}) replaced by the manifest's base"
                )
            mat["normalTexture"] = {"index": tex_index["base_normal"]}
        if pkg.meta.base_color is not None and target.base_color_texture is None:
            notes += _set_base_color(mat, m, tex_index[pkg.meta.base_color])
        mat.setdefault("extensions", {})[EXTENSION] = copy.deepcopy(ext)
    doc.use_extension(EXTENSION)
    if animations:
        doc.use_extension(POINTER_EXTENSION)
    return notes


def _set_base_color(mat: dict, index: int, texture: int) -> list[str]:
    """Make the manifest's base colour the material's ``baseColorTexture`` (the colour states
    blend over it), its factor's RGB 1 (the base colour is the map as painted)."""
    notes = []
    name = mat.get("name", index)
    pbr = mat.setdefault("pbrMetallicRoughness", {})
    if "baseColorTexture" in pbr:
        notes.append(
            f"material {name!r}: baseColorTexture (texture {pbr['baseColorTexture'].get('index')})"
            " replaced by the manifest's base_color"
        )
    pbr["baseColorTexture"] = {"index": texture}
    factor = pbr.get("baseColorFactor")
    if factor is not None and list(factor[:3]) != [1.0, 1.0, 1.0]:
        notes.append(
            f"material {name!r}: baseColorFactor RGB {list(factor[:3])} set to 1 (the manifest's "
            "base_color is the base colour as painted)"
        )
        pbr["baseColorFactor"] = [1.0, 1.0, 1.0, float(factor[3]) if len(factor) > 3 else 1.0]
    return notes
