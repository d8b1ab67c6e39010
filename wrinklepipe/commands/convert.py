"""``wrinklepipe convert``: run the whole pipeline on a manifest into one output folder."""

from __future__ import annotations

import argparse

from wrinklepipe.commands._options import add_fail_on, add_json
from wrinklepipe.commands._summary import exit_code, is_problem, summary_lines
from wrinklepipe.console import detail, emit_json, info, problem
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.masks.layouts import LAYOUTS

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

exit codes: 0 written and valid, 1 written but validation found issues at or above --fail-on
(default: errors), 2 could not run (nothing written), 130 / 143 interrupted (nothing written).

examples:
  wrinklepipe convert chars/ada/manifest.toml -o build/ada
  wrinklepipe convert chars/ada/manifest.toml -o build/ada --glb --usdz --force
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = ConvertOptions()  # the defaults: one place
    p.add_argument("manifest", metavar="MANIFEST", help="source manifest (manifest.toml)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder")
    p.add_argument("--glb", action="store_true", help="also write a self-contained NAME.glb")
    usd = p.add_mutually_exclusive_group()
    usd.add_argument("--usdc", action="store_true", help="also write binary NAME.usdc")
    usd.add_argument("--usdz", action="store_true", help="also write a packaged NAME.usdz")
    p.add_argument("--force", action="store_true", help="replace a non-empty output folder")
    p.add_argument(
        "--bits",
        type=int,
        choices=(8, 16),
        default=d.bits,
        metavar="BITS",
        help="PNG bits of the normal maps: 8 or 16",
    )
    p.add_argument(
        "--mask-layout",
        choices=LAYOUTS,
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
        default=d.png_level,
        metavar="0-9",
        help="zlib level of the PNGs (9: a few %% smaller, slower)",
    )
    add_fail_on(p)
    add_json(p, "report.json")


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
    code = exit_code(result.report, args.fail_on)
    if args.json:
        emit_json(result.report)
    else:
        for line in summary_lines(result.report, code, args.output, args.fail_on):
            (problem if is_problem(line) else info)(line)
        for note in result.report.get("notes", []):
            detail(f"note: {note}")
    return code
