"""glTF 2.0 / GLB writer for a :class:`~wrinklepipe.package.WrinklePackage`.

What is written (DESIGN.md section 4):

- one mesh primitive with POSITION, NORMAL, explicit TANGENT (always), TEXCOORD_0, and
  application-specific per-vertex data as SCALAR FLOAT accessors (one shape, which Blender's
  importer needs): ``_WRINKLE_VERTEX_ID`` (spatial-hash vertex IDs, exact in float32 below
  2^24) and ``_WRINKLE_BIAS_R``/``_G``/``_B``/``_A`` (rest-pose bias, from ``mesh.colors``)
  when present; morph targets (POSITION deltas) named in
  ``mesh.extras.targetNames``;
- a material whose core ``normalTexture`` is the base normal map (so plain viewers render the
  neutral face), carrying the vendor extension ``WRINKLEPIPE_wrinkle_maps`` (listed in
  ``extensionsUsed`` only, never ``extensionsRequired``): wrinkle states as textureInfo, masks with
  their channel table or array layout, encoding, scale, policy, regions, expressions, drivers and
  the region weights;
- region-weight curves as animations through ``KHR_animation_pointer`` targeting
  ``/materials/0/extensions/WRINKLEPIPE_wrinkle_maps/weights`` (the extension declares the
  property animatable), indexed from the extension's ``weightCurves``.

Output is deterministic: fixed buffer layout, sorted JSON keys, minimal PNGs.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import udim
from wrinklepipe.atomic import dumps_json, write_bytes
from wrinklepipe.errors import input_error
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, png_bytes
from wrinklepipe.metadata import (
    BIAS_CHANNEL_ATTRIBUTES,
    EXTENSION,
    VERTEX_ID_ATTRIBUTE,
    WrinkleMeta,
)
from wrinklepipe.package import MAX_FLOAT_ID, WrinklePackage, safe_name

POINTER_EXTENSION = "KHR_animation_pointer"
WEIGHTS_POINTER = f"/materials/0/extensions/{EXTENSION}/weights"

_FLOAT = 5126
_UINT = 5125
_USHORT = 5123
_ARRAY_BUFFER = 34962
_ELEMENT_ARRAY_BUFFER = 34963
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


@dataclass(frozen=True)
class GltfOptions:
    """Writer options.

    ``texture_dir``: folder (relative to the .gltf) holding the PNGs; ``generator``: the
    ``asset.generator`` string (no version timestamps, so reruns are byte-identical).
    """

    texture_dir: str = "textures"
    generator: str = "wrinklepipe"
    png_level: int = DEFAULT_PNG_LEVEL


class _Buffer:
    """Accumulates 4-byte aligned bufferViews into one binary buffer."""

    def __init__(self) -> None:
        self.chunks: list[bytes] = []
        self.length = 0
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = (-self.length) % 4
        if pad:
            self.chunks.append(b"\0" * pad)
            self.length += pad
        v: dict[str, Any] = {"buffer": 0, "byteOffset": self.length, "byteLength": len(data)}
        if target is not None:
            v["target"] = target
        self.chunks.append(data)
        self.length += len(data)
        self.views.append(v)
        return len(self.views) - 1

    def accessor(self, array: np.ndarray, target: int | None = None, minmax: bool = False) -> int:
        a = np.ascontiguousarray(array)
        width = 1 if a.ndim == 1 else int(np.prod(a.shape[1:]))
        if a.dtype == np.uint32:
            comp, a = _UINT, a.astype("<u4")
        elif a.dtype == np.uint16:
            comp, a = _USHORT, a.astype("<u2")
        else:
            comp, a = _FLOAT, a.astype("<f4")
        acc: dict[str, Any] = {
            "bufferView": self.view(a.tobytes(), target),
            "componentType": comp,
            "count": int(a.shape[0]),
            "type": _TYPES[width],
        }
        if minmax:
            flat = a.reshape(a.shape[0], width)
            if comp == _FLOAT:
                acc["min"] = [float(x) for x in flat.min(axis=0)]
                acc["max"] = [float(x) for x in flat.max(axis=0)]
            else:
                acc["min"] = [int(x) for x in flat.min(axis=0)]
                acc["max"] = [int(x) for x in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def data(self) -> bytes:
        return b"".join(self.chunks)


def _check_mesh(pkg: WrinklePackage) -> None:
    m = pkg.mesh
    where = f"{pkg.name} mesh {m.name!r}"
    if m.uvs is None or m.normals is None or m.tangents is None:
        raise input_error(where, "glTF output needs UVs, normals and tangents (run the stages)")
    if m.vertex_ids is None:
        raise input_error(where, "glTF output needs vertex IDs (run the vertex-ids stage)")
    if int(np.max(m.vertex_ids, initial=0)) >= MAX_FLOAT_ID or int(np.min(m.vertex_ids)) < 0:
        raise input_error(where, f"vertex IDs must lie in [0, {MAX_FLOAT_ID}) to be exact as FLOAT")


def skin_weights_normalized(weights: np.ndarray) -> np.ndarray:
    """Skin weights whose rows sum to 1 (rows off by more than 1e-6 are divided by their sum;
    all-zero rows bind to the first joint), as glTF requires of WEIGHTS_0."""
    w = np.asarray(weights, np.float32)
    total = w.sum(axis=1, dtype=np.float64)
    fix = np.abs(total - 1.0) > 1e-6
    if np.any(fix):
        w = w.copy()
        safe = np.where(total[fix] > 0, total[fix], 1.0)
        w[fix] = (w[fix] / safe[:, None]).astype(np.float32)
        w[fix & (total <= 0)] = np.array([1, 0, 0, 0], np.float32)
    return w


def _skin(m: Any, buf: _Buffer, attrs: dict[str, int], skin: bool = True) -> dict[str, Any] | None:
    """JOINTS_0/WEIGHTS_0 and a skin whose joints are root nodes placed at their bind pose
    (``skin`` False: the attributes only, for a primitive after the first of a tiled mesh).

    The mesh keeps joint names and inverse bind matrices but no hierarchy, so every joint is a
    root node whose matrix is its bind-pose world matrix ``inverse(IBM)``: the rest pose renders
    exactly and each joint drives its vertices.
    """
    if m.joints is None or m.skin_weights is None or not len(m.joint_names):
        return None
    n = len(m.joint_names)
    w = skin_weights_normalized(m.skin_weights)
    j = np.where(w > 0, np.asarray(m.joints, np.int64), 0)
    if j.max(initial=0) >= n or j.min(initial=0) < 0:
        raise input_error(m.name, f"joint indices must lie in [0, {n})")
    attrs["JOINTS_0"] = buf.accessor(j.astype(np.uint16), _ARRAY_BUFFER)
    attrs["WEIGHTS_0"] = buf.accessor(w, _ARRAY_BUFFER)
    if not skin:
        return None
    ibm = (
        np.asarray(m.inverse_bind, np.float32)
        if m.inverse_bind is not None
        else np.tile(np.eye(4, dtype=np.float32), (n, 1, 1))
    )
    nodes = []
    for name, inv in zip(m.joint_names, ibm):
        node: dict[str, Any] = {"name": str(name)}
        world = np.linalg.inv(inv.astype(np.float64))
        if not np.allclose(world, np.eye(4), atol=0.0):
            node["matrix"] = [float(np.float32(x)) for x in world.T.reshape(-1)]
        nodes.append(node)
    acc = buf.accessor(np.ascontiguousarray(ibm.transpose(0, 2, 1)).reshape(n, 16))
    return {"joints": list(range(1, n + 1)), "inverseBindMatrices": acc, "_nodes": nodes}


def weights_pointer(material: int) -> str:
    """The ``KHR_animation_pointer`` path of the extension's weights on material ``material``."""
    return f"/materials/{material}/extensions/{EXTENSION}/weights"


def extension_block(
    meta: WrinkleMeta, tex_index: dict[str, int], vertex_id_attribute: str = VERTEX_ID_ATTRIBUTE
) -> dict[str, Any]:
    """The ``WRINKLEPIPE_wrinkle_maps`` JSON of a package's ``meta`` (textures by glTF index):
    :meth:`~wrinklepipe.metadata.WrinkleMeta.to_extension`."""
    return meta.to_extension(tex_index, vertex_id_attribute)


@dataclass(frozen=True)
class MorphChannel:
    """A node whose morph weights a blendshapes curve animates: ``columns[i]`` is the column of
    the curve's ``morph_weights`` that drives the node's mesh target ``i`` (-1: held at 0)."""

    node: int
    columns: np.ndarray


def curve_animations(
    curves: list[Any],
    regions: int,
    accessor: Any,
    pointers: list[str],
    morphs: list[MorphChannel],
    where: str = "",
) -> list[dict[str, Any]]:
    """One glTF animation per weight curve: a LINEAR sampler of the region weights played
    through ``KHR_animation_pointer`` at each of ``pointers``, plus (for a curve with morph
    weights) one ``weights`` channel per node of ``morphs``. ``accessor(array, minmax)`` adds
    an accessor and returns its index."""
    animations = []
    for c in curves:
        times = np.asarray(c.times, np.float32)
        values = np.asarray(c.values, np.float32)
        if values.shape != (times.shape[0], regions):
            raise input_error(
                where,
                f"weight curve {c.name!r}: values {values.shape} do not match "
                f"{times.shape[0]} keys x {regions} regions",
            )
        t_acc = accessor(times, True)
        samplers = [
            {
                "input": t_acc,
                "output": accessor(values.reshape(-1), False),
                "interpolation": "LINEAR",
            }
        ]
        channels = [
            {
                "sampler": 0,
                "target": {
                    "path": "pointer",
                    "extensions": {POINTER_EXTENSION: {"pointer": p}},
                },
            }
            for p in pointers
        ]
        if c.morph_weights is not None:
            mw = np.asarray(c.morph_weights, np.float32)
            width = max((int(m.columns.max(initial=-1)) + 1 for m in morphs), default=0)
            if mw.ndim != 2 or mw.shape[0] != times.shape[0] or mw.shape[1] < width or not morphs:
                raise input_error(
                    where,
                    f"weight curve {c.name!r}: morph weights {mw.shape} do not match "
                    f"{times.shape[0]} keys x the morph targets",
                )
            padded = np.concatenate([mw, np.zeros((mw.shape[0], 1), np.float32)], axis=1)
            for m in morphs:
                out = accessor(np.ascontiguousarray(padded[:, m.columns]).reshape(-1), False)
                samplers.append({"input": t_acc, "output": out, "interpolation": "LINEAR"})
                channels.append(
                    {"sampler": len(samplers) - 1, "target": {"node": m.node, "path": "weights"}}
                )
        animations.append({"name": c.name, "samplers": samplers, "channels": channels})
    return animations


def gltf_document(
    pkg: WrinklePackage, options: GltfOptions | None = None, embed_images: bool = False
) -> tuple[dict[str, Any], bytes, dict[str, bytes]]:
    """Build the glTF JSON, its binary buffer and the image files ``{uri: png bytes}``.

    With ``embed_images`` the PNGs go into the buffer as bufferViews (GLB) and the returned dict
    is empty. The buffer's ``uri`` is left for the caller to set (absent for GLB).

    A UDIM package (``pkg.tiles``; glTF has no UDIM) is written one primitive per tile, each
    with its own material: the tile's triangles with their UVs moved into [0, 1]
    (:func:`wrinklepipe.udim.tile_package`), the tile's textures, and the extension block
    naming its ``tile``; the weight curves play on every tile's material at once.
    """
    opt = options or GltfOptions()
    _check_mesh(pkg)
    buf = _Buffer()
    views = [udim.tile_package(pkg, t) for t in pkg.tiles] if pkg.tiles else [pkg]
    m = pkg.mesh
    prims = []
    skin = None
    for i, view in enumerate(views):
        prim, got = _primitive(view.mesh, buf, i, skin=i == 0)
        prims.append(prim)
        skin = skin or got
    mesh: dict[str, Any] = {"name": m.name, "primitives": prims}
    if m.morph_deltas is not None and len(m.morph_names):
        mesh["weights"] = [0.0] * len(m.morph_names)
        mesh["extras"] = {"targetNames": list(m.morph_names)}

    images, textures, files = [], [], {}
    tex_index: dict[str, int] = {}
    for t in pkg.textures:
        if safe_name(t.name) != t.name:
            raise input_error(pkg.name, f"texture name {t.name!r} is not a safe file name")
        data = png_bytes(t.pixels, opt.png_level)
        img: dict[str, Any] = {"name": t.name}
        if embed_images:
            img["bufferView"] = buf.view(data)
            img["mimeType"] = "image/png"
        else:
            uri = f"{opt.texture_dir}/{t.name}.png" if opt.texture_dir else f"{t.name}.png"
            img["uri"] = uri
            files[uri] = data
        images.append(img)
        textures.append({"sampler": 0, "source": len(images) - 1, "name": t.name})
        tex_index[t.name] = len(textures) - 1

    animations = curve_animations(
        pkg.curves,
        len(pkg.meta.regions),
        lambda a, minmax: buf.accessor(a, minmax=minmax),
        [weights_pointer(i) for i in range(len(views))],
        [MorphChannel(0, np.arange(len(m.morph_names)))] if len(m.morph_names) else [],
        pkg.name,
    )
    materials = []
    for view in views:
        ext = extension_block(view.meta, tex_index)
        if view is not pkg:
            ext["tile"] = udim.split_name(view.base_name)[1]
        if animations:
            ext["weightCurves"] = [
                {"name": c.name, "animation": i} for i, c in enumerate(pkg.curves)
            ]
        materials.append(_material(view, tex_index, ext))
    used = [EXTENSION] + ([POINTER_EXTENSION] if animations else [])
    nodes: list[dict[str, Any]] = [{"name": pkg.name, "mesh": 0}]
    if skin is not None:
        nodes[0]["skin"] = 0
        nodes += skin.pop("_nodes")
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": opt.generator},
        "extensionsUsed": sorted(used),
        "scene": 0,
        "scenes": [{"name": pkg.name, "nodes": list(range(len(nodes)))}],
        "nodes": nodes,
        "meshes": [mesh],
        "materials": materials,
        "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}],
        "images": images,
        "textures": textures,
        "accessors": buf.accessors,
        "bufferViews": buf.views,
        "buffers": [{"byteLength": 0}],
    }
    if animations:
        doc["animations"] = animations
    if skin is not None:
        doc["skins"] = [skin]
    data = buf.data()
    data += b"\0" * ((-len(data)) % 4)
    doc["buffers"][0]["byteLength"] = len(data)
    return doc, data, files


def _material(
    pkg: WrinklePackage, tex_index: dict[str, int], ext: dict[str, Any]
) -> dict[str, Any]:
    """The wrinkled material of a package (one tile of a UDIM package: its ``NAME_skin.TILE``)."""
    pbr: dict[str, Any] = {
        "baseColorFactor": [0.8, 0.62, 0.52, 1.0],
        "metallicFactor": 0.0,
        "roughnessFactor": 0.55,
    }
    if pkg.meta.base_color is not None:  # the colour states blend over the base colour
        pbr["baseColorTexture"] = {"index": tex_index[pkg.meta.base_color]}
        pbr["baseColorFactor"] = [*(float(x) for x in pkg.meta.color_factor), 1.0]
    tile = udim.split_name(pkg.base_name)[1]
    return {
        "name": f"{pkg.name}_skin" + ("" if tile is None else f".{tile}"),
        "normalTexture": {"index": tex_index[pkg.base_name]},
        "pbrMetallicRoughness": pbr,
        "extensions": {EXTENSION: ext},
    }


def _primitive(
    m: Any, buf: _Buffer, material: int, skin: bool
) -> tuple[dict[str, Any], dict[str, Any] | None]:
    """One triangle primitive of the render mesh ``m`` (its accessors added to ``buf``) using
    ``material``; with ``skin`` also the skin object (the first primitive's)."""
    attrs = {
        "POSITION": buf.accessor(m.positions.astype(np.float32), _ARRAY_BUFFER, minmax=True),
        "NORMAL": buf.accessor(m.normals.astype(np.float32), _ARRAY_BUFFER),
        "TANGENT": buf.accessor(m.tangents.astype(np.float32), _ARRAY_BUFFER),
        "TEXCOORD_0": buf.accessor(m.uvs.astype(np.float32), _ARRAY_BUFFER),
        VERTEX_ID_ATTRIBUTE: buf.accessor(m.vertex_ids.astype(np.float32), _ARRAY_BUFFER),
    }
    if m.colors is not None:
        for c, name in enumerate(BIAS_CHANNEL_ATTRIBUTES):
            attrs[name] = buf.accessor(m.colors[:, c].astype(np.float32), _ARRAY_BUFFER)
    got = _skin(m, buf, attrs, skin)
    idx = m.indices.reshape(-1)
    idx_arr = idx.astype(np.uint16 if m.vertex_count < 65535 else np.uint32)
    prim: dict[str, Any] = {
        "attributes": attrs,
        "indices": buf.accessor(idx_arr, _ELEMENT_ARRAY_BUFFER, minmax=False),
        "material": material,
        "mode": 4,
    }
    if m.morph_deltas is not None and len(m.morph_names):
        prim["targets"] = [
            {"POSITION": buf.accessor(d.astype(np.float32), _ARRAY_BUFFER, minmax=True)}
            for d in m.morph_deltas
        ]
    return prim, got


def glb_bytes(doc: dict[str, Any], data: bytes) -> bytes:
    """Pack a glTF JSON and its binary buffer into a GLB container (deterministic)."""
    js = dumps_json(doc).encode("utf-8")
    js += b" " * ((-len(js)) % 4)
    binc = data + b"\0" * ((-len(data)) % 4)
    total = 12 + 8 + len(js) + 8 + len(binc)
    return (
        struct.pack("<III", 0x46546C67, 2, total)
        + struct.pack("<II", len(js), 0x4E4F534A)
        + js
        + struct.pack("<II", len(binc), 0x004E4942)
        + binc
    )


def write_gltf(
    pkg: WrinklePackage,
    folder: str | Path,
    stem: str | None = None,
    options: GltfOptions | None = None,
) -> list[Path]:
    """Write ``STEM.gltf`` + ``STEM.bin`` + ``textures/*.png`` into ``folder``; return the paths."""
    folder = Path(folder)
    stem = stem or pkg.name
    doc, data, files = gltf_document(pkg, options)
    doc["buffers"][0]["uri"] = f"{stem}.bin"
    written = [
        write_bytes(folder / f"{stem}.bin", data),
        write_bytes(folder / f"{stem}.gltf", dumps_json(doc).encode("utf-8")),
    ]
    for uri, png in files.items():
        written.append(write_bytes(folder / uri, png))
    return written


def write_glb(pkg: WrinklePackage, path: str | Path, options: GltfOptions | None = None) -> Path:
    """Write a self-contained GLB (images embedded as bufferViews)."""
    doc, data, _ = gltf_document(pkg, options, embed_images=True)
    return write_bytes(path, glb_bytes(doc, data))
