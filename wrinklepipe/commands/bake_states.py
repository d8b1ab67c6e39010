"""``wrinklepipe bake-states``: wrinkle maps baked from sculpts of each pose, in one frame."""

from __future__ import annotations

import argparse

from wrinklepipe.commands._options import add_force, add_json, add_output, finite_float
from wrinklepipe.console import emit_json, err, status
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.bake import BakeOptions
from wrinklepipe.jobs.bake_states import BakeStatesOptions, bake_states_job

NAME = "bake-states"
HELP = "bake the base and wrinkle normal maps from sculpts (neutral + one per pose) onto a mesh"
DESCRIPTION = """\
Bake tangent-space normal maps from high-resolution meshes (sculpts or scans of the neutral
face and of each wrinkled pose: OBJ, glTF, USD; no UVs needed) into the UV layout of LOW's
wrinkled material, in the frame convert ships (LOW's own tangents, MikkTSpace where it has
none): rays from a cage --max-distance above the low surface inwards, the sculpt's smooth
normal at the first hit, --supersample^2 samples a texel averaged, edge padding beyond the UV
islands. The neutral bake is the base, so base and states share one frame and one sampling.

  OUT/base_normal.png      the neutral sculpt (16-bit PNG, OpenGL +Y)
  OUT/wrinkle_NAME.png     each --state NAME=SCULPT (16-bit)
  OUT/mask_NAME.png        with --masks: a proposed mask where the state differs from the base
  OUT/bake.json            sizes, ray distance, misses

OUT is what `wrinklepipe regions --maps OUT` and a manifest's base/states read.

examples:
  wrinklepipe bake-states head.glb --material Skin --neutral neutral.obj \\
      --state compress=frown.obj --state stretch=surprise.obj --size 2048 -o maps/
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = BakeOptions()
    p.add_argument("low", metavar="LOW", help="the character's mesh (.glb .gltf .usd* .obj)")
    p.add_argument("--neutral", required=True, metavar="SCULPT", help="the neutral sculpt")
    p.add_argument(
        "--state",
        action="append",
        required=True,
        metavar="NAME=SCULPT",
        help="a wrinkled pose's sculpt (repeatable)",
    )
    add_output(p, "output folder")
    p.add_argument(
        "--material", default=None, metavar="NAME", help="the wrinkled material (glTF / USD)"
    )
    p.add_argument(
        "--meshes", default=None, metavar="NAMES", help="comma-separated meshes to wrinkle only"
    )
    p.add_argument("--size", type=int, default=d.size, metavar="N", help="map size")
    p.add_argument(
        "--supersample",
        type=int,
        choices=(1, 2, 3, 4),
        default=d.supersample,
        metavar="N",
        help="samples per texel per axis: 1 to 4",
    )
    p.add_argument(
        "--max-distance",
        type=finite_float,
        default=None,
        metavar="D",
        help="ray distance either side of the low surface, mesh units (default: measured)",
    )
    p.add_argument(
        "--padding",
        type=int,
        default=None,
        metavar="PX",
        help="edge padding in texels (default: size / 128)",
    )
    p.add_argument("--masks", action="store_true", help="also propose a mask per state")
    add_force(p)
    add_json(p, "bake.json's summary")


def _parse_states(items: list[str]) -> list[tuple[str, str]]:
    out = []
    for item in items:
        name, sep, path = item.partition("=")
        if not sep or not name or not path:
            raise input_error(
                "<arguments>", f"--state expects NAME=SCULPT, got {item!r}", "--state"
            )
        out.append((name, path))
    return out


def run(args: argparse.Namespace) -> int:
    if args.size < 4 or args.size > 16384:
        raise input_error("<arguments>", f"--size must be 4..16384, got {args.size}", "--size")
    if args.padding is not None and args.padding < 0:
        raise input_error("<arguments>", "--padding must be >= 0", "--padding")
    options = BakeStatesOptions(
        material=args.material,
        meshes=tuple(n.strip() for n in args.meshes.split(",") if n.strip()) if args.meshes else (),
        bake=BakeOptions(
            size=args.size,
            supersample=args.supersample,
            max_distance=args.max_distance,
            padding=args.padding,
        ),
        masks=args.masks,
        force=args.force,
    )

    def say(line: str) -> None:
        if not args.json:
            err.print(line, markup=False, soft_wrap=True)

    with status(f"baking onto {args.low}"):
        res = bake_states_job(
            args.low, args.neutral, _parse_states(args.state), args.output, options, say
        )
    if args.json:
        emit_json(
            {
                "output": str(res.output),
                "states": res.states,
                "samples": res.bake.samples,
                "max_distance": res.bake.max_distance,
                "missed_samples": res.bake.missed_samples,
                "notes": res.notes,
            }
        )
        return 0
    for n in res.notes:
        err.print(f"note: {n}", markup=False, soft_wrap=True)
    return 0
