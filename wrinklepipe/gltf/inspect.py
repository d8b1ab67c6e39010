"""What a glTF document holds, as plain JSON-able data, and what differs between two.

:func:`summary` lists (like ``gltf-transform inspect``) the scenes, nodes, meshes (primitives,
vertices, indices, morph targets, attributes with their component types), materials (textures
by slot, alpha mode, double-sided, extensions), textures (image size, format, bytes), skins
(joints, hierarchy depth), animations (channels, samplers, duration, keyframes) and extensions.
:func:`diff` compares two summaries element by element (by index) and returns one line per
difference; the tests use it to show exactly what convert changed.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.write import mime_type

_COMPONENT = {5120: "i8", 5121: "u8", 5122: "i16", 5123: "u16", 5125: "u32", 5126: "f32"}
_MODES = {0: "POINTS", 1: "LINES", 2: "LINE_LOOP", 3: "LINE_STRIP", 4: "TRIANGLES"}
_MODES.update({5: "TRIANGLE_STRIP", 6: "TRIANGLE_FAN"})


def image_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG, JPEG, KTX2 or WebP header, None when unknown."""
    if data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) >= 24:
        return struct.unpack(">II", data[16:24])
    if data[:12] == b"\xabKTX 20\xbb\r\n\x1a\n" and len(data) >= 28:
        return struct.unpack("<II", data[20:28])
    if data[:4] == b"RIFF" and data[8:12] == b"WEBP" and data[12:16] == b"VP8X":
        w = int.from_bytes(data[24:27], "little") + 1
        h = int.from_bytes(data[27:30], "little") + 1
        return w, h
    if data[:3] == b"\xff\xd8\xff":
        i = 2
        while i + 9 < len(data):
            if data[i] != 0xFF:
                return None
            marker = data[i + 1]
            seg = struct.unpack(">H", data[i + 2 : i + 4])[0]
            if marker in (0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD):
                h, w = struct.unpack(">HH", data[i + 5 : i + 9])
                return w, h
            i += 2 + seg
    return None


def _format(data: bytes) -> str:
    return mime_type(data)


def _texture_slots(material: dict[str, Any]) -> dict[str, int]:
    """``{slot: texture index}`` for the core slots and every extension's textureInfo."""
    out: dict[str, int] = {}

    def walk(obj: Any, path: str) -> None:
        if isinstance(obj, dict):
            if isinstance(obj.get("index"), int) and path:
                out[path] = obj["index"]
            for k, v in obj.items():
                if k != "index":
                    walk(v, f"{path}.{k}" if path else k)
        elif isinstance(obj, list):
            for i, v in enumerate(obj):
                walk(v, f"{path}[{i}]")

    walk({k: v for k, v in material.items() if k not in ("name", "extras")}, "")
    return out


def _depth(doc: Document, joints: list[int]) -> int:
    """Longest parent chain among ``joints`` (a single joint: 1)."""
    parent: dict[int, int] = {}
    for i, n in enumerate(doc.array("nodes")):
        for c in n.get("children", []):
            parent[c] = i
    js = set(joints)
    best = 0
    for j in joints:
        d, k, seen = 1, j, {j}
        while parent.get(k) in js and parent[k] not in seen:
            k = parent[k]
            seen.add(k)
            d += 1
        best = max(best, d)
    return best


def _attribute(a: dict[str, Any]) -> str:
    """``TYPE:component`` (``n`` appended for normalized), e.g. ``VEC3:f32``, ``VEC2:u16n``."""
    comp = _COMPONENT.get(a.get("componentType"), "?")
    return f"{a.get('type', '?')}:{comp}{'n' if a.get('normalized') else ''}"


def summary(doc: Document) -> dict[str, Any]:
    """The document's contents (see the module doc)."""
    accs = doc.array("accessors")
    meshes = []
    for mi, m in enumerate(doc.array("meshes")):
        prims = []
        for p in m.get("primitives", []):
            attrs = p.get("attributes", {})
            nv = int(accs[attrs["POSITION"]]["count"]) if "POSITION" in attrs else 0
            prims.append(
                {
                    "mode": _MODES.get(int(p.get("mode", 4)), str(p.get("mode"))),
                    "material": doc.material_name(p.get("material")),
                    "vertices": nv,
                    "indices": int(accs[p["indices"]]["count"]) if "indices" in p else None,
                    "attributes": {k: _attribute(accs[v]) for k, v in sorted(attrs.items())},
                    "targets": len(p.get("targets", [])),
                }
            )
        meshes.append(
            {
                "name": doc.mesh_name(mi),
                "primitives": prims,
                "vertices": sum(p["vertices"] for p in prims),
                "morphs": doc.target_names(mi),
                "instances": len(doc.mesh_nodes(mi)),
            }
        )
    materials = []
    for i, mat in enumerate(doc.array("materials")):
        materials.append(
            {
                "name": doc.material_name(i),
                "alphaMode": mat.get("alphaMode", "OPAQUE"),
                "doubleSided": bool(mat.get("doubleSided", False)),
                "textures": _texture_slots(mat),
                "extensions": sorted((mat.get("extensions") or {}).keys()),
                "instances": sum(1 for r in doc.primitives() if r.material == i),
            }
        )
    textures = []
    for i, t in enumerate(doc.array("textures")):
        src = t.get("source")
        ext = t.get("extensions") or {}
        for e in ext.values():  # KHR_texture_basisu, EXT_texture_webp, ...
            if isinstance(e, dict) and isinstance(e.get("source"), int):
                src = e["source"]
        entry: dict[str, Any] = {"name": str(t.get("name") or f"texture{i}"), "image": src}
        if isinstance(src, int):
            data = doc.image_bytes(src)
            size = image_size(data)
            entry.update(
                {
                    "format": _format(data),
                    "size": list(size) if size else None,
                    "bytes": len(data),
                    "imageName": doc.array("images")[src].get("name"),
                }
            )
        textures.append(entry)
    skins = []
    for i, s in enumerate(doc.array("skins")):
        joints = [int(j) for j in s.get("joints", [])]
        skins.append(
            {
                "name": str(s.get("name") or f"skin{i}"),
                "joints": len(joints),
                "depth": _depth(doc, joints),
                "skeleton": s.get("skeleton"),
            }
        )
    animations = []
    for i, a in enumerate(doc.array("animations")):
        samplers = a.get("samplers", [])
        times = [doc.accessor(s["input"])[:, 0] for s in samplers if "input" in s]
        keys = sum(len(t) for t in times)
        duration = float(max((t.max() for t in times if len(t)), default=0.0)) - float(
            min((t.min() for t in times if len(t)), default=0.0)
        )
        paths = sorted({str(c.get("target", {}).get("path")) for c in a.get("channels", [])})
        animations.append(
            {
                "name": str(a.get("name") or f"animation{i}"),
                "channels": len(a.get("channels", [])),
                "samplers": len(samplers),
                "duration": round(duration, 6),
                "keyframes": keys,
                "paths": paths,
            }
        )
    scenes = []
    for i, s in enumerate(doc.array("scenes")):
        scenes.append({"name": str(s.get("name") or f"scene{i}"), "roots": len(s.get("nodes", []))})
    return {
        "file": doc.path.name,
        "generator": (doc.gltf.get("asset") or {}).get("generator"),
        "extensionsUsed": sorted(doc.gltf.get("extensionsUsed", [])),
        "extensionsRequired": sorted(doc.gltf.get("extensionsRequired", [])),
        "decoded": list(doc.decoded_extensions),
        "scenes": scenes,
        "nodes": len(doc.array("nodes")),
        "meshes": meshes,
        "materials": materials,
        "textures": textures,
        "skins": skins,
        "animations": animations,
        "cameras": len(doc.array("cameras")),
        "vertices": int(sum(m["vertices"] for m in meshes)),
    }


def diff(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """What differs between two :func:`summary` results, one line each (``-`` only in A,
    ``+`` only in B, ``~`` changed), elements compared by index."""
    out: list[str] = []

    def walk(x: Any, y: Any, path: str) -> None:
        if isinstance(x, dict) and isinstance(y, dict):
            for k in sorted(set(x) | set(y)):
                p = f"{path}.{k}" if path else k
                if k not in y:
                    out.append(f"- {p}: {x[k]!r}")
                elif k not in x:
                    out.append(f"+ {p}: {y[k]!r}")
                else:
                    walk(x[k], y[k], p)
        elif isinstance(x, list) and isinstance(y, list) and _elements(x, y):
            for i in range(max(len(x), len(y))):
                p = f"{path}[{i}]"
                if i >= len(y):
                    out.append(f"- {p}: {_label(x[i])}")
                elif i >= len(x):
                    out.append(f"+ {p}: {_label(y[i])}")
                else:
                    walk(x[i], y[i], p)
        elif x != y and not (_num(x) and _num(y) and np.isclose(x, y, rtol=1e-9, atol=0)):
            out.append(f"~ {path}: {x!r} -> {y!r}")

    walk(
        {k: v for k, v in a.items() if k != "file"}, {k: v for k, v in b.items() if k != "file"}, ""
    )
    return out


def _elements(x: list[Any], y: list[Any]) -> bool:
    return any(isinstance(v, dict) for v in x + y)


def _num(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool)


def _label(v: Any) -> str:
    if isinstance(v, dict) and "name" in v:
        return repr(v["name"])
    return repr(v)
