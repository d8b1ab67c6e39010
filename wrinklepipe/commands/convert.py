"""``wrinklepipe convert``: run the whole pipeline on a manifest into one output folder."""

from __future__ import annotations

import argparse

from wrinklepipe.console import emit_json, err
from wrinklepipe.io.package import DEFAULT_PNG_LEVEL
from wrinklepipe.pipeline.convert import ConvertOptions, convert

NAME = "convert"
HELP = "convert a source manifest into glTF + USD + textures + weight curves + report"
DESCRIPTION = """\
Read a source manifest (TOML: mesh, base and wrinkle normal maps, region masks, expressions,
drivers), run every stage (ingest, resample, tangents, vertex IDs, drivers, encode, pack,
compress) and write one folder:

  NAME.gltf + NAME.bin   glTF 2.0 with the WRINKLEPIPE_wrinkle_maps material extension
  NAME.glb               self-contained GLB (--glb)
  NAME.usda              USD with the WrinkleMapsAPI schema (+ NAME.usdc / NAME.usdz on request)
  textures/*.png         base normal, wrinkle states, packed masks (shared by glTF and USD)
  compressed/*.dds|ktx2  BC copies of base and states: the smallest format within the budget
  curves/*.csv|json      region weights over time, one file pair per driver
  report.json, .html     what was read, done and written (hashes), validation results

The folder is built under a temporary name and renamed into place only when complete; an
existing non-empty OUT is replaced only with --force; OUT may not be, or contain, the input
folder. Two runs on the same inputs give byte-identical folders.

exit codes: 0 written and valid, 1 written but validation found errors, 2 could not run.

examples:
  wrinklepipe convert demo_src/manifest.toml -o out   # demo_src: demo.source.write_demo_source
  wrinklepipe convert head/manifest.toml -o build/head --glb --usdz --force
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("manifest", metavar="MANIFEST", help="source manifest (manifest.toml)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder")
    p.add_argument("--glb", action="store_true", help="also write a self-contained NAME.glb")
    usd = p.add_mutually_exclusive_group()
    usd.add_argument("--usdc", action="store_true", help="also write binary NAME.usdc")
    usd.add_argument("--usdz", action="store_true", help="also write a packaged NAME.usdz")
    p.add_argument("--force", action="store_true", help="replace a non-empty output folder")
    p.add_argument(
        "--bits", type=int, choices=(8, 16), default=8, help="PNG bits of normal maps (8)"
    )
    p.add_argument(
        "--mask-layout",
        choices=("rgba", "array", "lr-split", "jimenez8", "metahuman"),
        default=None,
        help="mask packing (default: the manifest's formats.mask_layout, else rgba)",
    )
    p.add_argument("--no-compress", action="store_true", help="skip DDS/KTX2 textures")
    p.add_argument("--no-validate", action="store_true", help="skip validating the output")
    p.add_argument("--no-render", action="store_true", help="validate without the GPU render pass")
    p.add_argument(
        "--png-level",
        type=int,
        choices=range(10),
        default=DEFAULT_PNG_LEVEL,
        metavar="0-9",
        help=f"zlib level of the PNGs (default {DEFAULT_PNG_LEVEL}; 9: a few %% smaller, slower)",
    )
    p.add_argument("--json", action="store_true", help="print report.json on stdout")


def run(args: argparse.Namespace) -> int:
    options = ConvertOptions(
        glb=args.glb,
        usd_format="usdc" if args.usdc else "usdz" if args.usdz else "usda",
        force=args.force,
        compressed=not args.no_compress,
        validate=not args.no_validate,
        render=not args.no_render,
        bits=args.bits,
        mask_layout=args.mask_layout,
        png_level=args.png_level,
    )
    result = convert(args.manifest, args.output, options)
    if args.json:
        emit_json(result.report)
    else:
        rep = result.report
        a = rep["asset"]
        err.print(
            f"[bold green]wrote[/] {result.output} ({len(rep['outputs']) + 2} files): "
            f"{len(a['states'])} states, {len(a['regions'])} regions, encoding {a['encoding']} "
            f"(scale {a['scale']}), {a['vertices']} vertices"
        )
        status = rep["validation"].get("status", "")
        if status:
            err.print(f"validation: {status}")
    return result.exit_code
