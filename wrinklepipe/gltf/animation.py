"""glTF animation channels, read once: what the drivers are given and what the other glTF
readers sample.

:func:`read_channels` reads the channels of one animation of any
:class:`wrinklepipe.gltf.primitive.GltfSource` (a file opened by
:class:`wrinklepipe.gltf.read.GltfFile`, or the pass-through
:class:`wrinklepipe.gltf.document.Document`): node, path (``translation``, ``rotation``,
``scale``, ``weights``), key times and values (``[N, C]``; CUBICSPLINE ``[N, 3, C]``: in-tangent,
value, out-tangent), interpolation. ``strict`` (the drivers' morph tracks, the skeleton
reader): every channel must name a node and a sampler, its interpolation must be one of the
spec's, its keys finite and strictly increasing and a ``weights`` channel must give one value
per morph target of the node's mesh per key; otherwise (the USD writer of a source's
animations) a channel that names no node or sampler is passed over.

The ``curves``, ``blendshapes`` and ``dynamic`` drivers read no files: the pipeline puts
:func:`read_morph_tracks` in :attr:`wrinklepipe.drivers.base.DriverContext.read_morph_tracks`,
and :func:`wrinklepipe.drivers.curves.sample_morph_tracks` samples what it returns. The file is
opened by the safe glTF container reader (:mod:`wrinklepipe.gltf.read`: URIs confined to the
file's folder, sizes capped) and accessors decoded by :mod:`wrinklepipe.gltf.accessors`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wrinklepipe.drivers.base import MorphClip, MorphTrack
from wrinklepipe.errors import input_error, plain_reason
from wrinklepipe.gltf.primitive import GltfSource, target_names
from wrinklepipe.gltf.read import GltfFile, GltfReadOptions

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")
#: Values per key of the node paths.
WIDTHS = {"translation": 3, "rotation": 4, "scale": 3}
PATHS = (*WIDTHS, "weights")


@dataclass(frozen=True)
class Channel:
    """One animation channel: ``values`` ``[N, C]`` (CUBICSPLINE ``[N, 3, C]``) at ``times``
    ``[N]`` (float64) for ``path`` of node ``node``."""

    node: int
    path: str
    times: np.ndarray
    values: np.ndarray
    interpolation: str


def read_channels(
    src: GltfSource,
    animation: int = 0,
    paths: tuple[str, ...] = PATHS,
    strict: bool = True,
) -> list[Channel]:
    """The channels of animation ``animation`` whose path is one of ``paths`` (see the module
    doc for ``strict``)."""
    anims = src.gltf.get("animations") or []
    if not 0 <= animation < len(anims):
        raise src.err("no animation in this file", "/animations")
    anim = anims[animation]
    nodes, meshes = src.gltf.get("nodes") or [], src.gltf.get("meshes") or []
    samplers = anim.get("samplers") or []
    out = []
    for ci, ch in enumerate(anim.get("channels") or []):
        tgt = ch.get("target") or {}
        node, path, si = tgt.get("node"), tgt.get("path"), ch.get("sampler")
        if path not in paths or node is None:
            continue
        key = f"/animations/{animation}/channels/{ci}"
        if not (isinstance(node, int) and isinstance(si, int) and 0 <= si < len(samplers)) or (
            strict and not 0 <= node < len(nodes)
        ):
            if strict:
                raise src.err("channel names a missing node or sampler", key)
            continue
        smp = samplers[si]
        interp = str(smp.get("interpolation", "LINEAR"))
        if strict and interp not in INTERPOLATIONS:
            raise src.err(
                f"unknown interpolation {interp!r}", f"/animations/{animation}/samplers/{si}"
            )
        t = np.asarray(src.accessor(smp["input"]), np.float64).reshape(-1)
        v = np.asarray(src.accessor(smp["output"]), np.float64)
        per_key = v.size // max(len(t), 1) // (3 if interp == "CUBICSPLINE" else 1)
        width = WIDTHS.get(path, per_key)
        if path == "weights" and strict:
            mesh = nodes[node].get("mesh")
            if not isinstance(mesh, int) or not 0 <= mesh < len(meshes):
                raise src.err("weights channel targets a node without a mesh", key)
            width = len(target_names(src.gltf, mesh))
        if strict:
            if not (np.isfinite(t).all() and np.isfinite(v).all()):
                bad = smp["input"] if not np.isfinite(t).all() else smp["output"]
                raise src.err("accessor holds non-finite values", f"/accessors/{bad}")
            n = width * (3 if interp == "CUBICSPLINE" else 1)
            if t.size == 0 or v.size != t.size * n:
                what = "weight values" if path == "weights" else "values"
                raise src.err(f"{v.size} {what} for {t.size} keys x {n} per key", key)
            if np.any(np.diff(t) <= 0):
                raise src.err("key times must increase strictly", key)
        shape = (len(t), 3, width) if interp == "CUBICSPLINE" else (len(t), width)
        out.append(Channel(node, path, t, v.reshape(shape), interp))
    return out


def read_morph_tracks(path: str | Path, animation: int = 0) -> list[MorphTrack]:
    """Every channel of animation ``animation`` that drives a mesh's morph-target ``weights``,
    one :class:`MorphTrack` each (targets named by ``mesh.extras.targetNames``, else
    ``target_<i>``, as the mesh readers name them: :func:`wrinklepipe.gltf.primitive.
    target_names`). An :class:`~wrinklepipe.errors.InputError` names the file and JSON
    pointer for anything malformed."""
    try:
        r = GltfFile(Path(path), GltfReadOptions())
        tracks = morph_tracks(r, animation)
        if not tracks:
            raise r.err("the animation drives no morph-target weights", f"/animations/{animation}")
        return tracks
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise input_error(path, f"malformed glTF animation: {plain_reason(exc)}") from None


def read_morph_clips(path: str | Path) -> list[MorphClip]:
    """Every animation of a glTF that drives morph-target ``weights``, as a
    :class:`~wrinklepipe.drivers.base.MorphClip` (named by the animation's ``name``, else
    ``animation <i>``), in the file's order: what a driver chooses its clip from
    (:func:`wrinklepipe.drivers.clips.choose_clip`)."""
    try:
        r = GltfFile(Path(path), GltfReadOptions())
        out = []
        for i, anim in enumerate(r.gltf.get("animations") or []):
            tracks = morph_tracks(r, i)
            if tracks:
                out.append(MorphClip(str(anim.get("name") or f"animation {i}"), i, tuple(tracks)))
        return out
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise input_error(path, f"malformed glTF animation: {plain_reason(exc)}") from None


def morph_tracks(src: GltfSource, animation: int = 0) -> list[MorphTrack]:
    """The ``weights`` channels of animation ``animation`` (possibly none) as morph tracks
    (:func:`read_channels`, strict)."""
    nodes = src.gltf.get("nodes") or []
    return [
        MorphTrack(
            tuple(target_names(src.gltf, int(nodes[c.node]["mesh"]))),
            c.times,
            c.values,
            c.interpolation,
            c.node,
        )
        for c in read_channels(src, animation, ("weights",))
    ]
