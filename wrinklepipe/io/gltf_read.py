"""Read a wrinklepipe glTF/GLB (one written by :mod:`wrinklepipe.io.gltf_write`) into a package.

The reader is defensive, because a glTF names other files: every URI must be relative and stay
inside the asset's folder (no ``..``, no absolute paths, no schemes other than ``data:``); data
URIs are capped in size; buffers, views and accessors are bounds-checked; image sizes are read
from the PNG header and capped before any pixel is decoded. Every problem is an
:class:`~wrinklepipe.errors.InputError` naming the file and the JSON pointer.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.document.container import open_container
from wrinklepipe.errors import input_error, plain_reason
from wrinklepipe.io.accessors import read_accessor
from wrinklepipe.io.gltf_limits import GltfReadOptions as GltfReadOptions  # re-exported
from wrinklepipe.io.package import (
    EXTENSION,
    PackedTexture,
    WeightCurves,
    WrinklePackage,
    png_pixels,
    safe_name,
)
from wrinklepipe.metadata import VERTEX_ID_ATTRIBUTE, WrinkleMeta


class _Reader:
    """A glTF file opened by the one container reader (:func:`wrinklepipe.document.container.
    open_container`: GLB chunks, confined URIs, capped data URIs and files, buffers), with
    bufferViews, accessors and PNG images on top."""

    def __init__(self, path: Path, options: GltfReadOptions) -> None:
        self.path = path
        self.file = str(path)
        self.opt = options
        self.folder = path.parent
        self.container = open_container(path, options)
        self.doc = self.container.gltf

    def err(self, message: str, key: str = "") -> Exception:
        return input_error(self.file, message, key)

    def buffer(self, i: int) -> bytes:
        return self.container.buffer(i)

    def view(self, i: int) -> tuple[bytes, int]:
        views = self.doc.get("bufferViews", [])
        if not isinstance(i, int) or isinstance(i, bool) or not 0 <= i < len(views):
            raise self.err(f"bufferView {i!r} does not exist", "/bufferViews")
        v = views[i]
        data = self.buffer(int(v.get("buffer", 0)))
        off, n = int(v.get("byteOffset", 0)), int(v["byteLength"])
        if off < 0 or off + n > len(data):
            raise self.err("bufferView runs past the end of its buffer", f"/bufferViews/{i}")
        return data[off : off + n], int(v.get("byteStride", 0))

    def accessor(self, i: int) -> np.ndarray:
        """Accessor ``i`` through :func:`wrinklepipe.io.accessors.read_accessor` (the one
        accessor reader); a SCALAR accessor as ``[count]``."""
        arr = read_accessor(self.doc, i, self.view, self.err)
        return arr[:, 0] if arr.shape[1] == 1 else arr

    def image(self, i: int) -> tuple[str, np.ndarray]:
        imgs = self.doc.get("images", [])
        key = f"/images/{i}"
        if not 0 <= i < len(imgs):
            raise self.err(f"image {i} does not exist", "/images")
        img = imgs[i]
        if "uri" in img:
            data = self.container.uri_bytes(img["uri"], key + "/uri")
        elif "bufferView" in img:
            data, _ = self.view(int(img["bufferView"]))
        else:
            raise self.err("image has neither uri nor bufferView", key)
        if data[:8] != b"\x89PNG\r\n\x1a\n" or len(data) < 24:
            raise self.err("image is not a PNG (only PNG textures are read)", key)
        w, h = struct.unpack(">II", data[16:24])
        if w * h > self.opt.max_pixels:
            raise self.err(f"image is {w} x {h}, over the cap of {self.opt.max_pixels} pixels", key)
        name = str(img.get("name") or f"image_{i}")
        return name, png_pixels(data, f"{self.file} {key}")


def _texture_image(
    doc: dict[str, Any], err: Callable[[str, str], Exception], tex_index: int, key: str
) -> int:
    """The image a texture shows (``KHR_texture_basisu`` / ``EXT_texture_webp`` source first)."""
    texs = doc.get("textures", [])
    if not isinstance(tex_index, int) or not 0 <= tex_index < len(texs):
        raise err(f"texture {tex_index} does not exist", key)
    ext = texs[tex_index].get("extensions") or {}
    for name in ("KHR_texture_basisu", "EXT_texture_webp"):
        src = (ext.get(name) or {}).get("source") if isinstance(ext, dict) else None
        if isinstance(src, int):
            return src
    src = texs[tex_index].get("source")
    if src is None:
        raise err(f"texture {tex_index} has no source image", key)
    return int(src)


def read_gltf(path: str | Path, options: GltfReadOptions | None = None) -> WrinklePackage:
    """Load a wrinklepipe .gltf/.glb as a :class:`WrinklePackage` (mesh, stored textures, meta).

    Raises :class:`InputError` naming the file (and JSON pointer) for anything malformed."""
    try:
        return _read_gltf(path, options)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        # Safety net for structures the specific checks did not foresee: still one clear line.
        raise input_error(path, f"malformed glTF: {plain_reason(exc)}") from None


def _read_gltf(path: str | Path, options: GltfReadOptions | None = None) -> WrinklePackage:
    r = _Reader(Path(path), options or GltfReadOptions())
    doc = r.doc
    mats = doc.get("materials", [])
    if not mats or EXTENSION not in mats[0].get("extensions", {}):
        raise r.err(
            f"no {EXTENSION} extension on materials[0]: not a wrinklepipe asset", "/materials/0"
        )
    ext = mats[0]["extensions"][EXTENSION]

    mesh = _first_mesh(r, ext)
    name = str(
        doc.get("scenes", [{}])[doc.get("scene", 0)].get("name")
        or doc.get("nodes", [{}])[0].get("name")
        or Path(path).stem
    )
    return package_from_gltf(
        doc,
        0,
        mesh,
        r.image,
        r.accessor,
        r.err,
        name,
        {0: list(range(len(mesh.morph_names)))},
    )


def _first_mesh(r: _Reader, ext: dict[str, Any]) -> Mesh:
    """``meshes[0]``'s first primitive as the render mesh of a file wrinklepipe wrote
    (``io.gltf_write``): its attributes, morph targets, the skin of the node instancing it."""
    doc = r.doc
    meshes = doc.get("meshes", [])
    if not meshes or not meshes[0].get("primitives"):
        raise r.err("no mesh primitive", "/meshes/0")
    gm = meshes[0]
    prim = gm["primitives"][0]
    attrs = prim.get("attributes", {})
    for need in (
        "POSITION",
        "NORMAL",
        "TANGENT",
        "TEXCOORD_0",
        ext.get("vertexIdAttribute", VERTEX_ID_ATTRIBUTE),
    ):
        if need not in attrs:
            raise r.err(f"primitive has no {need} attribute", "/meshes/0/primitives/0/attributes")
    positions = r.accessor(attrs["POSITION"]).astype(np.float32)
    bad = np.flatnonzero(~np.isfinite(positions).all(axis=-1))
    if bad.size:
        raise r.err(
            f"{bad.size} position(s) are NaN or infinite (first: vertex {int(bad[0])})",
            f"/accessors/{attrs['POSITION']}",
        )
    nv = positions.shape[0]
    ids_f = r.accessor(attrs[ext.get("vertexIdAttribute", VERTEX_ID_ATTRIBUTE)]).astype(np.float64)
    if np.any(ids_f != np.rint(ids_f)) or np.any(ids_f < 0):
        raise r.err("vertex IDs must be non-negative integers", "/meshes/0/primitives/0/attributes")
    if "indices" in prim:
        indices = r.accessor(prim["indices"]).astype(np.int64)
    else:
        indices = np.arange(nv, dtype=np.int64)
    if indices.size % 3 or (indices.size and (indices.min() < 0 or indices.max() >= nv)):
        raise r.err(
            "indices are not triangles over existing vertices", "/meshes/0/primitives/0/indices"
        )
    names = tuple(gm.get("extras", {}).get("targetNames", ()))
    targets = prim.get("targets", [])
    deltas = None
    if targets:
        deltas = np.stack([r.accessor(t["POSITION"]).astype(np.float32) for t in targets])
        if len(names) != len(targets):
            names = tuple(f"target_{i}" for i in range(len(targets)))
    mesh = Mesh(
        positions=positions,
        indices=indices.reshape(-1, 3).astype(np.uint32),
        uvs=r.accessor(attrs["TEXCOORD_0"]).astype(np.float32),
        normals=r.accessor(attrs["NORMAL"]).astype(np.float32),
        tangents=r.accessor(attrs["TANGENT"]).astype(np.float32),
        morph_names=names,
        morph_deltas=deltas,
        vertex_ids=ids_f.astype(np.int64),
        colors=r.accessor(attrs["_WRINKLE_BIAS"]).astype(np.float32)
        if "_WRINKLE_BIAS" in attrs
        else None,
        name=str(gm.get("name", "mesh")),
    )
    node = next((n for n in doc.get("nodes", []) if n.get("mesh") == 0), {})
    if "skin" in node and "JOINTS_0" in attrs and "WEIGHTS_0" in attrs:
        skins = doc.get("skins", [])
        si = node["skin"]
        if not isinstance(si, int) or not 0 <= si < len(skins):
            raise r.err(f"skin {si} does not exist", "/skins")
        joints = [int(j) for j in skins[si].get("joints", [])]
        nodes = doc.get("nodes", [])
        if any(not 0 <= j < len(nodes) for j in joints):
            raise r.err("skin joint is not a node", f"/skins/{si}/joints")
        mesh.joint_names = tuple(str(nodes[j].get("name") or f"joint{j}") for j in joints)
        mesh.joints = r.accessor(attrs["JOINTS_0"]).astype(np.int64)
        mesh.skin_weights = r.accessor(attrs["WEIGHTS_0"]).astype(np.float32)
        if mesh.joints.max(initial=0) >= len(joints):
            raise r.err("JOINTS_0 index past the skin's joints", "/meshes/0/primitives/0")
        if "inverseBindMatrices" in skins[si]:
            ibm = r.accessor(skins[si]["inverseBindMatrices"]).astype(np.float32)
            if ibm.shape != (len(joints), 16):
                raise r.err("inverseBindMatrices count differs from joints", f"/skins/{si}")
            mesh.inverse_bind = np.ascontiguousarray(ibm.reshape(-1, 4, 4).transpose(0, 2, 1))
    for a in (mesh.uvs, mesh.normals, mesh.tangents, mesh.colors):
        if a is not None and a.shape[0] != nv:
            raise r.err(
                "attribute counts differ from POSITION", "/meshes/0/primitives/0/attributes"
            )

    return mesh


def package_from_gltf(
    doc: dict[str, Any],
    material: int,
    mesh: Mesh,
    image: Callable[[int], tuple[str, np.ndarray]],
    accessor: Callable[[int], np.ndarray],
    err: Callable[[str, str], Exception],
    name: str,
    morph_nodes: dict[int, list[int]],
) -> WrinklePackage:
    """The package a glTF's wrinkled material ``material`` describes, over the render ``mesh``.

    ``image(i)`` returns image ``i``'s (name, stored pixels); ``accessor(i)`` an accessor's
    values; ``err(message, pointer)`` the error to raise. ``morph_nodes`` maps each node whose
    morph-weight channel plays a curve's blendshape inputs to the column of ``mesh.morph_names``
    of each of its targets (-1: none)."""
    mats = doc.get("materials", [])
    mat = mats[material]
    ext = mat["extensions"][EXTENSION]
    pkey = f"/materials/{material}/extensions/{EXTENSION}"
    mkey = f"/materials/{material}"
    # -- textures ---------------------------------------------------------------------------
    textures: list[PackedTexture] = []
    by_image: dict[int, str] = {}
    taken: set[str] = set()

    def tex(info: Any, key: str, role: str) -> str:
        if not isinstance(info, dict) or "index" not in info:
            raise err("expected a textureInfo object with 'index'", key)
        src = _texture_image(doc, err, info["index"], key)
        if src not in by_image:
            name, px = image(src)
            name = safe_name(name, taken)
            textures.append(PackedTexture(name, px, role))
            by_image[src] = name
        return by_image[src]

    if "normalTexture" not in mat:
        raise err("material has no normalTexture (the base normal map)", mkey)
    base_name = tex(mat["normalTexture"], f"{mkey}/normalTexture", "base_normal")
    if base_name != "base_normal":
        if "base_normal" in taken:
            raise err("an image other than the base normal map is named 'base_normal'")
        textures[-1].name = "base_normal"
        taken.add("base_normal")
        by_image = {k: ("base_normal" if v == base_name else v) for k, v in by_image.items()}

    def named(info: Any, key: str, role: str) -> str:
        if role != "copy":
            return tex(info, key, role)
        src = _texture_image(doc, err, info["index"], key)
        if src not in by_image:
            raise err("a compressed copy of a texture the extension does not use", key)
        return by_image[src]

    try:
        meta = WrinkleMeta.from_extension(ext, named, err, pkey)
    except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
        raise err(f"malformed extension block: {plain_reason(exc)}", pkey) from None
    try:
        json.dumps(meta.to_json(), allow_nan=False)
    except ValueError:
        raise err("the extension block holds a NaN or infinite number", pkey) from None
    curves = _weight_curves(
        doc, ext, accessor, err, pkey, len(meta.regions), len(mesh.morph_names), morph_nodes
    )
    return WrinklePackage(name, mesh, textures, meta, curves)


def _weight_curves(
    doc: dict[str, Any],
    ext: dict[str, Any],
    accessor: Callable[[int], np.ndarray],
    err: Callable[[str, str], Exception],
    pkey: str,
    n_regions: int,
    n_morphs: int,
    morph_nodes: dict[int, list[int]],
) -> list[WeightCurves]:
    """The extension's ``weightCurves``: each names a glTF animation whose
    ``KHR_animation_pointer`` channel plays the region weights, and whose morph ``weights``
    channels (on the nodes of ``morph_nodes``) play the blendshape inputs with them."""
    curves = []
    anims = doc.get("animations", [])
    for i, wc in enumerate(ext.get("weightCurves", [])):
        ai = wc.get("animation")
        if not isinstance(ai, int) or not 0 <= ai < len(anims):
            raise err(f"animation {ai!r} does not exist", f"{pkey}/weightCurves/{i}")
        anim = anims[ai]
        pointer = [
            ch for ch in anim.get("channels", []) if ch.get("target", {}).get("path") == "pointer"
        ]
        if not pointer:
            raise err("animation has no KHR_animation_pointer channel", f"/animations/{ai}")
        s = anim["samplers"][pointer[0]["sampler"]]
        times = accessor(s["input"]).astype(np.float32)
        vals = accessor(s["output"]).astype(np.float32).reshape(-1)
        morph = None
        for ch in anim.get("channels", []):
            tgt = ch.get("target", {})
            node = tgt.get("node")
            columns = morph_nodes.get(node) if isinstance(node, int) else None
            if tgt.get("path") != "weights" or columns is None:
                continue
            ms = anim["samplers"][ch["sampler"]]
            mv = accessor(ms["output"]).astype(np.float32).reshape(-1)
            n_m = len(columns)
            if not n_m or mv.size != times.size * n_m:
                raise err(
                    f"morph weights: {mv.size} values for {times.size} keys x {n_m} targets",
                    f"/animations/{ai}",
                )
            if morph is None:
                morph = np.zeros((times.size, n_morphs), np.float32)
            cols = np.asarray(columns, np.int64)
            keep = cols >= 0
            morph[:, cols[keep]] = mv.reshape(times.size, n_m)[:, keep]
        if vals.size != times.size * n_regions:
            raise err(
                f"animation output has {vals.size} values, expected {times.size} x {n_regions}",
                f"/animations/{ai}",
            )
        curves.append(
            WeightCurves(
                str(wc.get("name", f"curve_{i}")),
                times,
                vals.reshape(times.size, n_regions),
                morph,
            )
        )
    return curves
