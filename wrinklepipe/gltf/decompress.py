"""Compressed glTF geometry -> plain bytes: EXT_meshopt_compression and KHR_draco_mesh_compression.

- ``EXT_meshopt_compression`` (and its ratified twin ``KHR_meshopt_compression``): a bufferView
  whose bytes are the meshopt encoding of ``count`` elements of ``byteStride`` bytes, in mode
  ``ATTRIBUTES``, ``TRIANGLES`` or ``INDICES``, with an optional filter (``OCTAHEDRAL``,
  ``QUATERNION``, ``EXPONENTIAL``). Decoded with PyPI ``meshoptimizer`` (the official bindings of
  zeux/meshoptimizer). Two traps of its API are handled here: ``decode_vertex_buffer`` returns a
  float32 array whatever the data is (its bytes are the decoded bytes), and with 2-byte indices
  ``decode_index_buffer`` returns a uint32 array whose first ``2 * count`` bytes hold the uint16
  indices.
- ``KHR_draco_mesh_compression``: a primitive whose attributes and indices are one Draco
  bitstream; decoded with PyPI ``DracoPy``; each accessor gets its attribute (by the extension's
  unique id) converted to the accessor's component type.
"""

from __future__ import annotations

from typing import Any

import DracoPy
import meshoptimizer
import numpy as np

from wrinklepipe.asset import mesh_over_cap
from wrinklepipe.gltf.accessors import COMPONENTS, WIDTH, component_dtype

MESHOPT = ("EXT_meshopt_compression", "KHR_meshopt_compression")
DRACO = "KHR_draco_mesh_compression"


def compressed(gltf: dict[str, Any]) -> bool:
    """Whether a glTF tree holds compressed geometry: a bufferView carrying a meshopt extension
    or a primitive carrying a Draco one (what :func:`wrinklepipe.gltf.document.
    decode_geometry` decodes), whatever ``extensionsUsed`` says."""

    def ext(obj: Any) -> dict[str, Any]:
        e = obj.get("extensions") if isinstance(obj, dict) else None
        return e if isinstance(e, dict) else {}

    def array(obj: Any, key: str) -> list[Any]:
        v = obj.get(key) if isinstance(obj, dict) else None
        return v if isinstance(v, list) else []

    if any(n in ext(v) for v in array(gltf, "bufferViews") for n in MESHOPT):
        return True
    prims = (p for m in array(gltf, "meshes") for p in array(m, "primitives"))
    return any(DRACO in ext(p) for p in prims)


class DecodeError(ValueError):
    """Compressed data that does not decode (the caller names the file and pointer)."""


def meshopt_view(ext: dict[str, Any], source: bytes) -> bytes:
    """The decoded bytes (``count * byteStride``) of one meshopt-compressed bufferView."""

    try:
        count, stride = int(ext["count"]), int(ext["byteStride"])
        mode = str(ext["mode"])
    except (KeyError, TypeError, ValueError):
        raise DecodeError("meshopt extension lacks count, byteStride or mode") from None
    if count < 0 or stride <= 0:
        raise DecodeError(f"meshopt count {count} / byteStride {stride} are not sizes")
    over = mesh_over_cap(count, 0) if mode == "ATTRIBUTES" else mesh_over_cap(0, count)
    if over:  # the decoder allocates count x byteStride before it reads a byte
        raise DecodeError(f"meshopt data {over}")
    filt = str(ext.get("filter", "NONE"))
    if filt not in ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL"):
        raise DecodeError(f"unknown meshopt filter {filt!r}")
    try:
        if mode == "ATTRIBUTES":
            if stride % 4 or not 0 < stride <= 256:
                raise DecodeError(f"ATTRIBUTES byteStride {stride} is not a multiple of 4 <= 256")
            out = meshoptimizer.decode_vertex_buffer(count, stride, source)
            if filt == "OCTAHEDRAL":
                out = meshoptimizer.decode_filter_oct(out, count, stride)
            elif filt == "QUATERNION":
                out = meshoptimizer.decode_filter_quat(out, count, stride)
            elif filt == "EXPONENTIAL":
                out = meshoptimizer.decode_filter_exp(out, count, stride)
        elif mode in ("TRIANGLES", "INDICES"):
            if stride not in (2, 4):
                raise DecodeError(f"index byteStride {stride} must be 2 or 4")
            decode = (
                meshoptimizer.decode_index_buffer
                if mode == "TRIANGLES"
                else meshoptimizer.decode_index_sequence
            )
            out = decode(count, stride, source)
        else:
            raise DecodeError(f"unknown meshopt mode {mode!r}")
    except (RuntimeError, ValueError) as exc:
        if isinstance(exc, DecodeError):
            raise
        raise DecodeError(f"meshopt data does not decode ({exc})") from None
    data = np.ascontiguousarray(out).tobytes()[: count * stride]
    if len(data) != count * stride:
        raise DecodeError(f"meshopt decoded {len(data)} bytes, expected {count * stride}")
    return data


def draco_primitive(
    ext: dict[str, Any],
    data: bytes,
    accessors: list[dict[str, Any]],
    prim: dict[str, Any],
) -> dict[int, np.ndarray]:
    """Decode a Draco primitive: ``{accessor index: values [count, components]}`` in each
    accessor's component type (its indices accessor and every attribute the extension names)."""

    named = ext.get("attributes") or {}  # the JSON first, then the bitstream
    if not isinstance(named, dict):
        raise DecodeError("the extension's attributes must be an object")
    for semantic, uid in named.items():
        if not isinstance(uid, int) or isinstance(uid, bool):
            raise DecodeError(f"attribute id {uid!r} of {semantic} is not an integer")
    try:
        mesh = DracoPy.decode(data)
    except Exception as exc:  # DracoPy raises its own exception types for bad bitstreams
        raise DecodeError(f"Draco bitstream does not decode ({exc})") from None
    out: dict[int, np.ndarray] = {}
    attrs = prim.get("attributes", {})
    for semantic, uid in named.items():
        if semantic not in attrs:
            continue
        att = mesh.get_attribute_by_unique_id(uid)
        if att is None:
            raise DecodeError(f"Draco stream has no attribute {uid} ({semantic})")
        ai = attrs[semantic]
        out[ai] = _as_accessor(np.asarray(att["data"]), accessors[ai], semantic)
    if "indices" in prim:
        faces = getattr(mesh, "faces", None)
        if faces is None:
            raise DecodeError("Draco stream has no faces but the primitive has indices")
        ai = prim["indices"]
        out[ai] = _as_accessor(np.asarray(faces).reshape(-1, 1), accessors[ai], "indices")
    return out


def _as_accessor(values: np.ndarray, acc: dict[str, Any], what: str) -> np.ndarray:
    if acc.get("componentType") not in COMPONENTS or acc.get("type") not in WIDTH:
        raise DecodeError(
            f"Draco {what}: the accessor's componentType {acc.get('componentType')!r} / type "
            f"{acc.get('type')!r} is not one glTF defines"
        )
    dtype = component_dtype(acc["componentType"])
    width = WIDTH[acc["type"]]
    v = values.reshape(values.shape[0], -1)
    if v.shape != (int(acc["count"]), width):
        raise DecodeError(
            f"Draco {what}: {v.shape[0]} x {v.shape[1]} values, the accessor wants "
            f"{acc['count']} x {width}"
        )
    if dtype.kind in "iu" and v.dtype.kind == "f":
        if not acc.get("normalized"):
            raise DecodeError(f"Draco {what}: float data for an integer accessor")
        info = np.iinfo(dtype)
        v = np.rint(np.clip(v, -1.0 if dtype.kind == "i" else 0.0, 1.0) * info.max)
    return np.ascontiguousarray(v.astype(dtype))
