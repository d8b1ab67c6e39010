"""``wrinklepipe export``: a converted asset as a complete engine folder (a thin layer)."""

from __future__ import annotations

import argparse

from wrinklepipe.commands._options import add_force, add_json, add_output
from wrinklepipe.console import emit_json, err
from wrinklepipe.export.presets import ENGINE_PRESETS
from wrinklepipe.jobs.export import export
from wrinklepipe.names import plural

NAME = "export"
HELP = "export a converted asset for Unreal, Unity, Godot or Blender"
DESCRIPTION = """\
Read what `convert` wrote (the output folder, a .gltf/.glb or a .usda/.usdc/.usdz) and write one
folder an engine imports: the mesh (glTF), the textures in the engine's format and green
convention, the wrinkle shader generated from wrinklepipe's template (the whole model), the code
that drives the region weights, the weight curves named the engine's way, wrinkle_setup.json
and a README with the import steps:

  unreal   glTF for Interchange; DirectX (-Y) BC5 .dds with mip chains (PNG with a note when
           BC5 is over the budget); two material Custom nodes (WP_Decode, WP_Wrinkle); one
           scalar parameter per region, curves as a CurveTable CSV
  unity    glTF; +Y texture-array strips; Shader Graph Custom Function WrinkleMaps.hlsl;
           WrinkleWeights.cs plays the curves
  godot    glTF; +Y texture-array strips; wrinkle.gdshader; wrinkle_weights.gd
  blender  glTF; +Y PNGs; build_wrinkles.py builds the node group, drivers and keys

An asset a target cannot express is refused with one message (exit 2, nothing written). The
folder is written atomically and byte-identical on a rerun; --force replaces a non-empty OUT.

examples:
  wrinklepipe export build/ada --engine unreal -o build/ada_unreal
  wrinklepipe export build/ada/ada.usdz --engine godot -o build/godot --force
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", metavar="SOURCE", help="convert output folder, .gltf/.glb or USD")
    p.add_argument(
        "--engine",
        required=True,
        choices=sorted(ENGINE_PRESETS),
        metavar="ENGINE",
        help="the target engine: " + ", ".join(sorted(ENGINE_PRESETS)),
    )
    add_output(p, "output folder")
    add_force(p)
    add_json(p, "the written files")


def run(args: argparse.Namespace) -> int:
    files, notes = export(args.source, args.output, args.engine, force=args.force)
    if args.json:
        emit_json({"engine": args.engine, "files": sorted(files), "notes": notes})
    else:
        err.print(
            f"[bold green]wrote[/] {args.output} ({plural(len(files), 'file')}) for {args.engine}"
        )
        for n in notes:
            err.print(f"  {n}")
    return 0
