"""``wrinklepipe export``: engine presets over a converted asset (a thin layer over the writers)."""

from __future__ import annotations

import argparse

NAME = "export"
HELP = "export a converted asset for Unreal, Unity, Godot or Blender"
DESCRIPTION = """\
Read what `convert` wrote (the output folder, a .gltf/.glb or a .usda/.usdc/.usdz) and write the
wrinkle maps the way an engine wants them:

  unreal   DirectX normal maps (green flipped: stored G -> 255 - G) as BC5 .dds (a note says
           when BC5 exceeds the error budget), masks as PNG, HLSL combine function
  unity    OpenGL (+Y) PNGs + the glTF (for glTFast / UnityGLTF), HLSL combine function
  godot    OpenGL (+Y) PNGs + the glTF, GLSL combine function
  blender  OpenGL (+Y) PNGs + the glTF

Every preset writes ENGINE/wrinkle_setup.json (files, convention, encoding, scale, policy,
channel table, regions, expressions) and the weight curves as CSV/JSON. Masks are never
converted. The folder is written atomically; --force replaces a non-empty OUT.

examples:
  wrinklepipe export build/demo --engine unreal -o build/demo_unreal
  wrinklepipe export build/demo/demo_head.usdz --engine godot -o build/godot --force
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    from wrinklepipe.export.presets import ENGINE_PRESETS

    p.add_argument("source", metavar="SOURCE", help="convert output folder, .gltf/.glb or USD")
    p.add_argument("--engine", required=True, choices=sorted(ENGINE_PRESETS), help="target")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder")
    p.add_argument("--force", action="store_true", help="replace a non-empty output folder")
    p.add_argument("--json", action="store_true", help="print the written files as JSON")


def run(args: argparse.Namespace) -> int:
    from wrinklepipe.console import emit_json, err
    from wrinklepipe.export.job import export

    files, notes = export(args.source, args.output, args.engine, force=args.force)
    if args.json:
        emit_json({"engine": args.engine, "files": sorted(files), "notes": notes})
    else:
        err.print(f"[bold green]wrote[/] {args.output} ({len(files)} files) for {args.engine}")
        for n in notes:
            err.print(f"  {n}")
    return 0
