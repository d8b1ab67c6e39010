"""``wrinklepipe bench``: run named benchmarks; print medians and ratios to a same-run baseline."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from rich.table import Table

from wrinklepipe.atomic import dumps_json, write_output
from wrinklepipe.bench import load_all
from wrinklepipe.console import emit_json, err, out
from wrinklepipe.errors import input_error
from wrinklepipe.names import unknown_names

NAME = "bench"
HELP = "run benchmarks (medians, ratios against a baseline measured in the same run)"
DESCRIPTION = """Run named benchmarks. Each reports the median time of every step and its ratio to a
baseline measured in the same run, so results compare across machines; limits the project holds
itself to are checked (exit 1 when one is exceeded).

examples:
  wrinklepipe bench --list
  wrinklepipe bench model-metahuman
  wrinklepipe bench --quick --json          # every benchmark at small sizes
  wrinklepipe bench --record benchmarks/results.json
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("names", nargs="*", metavar="NAME", help="benchmarks to run (default: all)")
    p.add_argument("--list", action="store_true", help="list the benchmarks and exit")
    p.add_argument("--quick", action="store_true", help="small sizes (a smoke run)")
    p.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    p.add_argument(
        "--record",
        metavar="FILE",
        help="also write the results as JSON to FILE (benchmarks not run are kept from it)",
    )


def _merged(path: str, payload: dict) -> dict:
    """The recorded file with this run's benchmarks replaced (the others kept, by name), when
    it holds a run of the same kind (``quick`` or not); else this run alone."""
    try:
        old = json.loads(Path(path).read_text(encoding="utf-8"))
        kept = [r for r in old["results"] if isinstance(r, dict) and "name" in r]
        same = old.get("quick") == payload["quick"]
    except (OSError, ValueError, KeyError, TypeError):
        return payload
    if not same:
        return payload
    ran = {r["name"] for r in payload["results"]}
    results = [r for r in kept if r["name"] not in ran] + payload["results"]
    return {"quick": payload["quick"], "results": sorted(results, key=lambda r: r["name"])}


def run(args: argparse.Namespace) -> int:
    registry = load_all()
    if args.list:
        for name in sorted(registry):
            out.print(f"{name:24s} {registry[name][0]}")
        return 0
    names = args.names or sorted(registry)
    unknown = [n for n in names if n not in registry]
    if unknown:
        raise input_error("bench", unknown_names("benchmark", unknown, sorted(registry)))
    results = []
    for name in names:
        err.print(f"[bold]running[/] {name} ...")
        results.append(registry[name][1](args.quick))
    payload = {"quick": bool(args.quick), "results": [r.to_json() for r in results]}
    if args.record:
        write_output(args.record, dumps_json(_merged(args.record, payload)).encode("utf-8"))
    failures = [f for r in results for f in r.failures()]
    if args.json:
        emit_json(payload)
    else:
        for r in results:
            table = Table(title=f"{r.name}: {r.description}", title_justify="left")
            for col in ("step", "median", "ratio", "MP/s", "limit"):
                table.add_column(col, justify="left" if col == "step" else "right", overflow="fold")
            for row in r.rows:
                mps = "" if row.mpix_per_s is None else f"{row.mpix_per_s:.1f}"
                table.add_row(
                    row.step + (" (baseline)" if row.step == r.baseline else ""),
                    f"{row.median_s * 1e3:.2f} ms",
                    "" if math.isnan(row.ratio) else f"{row.ratio:.2f}x",
                    mps,
                    r.limit_text(row.step),
                )
            out.print(table)
        for f in failures:
            err.print(f"[bold red]limit exceeded:[/] {f}")
    return 1 if failures else 0
