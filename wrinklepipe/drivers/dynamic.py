"""``dynamic``: weights from the mesh's own stretch (Oat), implemented by the geometry module.

This driver is only the plug: the maths lives in :mod:`wrinklepipe.geometry.dynamic`. The mesh
is posed per frame from blend-shape weights (``keys``, ``morphs`` or a glTF morph animation in
``file``) with ``morph_pose``, and ``DynamicWeights.build(rest, indices, vertex_ids).
frame(deformed)`` gives one signed weight per vertex (negative = stretched, positive =
compressed), i.e. ``[F, V, 1]`` under state ``signed``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from wrinklepipe.drivers.base import (
    DriverContext,
    DriverResult,
    frame_times,
    register,
    resolve,
    spec_problem,
)
from wrinklepipe.drivers.curves import keys_range, load_keys, morph_animation, sample_keys
from wrinklepipe.geometry.dynamic import DynamicWeights, morph_pose
from wrinklepipe.names import unknown_names
from wrinklepipe.suffixes import is_gltf


def _morph_frames(
    ctx: DriverContext, spec: Mapping[str, Any], times: np.ndarray | None
) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    fps = float(spec.get("fps", ctx.fps))
    file = spec.get("file")
    if file is not None and is_gltf(file):
        return morph_animation(ctx, resolve(ctx, str(file)), times, fps, spec.get("clip"))
    if "morphs" in spec and "keys" not in spec:
        names = tuple(str(k) for k in spec["morphs"])
        t = np.zeros(1) if times is None else times
        return t, names, np.array([[float(spec["morphs"][n]) for n in names]] * len(t))
    keys, interp, _ = load_keys(ctx, spec)
    if not keys:
        raise spec_problem(ctx, "dynamic driver needs blend-shape keys, morphs or a file", "keys")
    names = tuple(keys)
    t = frame_times(*keys_range(keys), fps) if times is None else times
    return t, names, sample_keys(keys, names, t, interp)


@register("dynamic")
def dynamic_driver(
    ctx: DriverContext, spec: Mapping[str, Any], times: np.ndarray | None
) -> DriverResult:
    mesh = ctx.mesh
    if mesh is None or mesh.morph_deltas is None:
        raise spec_problem(ctx, "the 'dynamic' driver needs a mesh with morph targets", "kind")
    t, names, x = _morph_frames(ctx, spec, times)
    unknown = [n for n in names if n not in mesh.morph_names]
    if unknown:
        raise spec_problem(ctx, unknown_names("blend shape", unknown, mesh.morph_names), "keys")
    op = DynamicWeights.build(mesh.positions, mesh.indices, vertex_ids=mesh.vertex_ids)
    frames = [
        np.asarray(op.frame(morph_pose(mesh, dict(zip(names, map(float, row))))), np.float32)
        for row in x
    ]
    w = np.stack(frames)[..., None]
    return DriverResult("dynamic", np.asarray(t), w, (), ("signed",), per_vertex=True)
