"""A glTF file opened for reading its meshes and animations: the reader that the glTF mesh
reader (:mod:`wrinklepipe.gltf.meshes`) and the morph-animation reader
(:mod:`wrinklepipe.gltf.animation`) build on.

The file is opened by the one container reader (:func:`wrinklepipe.gltf.container.
open_container`), which is defensive because a glTF names other files: every URI must be
relative and stay inside the asset's folder (no ``..``, no absolute paths, no schemes other than
``data:``); data URIs and external files are capped in size. bufferViews are bounds-checked here
and accessors decoded by :func:`wrinklepipe.gltf.accessors.read_accessor`. A file with
compressed geometry (``EXT_meshopt_compression`` / ``KHR_meshopt_compression`` views,
``KHR_draco_mesh_compression`` primitives) is decoded at open by the document model's own
decoder (:func:`wrinklepipe.gltf.document.decode_geometry`): its tree and views are then the
decoded document's, so mesh ingest and the document read the same numbers. Every problem is an
:class:`~wrinklepipe.errors.InputError` naming the file and the JSON pointer.

:class:`GltfFile` is a :class:`wrinklepipe.gltf.primitive.GltfSource` (``gltf``,
``accessor``, ``err``), as the document model (:class:`wrinklepipe.gltf.document.Document`)
is: the one per-primitive reader (:func:`wrinklepipe.gltf.primitive.read_primitive`) reads
either.
A written wrinkle package is read by :func:`wrinklepipe.gltf.package_read.read_wrinkled` (the one
glTF package reader, on the document model).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.errors import InputError, input_error
from wrinklepipe.gltf.accessors import read_accessor
from wrinklepipe.gltf.container import open_container
from wrinklepipe.gltf.decompress import compressed
from wrinklepipe.gltf.document import Document, decode_geometry
from wrinklepipe.gltf.limits import GltfReadOptions as GltfReadOptions  # re-exported


class GltfFile:
    """A glTF file opened by the one container reader (:func:`wrinklepipe.gltf.container.
    open_container`: GLB chunks, confined URIs, capped data URIs and files, buffers), with
    bufferViews and accessors on top; compressed geometry decoded by the document model's
    decoder (``decoded``: the extensions it decoded, in the order it met them)."""

    def __init__(self, path: Path, options: GltfReadOptions) -> None:
        self.path = path
        self.file = str(path)
        self.opt = options
        self.folder = path.parent
        self.container = open_container(path, options)
        self.gltf: dict[str, Any] = self.container.gltf
        self.decoded: list[str] = []
        self._doc: Document | None = None
        if compressed(self.gltf):  # plain files keep their views unread until asked for
            self._doc = decode_geometry(self.container)
            self.gltf, self.decoded = self._doc.gltf, self._doc.decoded_extensions

    def err(self, message: str, key: str = "") -> InputError:
        return input_error(self.file, message, key)

    def buffer(self, i: int) -> bytes:
        return self.container.buffer(i)

    def view(self, i: Any) -> tuple[bytes, int]:
        """bufferView ``i``'s bytes and byteStride (0 when tightly packed)."""
        if self._doc is not None:  # decoded, and bounds-checked, by the document model
            return self._doc.view_bytes(i)
        views = self.gltf.get("bufferViews", [])
        if not isinstance(i, int) or isinstance(i, bool) or not 0 <= i < len(views):
            raise self.err(f"bufferView {i!r} does not exist", "/bufferViews")
        v, key = views[i], f"/bufferViews/{i}"
        if not isinstance(v, dict):
            raise self.err("bufferView must be an object", key)
        # bounds-checked by the container, as the document model's views are
        off, n = v.get("byteOffset", 0), v.get("byteLength")
        data = self.container.slice(v.get("buffer"), off, n, key)
        stride = v.get("byteStride", 0)
        return data, stride if isinstance(stride, int) and not isinstance(stride, bool) else 0

    def accessor(self, i: Any, normalize: bool = True) -> np.ndarray:
        """Accessor ``i`` as ``[count, components]`` through :func:`wrinklepipe.gltf.accessors.
        read_accessor` (the one accessor reader; ``normalize``: normalized integers as floats)."""
        return read_accessor(self.gltf, i, self.view, self.err, normalize)
