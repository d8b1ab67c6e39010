"""``wrinklepipe pack-masks``: read grey region masks, check them, pack them with a table."""

from __future__ import annotations

import argparse

from wrinklepipe.commands._options import add_fail_on, add_force, add_json, add_output, fails
from wrinklepipe.console import emit_json, err, problem, status
from wrinklepipe.jobs.pack_masks import PackMasksOptions, pack_mask_files
from wrinklepipe.masks import LAYOUTS
from wrinklepipe.names import plural

NAME = "pack-masks"
HELP = "pack region masks into RGBA textures, a texture array or the left/right split layout"
DESCRIPTION = """\
Read grey region masks (PNG, TIFF, EXR, ...; one region per file, named after the file stem
unless --names is given), check them (one size, values in [0, 1], grey RGB), report coverage,
overlaps (sum above 1) and empty regions, optionally resample, and pack them:

  rgba       4 regions per RGBA texture
  array      one texture-array layer per region (Reis et al.), written as a PNG strip
  lr-split   left/right pairs (x_l / x_r) share a channel; a split channel (1 = left) separates them
  jimenez8   Jimenez et al.'s 8 zones in 2 RGBA textures
  metahuman  MetaHuman's 37 head_wm<k>_<region> masks in 10 RGBA textures, plus an array

Writes OUT/masks_<t>.png (or masks_array.png) and OUT/channels.json (the channel table).
--invert reads masks painted as Reis et al. do (white = no wrinkle, black = full).
The findings (a region that covers nothing, masks summing above 1, texels no region covers) are
warnings: the outputs are written; --fail-on warning makes the exit code 1 when there is one.

examples:
  wrinklepipe pack-masks masks/*.png --layout jimenez8 -o packed/
  wrinklepipe pack-masks masks/forehead_outer_l.png masks/forehead_outer_r.png masks/chin.png \\
      --layout lr-split -o out --size 32
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = PackMasksOptions()  # the defaults: one place
    p.add_argument("masks", nargs="+", metavar="MASK", help="grey mask images, one per region")
    p.add_argument(
        "--layout",
        choices=LAYOUTS,
        default=d.layout,
        metavar="LAYOUT",
        help="packing layout: " + ", ".join(LAYOUTS),
    )
    add_output(p, "output folder")
    p.add_argument("--size", type=int, default=d.size, metavar="N", help="resample to N x N")
    p.add_argument(
        "--invert", action="store_true", help="inputs are painted white = none, black = full"
    )
    p.add_argument(
        "--names",
        default=None,
        metavar="NAMES",
        help="region names, comma-separated (default: the file names' stems)",
    )
    p.add_argument(
        "--bits",
        type=int,
        choices=(8, 16),
        default=d.bits,
        metavar="BITS",
        help="bits per channel: 8 or 16 (default: the inputs')",
    )
    p.add_argument(
        "--lr-conflict",
        choices=("error", "dominant"),
        default=d.lr_conflict,
        metavar="HOW",
        help="lr-split: a texel covered by both sides is an error, or goes to the larger "
        "(dominant)",
    )
    add_force(p)
    add_json(p, "the report and channel table")
    add_fail_on(p)


def run(args: argparse.Namespace) -> int:
    opts = PackMasksOptions(
        layout=args.layout,
        size=args.size,
        invert=args.invert,
        names=tuple(n.strip() for n in args.names.split(",")) if args.names else None,
        bits=args.bits,
        lr_conflict=args.lr_conflict,
        force=args.force,
    )
    with status(f"packing {plural(len(args.masks), 'mask')}"):
        res = pack_mask_files(args.masks, args.output, opts)
    warnings = [*res.report.warnings, *res.packed.notes]
    code = 1 if fails({"warning": len(warnings)}, args.fail_on) else 0
    if args.json:
        emit_json(res.to_json())
        return code
    n_tex = res.packed.textures.shape[0]
    kind = "layer" if res.packed.layout == "array" else "texture"
    w, h = res.size
    err.print(
        f"packed {plural(len(res.names), 'region')} into {plural(n_tex, kind)} ({res.layout}, "
        f"{w} x {h}, "
        f"{res.bits}-bit) -> {args.output}"
    )
    for warning in warnings:
        problem(f"[yellow]warning:[/] {warning}", markup=True)
    return code
