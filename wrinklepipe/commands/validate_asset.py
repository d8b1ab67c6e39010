"""``wrinklepipe validate-asset PATH``: coded rules, the GPU render pass, JSON/HTML reports."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from wrinklepipe.batch import AssetOptions, LocalEngine
from wrinklepipe.batch.folders import output_folders, plan_validation, single_result
from wrinklepipe.batch.publish import publish, run_and_publish
from wrinklepipe.batch.run import BatchRun
from wrinklepipe.commands._options import add_fail_on, add_json, add_report
from wrinklepipe.console import emit_json, err, status
from wrinklepipe.errors import InputError, input_error
from wrinklepipe.sources.validation import LoadOptions, load_input
from wrinklepipe.validate import validate
from wrinklepipe.validate.config import Config, load_config
from wrinklepipe.validate.context import RENDER_SIZE_MAX, RENDER_SIZE_MIN
from wrinklepipe.validate.report import print_summary, report_json, write_reports

NAME = "validate-asset"
HELP = "check a converted folder, glTF/GLB/USD or manifest: rules, GPU render pass, reports"
DESCRIPTION = """\
Validate a wrinkle asset: a folder written by `convert`, a .gltf/.glb with the
WRINKLEPIPE_wrinkle_maps extension, a .usda/.usdc/.usdz with the WrinkleMapsAPI schema, a
source manifest (.toml), a validation bundle (.wpv) or `demo[:ENCODING][@SIZE][+bc]`; or a
folder of outputs (a `batch` OUT, a build tree): every asset folder beneath it is validated on
its own (--jobs at a time), with a JSON summary (--report), JUnit (--junit) and SARIF (--sarif).

Runs every rule of docs/ISSUES.md, then renders neutral and every expression with the GLSL
shaders on a headless EGL context (llvmpipe without a GPU) and compares the normal buffer with
the numpy model at the same pixels.

exit codes: 0 clean, 1 issues at or above --fail-on (default: error), 2 could not run (over a
folder of outputs: the worst asset's).
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", metavar="PATH", help="folder, .gltf/.glb, .usd*, manifest, .wpv, demo")
    add_json(p, "the report (a folder of outputs: the summary)")
    add_report(p, "the report (a folder of outputs: the summary)")
    p.add_argument("--junit", metavar="FILE", help="write JUnit XML (one test case per asset)")
    p.add_argument("--sarif", metavar="FILE", help="write SARIF 2.1.0 (the validation issues)")
    p.add_argument(
        "-j",
        "--jobs",
        type=int,
        metavar="N",
        help="a folder of outputs: worker processes (default: the cores)",
    )
    p.add_argument(
        "--html", metavar="FILE", help="write an HTML report (images in FILE's <stem>_files/)"
    )
    add_fail_on(p)
    p.add_argument("--config", metavar="FILE", help="TOML/JSON: ignore codes, change severities")
    p.add_argument(
        "--no-timings",
        action="store_true",
        help="leave timings out of the JSON report (byte-identical reruns)",
    )
    p.add_argument("--no-render", action="store_true", help="skip the GPU render pass")
    p.add_argument(
        "--render-size",
        type=int,
        default=None,
        metavar="N",
        help=f"render target size (default: the base map's largest side, within "
        f"{RENDER_SIZE_MIN}..{RENDER_SIZE_MAX})",
    )
    p.add_argument(
        "--source", metavar="MANIFEST", help="source manifest to measure the shipping error against"
    )
    p.add_argument(
        "--textures",
        choices=("auto", "png", "compressed"),
        default=LoadOptions().textures,
        metavar="WHICH",
        help="a folder: validate the block-compressed copies in compressed/ (auto: when "
        "present), or the PNGs: auto, png or compressed",
    )


def _run_folder(args: argparse.Namespace, folders: list) -> int:
    """validate-asset over a folder of outputs: one job per asset on the local engine."""

    for flag, value in (("--html", args.html), ("--source", args.source)):
        if value:
            raise input_error(flag, f"takes one asset, not a folder of {len(folders)} outputs")
    if args.jobs is not None and args.jobs < 1:
        raise input_error("--jobs", f"{args.jobs} is not a number of workers (1 or more)")
    options = AssetOptions(render=not args.no_render, fail_on=args.fail_on)
    params = {"config": args.config, "textures": args.textures, "render_size": args.render_size}
    plan = plan_validation(Path(args.path), folders, options, params)
    result, doc = run_and_publish(
        plan,
        LocalEngine(args.jobs),
        None,
        command="validate-asset",
        console=err,
        summary_path=args.report,
        junit_path=args.junit,
        sarif_path=args.sarif,
    )
    if args.json:
        emit_json(doc)
    return result.exit_code


def run(args: argparse.Namespace) -> int:
    if args.render_size is not None and not 16 <= args.render_size <= 4096:
        raise input_error("--render-size", f"{args.render_size} is not in 16..4096")
    if Path(args.path).is_dir() and (folders := output_folders(Path(args.path))):
        return _run_folder(args, folders)
    t0 = time.perf_counter()
    config = load_config(args.config) if args.config else Config()
    options, config = config.run_options(not args.no_render, args.render_size)
    with status(f"loading {args.path}"):
        inp = load_input(args.path, LoadOptions(textures=args.textures, source=args.source))
    with status("validating"):
        try:
            report = validate(inp, options, config)
        except (MemoryError, KeyboardInterrupt, InputError):
            raise  # an InputError is the input's fault, reported as itself (not a bug report)
        except Exception as exc:  # noqa: BLE001 - a rule tripping on an odd asset: no traceback
            msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            raise input_error(
                args.path, f"validation could not run ({type(exc).__name__}: {msg}); please report"
            ) from None
    if args.no_timings:
        report.timings = {}
        report.render = {
            k: v for k, v in report.render.items() if k not in ("render_s", "compare_s")
        }
    inputs = (args.path,) if args.path and not str(args.path).startswith("demo") else ()
    write_reports(report, args.report, args.html, args.fail_on, inputs=inputs)
    if args.json:
        emit_json(report_json(report, args.fail_on))
    print_summary(report, args.fail_on)
    if args.junit or args.sarif:
        _one_asset_reports(args, report, time.perf_counter() - t0)
    return report.exit_code(args.fail_on)


def _one_asset_reports(args: argparse.Namespace, report: object, seconds: float) -> None:
    """JUnit / SARIF for one validated asset (the same reports as over a folder)."""

    issues = [i.to_json() for i in report.issues]
    name = str(report.input.get("name", ""))
    result, plan = single_result(issues, Path(args.path), name, args.fail_on, seconds)
    publish(
        BatchRun([result], seconds),
        plan,
        command="validate-asset",
        engine="this process",
        console=err,
        junit_path=args.junit,
        sarif_path=args.sarif,
    )
