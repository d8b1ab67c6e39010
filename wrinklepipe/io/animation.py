"""A glTF's morph-weight animation as the drivers are given it.

The ``curves``, ``blendshapes`` and ``dynamic`` drivers read no files: the pipeline puts
:func:`read_morph_tracks` in :attr:`wrinklepipe.drivers.base.DriverContext.read_morph_tracks`,
and :func:`wrinklepipe.drivers.curves.sample_morph_tracks` samples what it returns. The file is
opened by the safe glTF container reader (:mod:`wrinklepipe.io.gltf_read`: URIs confined to the
file's folder, sizes capped) and accessors decoded by :mod:`wrinklepipe.io.accessors`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wrinklepipe.drivers.base import MorphTrack
from wrinklepipe.errors import input_error, plain_reason
from wrinklepipe.io.gltf_primitive import target_names
from wrinklepipe.io.gltf_read import GltfFile, GltfReadOptions

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")


def read_morph_tracks(path: str | Path, animation: int = 0) -> list[MorphTrack]:
    """Every channel of animation ``animation`` that drives a mesh's morph-target ``weights``,
    one :class:`MorphTrack` each (targets named by ``mesh.extras.targetNames``, else
    ``target_<i>``, as the mesh readers name them: :func:`wrinklepipe.io.gltf_primitive.
    target_names`). An :class:`~wrinklepipe.errors.InputError` names the file and JSON
    pointer for anything malformed."""
    try:
        return _read(Path(path), animation)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise input_error(path, f"malformed glTF animation: {plain_reason(exc)}") from None


def _read(path: Path, animation: int) -> list[MorphTrack]:
    r = GltfFile(path, GltfReadOptions())
    tracks = morph_tracks(r, animation)
    if not tracks:
        raise r.err("the animation drives no morph-target weights", f"/animations/{animation}")
    return tracks


def morph_tracks(r: GltfFile, animation: int = 0) -> list[MorphTrack]:
    """The ``weights`` channels of animation ``animation`` of an opened file (possibly none),
    each checked (finite, keys strictly increasing, one value per target per key)."""
    doc = r.gltf
    anims = doc.get("animations") or []
    if not 0 <= animation < len(anims):
        raise r.err("no animation in this file", "/animations")
    anim = anims[animation]
    nodes, meshes = doc.get("nodes") or [], doc.get("meshes") or []
    samplers = anim.get("samplers") or []
    tracks = []
    for ci, ch in enumerate(anim.get("channels") or []):
        target = ch.get("target") or {}
        node_i = target.get("node")
        if target.get("path") != "weights" or node_i is None:
            continue
        key = f"/animations/{animation}/channels/{ci}"
        si = ch.get("sampler")
        if not 0 <= node_i < len(nodes) or not isinstance(si, int) or not 0 <= si < len(samplers):
            raise r.err("channel names a missing node or sampler", key)
        mesh_i = nodes[node_i].get("mesh")
        if not isinstance(mesh_i, int) or not 0 <= mesh_i < len(meshes):
            raise r.err("weights channel targets a node without a mesh", key)
        names = tuple(target_names(doc, mesh_i))  # the names the mesh readers give them
        s = samplers[si]
        interp = s.get("interpolation") or "LINEAR"
        if interp not in INTERPOLATIONS:
            raise r.err(
                f"unknown interpolation {interp!r}", f"/animations/{animation}/samplers/{si}"
            )
        kt = _finite(r, s["input"]).reshape(-1)
        kv = _finite(r, s["output"]).reshape(-1)
        per_key = len(names) * (3 if interp == "CUBICSPLINE" else 1)
        if kt.size == 0 or kv.size != kt.size * per_key:
            raise r.err(f"{kv.size} weight values for {kt.size} keys x {per_key} per key", key)
        if np.any(np.diff(kt) <= 0):
            raise r.err("key times must increase strictly", key)
        shape = (kt.size, 3, len(names)) if interp == "CUBICSPLINE" else (kt.size, len(names))
        tracks.append(MorphTrack(names, kt, kv.reshape(shape), interp, node_i))
    return tracks


def _finite(r: GltfFile, index: object) -> np.ndarray:
    """An accessor as float64 (normalized integers scaled per the spec), all values finite."""
    a = np.asarray(r.accessor(index), np.float64)  # type: ignore[arg-type]
    if not np.isfinite(a).all():
        raise r.err("accessor holds non-finite values", f"/accessors/{index}")
    return a
