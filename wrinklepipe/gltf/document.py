"""The source document: a glTF file held whole, so that convert adds to it and loses nothing.

glTF-Transform's shape (a Document in, transforms, a Document out), kept as simple as can be
faithful: the document *is* the source JSON tree (every scene, node, mesh, material, texture,
sampler, image, skin, animation, camera, extra and unknown extension, as written) plus the bytes
of every bufferView and of every external image. Accessors are decoded on demand
(:mod:`wrinklepipe.gltf.accessors`). Additions (bufferViews, accessors, images, textures,
samplers, animations, attributes, extensions) go through the methods below; nothing in the source
tree is rewritten except what ingest had to decode:

- ``EXT_meshopt_compression`` / ``KHR_meshopt_compression`` views are decoded, and
  ``KHR_draco_mesh_compression`` primitives get plain accessors; the output is written
  uncompressed (the extension leaves ``extensionsUsed`` / ``extensionsRequired``; ``notes`` says
  so). Draco bitstream views are then unused and dropped (bufferView indices renumbered).
- ``KHR_mesh_quantization`` accessors are kept as they are (their component types stay; the
  dequantising node transforms stay), so the extension stays required. Maths on them reads
  floats through :meth:`Document.accessor`.
- ``KHR_texture_basisu``, ``EXT_texture_webp`` and every other texture are passed through byte for
  byte; they are decoded only when the pipeline must read one (:mod:`wrinklepipe.gltf.images`).

The decoding is :func:`decode_geometry`, the one decoder of compressed glTF geometry: mesh
ingest (:class:`wrinklepipe.gltf.read.GltfFile`) reads a compressed file through it too.
:func:`wrinklepipe.gltf.write.pack` writes the document back (one buffer).
"""

from __future__ import annotations

import copy
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any

import numpy as np

from wrinklepipe.errors import InputError, input_error
from wrinklepipe.gltf import accessors as acc
from wrinklepipe.gltf import decompress
from wrinklepipe.gltf import primitive as gltf_primitive
from wrinklepipe.gltf.container import Container, data_uri_bytes, open_container
from wrinklepipe.gltf.limits import GltfReadOptions
from wrinklepipe.names import plural

ARRAY_BUFFER = 34962
ELEMENT_ARRAY_BUFFER = 34963
FLOAT = 5126
_COMPONENT_OF = {
    np.dtype(np.int8): 5120,
    np.dtype(np.uint8): 5121,
    np.dtype(np.int16): 5122,
    np.dtype(np.uint16): 5123,
    np.dtype(np.uint32): 5125,
    np.dtype(np.float32): 5126,
}
_TYPE_OF = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 9: "MAT3", 16: "MAT4"}


@dataclass(frozen=True)
class PrimitiveRef:
    """Where one primitive lives: ``meshes[mesh].primitives[primitive]`` and its material."""

    mesh: int
    primitive: int
    material: int | None

    @property
    def pointer(self) -> str:
        return f"/meshes/{self.mesh}/primitives/{self.primitive}"


@dataclass
class ImageFile:
    """An image stored outside the buffer: its bytes and the relative URI to write it at."""

    data: bytes
    uri: str


@dataclass
class Document:
    """A glTF document: the JSON tree, each bufferView's bytes, each external image's bytes."""

    path: Path
    gltf: dict[str, Any]
    views: list[bytes]
    images: dict[int, ImageFile] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    #: Extensions whose data ingest decoded, so the output is written without them.
    decoded_extensions: list[str] = field(default_factory=list)
    #: The caps it was read with (``max_pixels`` also bounds every image decoded from it).
    options: GltfReadOptions = field(default_factory=GltfReadOptions)

    # -- errors ----------------------------------------------------------------------------
    @property
    def file(self) -> str:
        return str(self.path)

    def err(self, message: str, key: str = "") -> InputError:
        return input_error(self.file, message, key)

    # -- reading ---------------------------------------------------------------------------
    def array(self, key: str) -> list[Any]:
        """A top-level array of the tree (``[]`` when absent)."""
        value = self.gltf.get(key, [])
        return value if isinstance(value, list) else []

    def view_bytes(self, i: Any) -> tuple[bytes, int]:
        """bufferView ``i``'s bytes and byteStride (0 when tightly packed)."""
        if not isinstance(i, int) or isinstance(i, bool) or not 0 <= i < len(self.views):
            raise self.err(f"bufferView {i!r} does not exist", "/bufferViews")
        stride = self.gltf["bufferViews"][i].get("byteStride", 0)
        return self.views[i], int(stride) if isinstance(stride, int) else 0

    def accessor(self, i: Any, normalize: bool = True) -> np.ndarray:
        """Accessor ``i`` as ``[count, components]`` (see :func:`accessors.read_accessor`)."""
        return acc.read_accessor(self.gltf, i, self.view_bytes, self.err, normalize)

    def image_bytes(self, i: int) -> bytes:
        """The stored bytes of image ``i`` (data URI, external file or bufferView)."""
        imgs = self.array("images")
        if not 0 <= i < len(imgs):
            raise self.err(f"image {i} does not exist", "/images")
        if i in self.images:
            return self.images[i].data
        img = imgs[i]
        if "bufferView" in img:
            return self.view_bytes(img["bufferView"])[0]
        if isinstance(img.get("uri"), str) and img["uri"].startswith("data:"):
            return data_uri_bytes(img["uri"], self.options, self.err, f"/images/{i}/uri")
        raise self.err("image has neither uri nor bufferView", f"/images/{i}")

    def primitives(self) -> list[PrimitiveRef]:
        """Every primitive of every mesh, in order."""
        out = []
        for mi, mesh in enumerate(self.array("meshes")):
            for pi, prim in enumerate(mesh.get("primitives", [])):
                m = prim.get("material")
                out.append(PrimitiveRef(mi, pi, m if isinstance(m, int) else None))
        return out

    def primitive(self, ref: PrimitiveRef) -> dict[str, Any]:
        return self.gltf["meshes"][ref.mesh]["primitives"][ref.primitive]

    def material_name(self, i: int | None) -> str:
        """A material's name (``material<i>`` when unnamed; ``(default material)`` for None)."""
        if i is None:
            return "(default material)"
        name = self.array("materials")[i].get("name")
        return str(name) if name else f"material{i}"

    def mesh_name(self, i: int) -> str:
        name = self.array("meshes")[i].get("name")
        return str(name) if name else f"mesh{i}"

    def node_name(self, i: int) -> str:
        return gltf_primitive.node_name(self.gltf, i)

    def mesh_nodes(self, mesh: int) -> list[int]:
        """The nodes that instance mesh ``mesh``, in node order."""
        return [i for i, n in enumerate(self.array("nodes")) if n.get("mesh") == mesh]

    def target_names(self, mesh: int) -> list[str]:
        """Morph target names of a mesh (``extras.targetNames``; ``target_<i>`` for the rest)."""
        return gltf_primitive.target_names(self.gltf, mesh)

    # -- additions -------------------------------------------------------------------------
    def add_view(self, data: bytes, target: int | None = None, stride: int | None = None) -> int:
        """Append a bufferView holding ``data``; return its index."""
        view: dict[str, Any] = {"buffer": 0, "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        if stride:
            view["byteStride"] = stride
        self.gltf.setdefault("bufferViews", []).append(view)
        self.views.append(bytes(data))
        return len(self.views) - 1

    def add_accessor(
        self, array: np.ndarray, target: int | None = None, minmax: bool = False
    ) -> int:
        """Append a tightly packed accessor of ``array`` (``[count]`` or ``[count, n]``;
        float32, uint8/16/32 or int8/16); return its index."""
        a = np.ascontiguousarray(array)
        if a.dtype == np.float64:
            a = a.astype(np.float32)
        width = 1 if a.ndim == 1 else int(np.prod(a.shape[1:]))
        comp = _COMPONENT_OF[np.dtype(a.dtype)]
        a = a.astype(a.dtype.newbyteorder("<"))
        entry: dict[str, Any] = {
            "bufferView": self.add_view(a.tobytes(), target),
            "componentType": comp,
            "count": int(a.shape[0]),
            "type": _TYPE_OF[width],
        }
        if minmax and a.shape[0]:
            flat = a.reshape(a.shape[0], width)
            cast = float if comp == FLOAT else int
            entry["min"] = [cast(x) for x in flat.min(axis=0)]
            entry["max"] = [cast(x) for x in flat.max(axis=0)]
        self.gltf.setdefault("accessors", []).append(entry)
        return len(self.gltf["accessors"]) - 1

    def add_image(self, data: bytes, mime_type: str, name: str, uri: str) -> int:
        """Append an image (written to ``uri`` next to a .gltf, embedded in a .glb)."""
        self.gltf.setdefault("images", []).append({"name": name, "mimeType": mime_type})
        i = len(self.gltf["images"]) - 1
        self.images[i] = ImageFile(bytes(data), uri)
        return i

    def add_sampler(self, sampler: dict[str, Any]) -> int:
        """Append a sampler, or return the index of an identical one."""
        samplers = self.gltf.setdefault("samplers", [])
        for i, s in enumerate(samplers):
            if s == sampler:
                return i
        samplers.append(dict(sampler))
        return len(samplers) - 1

    def add_texture(self, image: int, sampler: int | None, name: str) -> int:
        tex: dict[str, Any] = {"source": image, "name": name}
        if sampler is not None:
            tex["sampler"] = sampler
        self.gltf.setdefault("textures", []).append(tex)
        return len(self.gltf["textures"]) - 1

    def add_animation(self, animation: dict[str, Any]) -> int:
        self.gltf.setdefault("animations", []).append(animation)
        return len(self.gltf["animations"]) - 1

    def use_extension(self, name: str, required: bool = False) -> None:
        """List ``name`` in ``extensionsUsed`` (and ``extensionsRequired``), sorted, once."""
        used = set(self.gltf.get("extensionsUsed", [])) | {name}
        self.gltf["extensionsUsed"] = sorted(used)
        if required:
            req = set(self.gltf.get("extensionsRequired", [])) | {name}
            self.gltf["extensionsRequired"] = sorted(req)


# ------------------------------------------------------------------------------------------------
# reading


def read_document(path: str | Path, options: GltfReadOptions | None = None) -> Document:
    """Read a .gltf / .glb as a :class:`Document` (compressed geometry decoded, see the module
    doc). Bad input raises :class:`~wrinklepipe.errors.InputError` naming the file and pointer."""
    c = open_container(path, options)
    doc = decode_geometry(c)
    for i, img in enumerate(doc.array("images")):
        uri = img.get("uri")
        if isinstance(uri, str) and not uri.startswith("data:"):
            data = c.uri_bytes(uri, f"/images/{i}/uri")
            doc.images[i] = ImageFile(data, _clean_uri(uri))
    return doc


def decode_geometry(c: Container) -> Document:
    """The document of an opened file without its external images: its tree (a copy) and
    every bufferView's bytes, meshopt views and Draco primitives decoded (see the module doc).

    The one decoder of compressed glTF geometry: :func:`read_document` adds the images, and
    mesh ingest (:class:`wrinklepipe.gltf.read.GltfFile`) reads a compressed file through
    it. Data that does not decode raises :class:`~wrinklepipe.errors.InputError` naming the
    file and the pointer of the extension."""
    gltf = copy.deepcopy(c.gltf)
    views, decoded, decoded_views = _views(c, gltf)
    doc = Document(c.path, gltf, views, decoded_extensions=decoded, options=c.options)
    decoded_views |= _decode_draco(doc)
    _true_bounds(doc, decoded_views)
    for name in doc.decoded_extensions:
        doc.notes.append(f"{name}: decoded; written uncompressed")
    _drop_extensions(doc.gltf, doc.decoded_extensions)
    return doc


def _views(c: Container, gltf: dict[str, Any]) -> tuple[list[bytes], list[str], set[int]]:
    """Every bufferView's bytes (meshopt decoded), the meshopt extensions that were used and
    the decoded views."""
    views = gltf.get("bufferViews", [])
    out = []
    used: set[str] = set()
    decoded: set[int] = set()
    for i, v in enumerate(views):
        key = f"/bufferViews/{i}"
        if not isinstance(v, dict):
            raise c.err("bufferView must be an object", key)
        ext = v.get("extensions") or {}
        name = next((n for n in decompress.MESHOPT if n in ext), None)
        if name is not None:
            e = ext[name]
            src = c.slice(e.get("buffer"), e.get("byteOffset", 0), e.get("byteLength"), key)
            try:
                data = decompress.meshopt_view(e, src)
            except decompress.DecodeError as exc:
                raise c.err(str(exc), f"{key}/extensions/{name}") from None
            del ext[name]
            if not ext:
                v.pop("extensions", None)
            v["byteLength"] = len(data)
            used.add(name)
            decoded.add(i)
        else:
            data = c.slice(v.get("buffer"), v.get("byteOffset", 0), v.get("byteLength"), key)
        v["buffer"] = 0
        v.pop("byteOffset", None)
        out.append(data)
    return out, sorted(used), decoded


def _decode_draco(doc: Document) -> set[int]:
    """Give Draco primitives plain accessors; return the new bufferViews."""
    decoded = doc.decoded_extensions
    new_views: set[int] = set()
    draco_views: set[int] = set()
    accessors = doc.array("accessors")
    for ref in doc.primitives():
        prim = doc.primitive(ref)
        ext = (prim.get("extensions") or {}).get(decompress.DRACO)
        if ext is None:
            continue
        key = f"{ref.pointer}/extensions/{decompress.DRACO}"
        view = ext.get("bufferView") if isinstance(ext, dict) else None
        if not isinstance(view, int) or isinstance(view, bool) or not 0 <= view < len(doc.views):
            raise doc.err(f"Draco bufferView {view!r} does not exist", key)
        data, _ = doc.view_bytes(view)
        try:
            values = decompress.draco_primitive(ext, data, accessors, prim)
        except (decompress.DecodeError, KeyError, IndexError, TypeError, ValueError) as exc:
            raise doc.err(f"Draco primitive does not decode: {exc}", key) from None
        except AttributeError:  # a member that should be an object is not one
            raise doc.err("Draco primitive does not decode: malformed extension", key) from None
        for ai, arr in values.items():
            a = accessors[ai]
            target = ELEMENT_ARRAY_BUFFER if ai == prim.get("indices") else ARRAY_BUFFER
            a["bufferView"] = doc.add_view(arr.tobytes(), target)
            a.pop("byteOffset", None)
            new_views.add(a["bufferView"])
        draco_views.add(int(ext["bufferView"]))
        del prim["extensions"][decompress.DRACO]
        if not prim["extensions"]:
            del prim["extensions"]
        if decompress.DRACO not in decoded:
            decoded.append(decompress.DRACO)
    if draco_views:
        remap = drop_views(doc, draco_views)
        new_views = {remap[v] for v in new_views}
    return new_views


def _true_bounds(doc: Document, views: set[int]) -> None:
    """Rewrite the min/max of accessors in decoded views where they differ from the data.

    Encoders may write bounds of the data before their own rounding (gltfpack -vpf does); the
    decoded values are what a viewer gets, and the spec wants their exact bounds."""
    fixed = []
    for i, a in enumerate(doc.array("accessors")):
        if a.get("bufferView") not in views or not ("min" in a or "max" in a):
            continue
        v = doc.accessor(i, normalize=False)
        if not len(v):
            continue
        cast = float if a.get("componentType") == FLOAT else int
        lo = [cast(x) for x in v.min(axis=0)]
        hi = [cast(x) for x in v.max(axis=0)]
        if a.get("min", lo) != lo or a.get("max", hi) != hi:
            a["min"], a["max"] = lo, hi
            fixed.append(i)
    if fixed:
        doc.notes.append(
            f"min/max of {plural(len(fixed), 'decoded accessor')} set to the decoded data's bounds "
            f"(the encoder's differed): {', '.join(map(str, fixed[:12]))}"
            + (" ..." if len(fixed) > 12 else "")
        )


def drop_views(doc: Document, drop: set[int]) -> dict[int, int]:
    """Remove unused bufferViews and renumber the references (accessors, sparse, images);
    return the old -> new index map."""
    keep = [i for i in range(len(doc.views)) if i not in drop]
    remap = {old: new for new, old in enumerate(keep)}
    doc.views = [doc.views[i] for i in keep]
    doc.gltf["bufferViews"] = [doc.gltf["bufferViews"][i] for i in keep]

    def fix(obj: dict[str, Any]) -> None:
        if "bufferView" in obj:
            if obj["bufferView"] in drop:
                i = obj["bufferView"]
                raise doc.err(f"bufferView {i} is removed but still used by other data")
            obj["bufferView"] = remap[obj["bufferView"]]

    for a in doc.array("accessors"):
        fix(a)
        if isinstance(a.get("sparse"), dict):
            fix(a["sparse"].get("indices", {}))
            fix(a["sparse"].get("values", {}))
    for img in doc.array("images"):
        fix(img)
    return remap


def _drop_extensions(gltf: dict[str, Any], names: list[str]) -> None:
    for key in ("extensionsUsed", "extensionsRequired"):
        if key in gltf:
            gltf[key] = [n for n in gltf[key] if n not in names]
            if not gltf[key]:
                del gltf[key]
    for b in gltf.get("buffers", []):  # meshopt fallback buffers hold no data of their own
        ext = b.get("extensions") or {}
        for n in names:
            ext.pop(n, None)
        if "extensions" in b and not ext:
            del b["extensions"]


def _clean_uri(uri: str) -> str:
    parts = PurePosixPath(urllib.parse.unquote(uri).replace("\\", "/")).parts
    return "/".join(p for p in parts if p not in ("", "."))
