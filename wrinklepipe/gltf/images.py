"""Images of a source document that the pipeline must read (everything else passes through).

Only a map the pipeline needs is decoded (the wrinkled material's own ``normalTexture`` when it
is the base, the base texture of a converted output the validator reads); the document keeps
every image's bytes as they are either way.

- :func:`texture_source`: the image a texture shows: ``KHR_texture_basisu``'s source when present
  (a KTX2 / Basis Universal image), else ``EXT_texture_webp``'s, else ``source``.
- :func:`image_values`: image bytes -> float32 ``[H, W, C]`` in [0, 1] and the stored bits.
  PNG / JPEG / WebP through OpenImageIO (:func:`wrinklepipe.io.images.read_image`); KTX2 (Basis
  Universal ETC1S / UASTC) transcoded to RGBA8 by ``alktx2`` first.
- :func:`texture_normals`: a texture as unit normals (+Y, what glTF's normalTexture holds).

OpenImageIO reads files, so the bytes go through a private temporary folder that is removed
afterwards (nothing is written beside the source). Every image is held to the document's
``max_pixels`` (:class:`~wrinklepipe.gltf.limits.GltfReadOptions`) before a pixel is decoded:
PNG and KTX2 by their headers (a KTX2 before it is transcoded), JPEG and WebP by OpenImageIO's
header. Problems name the glTF file and pointer.
"""

from __future__ import annotations

import struct
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.errors import InputError
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.write import mime_type
from wrinklepipe.io.images import read_image
from wrinklepipe.io.png import png_pixels
from wrinklepipe.io.scratch import hold
from wrinklepipe.normals.held import HeldMap
from wrinklepipe.normals.read import ReadOptions, read_normal_map

BASISU = "KHR_texture_basisu"
WEBP = "EXT_texture_webp"
_SUFFIX = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp"}


def texture_source(doc: Document, texture: int) -> int:
    """The image index texture ``texture`` shows (basisu / webp extension source first)."""
    texs = doc.array("textures")
    key = f"/textures/{texture}"
    if not isinstance(texture, int) or not 0 <= texture < len(texs):
        raise doc.err(f"texture {texture!r} does not exist", "/textures")
    t = texs[texture]
    ext = t.get("extensions") or {}
    for name in (BASISU, WEBP):
        src = (ext.get(name) or {}).get("source")
        if isinstance(src, int):
            return src
    src = t.get("source")
    if not isinstance(src, int):
        raise doc.err("texture has no source image", key)
    return src


#: The first bytes of each image format the document's images are read in.
_SIGNATURES = {
    "image/png": (b"\x89PNG\r\n\x1a\n",),
    "image/jpeg": (b"\xff\xd8\xff",),
    "image/ktx2": (b"\xabKTX 20\xbb\r\n\x1a\n",),
}


def _stored_size(data: bytes, mime: str) -> tuple[int, int] | None:
    """Width and height from a PNG's IHDR or a KTX2 header (None: another format, or too short
    to say; the decoder refuses those). Only from bytes that are that format (signature)."""
    if mime == "image/png" and len(data) >= 24 and data[12:16] == b"IHDR":
        return struct.unpack(">II", data[16:24])
    if mime == "image/ktx2" and len(data) >= 28:  # identifier, vkFormat, typeSize, then the size
        return struct.unpack("<II", data[20:28])
    return None


def _check_pixels(doc: Document, image: int, size: tuple[int, int] | None) -> None:
    """Refuse an image over the document's ``max_pixels`` (before decoding it)."""
    cap = doc.options.max_pixels
    if size is not None and size[0] * size[1] > cap:
        w, h = size
        raise doc.err(f"image is {w} x {h}, over the cap of {cap} pixels", f"/images/{image}")


def _ktx2_to_png(data: bytes, doc: Document, key: str) -> bytes:
    # alktx2 (Basis Universal transcoder) is imported only when a KTX2 map must be read.
    import alktx2

    try:
        png, _ = alktx2.decode_ktx2_to_bytes(data, format="png")
    except Exception as exc:  # noqa: BLE001 - the binding raises plain RuntimeErrors
        raise doc.err(f"KTX2 image does not decode (alktx2: {exc})", key) from None
    return bytes(png)


def _with_file(data: bytes, suffix: str, read: Any) -> Any:
    with tempfile.TemporaryDirectory(prefix="wrinklepipe-image-") as folder:
        path = Path(folder) / f"image{suffix}"
        path.write_bytes(data)
        return read(path)


def _decodable(doc: Document, image: int) -> tuple[bytes, str]:
    key = f"/images/{image}"
    data = doc.image_bytes(image)
    img = doc.array("images")[image]
    mime = mime_type(data, str(img.get("uri", "")))
    signatures = _SIGNATURES.get(mime)
    if signatures is not None and not data.startswith(signatures):
        kind = mime.split("/")[1].upper()
        what = "empty" if not data else f"not a {kind} file (its first bytes are not {kind}'s)"
        raise doc.err(f"image is {what}", key)
    _check_pixels(doc, image, _stored_size(data, mime))
    if mime == "image/ktx2":
        return _ktx2_to_png(data, doc, key), ".png"
    if mime not in _SUFFIX:
        raise doc.err(f"image is {mime}; only PNG, JPEG, WebP and KTX2 maps are read", key)
    return data, _SUFFIX[mime]


def _renamed(exc: InputError, doc: Document, key: str) -> InputError:
    text = "; ".join(p.message for p in exc.problems)
    return doc.err(text, key)


def image_values(doc: Document, image: int) -> tuple[np.ndarray, int]:
    """Image ``image`` as float32 ``[H, W, C]`` in [0, 1] and its stored bits (8 or 16)."""
    key = f"/images/{image}"
    data, suffix = _decodable(doc, image)
    try:
        values, info = _with_file(data, suffix, lambda p: read_image(p, doc.options.max_pixels))
    except InputError as exc:
        raise _renamed(exc, doc, key) from None
    return values, 16 if info.format == "uint16" else 8


def image_pixels(doc: Document, image: int) -> np.ndarray:
    """Image ``image`` as stored integers ``[H, W, C]`` (uint8, or uint16 for 16-bit PNGs):
    PNG (and KTX2, transcoded to PNG) through :func:`wrinklepipe.io.png.png_pixels`, the
    texels exactly as stored; other formats through :func:`image_values`."""
    data, suffix = _decodable(doc, image)
    if suffix == ".png":
        return png_pixels(data, f"{doc.file} /images/{image}")
    values, bits = image_values(doc, image)
    top = (1 << bits) - 1
    dtype = np.uint16 if bits == 16 else np.uint8
    return np.clip(np.rint(values.astype(np.float64) * top), 0, top).astype(dtype)


def texture_texels(doc: Document, texture: int) -> np.ndarray:
    """Texture ``texture``'s image as stored integers ``[H, W, C]`` (:func:`image_pixels`)."""
    return image_pixels(doc, texture_source(doc, texture))


def texture_normals(
    doc: Document,
    texture: int,
    key: str,
    stats: dict[str, Any] | None = None,
    held: bool = False,
) -> tuple[np.ndarray | HeldMap, list[str]]:
    """Texture ``texture`` as unit normals ``[H, W, 3]`` (+Y: glTF normal textures are OpenGL
    tangent space by the spec) and notes on what was read. ``stats``: filled with the reader's
    counts of problem texels (off unit length, z < 0: ``file``, ``stats``, ``tolerance``), as
    ingest records a manifest's own map files. ``held``: an 8- or 16-bit image's normals as its
    integers (:class:`wrinklepipe.normals.held.HeldMap`, decoded where read), never made whole."""
    image = texture_source(doc, texture)
    data, suffix = _decodable(doc, image)
    options = ReadOptions(convention="opengl", detect=False, max_pixels=doc.options.max_pixels)
    try:
        nm = _with_file(data, suffix, lambda p: read_normal_map(p, options, held=held))
    except InputError as exc:
        raise _renamed(exc, doc, key) from None
    img = doc.array("images")[image]
    label = img.get("name") or img.get("uri") or f"image {image}"
    notes = [f"base normal map: {doc.path.name} {key} ({label}, {nm.source_format})"]
    if stats is not None:
        stats.update(
            {
                "file": f"{doc.path.name} {key} ({label})",
                "stats": nm.stats.to_json(),
                "tolerance": options.unit_tolerance,
            }
        )
    if nm.integers is not None and held:
        return HeldMap(hold(nm.integers), nm.layout, False), notes  # read as OpenGL: never flipped
    return np.asarray(nm.normals, np.float32), notes
