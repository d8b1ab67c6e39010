"""``wrinklepipe bake``: evaluate a weight driver over an animation; optionally pre-blend maps."""

from __future__ import annotations

import argparse
from pathlib import Path

from wrinklepipe.commands._options import add_force, add_json, add_output, finite_float
from wrinklepipe.console import emit_json, err
from wrinklepipe.drivers import KINDS
from wrinklepipe.jobs.bake import BakeOptions, bake_manifest

NAME = "bake"
HELP = "evaluate a weight driver over time: weight curves (JSON, CSV) and pre-blended maps"
DESCRIPTION = """\
Evaluate one of the manifest's [[drivers]] (the first, or the first of --driver KIND) over its
animation and write, into the output folder OUT:

  weights.json   {kind, policy, regions, states, times, weights[frame][region][state], ...}
  weights.csv    time, then one column per region:state
  maps/          with --maps: the pre-blended normal map of each keyframe (16-bit PNG, +Y),
                 rendered only when the weights change (the 2009 blog's "render only when the
                 expression changes"); frames whose weights did not change are skipped and
                 weights.json says which file each frame uses

Weights are linear (what the shader receives); the manifest's policy acts per texel when maps are
blended. Per-vertex drivers (bones, dynamic) write weights[frame][vertex][state] and no maps.

examples:
  wrinklepipe bake chars/ada/manifest.toml -o baked/
  wrinklepipe bake chars/ada/manifest.toml --driver expressions --maps -o baked-maps/ --fps 30
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = BakeOptions()  # the defaults: one place
    p.add_argument("manifest", metavar="MANIFEST", help="source manifest (manifest.toml)")
    p.add_argument(
        "--driver",
        choices=KINDS,
        default=d.driver,
        metavar="KIND",
        help="the driver to evaluate: " + ", ".join(KINDS) + " (default: the manifest's first)",
    )
    add_output(p, "output folder")
    p.add_argument("--maps", action="store_true", help="also write a blended normal map per frame")
    p.add_argument(
        "--fps",
        type=finite_float,
        default=d.fps,
        metavar="FPS",
        help="frames per second (default: the driver's)",
    )
    p.add_argument(
        "--start", type=finite_float, default=d.start, metavar="S", help="first time (s)"
    )
    p.add_argument("--end", type=finite_float, default=d.end, metavar="S", help="last time (s)")
    p.add_argument(
        "--tolerance",
        type=finite_float,
        default=d.tolerance,
        metavar="W",
        help="weights within W of the last rendered frame count as unchanged",
    )
    p.add_argument(
        "--size",
        type=int,
        default=d.size,
        metavar="N",
        help="side of the blended maps (default: the base map's)",
    )
    add_force(p)
    add_json(p, "a summary")


def run(args: argparse.Namespace) -> int:
    opts = BakeOptions(
        driver=args.driver,
        maps=args.maps,
        fps=args.fps,
        start=args.start,
        end=args.end,
        tolerance=args.tolerance,
        size=args.size,
    )
    summary = bake_manifest(Path(args.manifest), Path(args.output), opts, force=args.force)
    if args.json:
        emit_json(summary)
    else:
        err.print(
            f"baked {summary['frames']} frames of the {summary['kind']} driver "
            f"({summary['regions']} {'vertices' if summary['per_vertex'] else 'regions'} x "
            f"{summary['states']} states) -> {args.output}"
        )
        if args.maps:
            err.print(
                f"rendered {summary['maps_rendered']} maps; skipped {summary['maps_skipped']} "
                "frames whose weights did not change"
            )
        for note in summary["notes"]:
            err.print(f"note: {note}")
    return 0
