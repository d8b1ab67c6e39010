"""``wrinklepipe batch``: convert many manifests, with a cache, locally or on a Dask cluster."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

from wrinklepipe.batch import Cache, DaskEngine, LocalEngine, parse_size, plan_batch
from wrinklepipe.batch.cache import DEFAULT_MAX_BYTES
from wrinklepipe.batch.engines import (
    DEFAULT_NO_WORKERS_S,
    DEFAULT_TIMEOUT_S,
    check_scheduler_address,
)
from wrinklepipe.batch.options import MASK_LAYOUTS, AssetOptions
from wrinklepipe.batch.publish import run_and_publish
from wrinklepipe.commands._options import add_fail_on, add_json, add_report, finite_float
from wrinklepipe.console import emit_json, err
from wrinklepipe.demo.source import cache_root
from wrinklepipe.errors import input_error

NAME = "batch"
HELP = "convert many manifests (folders, globs, a batch file): cache, workers, Dask, CI reports"
DESCRIPTION = """\
Convert and validate every manifest of SOURCE... into OUT, one folder per asset: the manifest's
path relative to the batch root, without .toml. The root is --root, else the folder given, the
batch file's root or the working folder: `batch chars/ -o OUT` writes chars/ada/manifest.toml
to OUT/ada/manifest, `batch 'chars/**/manifest.toml' -o OUT` to OUT/chars/ada/manifest. SOURCE is a
manifest, a folder (searched for .toml files declaring schema = "wrinklepipe/manifest@1"), a
glob ('chars/**/manifest.toml') or one batch file (TOML, schema "wrinklepipe/batch@1",
schemas/batch.schema.json) listing manifests with per-asset options.

Each asset runs on its own: one that fails never stops or changes the others. Unchanged assets
are restored from a content-addressed cache (keyed by every input byte, the options and the
tool), the rest run in --jobs local processes or on a Dask cluster (--scheduler); the outputs
are byte-identical either way. Reports for CI: --report (the JSON summary), --junit, --sarif.

Options given here apply to every asset and win over the batch file's.

exit codes: the worst asset's: 0 all written and valid, 1 some failed validation, 2 some could
not run (or the batch could not start: bad sources, output collisions; nothing written).

examples:
  wrinklepipe batch chars/ -o build/chars --junit junit.xml --sarif wrinkles.sarif
  wrinklepipe batch 'chars/**/manifest.toml' -o build --jobs 4 --force
  wrinklepipe batch studio-batch.toml --report summary.json
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    # Conversion options default to None here (the batch file's value, else AssetOptions'):
    # the defaults shown in the help come from AssetOptions, the one place.
    d = AssetOptions()
    p.add_argument(
        "sources", nargs="+", metavar="SOURCE", help="manifests, folders, globs or a batch file"
    )
    p.add_argument(
        "-o", "--output", metavar="OUT", help="output folder (default: the batch file's)"
    )
    p.add_argument(
        "--root", metavar="DIR", help="batch root: outputs are manifest paths relative to it"
    )
    p.add_argument("--force", action="store_true", help="replace existing non-empty output folders")
    run = p.add_argument_group("where it runs")
    where = run.add_mutually_exclusive_group()
    where.add_argument(
        "-j", "--jobs", type=int, metavar="N", help="local worker processes (default: the cores)"
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on the Dask scheduler at ADDRESS (tcp://host:8786)",
    )
    run.add_argument(
        "--timeout",
        type=finite_float,
        metavar="S",
        help="local workers: the watchdog stops an asset after S seconds and fails it "
        f"(default {DEFAULT_TIMEOUT_S:g}; 0: no watchdog)",
    )
    run.add_argument(
        "--no-workers",
        type=finite_float,
        metavar="S",
        help="Dask: fail the assets left when the cluster has had no worker for S seconds "
        f"(default {DEFAULT_NO_WORKERS_S:g})",
    )
    cache = p.add_argument_group("cache")
    cache.add_argument(
        "--no-cache", action="store_true", help="convert everything; do not read or fill the cache"
    )
    cache.add_argument(
        "--cache", metavar="DIR", help="cache folder (default: $WRINKLEPIPE_CACHE/batch)"
    )
    cache.add_argument(
        "--cache-size",
        metavar="SIZE",
        default=f"{DEFAULT_MAX_BYTES >> 30}G",
        help="size cap, least recently used evicted first",
    )
    conv = p.add_argument_group("conversion (every asset; win over the batch file)")
    conv.add_argument("--glb", action="store_const", const=True, help="also write NAME.glb")
    usd = conv.add_mutually_exclusive_group()
    usd.add_argument(
        "--usdc", dest="usd", action="store_const", const="usdc", help="also write NAME.usdc"
    )
    usd.add_argument(
        "--usdz", dest="usd", action="store_const", const="usdz", help="also write NAME.usdz"
    )
    conv.add_argument(
        "--bits",
        type=int,
        choices=(8, 16),
        metavar="BITS",
        help=f"PNG bits of normal maps: 8 or 16 (default: {d.bits})",
    )
    conv.add_argument(
        "--mask-layout",
        choices=MASK_LAYOUTS,
        metavar="LAYOUT",
        help="mask packing: " + ", ".join(MASK_LAYOUTS) + " (default: each manifest's)",
    )
    conv.add_argument(
        "--no-compress", dest="compress", action="store_const", const=False, help="skip DDS/KTX2"
    )
    conv.add_argument(
        "--no-validate", dest="validate", action="store_const", const=False, help="skip validation"
    )
    conv.add_argument(
        "--no-render",
        dest="render",
        action="store_const",
        const=False,
        help="validate without rendering",
    )
    conv.add_argument(
        "--png-level",
        type=int,
        choices=range(10),
        metavar="0-9",
        help=f"zlib level of the PNGs (default: {d.png_level})",
    )
    add_fail_on(conv, default=None)
    rep = p.add_argument_group("reports")
    add_json(rep, "the summary")
    add_report(rep, "the summary", old="--summary")
    rep.add_argument("--junit", metavar="FILE", help="write JUnit XML (one test case per asset)")
    rep.add_argument("--sarif", metavar="FILE", help="write SARIF 2.1.0 (validation issues)")


def _cli_options(args: argparse.Namespace) -> dict[str, Any]:
    names = (
        "glb",
        "usd",
        "bits",
        "mask_layout",
        "compress",
        "validate",
        "render",
        "png_level",
        "fail_on",
    )
    return {n: getattr(args, n) for n in names if getattr(args, n) is not None}


def run(args: argparse.Namespace) -> int:
    if args.jobs is not None and args.jobs < 1:
        raise input_error("--jobs", f"{args.jobs} is not a number of workers (1 or more)")
    if args.timeout is not None and args.scheduler:
        raise input_error("--timeout", "applies to local workers; Dask has its own limits")
    if args.no_workers is not None and not args.scheduler:
        raise input_error("--no-workers", "applies to a Dask cluster (--scheduler)")
    for name, value in (("--timeout", args.timeout), ("--no-workers", args.no_workers)):
        if value is not None and not (math.isfinite(value) and value >= 0):
            raise input_error(name, f"{value:g} is not a number of seconds (0 or more)")
    if args.scheduler:
        check_scheduler_address(args.scheduler)
    plan = plan_batch(
        args.sources, args.output, root=args.root, cli_options=_cli_options(args), force=args.force
    )
    cache = None
    if not args.no_cache:
        folder = Path(args.cache) if args.cache else cache_root() / "batch"
        cache = Cache(folder, parse_size(args.cache_size))
    if args.scheduler:
        wait = DEFAULT_NO_WORKERS_S if args.no_workers is None else args.no_workers
        engine: LocalEngine | DaskEngine = DaskEngine(args.scheduler, no_workers_s=wait)
    else:
        timeout = DEFAULT_TIMEOUT_S if args.timeout is None else args.timeout
        engine = LocalEngine(args.jobs, timeout)
    result, doc = run_and_publish(
        plan,
        engine,
        cache,
        command="batch",
        console=err,
        summary_path=args.report,
        junit_path=args.junit,
        sarif_path=args.sarif,
    )
    if args.json:
        emit_json(doc)
    return result.exit_code
