"""``wrinklepipe demo``: generate the demo character, convert it and validate it."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from wrinklepipe.atomic import staged_folder
from wrinklepipe.console import emit_json, err, status
from wrinklepipe.demo.source import demo_source_dir
from wrinklepipe.jobs.convert import ConvertOptions, convert

NAME = "demo"
HELP = "convert and validate the built-in demo character; print where the outputs are"
DESCRIPTION = """\
Generate the built-in demo character (a seeded head with 8 morph targets, a pore-detailed base
normal map, stretch and compress wrinkle maps, the 8 Jimenez zones and their Table 1.1) as the
source files an artist would hand over (cached in $WRINKLEPIPE_CACHE or ~/.cache/wrinklepipe),
run `convert` on its manifest (which validates the result, GPU render pass included), and print
where the outputs and the report are.

The output folder (default ./demo-out) is replaced when it holds a previous demo; any other
non-empty folder needs --force.

--write-source DIR writes the demo's source files (manifest.toml, head.glb, the maps, masks/)
into DIR instead, and stops: a template to start your own character from.

examples:
  wrinklepipe demo
  wrinklepipe demo -o /tmp/demo --size 512 --glb
  wrinklepipe demo --size 256 --write-source robot
"""

DEFAULT_OUTPUT = "demo-out"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", default=DEFAULT_OUTPUT, help="output folder (./demo-out)")
    p.add_argument(
        "--size",
        type=int,
        default=1024,
        choices=(64, 128, 256, 512, 1024, 2048),
        help="demo map size (1024; wrinkle maps are a quarter, masks a sixteenth)",
    )
    p.add_argument("--glb", action="store_true", help="also write a self-contained GLB")
    p.add_argument("--force", action="store_true", help="replace a non-empty output folder")
    p.add_argument("--json", action="store_true", help="print the conversion report as JSON")
    p.add_argument(
        "--write-source",
        metavar="DIR",
        help="write the demo's source files (manifest, mesh, maps, masks) into DIR and stop",
    )


def _previous_demo(folder: Path) -> bool:
    """True when ``folder`` holds the output of an earlier ``wrinklepipe demo``."""
    report = folder / "report.json"
    try:
        data = json.loads(report.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and data.get("name") == "demo_head"


def _write_source(manifest: Path, folder: str, force: bool) -> int:
    """Copy the cached demo source into ``folder`` (staged: complete or absent)."""
    with staged_folder(folder, force=force) as tmp:
        shutil.copytree(manifest.parent, tmp, dirs_exist_ok=True)
    err.print(f"[bold]demo source[/]  {folder}  (edit {Path(folder) / 'manifest.toml'})")
    return 0


def run(args: argparse.Namespace) -> int:
    out = Path(args.output)
    with status(f"generating the demo character ({args.size}²)"):
        manifest = demo_source_dir(args.size)
    if args.write_source:
        return _write_source(manifest, args.write_source, args.force)
    err.print(f"[bold]demo source[/]  {manifest.parent}")
    force = args.force or _previous_demo(out)
    with status("converting and validating"):
        result = convert(manifest, out, ConvertOptions(glb=args.glb, force=force))
    rep = result.report
    if args.json:
        emit_json(rep)
        return result.exit_code
    validation = rep.get("validation", {})
    counts = validation.get("counts", {})
    err.print(f"[bold]outputs[/]      {result.output.resolve()}")
    for entry in sorted(result.output.iterdir()):
        err.print(f"  {entry.name}{'/' if entry.is_dir() else ''}")
    err.print(f"[bold]report[/]       {(result.output / 'report.html').resolve()}")
    page = result.output / "validation.html"
    if page.is_file():
        err.print(f"[bold]renders[/]      {page.resolve()}")
    if validation.get("status") == "skipped":
        err.print(f"[bold]validation[/]   skipped: {validation.get('reason', '')}")
        return result.exit_code
    verdict = "[bold green]valid[/]" if result.exit_code == 0 else "[bold red]errors found[/]"
    err.print(
        f"[bold]validation[/]   {verdict}: "
        + ", ".join(f"{counts.get(k, 0)} {k}s" for k in ("error", "warning", "info"))
    )
    return result.exit_code
