"""``wrinklepipe demo``: generate the demo character, convert it and validate it."""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

from rich.markup import escape

from wrinklepipe.atomic import staged_folder
from wrinklepipe.commands._options import add_fail_on, add_force, add_json, add_output
from wrinklepipe.commands._summary import color_table, exit_code, is_problem, summary_lines
from wrinklepipe.console import emit_json, info, issue_counts, problem, status
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
  wrinklepipe demo -o demo-512 --size 512 --glb
  wrinklepipe demo --size 256 --write-source robot
"""

DEFAULT_OUTPUT = "demo-out"


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_output(p, "output folder", required=False, default=DEFAULT_OUTPUT)
    p.add_argument(
        "--size",
        type=int,
        default=1024,
        choices=(64, 128, 256, 512, 1024, 2048),
        metavar="N",
        help="side of the demo's maps: 64, 128, 256, 512, 1024 or 2048 (the wrinkle maps "
        "and masks are made smaller)",
    )
    p.add_argument("--glb", action="store_true", help="also write a self-contained GLB")
    add_force(p)
    add_fail_on(p)
    add_json(p, "the conversion report")
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
    edit = escape(str(Path(folder) / "manifest.toml"))
    info(f"[bold]demo source[/]  {escape(folder)}  (edit {edit})", markup=True)
    return 0


def run(args: argparse.Namespace) -> int:
    out = Path(args.output)
    with status(f"generating the demo character ({args.size}²)"):
        manifest = demo_source_dir(args.size)
    if args.write_source:
        return _write_source(manifest, args.write_source, args.force)
    info(f"[bold]demo source[/]  {escape(str(manifest.parent))}", markup=True)
    force = args.force or _previous_demo(out)
    result = convert(manifest, out, ConvertOptions(glb=args.glb, force=force))
    rep = result.report
    code = exit_code(rep, args.fail_on)
    if args.json:
        emit_json(rep)
        return code
    validation = rep.get("validation", {})
    shown = escape(args.output)  # as typed
    info(f"[bold]outputs[/]      {shown}", markup=True)
    for entry in sorted(result.output.iterdir()):
        info(f"  {entry.name}{'/' if entry.is_dir() else ''}")
    info(f"[bold]report[/]       {escape(str(Path(args.output) / 'report.html'))}", markup=True)
    if (result.output / "validation.html").is_file():
        page = escape(str(Path(args.output) / "validation.html"))
        info(f"[bold]renders[/]      {page}", markup=True)
    copies = rep.get("compression", {}).get("color")
    for line in color_table(rep.get("color"), copies):  # the colour states, their fidelity
        info(escape(line))
    if validation.get("status") == "skipped":
        info(f"[bold]validation[/]   skipped: {escape(validation.get('reason', ''))}", markup=True)
        return code
    for line in summary_lines(rep, code, args.output, args.fail_on):
        if is_problem(line):
            problem(line)
    verdict = "[bold green]valid[/]" if code == 0 else "[bold red]failed[/]"
    (problem if code else info)(
        f"[bold]validation[/]   {verdict}: {issue_counts(validation.get('counts', {}))}"
        + (f" (failing on {args.fail_on})" if args.fail_on != "error" else ""),
        markup=True,
    )
    return code
