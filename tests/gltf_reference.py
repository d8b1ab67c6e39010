"""An independent glTF reader for tests: pygltflib parses the file, this decodes accessors with
plain struct/numpy (written apart from wrinklepipe.gltf, so tests compare two readers)."""

from __future__ import annotations

import pickle
import struct
from pathlib import Path

import numpy as np
import pygltflib

_FMT = {5120: "b", 5121: "B", 5122: "h", 5123: "H", 5125: "I", 5126: "f"}
_N = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


#: Files pygltflib parsed in this process, pickled, by (path, mtime, size): the suite reads the
#: same few documents (RobotExpressive, its conversions) dozens of times, and pygltflib's
#: dataclasses-json parse takes 0.22 s of CPU for RobotExpressive where unpickling takes 2 ms.
_PARSED: dict[tuple[str, int, int], bytes] = {}


def load(path: str | Path) -> pygltflib.GLTF2:
    """pygltflib's parse of ``path``: a fresh object of the caller's own (a file rewritten since
    is parsed again)."""
    st = Path(path).stat()
    key = (str(Path(path).resolve()), st.st_mtime_ns, st.st_size)
    if key not in _PARSED:
        _PARSED[key] = pickle.dumps(pygltflib.GLTF2().load(str(path)))
    return pickle.loads(_PARSED[key])


def buffer_bytes(g: pygltflib.GLTF2, path: str | Path, i: int) -> bytes:
    b = g.buffers[i]
    if b.uri is None:
        return g.binary_blob()
    if b.uri.startswith("data:"):
        return g.decode_data_uri(b.uri)
    return (Path(path).parent / b.uri).read_bytes()


def accessor(g: pygltflib.GLTF2, path: str | Path, i: int) -> np.ndarray:
    """Accessor i as stored ([count, n]; no sparse, no matrix padding: test assets need none)."""
    a = g.accessors[i]
    n = _N[a.type]
    fmt = "<" + _FMT[a.componentType] * n
    size = struct.calcsize(fmt)
    bv = g.bufferViews[a.bufferView]
    data = buffer_bytes(g, path, bv.buffer)
    stride = bv.byteStride or size
    start = (bv.byteOffset or 0) + (a.byteOffset or 0)
    rows = [struct.unpack_from(fmt, data, start + k * stride) for k in range(a.count)]
    out = np.array(rows, dtype=np.float64 if a.componentType == 5126 else np.int64)
    return out.reshape(a.count, n)


def image_bytes(g: pygltflib.GLTF2, path: str | Path, i: int) -> bytes:
    img = g.images[i]
    if img.bufferView is not None:
        bv = g.bufferViews[img.bufferView]
        data = buffer_bytes(g, path, bv.buffer)
        return data[(bv.byteOffset or 0) : (bv.byteOffset or 0) + bv.byteLength]
    if img.uri.startswith("data:"):
        return g.decode_data_uri(img.uri)
    return (Path(path).parent / img.uri).read_bytes()
