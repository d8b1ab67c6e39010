"""``wrinklepipe regions``: masks and driver rows from a mesh's morph targets (blend shapes)."""

from __future__ import annotations

import argparse

from wrinklepipe.commands._options import add_force, add_json, add_output, finite_float
from wrinklepipe.console import emit_json, err, status
from wrinklepipe.jobs.regions import SNIPPET_FILE, RegionsJobOptions, regions_job
from wrinklepipe.masks.layouts import LAYOUTS
from wrinklepipe.masks.targets import TargetRegionsOptions

NAME = "regions"
HELP = "regions, masks and blend-shape driver rows from a mesh's morph targets (Oat's area change)"
DESCRIPTION = """\
For every morph target of MESH (glTF/GLB targets, USD blend shapes), the skin's area change at
full weight (Oat: (A_rest - A_target) / A_rest per triangle, positive where it compresses),
smoothed per vertex across UV seams (spatial-hash vertex IDs), rendered into the wrinkled
material's UV layout (supersampled, a Gaussian blur over covered texels, edge padding). Writes:

  OUT/masks_<t>.png           the masks, four regions per RGBA texture
  OUT/channels.json           their channel table
  OUT/regions.json            targets, regions, rows, fit, symmetry plane
  OUT/manifest_snippet.toml   a manifest convert accepts as is (with --maps)

Regions: by default one mask per target and state (Open 3D Engine's convention, split by
state): <target>_compress drives the compress wrinkle map where the target compresses the skin,
<target>_stretch the stretch map where it stretches it. --regions N clusters the targets' areas
into at most N regions, split into _l / _r by the mesh's symmetry plane where they do not cross
it, with driver rows fitted to rebuild each target's own area change.

--maps DIR names a bake-states output (base_normal.png, wrinkle_compress.png,
wrinkle_stretch.png): the snippet then converts as is. Files outside OUT need --allow-root when
converting; the command prints the convert command line.

examples:
  wrinklepipe regions head.glb --material Skin --maps maps/ -o regions/
  wrinklepipe regions head.glb --material Skin --regions 8 --layout lr-split -o regions8/
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = RegionsJobOptions()
    m = TargetRegionsOptions()
    p.add_argument("mesh", metavar="MESH", help="mesh with morph targets (.glb .gltf .usd* .obj)")
    add_output(p, "output folder")
    p.add_argument(
        "--material", default=None, metavar="NAME", help="the wrinkled material (glTF / USD)"
    )
    p.add_argument(
        "--meshes", default=None, metavar="NAMES", help="comma-separated meshes to wrinkle only"
    )
    p.add_argument(
        "--regions", type=int, default=None, metavar="N", help="cluster into at most N regions"
    )
    p.add_argument("--size", type=int, default=m.size, metavar="N", help="mask size")
    p.add_argument(
        "--supersample",
        type=int,
        choices=(1, 2, 3, 4),
        default=m.supersample,
        metavar="N",
        help="samples per texel per axis: 1 to 4",
    )
    p.add_argument(
        "--blur", type=finite_float, default=m.blur, metavar="PX", help="Gaussian sigma in texels"
    )
    p.add_argument(
        "--padding", type=int, default=m.padding, metavar="PX", help="edge padding in texels"
    )
    p.add_argument(
        "--threshold",
        type=finite_float,
        default=m.threshold,
        metavar="F",
        help="fraction of a target's reference change below which masks are 0",
    )
    p.add_argument(
        "--layout",
        choices=LAYOUTS,
        default=d.layout,
        metavar="LAYOUT",
        help="mask layout convert ships: " + ", ".join(LAYOUTS),
    )
    p.add_argument(
        "--bits",
        type=int,
        choices=(8, 16),
        default=d.bits,
        metavar="BITS",
        help="mask PNG bits: 8 or 16",
    )
    p.add_argument("--maps", default=None, metavar="DIR", help="a bake-states output folder")
    add_force(p)
    add_json(p, "regions.json's summary")


def run(args: argparse.Namespace) -> int:
    masks = TargetRegionsOptions(
        size=args.size,
        supersample=args.supersample,
        blur=args.blur,
        padding=args.padding,
        threshold=args.threshold,
        regions=args.regions,
    )
    options = RegionsJobOptions(
        material=args.material,
        meshes=tuple(n.strip() for n in args.meshes.split(",") if n.strip()) if args.meshes else (),
        masks=masks,
        layout=args.layout,
        bits=args.bits,
        maps=args.maps,
        force=args.force,
    )
    say = (
        (lambda _line: None)
        if args.json
        else (lambda line: err.print(line, markup=False, soft_wrap=True))
    )
    with status(f"regions from {args.mesh}"):
        res = regions_job(args.mesh, args.output, options, say)
    if args.json:
        r = res.regions
        emit_json(
            {
                "output": str(res.output),
                "regions": [
                    {"name": x.name, "side": x.side, "states": list(x.states)} for x in r.regions
                ],
                "rows": [list(x) for x in r.rows],
                "targets": list(r.targets),
                "skipped_targets": list(r.skipped),
                "notes": res.notes,
            }
        )
        return 0
    for n in res.notes:
        err.print(f"note: {n}", markup=False, soft_wrap=True)
    roots = "".join(f" --allow-root {root}" for root in res.allow_roots)
    err.print(
        f"convert it: wrinklepipe convert {res.output / SNIPPET_FILE} -o BUILD{roots}",
        markup=False,
        soft_wrap=True,
    )
    return 0
