"""Write a :class:`~wrinklepipe.gltf.document.Document` back: one buffer, the tree as it is.

Every bufferView's bytes go, unchanged and 4-byte aligned, into one new buffer (accessors keep
their byteOffsets, component types and values); images are copied byte for byte: embedded as
bufferViews in a .glb, written at their relative URI beside a .gltf (data URIs stay in the JSON).
The JSON is written with sorted keys, so the same document gives the same bytes.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from wrinklepipe.atomic import dumps_json, write_bytes
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.package_write import glb_bytes

_MAGIC_MIME = (
    (b"\x89PNG\r\n\x1a\n", "image/png"),
    (b"\xff\xd8\xff", "image/jpeg"),
    (b"\xabKTX 20\xbb\r\n\x1a\n", "image/ktx2"),
)


def mime_type(data: bytes, uri: str = "") -> str:
    """The MIME type of image bytes, from their magic number (WebP: RIFF....WEBP)."""
    for magic, mime in _MAGIC_MIME:
        if data.startswith(magic):
            return mime
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
        return "image/webp"
    suffix = Path(uri).suffix.lower()
    return {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg"}.get(
        suffix, "application/octet-stream"
    )


def pack(
    doc: Document, embed_images: bool, bin_uri: str | None = None
) -> tuple[dict[str, Any], bytes, dict[str, bytes]]:
    """The output JSON, its one binary buffer and the image files ``{relative uri: bytes}``.

    ``embed_images``: put external images into the buffer (GLB). ``bin_uri``: the buffer's URI
    (None for a GLB, whose buffer is the binary chunk)."""
    gltf = copy.deepcopy(doc.gltf)
    views: list[bytes] = list(doc.views)
    view_json: list[dict[str, Any]] = gltf.setdefault("bufferViews", [])
    files: dict[str, bytes] = {}
    for i, img_file in sorted(doc.images.items()):
        img = gltf["images"][i]
        if embed_images:
            img.pop("uri", None)
            img.setdefault("mimeType", mime_type(img_file.data, img_file.uri))
            view_json.append({"buffer": 0, "byteLength": len(img_file.data)})
            views.append(img_file.data)
            img["bufferView"] = len(views) - 1
        else:
            img["uri"] = img_file.uri
            files[img_file.uri] = img_file.data
    chunks: list[bytes] = []
    length = 0
    for v, data in zip(view_json, views):
        pad = (-length) % 4
        if pad:
            chunks.append(b"\0" * pad)
            length += pad
        v["buffer"] = 0
        v["byteLength"] = len(data)
        v["byteOffset"] = length  # always written, as the package writer does
        chunks.append(data)
        length += len(data)
    data = b"".join(chunks)
    data += b"\0" * ((-len(data)) % 4)
    if views:
        buf: dict[str, Any] = {"byteLength": len(data)}
        if bin_uri is not None:
            buf["uri"] = bin_uri
        gltf["buffers"] = [buf]
    else:
        gltf.pop("buffers", None)
        gltf.pop("bufferViews", None)
    return gltf, data, files


def document_files(doc: Document, name: str, glb: bool) -> dict[str, bytes]:
    """The output files of a document as ``{relative path: bytes}``: ``NAME.glb``, or
    ``NAME.gltf`` + ``NAME.bin`` + its images."""
    if glb:
        gltf, data, _ = pack(doc, embed_images=True)
        return {f"{name}.glb": glb_bytes(gltf, data)}
    gltf, data, files = pack(doc, embed_images=False, bin_uri=f"{name}.bin")
    out = {f"{name}.gltf": dumps_json(gltf).encode("utf-8")}
    if "buffers" in gltf:
        out[f"{name}.bin"] = data
    for uri, image in files.items():
        if uri in out or uri.lower() in (k.lower() for k in out):
            raise doc.err(f"image URI {uri!r} collides with an output file; rename the image")
        out[uri] = image
    return out


def write_document(doc: Document, path: str | Path) -> list[Path]:
    """Write ``doc`` to ``path`` (.glb, or .gltf with its .bin and images beside it),
    atomically, never over the source document; return the paths written."""
    path = Path(path)
    glb = path.suffix.lower() == ".glb"
    files = document_files(doc, path.stem, glb)
    inputs = [doc.path]
    return [write_bytes(path.parent / rel, data, inputs) for rel, data in sorted(files.items())]
