"""The ``dynamic`` job: per-vertex dynamic wrinkle weights of one deformed pose (Oat).

:func:`dynamic_weights` reads the rest mesh, poses it (a mesh file or ``.npy`` positions, morph
weights, or the file's own animation at a time), runs :class:`wrinklepipe.geometry.dynamic.
DynamicWeights` and, on request, Oat's texture-space variant; it returns the weights and the
summary the command prints and writes beside them (:mod:`wrinklepipe.outputs.per_vertex`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.dynamic import (
    DynamicOptions,
    DynamicWeights,
    morph_pose,
    sample_bilinear,
    seam_jump,
    skinned_pose,
    texture_space_weights,
)
from wrinklepipe.geometry.vertex_ids import compute_vertex_ids
from wrinklepipe.gltf.meshes import gltf_joint_world_matrices_at, gltf_morph_weights
from wrinklepipe.masks.targets import MAX_BLUR_TEXELS
from wrinklepipe.readers.meshes import LoadOptions, load_mesh, load_meshes, merge_meshes
from wrinklepipe.readers.registry import format_of
from wrinklepipe.usd.meshes import open_stage
from wrinklepipe.usd.poses import usd_blend_shape_weights, usd_joint_world_matrices


@dataclass(frozen=True)
class DynamicJobOptions:
    """The deformed pose: ``pose`` (a mesh file with the same vertices or a ``.npy`` [V, 3]),
    ``morphs`` ({name: weight}) or ``time`` (the file's own animation); exactly one is given.
    ``weighting`` as :class:`DynamicOptions`; ``bias_channel``: vertex colour channel (0-3,
    [0, 1] -> [-1, 1]) as the rest-pose bias; ``texture_space``: also run the N x N
    texture-space variant with a ``blur`` px Gaussian."""

    pose: str | None = None
    morphs: dict[str, float] = field(default_factory=dict)
    time: float | None = None
    weighting: str = DynamicOptions().weighting
    bias_channel: int | None = None
    texture_space: int | None = None
    blur: float = 4.0


def rest_and_deformed(
    source: str | Path, mesh: Mesh, parts: list[Mesh], opt: DynamicJobOptions
) -> tuple[np.ndarray, np.ndarray]:
    """The rest and the deformed positions ``[V, 3]`` (float64), in one space, of the pose
    ``opt`` chooses (``parts``: the unmerged meshes of ``mesh``, in merge order; USD poses
    each prim).

    The rest is the mesh as read, except for a skinned glTF or USD prim posed by ``time``. A
    USD prim's rest is its points skinned with the skeleton's ``restTransforms`` (the bind
    points are the rest only when rest equals bind). A glTF's deformed
    shape is skinned into world space, so its rest is the skinned rest pose (the nodes'
    default transforms, no animation), not the bind-space positions, which may be in another
    space altogether (KHR_mesh_quantization: gltfpack stores integer positions and puts the
    dequantization into the inverse bind matrices). A mesh without a skin is baked into
    world space at read (positions and morph deltas alike), so its rest and pose agree."""
    rest = mesh.positions.astype(np.float64)
    if opt.morphs:
        return rest, morph_pose(mesh, opt.morphs, source=str(source))
    if opt.pose:
        pose = Path(opt.pose)
        if pose.suffix.lower() == ".npy":
            try:
                arr = np.load(pose, allow_pickle=False)
            except (OSError, ValueError) as exc:
                raise input_error(pose, f"cannot read positions: {exc}") from None
        else:
            arr = load_mesh(pose, LoadOptions(generate_uvs=False)).positions
        arr = np.asarray(arr, dtype=np.float64)
        if arr.shape != mesh.positions.shape:
            raise input_error(
                pose, f"pose has shape {list(arr.shape)}, the mesh {list(mesh.positions.shape)}"
            )
        return rest, arr
    fmt = format_of(source)
    kind = fmt.name if fmt is not None else None
    if kind == "usd":
        stage = open_stage(Path(source))  # once: every part is posed on it
        posed = [_usd_part_pose(source, stage, part, opt.time) for part in parts]
        return np.concatenate([r for r, _ in posed]), np.concatenate([q for _, q in posed])
    if kind == "gltf":
        p = rest
        if mesh.morph_names:
            w = gltf_morph_weights(source, mesh, opt.time)
            p = morph_pose(mesh, w, source=str(source))
        if mesh.joints is not None:
            at_rest, at_time = gltf_joint_world_matrices_at(source, mesh, [None, opt.time])
            rest = skinned_pose(mesh, at_rest, source=str(source))
            bind = mesh.positions
            mesh.positions = p.astype(np.float32)
            try:
                p = skinned_pose(mesh, at_time, source=str(source))
            finally:
                mesh.positions = bind
        elif not mesh.morph_names:
            raise input_error(source, "--time needs a skinned or morph-animated glTF mesh")
        return rest, p
    raise input_error(source, "--time needs a glTF or USD file with an animation")


def _usd_part_pose(
    source: str | Path, stage: Any, part: Mesh, time: float | None
) -> tuple[np.ndarray, np.ndarray]:
    """One prim's rest and posed positions: a skinned prim's rest is its points skinned with
    the skeleton's ``restTransforms`` (no animation, no blend shapes), in the posed shape's
    space (the skeleton's world), not the bind-space points: they agree only when the rest
    transforms equal the bind transforms."""
    rest = p = part.positions.astype(np.float64)
    if part.morph_names:
        w = usd_blend_shape_weights(source, part, time, stage)
        w = {k: v for k, v in w.items() if k in part.morph_names}
        p = morph_pose(part, w, source=str(source))
    if part.joints is not None:
        at_rest = usd_joint_world_matrices(source, part, time, at_rest=True, stage=stage)
        rest = skinned_pose(part, at_rest, source=str(source))
        jm = usd_joint_world_matrices(source, part, time, stage=stage)
        bind = part.positions
        part.positions = p.astype(np.float32)
        try:
            p = skinned_pose(part, jm, source=str(source))
        finally:
            part.positions = bind
    return rest, p


def dynamic_weights(
    source: str | Path, opt: DynamicJobOptions
) -> tuple[np.ndarray, dict[str, Any]]:
    """Per-vertex weights ``[V]`` (float32) of the rest mesh ``source`` in the pose ``opt``
    chooses, and the summary (counts, range, seam jump, the texture-space variant's)."""
    if opt.texture_space is not None and not 8 <= opt.texture_space <= 8192:
        raise input_error("<arguments>", "--texture-space must be in 8..8192")
    top = None if opt.texture_space is None else min(MAX_BLUR_TEXELS, opt.texture_space)
    if top is not None and not 0 <= opt.blur <= top:
        raise input_error(  # (a wider one: an internal error, or minutes of filtering)
            "--blur", f"{opt.blur:g} is out of range; expected 0..{top:g} texels"
        )
    parts = load_meshes(source, LoadOptions(generate_uvs=opt.texture_space is not None))
    mesh = parts[0] if len(parts) == 1 else merge_meshes(parts)
    rest, deformed = rest_and_deformed(source, mesh, parts, opt)
    bias = None
    if opt.bias_channel is not None:
        if mesh.colors is None:
            raise input_error(source, "--bias-channel: the mesh has no vertex colours")
        bias = 2.0 * mesh.colors[:, opt.bias_channel] - 1.0
    ids = compute_vertex_ids(mesh.positions, source=str(source))
    op = DynamicWeights.build(
        rest,
        mesh.indices,
        vertex_ids=ids,
        bias=bias,
        options=DynamicOptions(weighting=opt.weighting),
        source=str(source),
    )
    w = op.frame(deformed)
    summary: dict[str, Any] = {
        "mesh": str(source),
        "vertices": int(len(w)),
        "triangles": int(mesh.triangle_count),
        "skipped_triangles": op.skipped_triangles,
        "min": float(w.min()),
        "max": float(w.max()),
        "mean": float(w.mean()),
        "compressed_vertices": int((w > 1e-6).sum()),
        "stretched_vertices": int((w < -1e-6).sum()),
        "seam_jump_max": float(seam_jump(w, ids).max(initial=0.0)),
        "notes": [*mesh.notes, *op.notes],
    }
    if opt.texture_space is not None:
        img, _ = texture_space_weights(
            mesh.uvs, mesh.indices, op.triangle_frame(deformed), opt.texture_space, opt.blur
        )
        jump = seam_jump(sample_bilinear(img, mesh.uvs), ids)
        summary["texture_space"] = {
            "size": opt.texture_space,
            "blur_px": opt.blur,
            "seam_jump_max": float(jump.max(initial=0.0)),
            "seam_jump_mean": float(jump.mean()) if len(jump) else 0.0,
        }
    return w.astype(np.float32), summary
