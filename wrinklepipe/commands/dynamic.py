"""``wrinklepipe dynamic``: per-vertex dynamic wrinkle weights of one deformed pose (Oat)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from wrinklepipe.commands._options import add_output, finite_float
from wrinklepipe.console import emit_json, err, status
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.dynamic import DynamicOptions
from wrinklepipe.outputs.per_vertex import write_per_vertex
from wrinklepipe.pipeline.dynamic import DynamicJobOptions, dynamic_weights

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
  wrinklepipe dynamic RiggedFigure.glb --time 0.5 -o w.json --json
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = DynamicOptions()  # the defaults: one place
    p.add_argument("mesh", metavar="MESH", help="rest mesh file")
    g = p.add_mutually_exclusive_group(required=True)
    g.add_argument("--pose", metavar="POSE", help="deformed mesh file or .npy positions")
    g.add_argument("--morph", metavar="NAME=W", action="append", help="morph weight")
    g.add_argument("--time", type=finite_float, metavar="T", help="time of the file's animation")
    add_output(p, "output file: .npy, .json, .txt or .csv")
    p.add_argument(
        "--weighting",
        choices=("angle", "uniform"),
        default=d.weighting,
        metavar="HOW",
        help="vertex smoothing: angle or uniform",
    )
    p.add_argument(
        "--bias-channel",
        type=int,
        choices=(0, 1, 2, 3),
        default=None,
        metavar="C",
        help="vertex colour channel 0-3 holding the rest-pose bias ([0, 1] -> [-1, 1])",
    )
    p.add_argument(
        "--texture-space",
        type=int,
        default=None,
        metavar="N",
        help="also run Oat's texture-space variant at N x N",
    )
    p.add_argument(
        "--blur",
        type=finite_float,
        default=DynamicJobOptions().blur,
        metavar="PX",
        help="texture-space blur in texels",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")


#: The largest morph weight ``--morph`` takes, either sign: Blender's shape-key slider range.
MAX_MORPH_WEIGHT = 10.0


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
        if abs(w) > MAX_MORPH_WEIGHT:  # (1e30 moved the vertices past float32: NaN weights)
            raise input_error(
                "--morph",
                f"{name}={val}: a weight is at most {MAX_MORPH_WEIGHT:g} either way (Blender's "
                "shape-key range)",
            )
        out[name] = w
    return out


def run(args: argparse.Namespace) -> int:
    options = DynamicJobOptions(
        pose=args.pose,
        morphs=_parse_morphs(args.morph) if args.morph else {},
        time=args.time,
        weighting=args.weighting,
        bias_channel=args.bias_channel,
        texture_space=args.texture_space,
        blur=args.blur,
    )
    with status(f"reading {args.mesh}"):
        w, summary = dynamic_weights(args.mesh, options)
    inputs = [args.mesh] + ([args.pose] if args.pose else [])
    write_per_vertex(Path(args.output), w, summary, inputs)
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
