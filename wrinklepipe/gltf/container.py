"""The glTF container: a .glb or .gltf file -> its JSON tree and the bytes it names.

Every glTF reader opens its file here. Every URI is relative and stays inside the asset's
folder (:func:`~wrinklepipe.gltf.limits.safe_uri_path`), data URIs and external files are capped
(:class:`~wrinklepipe.gltf.limits.GltfReadOptions`; :func:`data_uri_bytes` also for the
document's data-URI images), GLB chunk lengths are checked. Every problem
is an :class:`~wrinklepipe.errors.InputError` naming the file and the JSON pointer.
"""

from __future__ import annotations

import base64
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wrinklepipe.errors import InputError, input_error
from wrinklepipe.gltf.limits import GltfReadOptions, safe_uri_path
from wrinklepipe.io.json_safe import loads_json

GLB_MAGIC = 0x46546C67
JSON_CHUNK = 0x4E4F534A
BIN_CHUNK = 0x004E4942


@dataclass
class Container:
    """A parsed glTF file: its JSON, the GLB binary chunk (if any) and a cache of resolved URIs."""

    path: Path
    gltf: dict[str, Any]
    glb_bin: bytes | None
    options: GltfReadOptions
    _buffers: dict[int, bytes] = field(default_factory=dict)

    @property
    def file(self) -> str:
        return str(self.path)

    def err(self, message: str, key: str = "") -> InputError:
        return input_error(self.file, message, key)

    def uri_bytes(self, uri: Any, key: str) -> bytes:
        """The bytes a URI names: a base64 data URI or a relative file inside the asset folder."""
        if not isinstance(uri, str):
            raise self.err("uri must be a string", key)
        if uri.startswith("data:"):
            return data_uri_bytes(uri, self.options, self.err, key)
        p = safe_uri_path(self.path.parent, uri, self.file, key)
        if not p.is_file():
            raise self.err(f"referenced file {uri!r} not found", key)
        if p.stat().st_size > self.options.max_file_bytes:
            raise self.err(
                f"referenced file {uri!r} is over {self.options.max_file_bytes} bytes", key
            )
        return p.read_bytes()

    def buffer(self, i: Any) -> bytes:
        """Buffer ``i``'s bytes (its URI, or the GLB binary chunk for buffer 0 without one)."""
        bufs = self.gltf.get("buffers", [])
        if not isinstance(i, int) or not 0 <= i < len(bufs):
            raise self.err(f"buffer {i!r} does not exist", "/buffers")
        if i not in self._buffers:
            b = bufs[i]
            key = f"/buffers/{i}"
            if "uri" in b:
                data = self.uri_bytes(b["uri"], key + "/uri")
            elif i == 0 and self.glb_bin is not None:
                data = self.glb_bin
            else:
                raise self.err("buffer has no uri and there is no GLB binary chunk", key)
            need = b.get("byteLength", 0)
            if not isinstance(need, int) or len(data) < need:
                raise self.err(f"buffer holds {len(data)} bytes, byteLength says {need!r}", key)
            self._buffers[i] = data
        return self._buffers[i]

    def slice(self, buffer: Any, offset: Any, length: Any, key: str) -> bytes:
        """``length`` bytes at ``offset`` of a buffer, bounds-checked."""
        if not isinstance(offset, int) or not isinstance(length, int) or offset < 0 or length < 0:
            raise self.err("byteOffset / byteLength must be non-negative integers", key)
        data = self.buffer(buffer)
        if offset + length > len(data):
            raise self.err(
                f"bytes {offset}..{offset + length} run past the end of buffer {buffer} "
                f"({len(data)} bytes)",
                key,
            )
        return data[offset : offset + length]


def data_uri_bytes(
    uri: str, options: GltfReadOptions, err: Callable[[str, str], InputError], key: str
) -> bytes:
    """A base64 ``data:`` URI's bytes, refused over ``options.max_data_uri_bytes`` (estimated
    from its length, before decoding) or when it is not valid base64."""
    head, _, payload = uri.partition(",")
    est = len(payload) * 3 // 4
    if est > options.max_data_uri_bytes:
        raise err(f"data URI of ~{est} bytes is over the cap of {options.max_data_uri_bytes}", key)
    if not head.endswith(";base64"):
        raise err("data URI is not base64", key)
    try:
        return base64.b64decode(payload, validate=True)
    except ValueError:
        raise err("data URI is not valid base64", key) from None


def split_glb(data: bytes, file: str) -> tuple[bytes, bytes | None]:
    """The JSON chunk and the first binary chunk (or None) of a GLB container."""
    if len(data) < 20:
        raise input_error(file, "GLB header truncated")
    _, version, total = struct.unpack_from("<III", data, 0)
    if version != 2:
        raise input_error(file, f"GLB version {version}, expected 2")
    if total != len(data):
        raise input_error(file, f"GLB length field {total} != file size {len(data)}")
    off, chunks = 12, []
    while off + 8 <= len(data):
        n, kind = struct.unpack_from("<II", data, off)
        if off + 8 + n > len(data):
            raise input_error(file, f"GLB chunk at byte {off} runs past the end of the file")
        chunks.append((kind, data[off + 8 : off + 8 + n]))
        off += 8 + n
    if not chunks or chunks[0][0] != JSON_CHUNK:
        raise input_error(file, "GLB has no JSON chunk first")
    bins = [c for k, c in chunks[1:] if k == BIN_CHUNK]
    return chunks[0][1], (bins[0] if bins else None)


def open_container(path: str | Path, options: GltfReadOptions | None = None) -> Container:
    """Parse a .gltf / .glb file (JSON checked to be a glTF 2.0 document)."""
    path = Path(path)
    file = str(path)
    if not path.is_file():
        raise input_error(file, "file not found")
    data = path.read_bytes()
    glb_bin = None
    if data[:4] == b"glTF":
        text, glb_bin = split_glb(data, file)
    else:
        text = data
    gltf = loads_json(text, file, "glTF JSON")
    if not isinstance(gltf, dict) or not isinstance(gltf.get("asset"), dict):
        raise input_error(file, "not a glTF document (no asset object)", "/asset")
    if str(gltf["asset"].get("version")) != "2.0":
        raise input_error(file, "not a glTF 2.0 document (asset.version must be '2.0')", "/asset")
    for key, value in gltf.items():
        if key not in ("asset", "extensions", "extras", "scene") and not isinstance(value, list):
            if key in _ARRAYS:
                raise input_error(file, f"{key} must be an array", f"/{key}")
    return Container(path, gltf, glb_bin, options or GltfReadOptions())


_ARRAYS = (
    "accessors",
    "animations",
    "buffers",
    "bufferViews",
    "cameras",
    "images",
    "materials",
    "meshes",
    "nodes",
    "samplers",
    "scenes",
    "skins",
    "textures",
    "extensionsUsed",
    "extensionsRequired",
)
