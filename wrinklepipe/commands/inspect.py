"""``wrinklepipe inspect``: what a glTF or USD file holds (like ``gltf-transform inspect``), or
what differs between two."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from rich.table import Table

from wrinklepipe.console import emit_json, out
from wrinklepipe.errors import input_error, plain_reason
from wrinklepipe.gltf.document import read_document
from wrinklepipe.gltf.inspect import diff, summary
from wrinklepipe.suffixes import USD_SUFFIXES
from wrinklepipe.usd.inspect import usd_summary

NAME = "inspect"
HELP = "list a glTF's or USD stage's meshes, materials, skins, animations; or diff two"
DESCRIPTION = """\
Read a .gltf/.glb whole (meshopt and Draco geometry decoded) and list its scenes, nodes,
meshes (primitives, vertices, morph targets, attributes with component types), materials
(texture slots, alpha mode, extensions), textures (size, format, bytes), skins (joints,
hierarchy depth), animations (channels, duration, keyframes) and extensions.

A USD file (.usd/.usda/.usdc/.usdz) is opened composed (sublayers, references, payloads,
variants) and listed by prim: type, applied schemas, authored attributes (type, count,
interpolation, time samples), relationships; meshes (points, faces, material, skeleton),
materials (surface shader), skeletons (joints).

With --diff A B, list what differs between two files of one kind, one line each: '-' only in
A, '+' only in B, '~' changed. Exit 0 when they hold the same, 1 when something differs.

examples:
  wrinklepipe inspect RobotExpressive.glb
  wrinklepipe inspect build/ada/ada.glb --json
  wrinklepipe inspect --diff head.glb build/ada/ada.glb     # exit 1: what convert added
  wrinklepipe inspect --diff assets/hero.usd build/hero/hero.usda --allow-root assets
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "files", metavar="FILE", nargs="+", help=".gltf/.glb or a USD file (two with --diff)"
    )
    p.add_argument(
        "--diff",
        action="store_true",
        help="list what differs between two files A and B (exit 1 when they differ)",
    )
    p.add_argument("--json", action="store_true", help="print what it finds as JSON on stdout")


def _table(title: str, rows: list[dict[str, Any]], columns: list[str]) -> Table:
    t = Table(title=title, title_justify="left", show_lines=False)
    for c in ["#", *columns]:
        t.add_column(c, overflow="fold")  # a narrow terminal wraps a cell, never cuts it
    for i, r in enumerate(rows):
        t.add_row(str(i), *(_cell(r.get(c)) for c in columns))
    return t


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, dict):
        return ", ".join(f"{k}:{x}" for k, x in v.items())
    if isinstance(v, list):
        return ", ".join(str(x) for x in v)
    return str(v)


def print_summary(s: dict[str, Any]) -> None:
    """The summary as rich tables on stdout."""
    out.print(f"[bold]{s['file']}[/bold]  generator {s['generator']!r}")
    out.print(f"extensionsUsed: {', '.join(s['extensionsUsed']) or 'none'}")
    out.print(f"extensionsRequired: {', '.join(s['extensionsRequired']) or 'none'}")
    if s["decoded"]:
        out.print(f"decoded on read: {', '.join(s['decoded'])}")
    out.print(f"{s['nodes']} nodes, {s['cameras']} cameras, {s['vertices']} vertices")
    out.print(_table("SCENES", s["scenes"], ["name", "roots"]))
    rows = []
    for m in s["meshes"]:
        for j, p in enumerate(m["primitives"]):
            rows.append(
                {
                    "mesh": m["name"] if j == 0 else "",
                    "prim": j,
                    "material": p["material"],
                    "mode": p["mode"],
                    "vertices": p["vertices"],
                    "indices": p["indices"],
                    "attributes": p["attributes"],
                    "morphs": len(m["morphs"]) if j == 0 else "",
                }
            )
    cols = ["mesh", "prim", "material", "mode", "vertices", "indices", "attributes", "morphs"]
    out.print(_table("MESHES", rows, cols))
    out.print(
        _table(
            "MATERIALS",
            s["materials"],
            ["name", "instances", "textures", "alphaMode", "doubleSided", "extensions"],
        )
    )
    out.print(_table("TEXTURES", s["textures"], ["name", "format", "size", "bytes", "image"]))
    out.print(_table("SKINS", s["skins"], ["name", "joints", "depth", "skeleton"]))
    out.print(
        _table(
            "ANIMATIONS",
            s["animations"],
            ["name", "channels", "samplers", "duration", "keyframes", "paths"],
        )
    )


def print_usd_summary(s: dict[str, Any]) -> None:
    """A USD summary as rich tables on stdout."""
    out.print(f"[bold]{s['file']}[/bold]  defaultPrim {s['defaultPrim']!r}")
    out.print(f"sublayers: {', '.join(s['layers']) or 'none'} ({s['used_layers']} layers used)")
    start, end, tcps = s["timeCodes"]
    out.print(
        f"upAxis {s['upAxis']}, metersPerUnit {s['metersPerUnit']:g}, time codes "
        f"{start:g}..{end:g} at {tcps:g}/s; "
        + ", ".join(f"{n} {k}" for k, n in s["counts"].items())
    )
    prims = s["prims"]
    for path, r in prims.items():
        for name, vs in r.get("variantSets", {}).items():
            out.print(
                f"variant set {name!r} on {path}: {len(vs['variants'])} variants "
                f"({', '.join(vs['variants'][:6])}{', ...' if len(vs['variants']) > 6 else ''}), "
                f"selected {vs['selected']!r}"
            )

    def rows(kind: str, cols: list[str]) -> list[dict[str, Any]]:
        return [
            {"path": p, **{c: r.get(c) for c in cols}}
            for p, r in prims.items()
            if r["type"] == kind
        ]

    meshes = rows("Mesh", ["points", "faces", "material", "skeleton"])
    for m in meshes:
        attrs = prims[m["path"]].get("attributes", {})
        m["primvars"] = [a.removeprefix("primvars:") for a in attrs if a.startswith("primvars:")]
    out.print(
        _table("MESHES", meshes, ["path", "points", "faces", "material", "skeleton", "primvars"])
    )
    out.print(
        _table(
            "MATERIALS",
            rows("Material", ["surface", "apiSchemas"]),
            ["path", "surface", "apiSchemas"],
        )
    )
    out.print(_table("SKELETONS", rows("Skeleton", ["joints"]), ["path", "joints"]))
    anims = rows("SkelAnimation", ["attributes"])
    for a in anims:
        a["animated"] = [k for k, v in (a.pop("attributes") or {}).items() if "time samples" in v]
    out.print(_table("ANIMATIONS", anims, ["path", "animated"]))


def _summary(file: str, read: Any, summarize: Any) -> dict[str, Any]:
    """One file's summary; a structure the reader's checks did not foresee (an index into a
    missing array, a wrong type) is one message naming the file, not a traceback."""

    try:
        return summarize(read(file))
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        raise input_error(file, f"malformed glTF: {plain_reason(exc)}") from None


def run(args: argparse.Namespace) -> int:
    if args.diff and len(args.files) != 2:
        raise input_error("<arguments>", f"--diff needs two files, got {len(args.files)}")
    if not args.diff and len(args.files) != 1:
        raise input_error("<arguments>", "give one file (or two with --diff)")
    usd = [Path(f).suffix.lower() in USD_SUFFIXES for f in args.files]
    if len(set(usd)) > 1:
        raise input_error(
            "<arguments>", "--diff compares two glTF files or two USD files, not one of each"
        )
    if usd[0]:
        summaries = [usd_summary(f) for f in args.files]
    else:
        summaries = [_summary(f, read_document, summary) for f in args.files]
    if not args.diff:
        if args.json:
            emit_json(summaries[0])
        elif usd[0]:
            print_usd_summary(summaries[0])
        else:
            print_summary(summaries[0])
        return 0
    lines = diff(summaries[0], summaries[1])
    if args.json:
        emit_json({"a": args.files[0], "b": args.files[1], "differences": lines})
    else:
        for line in lines:
            out.print(line, markup=False, highlight=False)
        if not lines:
            out.print("no differences")
    return 1 if lines else 0
