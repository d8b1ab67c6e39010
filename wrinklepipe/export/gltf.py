"""The mesh an engine imports: the asset's glTF without the wrinkle extension.

Engines run the wrinkle model in their own material (the export's shader files), so the glTF they
import carries the mesh, skin, morph targets, the morph-weight animations and (where the engine's
material samples it from there) the base normal map; the wrinkle states, masks and the
``KHR_animation_pointer`` weight channels live in the export's own files instead, so no texture
ships twice. The result still passes the Khronos glTF-Validator (tested).
"""

from __future__ import annotations

from typing import Any

from wrinklepipe.atomic import dumps_json
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.package_read import wrinkled_materials
from wrinklepipe.gltf.package_write import gltf_document
from wrinklepipe.gltf.plain import normal_image, plain_document
from wrinklepipe.gltf.write import document_files, mime_type
from wrinklepipe.io.png import png_bytes
from wrinklepipe.metadata import EXTENSION
from wrinklepipe.package import WrinklePackage

POINTER = "KHR_animation_pointer"


def _drop_pointer_channels(doc: dict[str, Any]) -> None:
    anims = []
    for a in doc.get("animations", []):
        channels = [c for c in a["channels"] if c["target"].get("path") != "pointer"]
        used = sorted({c["sampler"] for c in channels})
        remap = {old: new for new, old in enumerate(used)}
        if not channels:
            continue
        anims.append(
            {
                **a,
                "samplers": [a["samplers"][i] for i in used],
                "channels": [{**c, "sampler": remap[c["sampler"]]} for c in channels],
            }
        )
    if anims:
        doc["animations"] = anims
    else:
        doc.pop("animations", None)


def _keep_textures(
    doc: dict[str, Any], images: dict[str, bytes], keep_normal: bool
) -> dict[str, bytes]:
    """Keep only the textures the core materials reference (the base normal map, and with
    colour states the base colour); returns the images still used."""
    keep: list[int] = []
    for m in doc.get("materials", []):
        nt = m.get("normalTexture")
        if nt is None:
            continue
        if not keep_normal:
            m.pop("normalTexture")
            continue
        if nt["index"] not in keep:
            keep.append(nt["index"])
    for m in doc.get("materials", []):
        bt = (m.get("pbrMetallicRoughness") or {}).get("baseColorTexture")
        if bt is not None and bt["index"] not in keep:
            keep.append(bt["index"])
    textures = doc.get("textures", [])
    new_tex = [textures[i] for i in keep]
    remap = {old: new for new, old in enumerate(keep)}
    for m in doc.get("materials", []):
        if "normalTexture" in m:
            m["normalTexture"] = {**m["normalTexture"], "index": remap[m["normalTexture"]["index"]]}
        pbr = m.get("pbrMetallicRoughness") or {}
        if "baseColorTexture" in pbr:
            bt = pbr["baseColorTexture"]
            pbr["baseColorTexture"] = {**bt, "index": remap[bt["index"]]}
    img_keep = sorted({t["source"] for t in new_tex})
    img_remap = {old: new for new, old in enumerate(img_keep)}
    all_images = doc.get("images", [])
    for t in new_tex:
        t["source"] = img_remap[t["source"]]
    kept_images = [all_images[i] for i in img_keep]
    uris = {im.get("uri") for im in kept_images}
    for key in ("textures", "images"):
        doc.pop(key, None)
    if new_tex:
        doc["textures"] = new_tex
        doc["images"] = kept_images
    else:
        doc.pop("samplers", None)
    return {u: b for u, b in images.items() if u in uris}


def plain_gltf(
    pkg: WrinklePackage, keep_normal: bool = True, document: Document | None = None
) -> tuple[dict[str, bytes], str]:
    """``{relative path: bytes}`` of ``NAME.gltf`` + ``NAME.bin`` (+ the base normal PNG when
    ``keep_normal``) and the base image's path (empty without it). ``document``: the converted
    glTF as a document (then the whole character, see the module doc)."""
    if document is not None:
        return _plain_document_files(pkg, document, keep_normal)
    doc, data, images = gltf_document(pkg)
    doc["buffers"][0]["uri"] = f"{pkg.name}.bin"
    for m in doc.get("materials", []):
        (m.get("extensions") or {}).pop(EXTENSION, None)
        if "extensions" in m and not m["extensions"]:
            m.pop("extensions")
    _drop_pointer_channels(doc)
    images = _keep_textures(doc, images, keep_normal)
    used = [e for e in doc.get("extensionsUsed", []) if e not in (EXTENSION, POINTER)]
    doc.pop("extensionsUsed", None)
    if used:
        doc["extensionsUsed"] = used
    files = {f"{pkg.name}.gltf": dumps_json(doc).encode("utf-8"), f"{pkg.name}.bin": data}
    files.update(images)
    return files, next(iter(images), "")


def _plain_document_files(
    pkg: WrinklePackage, document: Document, keep_normal: bool
) -> tuple[dict[str, bytes], str]:
    wrinkled = wrinkled_materials(document)
    doc = plain_document(document, keep_normal)
    files = document_files(doc, pkg.name, glb=False)
    if not keep_normal:
        return files, ""
    image = normal_image(doc, wrinkled[0]) if wrinkled else None
    if image is not None and image in doc.images:
        uri = doc.images[image].uri
        if mime_type(files[uri], uri) in ("image/png", "image/jpeg"):
            return files, uri  # the material's own file, as the glTF references it
    # embedded in the buffer, or a format an engine's texture importer does not read (KTX2,
    # WebP): the package's base as a PNG beside the glTF
    uri, k = "textures/base_normal.png", 1
    while uri in files:
        k += 1
        uri = f"textures/base_normal_{k}.png"
    base = next(t for t in pkg.textures if t.role == "base_normal")
    files[uri] = png_bytes(base.pixels)
    return files, uri
