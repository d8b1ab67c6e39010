"""``wrinklepipe dynamic``: per-vertex dynamic wrinkle weights of one deformed pose (Oat)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wrinklepipe.console import emit_json, err, status
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
from wrinklepipe.io.mesh import LoadOptions, load_mesh, load_meshes, merge_meshes
from wrinklepipe.io.mesh_gltf import gltf_joint_world_matrices, gltf_morph_weights
from wrinklepipe.io.mesh_usd import usd_blend_shape_weights, usd_joint_world_matrices
from wrinklepipe.io.readers import format_of
from wrinklepipe.outputs.per_vertex import write_per_vertex

NAME = "dynamic"
HELP = "dynamic wrinkle weights from the mesh's own stretch (Oat): rest vs a deformed pose"
DESCRIPTION = """\
Per triangle w = clamp((A_rest - A_deformed) / A_rest, -1, 1), positive where the skin
compresses, negative where it stretches; smoothed per vertex by the angle-weighted average over
the incident triangles of all render vertices with the same vertex ID, so UV seams do not show.

The deformed pose is one of:
  --pose POSE        a mesh file with the same vertices (.glb .usd .obj ...) or a .npy [V, 3]
  --morph NAME=W     morph-target / blend-shape weights (repeatable; USD inbetweens honoured)
  --time T           the file's own animation at T: glTF first animation / UsdSkel joints and
                     blend-shape weights (skinned meshes are posed by linear blend skinning)

--bias-channel C uses vertex colour channel C (0-3, mapped [0,1] -> [-1,1]) as the rest-pose
bias. --texture-space N also runs Oat's texture-space variant (N x N, blur --blur px) and
reports its jump across UV seams next to the vertex smoothing's (which is 0).

OUT by extension: .npy (float32 [V]), .json ({"values": [...], ...summary}), .txt/.csv.

examples:
  wrinklepipe dynamic head.glb --morph brow_raise=1 -o w.npy
  wrinklepipe dynamic figure.glb --time 0.5 -o w.json --json
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = DynamicOptions()  # the defaults: one place
    p.add_argument("mesh", metavar="MESH", help="rest mesh file")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--pose", metavar="POSE", help="deformed mesh file or .npy positions")
    g.add_argument("--morph", metavar="NAME=W", action="append", help="morph weight")
    g.add_argument("--time", type=float, metavar="T", help="time of the file's animation")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help=".npy, .json, .txt, .csv")
    p.add_argument(
        "--weighting", choices=("angle", "uniform"), default=d.weighting, help="vertex smoothing"
    )
    p.add_argument("--bias-channel", type=int, choices=(0, 1, 2, 3), default=None)
    p.add_argument("--texture-space", type=int, default=None, metavar="N", help="also N x N")
    p.add_argument("--blur", type=float, default=4.0, metavar="PX", help="texture-space blur")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")


def _parse_morphs(items: list[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items:
        name, sep, val = item.rpartition("=")
        try:
            w = float(val)
        except ValueError:
            w = float("nan")
        if not sep or not name or not np.isfinite(w):
            raise input_error("<arguments>", f"--morph expects NAME=WEIGHT, got {item!r}")
        out[name] = w
    return out


def deformed_pose(args: argparse.Namespace, mesh: object, parts: list) -> np.ndarray:
    """The deformed positions chosen by --pose / --morph / --time (``parts``: the unmerged
    meshes of ``mesh``, in merge order; USD poses each prim)."""

    if args.morph:
        return morph_pose(mesh, _parse_morphs(args.morph), source=str(args.mesh))
    if args.pose:
        pose = Path(args.pose)
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
        return arr
    fmt = format_of(args.mesh)
    kind = fmt.name if fmt is not None else None
    if kind == "usd":
        return np.concatenate([_usd_part_pose(args, part) for part in parts])
    if kind == "gltf":
        p = mesh.positions.astype(np.float64)
        if mesh.morph_names:
            w = gltf_morph_weights(args.mesh, mesh, args.time)
            p = morph_pose(mesh, w, source=str(args.mesh))
        if mesh.joints is not None:
            rest = mesh.positions
            mesh.positions = p.astype(np.float32)
            try:
                jm = gltf_joint_world_matrices(args.mesh, mesh, args.time)
                p = skinned_pose(mesh, jm, source=str(args.mesh))
            finally:
                mesh.positions = rest
        elif not mesh.morph_names:
            raise input_error(args.mesh, "--time needs a skinned or morph-animated glTF mesh")
        return p
    raise input_error(args.mesh, "--time needs a glTF or USD file with an animation")


def _usd_part_pose(args: argparse.Namespace, part: object) -> np.ndarray:
    p = part.positions.astype(np.float64)
    if part.morph_names:
        w = usd_blend_shape_weights(args.mesh, part, args.time)
        w = {k: v for k, v in w.items() if k in part.morph_names}
        p = morph_pose(part, w, source=str(args.mesh))
    if part.joints is not None:
        jm = usd_joint_world_matrices(args.mesh, part, args.time)
        rest = part.positions
        part.positions = p.astype(np.float32)
        try:
            p = skinned_pose(part, jm, source=str(args.mesh))
        finally:
            part.positions = rest
    return p


def run(args: argparse.Namespace) -> int:
    with status(f"reading {args.mesh}"):
        parts = load_meshes(args.mesh, LoadOptions(generate_uvs=args.texture_space is not None))
    mesh = parts[0] if len(parts) == 1 else merge_meshes(parts)
    deformed = deformed_pose(args, mesh, parts)
    bias = None
    if args.bias_channel is not None:
        if mesh.colors is None:
            raise input_error(args.mesh, "--bias-channel: the mesh has no vertex colours")
        bias = 2.0 * mesh.colors[:, args.bias_channel] - 1.0
    ids = compute_vertex_ids(mesh.positions, source=str(args.mesh))
    op = DynamicWeights.build(
        mesh.positions,
        mesh.indices,
        vertex_ids=ids,
        bias=bias,
        options=DynamicOptions(weighting=args.weighting),
        source=str(args.mesh),
    )
    w = op.frame(deformed)
    summary: dict = {
        "mesh": str(args.mesh),
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
    if args.texture_space is not None:
        if args.texture_space < 8 or args.texture_space > 8192:
            raise input_error("<arguments>", "--texture-space must be in 8..8192")
        img, _ = texture_space_weights(
            mesh.uvs, mesh.indices, op.triangle_frame(deformed), args.texture_space, args.blur
        )
        jump = seam_jump(sample_bilinear(img, mesh.uvs), ids)
        summary["texture_space"] = {
            "size": args.texture_space,
            "blur_px": args.blur,
            "seam_jump_max": float(jump.max(initial=0.0)),
            "seam_jump_mean": float(jump.mean()) if len(jump) else 0.0,
        }
    inputs = [args.mesh] + ([args.pose] if args.pose else [])
    write_per_vertex(Path(args.output), w.astype(np.float32), summary, inputs)
    summary["output"] = str(args.output)
    if args.json:
        emit_json(summary)
    else:
        err.print(
            f"{summary['vertices']} vertices: weights {summary['min']:+.3f}..{summary['max']:+.3f}"
            f" ({summary['compressed_vertices']} compressed, {summary['stretched_vertices']}"
            f" stretched) -> {args.output}"
        )
        if "texture_space" in summary:
            ts = summary["texture_space"]
            err.print(
                f"texture-space variant: seam jump max {ts['seam_jump_max']:.4f}"
                f" (vertex smoothing: {summary['seam_jump_max']:.4f})"
            )
        for n in summary["notes"]:
            err.print(f"note: {n}")
    return 0
