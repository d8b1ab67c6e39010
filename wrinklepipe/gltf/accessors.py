"""glTF accessors -> numpy arrays, per the glTF 2.0 spec (section 3.6).

THE accessor reader: the glTF document model (:mod:`wrinklepipe.gltf`), the mesh reader
(:mod:`wrinklepipe.gltf.meshes` over :mod:`wrinklepipe.gltf.read`) and the glTF animations
the drivers are given all decode accessors here, so every one of them reads any component type
(little-endian), every element type (``MAT2``/``MAT3`` with byte-aligned columns as the spec
requires for 1- and 2-byte components), byte strides, sparse substitution, accessors without a
bufferView (zeros), ``normalized`` integers (unsigned ``c / MAX``, signed ``max(c / MAX, -1)``).
The bytes of each bufferView come from a callable, so compressed views
(``EXT_meshopt_compression``) and Draco primitives are decoded once, for the document and mesh
ingest alike, by :func:`wrinklepipe.gltf.document.decode_geometry` and read here like any
other.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from wrinklepipe.errors import InputError

COMPONENTS: dict[int, type[np.generic]] = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: (columns, rows) of the matrix types.
_MATRIX = {"MAT2": (2, 2), "MAT3": (3, 3), "MAT4": (4, 4)}

ViewBytes = Callable[[int], tuple[bytes, int]]
Err = Callable[[str, str], InputError]


def component_dtype(component_type: Any) -> np.dtype:
    """The little-endian numpy dtype of a glTF componentType (KeyError when unknown)."""
    return np.dtype(COMPONENTS[component_type]).newbyteorder("<")


def element_layout(dtype: np.dtype, type_: str) -> tuple[int, int, int]:
    """(components per element, bytes of one element, bytes of each column with padding).

    Matrices of 1- and 2-byte components pad every column to 4 bytes (spec 3.6.2.4)."""
    width = WIDTH[type_]
    if type_ in _MATRIX and dtype.itemsize < 4:
        cols, rows = _MATRIX[type_]
        col_bytes = -(-rows * dtype.itemsize // 4) * 4
        return width, cols * col_bytes, col_bytes
    return width, width * dtype.itemsize, width * dtype.itemsize


def _rows(
    data: bytes,
    stride: int,
    offset: int,
    count: int,
    dtype: np.dtype,
    type_: str,
    err: Err,
    key: str,
) -> np.ndarray:
    width, elem, col_bytes = element_layout(dtype, type_)
    if count == 0:
        return np.zeros((0, width), dtype)
    stride = stride or elem
    if stride < elem:
        raise err(f"byteStride {stride} is smaller than the {elem}-byte element", key)
    need = offset + (count - 1) * stride + elem
    if offset < 0 or need > len(data):
        raise err(f"accessor needs {need} bytes, its bufferView has {len(data)}", key)
    raw = np.frombuffer(data, np.uint8, count=need - offset, offset=offset)
    rows = np.lib.stride_tricks.as_strided(raw, (count, elem), (stride, 1))
    if type_ in _MATRIX and dtype.itemsize < 4:  # drop the column padding
        cols, nrows = _MATRIX[type_]
        rows = rows.reshape(count, cols, col_bytes)[:, :, : nrows * dtype.itemsize]
    return np.ascontiguousarray(rows).reshape(count, -1).view(dtype).reshape(count, width)


def read_accessor(
    gltf: dict[str, Any],
    index: Any,
    view_bytes: ViewBytes,
    err: Err,
    normalize: bool = True,
) -> np.ndarray:
    """Accessor ``index`` as ``[count, components]`` (sparse applied).

    With ``normalize`` (default) a ``normalized`` integer accessor comes back as float32 per the
    spec; otherwise every accessor keeps its stored component type. ``view_bytes(i)`` returns a
    bufferView's bytes and byteStride; ``err(message, pointer)`` makes the error to raise.
    """
    accs = gltf.get("accessors", [])
    if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(accs):
        raise err(f"accessor {index!r} does not exist", "/accessors")
    a = accs[index]
    key = f"/accessors/{index}"
    try:
        dtype = component_dtype(a["componentType"])
        type_ = str(a["type"])
        WIDTH[type_]
        count = int(a["count"])
        offset = int(a.get("byteOffset", 0))
    except (KeyError, TypeError, ValueError):
        raise err("accessor has a bad componentType, type, count or byteOffset", key) from None
    if count < 0:
        raise err("accessor count is negative", key)
    if offset % dtype.itemsize:
        raise err(f"byteOffset {offset} is not a multiple of the component size", key)
    if "bufferView" in a:
        data, stride = view_bytes(a["bufferView"])
        if stride % dtype.itemsize:
            raise err(f"byteStride {stride} is not a multiple of the component size", key)
        arr = _rows(data, stride, offset, count, dtype, type_, err, key)
    else:
        arr = np.zeros((count, WIDTH[type_]), dtype)
    if "sparse" in a:
        arr = _apply_sparse(a["sparse"], arr, dtype, type_, view_bytes, err, key + "/sparse")
    if normalize and a.get("normalized") and dtype.kind in "iu":
        out = arr.astype(np.float32) / np.float32(np.iinfo(dtype).max)
        if dtype.kind == "i":
            np.maximum(out, -1.0, out=out)
        return out
    return arr


def _apply_sparse(
    sp: Any,
    arr: np.ndarray,
    dtype: np.dtype,
    type_: str,
    view_bytes: ViewBytes,
    err: Err,
    key: str,
) -> np.ndarray:
    try:
        n = int(sp["count"])
        si, sv = sp["indices"], sp["values"]
        idt = component_dtype(si["componentType"])
        ioff, voff = int(si.get("byteOffset", 0)), int(sv.get("byteOffset", 0))
        iview, vview = si["bufferView"], sv["bufferView"]
    except (KeyError, TypeError, ValueError):
        raise err("sparse accessor has a bad count, indices or values", key) from None
    if idt.kind != "u":
        raise err("sparse indices must be an unsigned integer type", key + "/indices")
    idata, _ = view_bytes(iview)
    idx = _rows(idata, 0, ioff, n, idt, "SCALAR", err, key + "/indices")[:, 0].astype(np.int64)
    vdata, _ = view_bytes(vview)
    vals = _rows(vdata, 0, voff, n, dtype, type_, err, key + "/values")
    if n and (idx.min() < 0 or idx.max() >= len(arr)):
        raise err("sparse indices out of range", key + "/indices")
    if n > 1 and np.any(np.diff(idx) <= 0):
        raise err("sparse indices are not strictly increasing", key + "/indices")
    out = arr.copy()
    out[idx] = vals
    return out
