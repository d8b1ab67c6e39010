"""``bones``: wrinkles from reference poses on a skeleton (Dutreve et al.).

A reference pose is a skeleton pose with its own wrinkle map (a state). At frame f, for bone j
with neutral position A, current position B and position C in reference pose k (all in the head
root's space, so the head's rigid motion does not count)::

    alpha_jfk = clamp( AB . AC / |AC|^2, 0, 1 )        (eq. 4: the projection of B on [A, C],
                                                         normalised by the segment's length)
    beta_ifk  = sum_j lambda_ij * theta(alpha_jfk)     (eq. 5) lambda_ij = 1 if w_ij > 0 else 0
    theta(x)  = (cos(pi (1 + x)) + 1) / 2              (eq. 6) slow start, fast finish

The seed's typeset eq. 4 divides by ``|AC|``; the text ("normalized by the size of the segment")
and the clamp to [0, 1] need ``|AC|^2``, which we use. A bone that does not move in pose k
(``|AC| = 0``) has ``alpha = 0``. ``beta`` sums over every bone that skins the vertex and can
exceed 1; by default it is clamped to [0, 1] (``combine = "clamp"``; ``"sum"`` keeps the raw sum).
The values are per vertex, which the rasteriser interpolates: no mask texture is needed.

Spec::

    kind = "bones"
    file = "bones.json"     # {"times": [...], "bones": {name: [[x, y, z], ...]},  (animation)
                            #  "neutral": {name: [x,y,z]}, "reference_poses": {pose: {name: xyz}},
                            #  "skin": {"joints": [names], "weights": [[w per joint] per vertex]}}
    poses = [{name = "neutral", bones = {jaw = [0, 0, 0]}}, {name = "compress", bones = {...}}]

``poses`` (if given) replaces the file's neutral/reference poses; the first pose named
``neutral`` is the neutral one. Skin weights come from the file, else from the mesh.

Or the animation of a skinned glTF/GLB (the joints' world positions over its first animation,
sampled per glTF 2.0; the rest pose is the neutral one unless ``poses`` names one)::

    kind = "bones"
    file = "face_rig.glb"
    root = "head"                              # optional: positions in this joint's space
    joints = ["brow_l", "brow_r", "jaw"]       # optional: default every joint of the skin
    reference_times = {compress = 2.0, stretch = 3.5}   # reference poses = frames of the file
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
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
from wrinklepipe.io.json_safe import loads_json
from wrinklepipe.names import did_you_mean, noun, unknown_names
from wrinklepipe.suffixes import is_gltf


def theta(x: np.ndarray | float) -> np.ndarray:
    """Dutreve et al.'s modulation ``(cos(pi (1 + x)) + 1) / 2``: 0 -> 0, 1 -> 1, monotone."""
    x = np.asarray(x, np.float64)
    return (np.cos(np.pi * (1.0 + x)) + 1.0) / 2.0


def pose_influence(neutral: np.ndarray, reference: np.ndarray, current: np.ndarray) -> np.ndarray:
    """alpha ``[F, P, J]``: neutral ``[J, 3]``, reference ``[P, J, 3]``, frames ``[F, J, 3]``."""
    a = np.asarray(neutral, np.float64)
    ab = np.asarray(current, np.float64) - a[None]  # [F, J, 3]
    ac = np.asarray(reference, np.float64) - a[None]  # [P, J, 3]
    num = np.einsum("fjc,pjc->fpj", ab, ac)
    den = np.broadcast_to(np.einsum("pjc,pjc->pj", ac, ac)[None], num.shape)
    alpha = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    return np.clip(alpha, 0.0, 1.0)


def dense_skin(joints: np.ndarray, weights: np.ndarray, n_joints: int) -> np.ndarray:
    """glTF-style ``JOINTS_0`` / ``WEIGHTS_0`` ``[V, 4]`` -> dense ``[V, J]`` skin weights."""
    j = np.asarray(joints, np.int64)
    w = np.asarray(weights, np.float64)
    out = np.zeros((j.shape[0], n_joints))
    rows = np.repeat(np.arange(j.shape[0]), j.shape[1])
    np.add.at(out, (rows, j.reshape(-1)), w.reshape(-1))
    return out


def vertex_influence(alpha: np.ndarray, skin: np.ndarray, combine: str = "clamp") -> np.ndarray:
    """beta ``[F, V, P]`` from alpha ``[F, P, J]`` and dense skin weights ``[V, J]``."""
    lam = (np.asarray(skin, np.float64) > 0).astype(np.float64)
    t = theta(alpha)  # [F, P, J]
    f, p, j = t.shape
    beta = (lam @ t.reshape(f * p, j).T).reshape(-1, f, p).transpose(1, 0, 2)  # BLAS matmul
    if combine == "clamp":
        return np.clip(beta, 0.0, 1.0)
    if combine == "sum":
        return beta
    raise ValueError(f"unknown combine {combine!r} (clamp, sum)")


def _xyz_table(
    ctx: DriverContext, table: Mapping[str, Any], bones: Sequence[str], key: str
) -> np.ndarray:
    missing = [b for b in bones if b not in table]
    if missing:
        raise spec_problem(ctx, f"no position for {noun(len(missing), 'bone')} {missing}", key)
    try:
        out = np.array([table[b] for b in bones], np.float64)
    except (TypeError, ValueError):
        out = np.zeros((0,))
    if out.shape != (len(bones), 3) or not np.isfinite(out).all():
        raise spec_problem(ctx, "bone positions must be [x, y, z] numbers", key)
    return out


def _gltf_bones_doc(
    ctx: DriverContext, spec: Mapping[str, Any], times: np.ndarray | None
) -> dict[str, Any]:
    """The bones file's content (see the module doc) from a skinned glTF's first animation
    (opened by ``ctx.read_rig``)."""
    path = resolve(ctx, str(spec["file"]))
    if ctx.read_rig is None:
        raise spec_problem(ctx, f"{path.name}: no rig reader in this context", "file")
    rig = ctx.read_rig(path)
    if not rig.joint_names:
        raise spec_problem(ctx, f"{path.name} has no skin (no joints)", "file")
    if times is None:
        keys = rig.key_times()
        frame_times(float(keys[0]), float(keys[-1]), ctx.fps)  # refuses too many, before any
        n = max(int(round((keys[-1] - keys[0]) * ctx.fps)) + 1, 1)
        times = keys[0] + np.arange(n) / ctx.fps
    names = list(rig.joint_names)
    joints = [str(j) for j in spec.get("joints", names)]
    unknown = [j for j in joints if j not in names]
    if unknown:
        raise spec_problem(
            ctx, unknown_names("joint", unknown, names, f" of {path.name}'s skin"), "joints"
        )
    root = spec.get("root")
    if root is not None and str(root) not in names:
        raise spec_problem(
            ctx,
            f"root joint {root!r} is not in {path.name}'s skin{did_you_mean(str(root), names)}",
            "root",
        )
    ref_names = [str(k) for k in dict(spec.get("reference_times", {}))]
    ref_times = [float(t) for t in dict(spec.get("reference_times", {})).values()]
    # one read of the file: rest pose, reference frames, animation frames
    m = rig.joint_matrices([None, *ref_times, *map(float, times)])
    if root is not None:
        m = np.linalg.inv(m[:, names.index(str(root))])[:, None] @ m
    sel = [names.index(j) for j in joints]
    pos = m[:, sel][..., :3, 3]  # [1 + P + F, J, 3]

    def table(p: np.ndarray) -> dict[str, list[float]]:
        return {j: p[i].tolist() for i, j in enumerate(joints)}

    frames = pos[1 + len(ref_times) :]
    out: dict[str, Any] = {
        "times": [float(t) for t in times],
        "bones": {j: frames[:, i].tolist() for i, j in enumerate(joints)},
        "neutral": table(pos[0]),
        "reference_poses": {n: table(pos[1 + i]) for i, n in enumerate(ref_names)},
    }
    if ctx.mesh is None or ctx.mesh.skin_weights is None:
        out["skin"] = {
            "joints": names,
            "weights": dense_skin(rig.joints, rig.skin_weights, len(names)).tolist(),
        }
    return out


@register("bones")
def bones_driver(
    ctx: DriverContext, spec: Mapping[str, Any], times: np.ndarray | None
) -> DriverResult:
    doc: dict[str, Any] = {}
    if "file" in spec and is_gltf(spec["file"]):
        doc = _gltf_bones_doc(ctx, spec, times)
    elif "file" in spec:
        path = resolve(ctx, str(spec["file"]))
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise spec_problem(ctx, f"cannot read bones file {path}: {exc}", "file") from None
        doc = loads_json(data, path, "bones JSON")
        if not isinstance(doc, dict):
            raise spec_problem(ctx, f"bones file {path} must hold a JSON object", "file")
    anim = doc.get("bones")
    if not isinstance(anim, dict) or not anim:
        raise spec_problem(ctx, "bones driver needs an animation: file with 'bones'", "file")
    bones = sorted(anim)
    poses: dict[str, Mapping[str, Any]] = {}
    if "poses" in spec:
        for i, p in enumerate(spec["poses"]):
            if not isinstance(p, Mapping) or "name" not in p or "bones" not in p:
                raise spec_problem(ctx, "a pose needs 'name' and 'bones'", f"poses[{i}]")
            poses[str(p["name"])] = p["bones"]
        neutral_t = poses.pop("neutral", None)
    else:
        neutral_t = doc.get("neutral")
        poses = dict(doc.get("reference_poses", {}))
    if neutral_t is None:
        raise spec_problem(ctx, "no neutral pose (a pose named 'neutral')", "poses")
    if not poses:
        raise spec_problem(ctx, "no reference pose besides the neutral one", "poses")
    neutral = _xyz_table(ctx, neutral_t, bones, "poses.neutral")
    reference = np.stack([_xyz_table(ctx, t, bones, f"poses.{n}") for n, t in poses.items()])
    try:
        frames = np.stack([np.asarray(anim[b], np.float64) for b in bones], axis=1)  # [F, J, 3]
    except ValueError:
        raise spec_problem(
            ctx, "every animated bone needs the same number of frames", "file"
        ) from None
    if frames.ndim != 3 or frames.shape[2] != 3:
        raise spec_problem(ctx, "animated bone positions must be [[x, y, z], ...]", "file")
    anim_times = np.asarray(doc.get("times", np.arange(frames.shape[0]) / ctx.fps), np.float64)
    if anim_times.shape != (frames.shape[0],):
        raise spec_problem(ctx, "'times' must have one entry per frame", "file")
    if times is not None:
        flat = frames.reshape(frames.shape[0], -1)
        cols = [np.interp(times, anim_times, flat[:, c]) for c in range(flat.shape[1])]
        frames = np.stack(cols, axis=1).reshape(len(times), len(bones), 3)
        anim_times = np.asarray(times, np.float64)
    skin_doc = doc.get("skin")
    if isinstance(skin_doc, Mapping):
        names = [str(n) for n in skin_doc.get("joints", [])]
        w = np.asarray(skin_doc.get("weights", []), np.float64)
        if w.ndim != 2 or w.shape[1] != len(names):
            raise spec_problem(ctx, "skin.weights must be [vertices][joints]", "file")
    elif ctx.mesh is not None and ctx.mesh.skin_weights is not None:
        names = list(ctx.mesh.joint_names)
        w = dense_skin(ctx.mesh.joints, ctx.mesh.skin_weights, len(names))
    else:
        raise spec_problem(ctx, "no skin weights (file 'skin' or a skinned mesh)", "file")
    skin = np.zeros((w.shape[0], len(bones)))
    for j, b in enumerate(bones):
        if b in names:
            skin[:, j] = w[:, names.index(b)]
    alpha = pose_influence(neutral, reference, frames)
    combine = str(spec.get("combine", "clamp"))
    if combine not in ("clamp", "sum"):
        raise spec_problem(ctx, f"unknown combine {combine!r} (clamp, sum)", "combine")
    beta = vertex_influence(alpha, skin, combine).astype(np.float32)
    return DriverResult(
        "bones",
        anim_times,
        beta,
        (),
        tuple(poses),
        per_vertex=True,
        notes=[f"{len(bones)} bones, {len(poses)} reference poses, {skin.shape[0]} vertices"],
    )
