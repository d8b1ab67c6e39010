"""``wrinklepipe vertex-ids``: spatial-hash vertex IDs of a mesh (Oat)."""

from __future__ import annotations

import argparse
from pathlib import Path

from wrinklepipe.commands._options import add_output, finite_float
from wrinklepipe.console import emit_json, err, status
from wrinklepipe.geometry.vertex_ids import VertexIdOptions
from wrinklepipe.outputs.per_vertex import write_per_vertex
from wrinklepipe.pipeline.vertex_ids import mesh_vertex_ids

NAME = "vertex-ids"
HELP = "spatial-hash vertex IDs: render vertices at the same position share an ID"
DESCRIPTION = """\
Read a mesh (.glb .gltf .usd .usda .usdc .usdz .obj; all parts merged), give every render
vertex the ID of its position (Oat's spatial hash), numbered 0..n-1 by first appearance, so
vertices split by UV seams or hard normals share an ID. Two positions closer than the tolerance
(per axis) always share an ID, also across hash-cell borders; -0.0 equals 0.0.

The tolerance is --tolerance (absolute, mesh units) or --relative times the bounding-box
diagonal (default 1e-6). Without -o only the summary is printed.

OUT by extension: .npy (int64 [V]), .json ({"ids": [...], ...summary}), .txt (one per line).

examples:
  wrinklepipe vertex-ids head.glb
  wrinklepipe vertex-ids head.glb -o ids.npy --relative 1e-5 --json
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = VertexIdOptions()  # the defaults: one place
    p.add_argument("mesh", metavar="MESH", help="mesh file")
    add_output(p, "output file: .npy, .json or .txt (default: the summary only)", required=False)
    p.add_argument(
        "--tolerance", type=finite_float, default=None, metavar="T", help="absolute tolerance"
    )
    p.add_argument(
        "--relative",
        type=finite_float,
        default=d.relative_tolerance,
        metavar="R",
        help="tolerance relative to the bounding-box diagonal",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON on stdout")


def run(args: argparse.Namespace) -> int:
    opts = VertexIdOptions(relative_tolerance=args.relative, tolerance=args.tolerance)
    with status(f"reading {args.mesh}"):
        ids, summary = mesh_vertex_ids(args.mesh, opts)
    if args.output:
        write_per_vertex(Path(args.output), ids, summary, [args.mesh])
        summary["output"] = str(args.output)
    if args.json:
        emit_json(summary)
    else:
        err.print(
            f"{summary['vertices']} vertices -> {summary['ids']} IDs; {summary['shared_ids']} IDs"
            f" shared by {summary['vertices_sharing']} split vertices (tolerance "
            f"{summary['tolerance']:.3g})" + (f" -> {args.output}" if args.output else "")
        )
    return 0
