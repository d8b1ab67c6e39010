"""A converted document without its wrinkle additions: what an engine imports.

The engines run the wrinkle model in their own material (the export's shader files), so the glTF
they import is the whole character as convert wrote it (every node, mesh, primitive, material,
texture, skin, animation of the source, the tangents and vertex IDs on the wrinkled primitives)
less what only the wrinkle extension used:

- ``WRINKLEPIPE_wrinkle_maps`` on the wrinkled material(s), and with it the textures, images and
  samplers only it referenced (the states, masks and compressed copies, shipped by the export in
  the engine's own formats);
- without ``keep_normal`` (Unreal, which gets a DirectX base of its own) the wrinkled
  material's ``normalTexture`` too;
- the ``KHR_animation_pointer`` channels that drive the extension's region weights (animations
  left without channels go; a blendshapes driver's morph-weight channels stay).

Every other element is untouched (the same JSON, accessors and image bytes). Accessors that only
the dropped weight channels read stay in the buffer, unreferenced (a few hundred bytes; the
Khronos validator reports them as information, not as errors).
"""

from __future__ import annotations

import copy
from typing import Any

from wrinklepipe.gltf.document import Document, drop_views
from wrinklepipe.gltf.package_read import wrinkled_materials
from wrinklepipe.gltf.package_write import POINTER_EXTENSION
from wrinklepipe.metadata import EXTENSION

#: Texture-source keys of the image extensions a texture may carry.
_IMAGE_EXTENSIONS = (
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
    "MSFT_texture_dds",
)


def _extension_textures(ext: Any) -> set[int]:
    """The glTF texture indices a wrinkle extension block references."""
    if not isinstance(ext, dict):
        return set()
    infos = [s.get("texture") for s in ext.get("states", []) if isinstance(s, dict)]
    infos += list((ext.get("masks") or {}).get("textures", []))
    infos += [c.get("texture") for c in ext.get("compressed", []) if isinstance(c, dict)]
    return {i["index"] for i in infos if isinstance(i, dict) and isinstance(i.get("index"), int)}


def _texture_infos(obj: Any, key: str = "") -> list[dict[str, Any]]:
    """Every textureInfo in a material (core and extension slots: keys ending in 'Texture')."""
    out: list[dict[str, Any]] = []
    if isinstance(obj, dict):
        if key.endswith("Texture") and isinstance(obj.get("index"), int):
            out.append(obj)
        for k, v in obj.items():
            out += _texture_infos(v, k)
    elif isinstance(obj, list):
        for v in obj:
            out += _texture_infos(v, key)
    return out


def _texture_images(tex: dict[str, Any]) -> list[dict[str, Any]]:
    """The objects of a texture that name an image (its ``source`` and image extensions)."""
    holders = [tex] if isinstance(tex.get("source"), int) else []
    for name in _IMAGE_EXTENSIONS:
        e = (tex.get("extensions") or {}).get(name)
        if isinstance(e, dict) and isinstance(e.get("source"), int):
            holders.append(e)
    return holders


def _drop_textures(doc: Document, drop: set[int]) -> None:
    """Remove textures ``drop`` (referenced by no material any more) and the images and samplers
    only they used; renumber what remains."""
    textures = doc.array("textures")
    keep = [i for i in range(len(textures)) if i not in drop]
    remap = {old: new for new, old in enumerate(keep)}
    for m in doc.array("materials"):
        for info in _texture_infos(m):
            info["index"] = remap[info["index"]]
    kept = [textures[i] for i in keep]
    # images and samplers that only dropped textures used
    used_images = {h["source"] for t in kept for h in _texture_images(t)}
    gone_images = {h["source"] for i in drop for h in _texture_images(textures[i])} - used_images
    used_samplers = {t["sampler"] for t in kept if isinstance(t.get("sampler"), int)}
    gone_samplers = {
        textures[i]["sampler"] for i in drop if isinstance(textures[i].get("sampler"), int)
    } - used_samplers
    doc.gltf["textures"] = kept
    if gone_samplers:
        samplers = doc.array("samplers")
        s_keep = [i for i in range(len(samplers)) if i not in gone_samplers]
        s_map = {old: new for new, old in enumerate(s_keep)}
        doc.gltf["samplers"] = [samplers[i] for i in s_keep]
        for t in kept:
            if isinstance(t.get("sampler"), int):
                t["sampler"] = s_map[t["sampler"]]
    if gone_images:
        images = doc.array("images")
        i_keep = [i for i in range(len(images)) if i not in gone_images]
        i_map = {old: new for new, old in enumerate(i_keep)}
        views = {images[i]["bufferView"] for i in gone_images if "bufferView" in images[i]}
        doc.gltf["images"] = [images[i] for i in i_keep]
        doc.images = {i_map[i]: f for i, f in doc.images.items() if i in i_map}
        for t in kept:
            for h in _texture_images(t):
                h["source"] = i_map[h["source"]]
        still = {a.get("bufferView") for a in doc.array("accessors")}
        still |= {im.get("bufferView") for im in doc.array("images")}
        if views - still:
            drop_views(doc, views - still)
    for key in ("textures", "samplers", "images"):
        if key in doc.gltf and not doc.gltf[key]:
            del doc.gltf[key]


def _drop_weight_channels(doc: Document, materials: list[int]) -> None:
    """Remove the pointer channels that target the wrinkle extension of ``materials``."""
    prefixes = tuple(f"/materials/{m}/extensions/{EXTENSION}/" for m in materials)
    animations = []
    for a in doc.array("animations"):
        channels = [
            c
            for c in a.get("channels", [])
            if not str(
                ((c.get("target") or {}).get("extensions") or {})
                .get(POINTER_EXTENSION, {})
                .get("pointer", "")
            ).startswith(prefixes)
        ]
        if not channels:
            continue
        used = sorted({c["sampler"] for c in channels})
        remap = {old: new for new, old in enumerate(used)}
        a["samplers"] = [a["samplers"][i] for i in used]
        a["channels"] = [{**c, "sampler": remap[c["sampler"]]} for c in channels]
        animations.append(a)
    if animations:
        doc.gltf["animations"] = animations
    else:
        doc.gltf.pop("animations", None)


def _pointer_channels(doc: Document) -> bool:
    return any(
        (c.get("target") or {}).get("path") == "pointer"
        for a in doc.array("animations")
        for c in a.get("channels", [])
    )


def plain_document(source: Document, keep_normal: bool = True) -> Document:
    """``source`` (a converted document) without its wrinkle additions (see the module doc); the
    source object is left as it was."""
    doc = copy.copy(source)
    doc.gltf = copy.deepcopy(source.gltf)
    doc.views = list(source.views)
    doc.images = dict(source.images)
    mats = wrinkled_materials(doc)
    candidates: set[int] = set()
    for m in mats:
        mat = doc.gltf["materials"][m]
        candidates |= _extension_textures(mat["extensions"].pop(EXTENSION))
        if not mat["extensions"]:
            del mat["extensions"]
        if not keep_normal and isinstance(mat.get("normalTexture"), dict):
            candidates.add(mat.pop("normalTexture")["index"])
    still = {info["index"] for m in doc.array("materials") for info in _texture_infos(m)}
    n = len(doc.array("textures"))
    _drop_textures(doc, {i for i in candidates - still if 0 <= i < n})
    _drop_weight_channels(doc, mats)
    drop = [EXTENSION] + ([] if _pointer_channels(doc) else [POINTER_EXTENSION])
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in doc.gltf:
            doc.gltf[key] = [e for e in doc.gltf[key] if e not in drop]
            if not doc.gltf[key]:
                del doc.gltf[key]
    return doc


def normal_image(doc: Document, material: int) -> int | None:
    """The image of ``material``'s ``normalTexture`` (None without one)."""
    info = doc.array("materials")[material].get("normalTexture")
    if not isinstance(info, dict):
        return None
    tex = doc.array("textures")[info["index"]]
    return tex.get("source") if isinstance(tex.get("source"), int) else None
