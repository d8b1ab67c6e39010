"""``wrinklepipe validate-asset PATH``: coded rules, the GPU render pass, JSON/HTML reports."""

from __future__ import annotations

import argparse
import dataclasses

from wrinklepipe.errors import InputError, input_error

NAME = "validate-asset"
HELP = "check a converted folder, glTF/GLB/USD or manifest: rules, GPU render pass, reports"
DESCRIPTION = """\
Validate a wrinkle asset: a folder written by `convert`, a .gltf/.glb with the
WRINKLEPIPE_wrinkle_maps extension, a .usda/.usdc/.usdz with the WrinkleMapsAPI schema, a
source manifest (.toml), a validation bundle (.wpv) or `demo[:ENCODING][@SIZE][+bc]`.

Runs every rule of docs/ISSUES.md, then renders neutral and every expression with the GLSL
shaders on a headless EGL context (llvmpipe without a GPU) and compares the normal buffer with
the numpy model at the same pixels.

exit codes: 0 clean, 1 issues at or above --fail-on (default: error), 2 could not run.
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", metavar="PATH", help="folder, .gltf/.glb, .usd*, manifest, .wpv, demo")
    p.add_argument("--json", action="store_true", help="print the JSON report on stdout")
    p.add_argument("--report", metavar="FILE", help="write the JSON report to FILE")
    p.add_argument(
        "--html", metavar="FILE", help="write an HTML report (images in FILE's <stem>_files/)"
    )
    p.add_argument(
        "--fail-on",
        choices=("error", "warning", "info"),
        default="error",
        help="lowest severity that makes the exit code 1 (default: error)",
    )
    p.add_argument("--config", metavar="FILE", help="TOML/JSON: ignore codes, change severities")
    p.add_argument(
        "--no-timings",
        action="store_true",
        help="leave timings out of the JSON report (byte-identical reruns)",
    )
    p.add_argument("--no-render", action="store_true", help="skip the GPU render pass")
    p.add_argument("--render-size", type=int, default=None, help="render target size (default 512)")
    p.add_argument(
        "--source", metavar="MANIFEST", help="source manifest to measure the shipping error against"
    )
    p.add_argument(
        "--textures",
        choices=("auto", "png", "compressed"),
        default="auto",
        help="folders: validate the BC copies in compressed/ (auto: when present) or the PNGs",
    )


def run(args: argparse.Namespace) -> int:
    from wrinklepipe.console import emit_json, err, status
    from wrinklepipe.sources.validation import LoadOptions, load_input
    from wrinklepipe.validate import validate
    from wrinklepipe.validate.config import Config, load_config
    from wrinklepipe.validate.context import ValidateOptions
    from wrinklepipe.validate.report import print_summary, report_json, write_reports

    if args.render_size is not None and not 16 <= args.render_size <= 4096:
        raise input_error("--render-size", f"{args.render_size} is not in 16..4096")
    config = load_config(args.config) if args.config else Config()
    options = config.validate_options(ValidateOptions())
    if args.no_render:
        options = dataclasses.replace(options, render=False)
    if args.render_size is not None:
        options = dataclasses.replace(options, render_size=args.render_size)
    config = Config(config.ignore, config.severity, {})  # options are applied above
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
    print_summary(report, err, args.fail_on)
    return report.exit_code(args.fail_on)
