"""``wrinklepipe convert``: run the whole pipeline on a manifest into one output folder."""

from __future__ import annotations

import argparse
from typing import Any

from wrinklepipe.console import emit_json, err
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.masks.layouts import LAYOUTS
from wrinklepipe.metrics import Budget, Stats

NAME = "convert"
HELP = "convert a source manifest into glTF + USD + textures + weight curves + report"
DESCRIPTION = """\
Read a source manifest (TOML: mesh, base and wrinkle normal maps, region masks, expressions,
drivers), run every stage (ingest, resample, tangents, vertex IDs, drivers, encode, pack,
compress) and write one folder:

  NAME.gltf + NAME.bin   glTF 2.0 with the WRINKLEPIPE_wrinkle_maps material extension
  NAME.glb               self-contained GLB (--glb)
  NAME.usda              USD with the WrinkleMapsAPI schema (+ NAME.usdc / NAME.usdz on request)
  textures/*.png         base normal, wrinkle states, packed masks (shared by glTF and USD)
  compressed/*.dds|ktx2  BC copies of base and states: the smallest format within the budget
  curves/*.csv|json      region weights over time, one file pair per driver
  report.json, .html     what was read, done and written (hashes), validation results

The folder is built under a temporary name and renamed into place only when complete; an
existing non-empty OUT is replaced only with --force; OUT may not be, or contain, the input
folder. Two runs on the same inputs give byte-identical folders.

exit codes: 0 written and valid, 1 written but validation found errors, 2 could not run.

examples:
  wrinklepipe convert demo_src/manifest.toml -o out   # demo_src: demo.source.write_demo_source
  wrinklepipe convert head/manifest.toml -o build/head --glb --usdz --force
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    d = ConvertOptions()  # the defaults: one place
    p.add_argument("manifest", metavar="MANIFEST", help="source manifest (manifest.toml)")
    p.add_argument("-o", "--output", required=True, metavar="OUT", help="output folder")
    p.add_argument("--glb", action="store_true", help="also write a self-contained NAME.glb")
    usd = p.add_mutually_exclusive_group()
    usd.add_argument("--usdc", action="store_true", help="also write binary NAME.usdc")
    usd.add_argument("--usdz", action="store_true", help="also write a packaged NAME.usdz")
    p.add_argument("--force", action="store_true", help="replace a non-empty output folder")
    p.add_argument(
        "--bits",
        type=int,
        choices=(8, 16),
        default=d.bits,
        help=f"PNG bits of normal maps ({d.bits})",
    )
    p.add_argument(
        "--mask-layout",
        choices=LAYOUTS,
        default=None,
        help="mask packing (default: the manifest's formats.mask_layout, else rgba)",
    )
    p.add_argument("--no-compress", action="store_true", help="skip DDS/KTX2 textures")
    p.add_argument("--no-validate", action="store_true", help="skip validating the output")
    p.add_argument("--no-render", action="store_true", help="validate without the GPU render pass")
    p.add_argument(
        "--png-level",
        type=int,
        choices=range(10),
        default=d.png_level,
        metavar="0-9",
        help=f"zlib level of the PNGs (default {d.png_level}; 9: a few %% smaller, slower)",
    )
    p.add_argument("--json", action="store_true", help="print report.json on stdout")


def run(args: argparse.Namespace) -> int:
    options = ConvertOptions(
        glb=args.glb,
        usd_format="usdc" if args.usdc else "usdz" if args.usdz else "usda",
        force=args.force,
        compressed=not args.no_compress,
        validate=not args.no_validate,
        render=not args.no_render,
        bits=args.bits,
        mask_layout=args.mask_layout,
        png_level=args.png_level,
    )
    result = convert(args.manifest, args.output, options)
    if args.json:
        emit_json(result.report)
    else:
        for line in summary_lines(result.report, result.exit_code, str(result.output)):
            err.print(line, markup=False, highlight=False, soft_wrap=True)
    return result.exit_code


def _fmt(f: str) -> str:
    return "none (PNG only)" if f == "png" else f


def _formats_tried(tried: list[dict[str, Any]]) -> list[str]:
    """One line per group: each block format tried, its worst pose inside the active regions
    (p99 / mean degrees) and whether it met the budget."""
    out = []
    for step, label in (("state format", "states"), ("base format", "base")):
        rows = [t for t in tried if t["step"] == step]
        if rows:
            out.append(
                f"formats tried for the {label} (worst pose p99 / mean deg): "
                + ", ".join(
                    f"{t['value']} {t['worst_p99_deg']:.2f} / {t['worst_mean_deg']:.2f}"
                    + ("" if t["ok"] else " over")
                    for t in rows
                )
            )
    return out


def fidelity_table(fid: dict[str, Any], which: str) -> list[str]:
    """The per-pose fidelity table of report.json's ``fidelity`` record (worst first)."""
    part = fid.get(which)
    if not part:
        return []
    budget = fid.get("budget" if which == "png" else "compressed_budget", {})
    limit = ", ".join(f"{k[4:-4]} {v:g}" for k, v in sorted(budget.items()))
    rows = sorted(part["poses"], key=lambda p: -p["p99_deg"])
    width = max([16, *(len(r["pose"]) + 2 for r in rows)])
    out = [f"fidelity ({which}, degrees inside each pose's active region; budget {limit}):"]
    out.append(f"  {'pose':<{width}}{'mean':>7}{'p99':>7}{'max':>8}")
    verdict = Budget.from_dict(budget)
    for r in rows:
        st = Stats(r["mean_deg"], r["p99_deg"], r["max_deg"], r.get("texels", 0), 0.0)
        over = not verdict.ok(st)
        out.append(
            f"  {r['pose']:<{width}}{r['mean_deg']:7.2f}{r['p99_deg']:7.2f}{r['max_deg']:8.2f}"
            + ("  over budget" if over else "")
        )
    b = part.get("base")
    if b:
        out.append(
            f"  {'base (face)':<{width}}{b['mean_deg']:7.2f}{b['p99_deg']:7.2f}{b['max_deg']:8.2f}"
        )
    return out


def color_table(color: dict[str, Any] | None) -> list[str]:
    """The colour states' size and the per-pose colour fidelity table (CIEDE2000, worst
    first) of report.json's ``color`` record; nothing without colour states."""
    if not color:
        return []
    b = color["budget"]
    verdict = Budget(b["max_mean_delta_e"], b["max_p99_delta_e"])
    h, w = color["size"]
    rows = sorted(color["fidelity"]["poses"], key=lambda p: -p["p99_delta_e"])
    width = max([16, *(len(r["pose"]) + 2 for r in rows)])
    out = [
        f"colour states {w}x{h} ({color['how']}); colour fidelity (CIEDE2000 inside each pose's "
        f"active region; budget mean {b['max_mean_delta_e']:g}, p99 {b['max_p99_delta_e']:g}):",
        f"  {'pose':<{width}}{'mean':>7}{'p99':>7}{'max':>8}",
    ]
    for r in rows:
        st = Stats(r["mean_delta_e"], r["p99_delta_e"], r["max_delta_e"], r["texels"], 0.0)
        out.append(
            f"  {r['pose']:<{width}}{r['mean_delta_e']:7.2f}{r['p99_delta_e']:7.2f}"
            f"{r['max_delta_e']:8.2f}" + ("" if verdict.ok(st) else "  over budget")
        )
    return out


def summary_lines(rep: dict[str, Any], exit_code: int, where: str = "") -> list[str]:
    """What convert tells the terminal: what it wrote, the choices and their fidelity, every
    warning and validation error or warning, and why the exit code is 1."""
    a = rep["asset"]
    out = [
        f"wrote {where + ' ' if where else ''}({len(rep['outputs']) + 2} files): "
        f"{len(a['states'])} states, "
        f"{len(a['regions'])} regions, encoding {a['encoding']} (scale {a['scale']}), "
        f"{a['vertices']} vertices"
    ]
    fid = rep.get("fidelity")
    if fid and "wrinkle" not in fid:  # another encoding than pd: only the formats are chosen
        out.append(
            f"chosen: compressed copies: base {_fmt(fid['base_format'])}, states "
            f"{_fmt(fid['state_format'])} (maps at the manifest's sizes)"
        )
        out += fidelity_table(fid, "compressed")
        out += [f"note: {n}" for n in fid.get("notes", [])]
        out += _formats_tried(fid.get("tried", []))
    elif fid:
        out.append(
            f"chosen: states {fid['wrinkle']}^2, masks {fid['mask']}^2, pd_scale "
            f"{fid['pd_scale']:g}; compressed copies: base "
            f"{_fmt(fid['base_format'])}, states {_fmt(fid['state_format'])}"
        )
        out += fidelity_table(fid, "png") + fidelity_table(fid, "compressed")
        out += [f"note: {n}" for n in fid.get("notes", [])]
    out += color_table(rep.get("color"))
    clipped = rep.get("pd_scale", {}).get("clipped_texels") or {}
    if any(clipped.values()):
        out.append(
            "clipped texels (stored at the end of the PD range): "
            + ", ".join(f"{k} {v}" for k, v in sorted(clipped.items()))
        )
    out += [f"warning: {w}" for w in rep.get("warnings", [])]
    v = rep.get("validation", {})
    if v.get("status") != "ran":
        out.append(f"validation: {v.get('reason', v.get('status', 'skipped'))}")
        return out
    issues = [i for i in v.get("issues", []) if i.get("severity") in ("error", "warning")]
    for i in issues:
        out.append(f"{i['severity']} {i['code']}: {i['message']}")
    counts = v.get("counts", {})
    out.append(
        f"validation: {counts.get('error', 0)} error(s), {counts.get('warning', 0)} warning(s), "
        f"{counts.get('info', 0)} info (report.json, validation.html)"
    )
    if exit_code == 1:
        codes = sorted({i["code"] for i in issues if i["severity"] == "error"})
        out.append(
            f"exit 1: the output was written but validation found errors ({', '.join(codes)})"
        )
    return out
