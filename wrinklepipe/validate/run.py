"""Run every rule, then the render pass, and collect one :class:`Report`."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from wrinklepipe.validate import (
    render,
    rules_color,
    rules_compression,
    rules_fidelity,
    rules_maps,
    rules_masks,
    rules_mesh,
    rules_rig,
    rules_usd,
    rules_weights,
    tiles,
)
from wrinklepipe.validate.catalogue import SEVERITIES, Issue
from wrinklepipe.validate.config import Config
from wrinklepipe.validate.context import Context, ValidateOptions
from wrinklepipe.validate.inputs import ValidationInput

#: (name, check) in the order they run.
CHECKS: tuple[tuple[str, Callable[[Context], list[Issue]]], ...] = (
    ("usd composition", rules_usd.check_composition),
    ("declarations", rules_maps.check_declarations),
    ("formats", rules_compression.check_formats),
    ("maps", rules_maps.check_maps),
    ("channel_table", rules_masks.check_channel_table),
    ("masks", rules_masks.check_masks),
    ("sides", rules_fidelity.check_sides),
    ("weights", rules_weights.check_weights),
    ("rig", rules_rig.check_rig),
    ("mesh", rules_mesh.check_mesh),
    ("source texels", rules_fidelity.check_source_texels),
    ("alignment", rules_fidelity.check_alignment),
    ("fidelity", rules_fidelity.check_fidelity),
    ("colour", rules_color.check_color),
    ("compression", rules_compression.check_compression),
    ("footprint", rules_compression.check_footprint),
)

_RANK = {s: i for i, s in enumerate(SEVERITIES)}


@dataclass
class Report:
    """Everything one validation found: issues (after config), metrics, timings, images."""

    input: dict[str, Any]
    issues: list[Issue]
    metrics: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    render: dict[str, Any] = field(default_factory=dict)
    images: dict[str, Any] = field(default_factory=dict)  # name -> array, for the HTML report
    ignored: int = 0

    @property
    def counts(self) -> dict[str, int]:
        return {s: sum(i.severity == s for i in self.issues) for s in SEVERITIES}

    def codes(self) -> list[str]:
        return sorted({i.code for i in self.issues})

    def exit_code(self, fail_on: str = "error") -> int:
        """0 clean, 1 when an issue at or above ``fail_on`` severity was found."""
        limit = _RANK[fail_on]
        return 1 if any(_RANK[i.severity] <= limit for i in self.issues) else 0


def describe_input(inp: ValidationInput) -> dict[str, Any]:
    a = inp.asset
    tiled = {"tiles": sorted(inp.tiles)} if inp.tiles else {}
    return {
        **tiled,
        "path": inp.path,
        "kind": inp.kind,
        "name": a.name,
        "encoding": a.encoding,
        "policy": a.policy,
        "pd_scale": float(a.pd_scale),
        "states": list(a.state_names),
        "regions": list(a.region_names),
        "expressions": sorted(a.expressions),
        "has_source": bool(inp.has_source),
        "textures": [
            {
                "name": t.name,
                "role": t.role,
                "format": t.fmt,
                "width": t.width,
                "height": t.height,
                "bytes": len(t.data),
                "srgb": bool(t.srgb),
                "pointer": t.where,
            }
            for t in inp.textures
        ],
        "mesh": None
        if a.mesh is None
        else {"vertices": a.mesh.vertex_count, "triangles": a.mesh.triangle_count},
    }


def one_cause_once(issues: list[Issue]) -> list[Issue]:
    """Each defect said once: an issue that names what another one measured (``data
    ["explains"]``: the pointer of the texture whose issue it explains) replaces that texture's
    WP-MAP-003 (a base mirrored relative to its states also fails the curl test)."""
    explained = {i.data["explains"] for i in issues if "explains" in i.data}
    return [i for i in issues if not (i.code == "WP-MAP-003" and i.pointer in explained)]


def validate(
    inp: ValidationInput,
    options: ValidateOptions | None = None,
    config: Config | None = None,
    progress: Callable[[str], None] | None = None,
) -> Report:
    """Validate one asset: all rules, then (``options.render``) the GPU render pass; a UDIM
    asset tile by tile and over the whole face (:mod:`wrinklepipe.validate.tiles`)."""
    if inp.tiles:
        return _validate_tiles(inp, options, config, progress)
    return _validate_one(inp, options, config, progress)[0]


def _validate_one(
    inp: ValidationInput,
    options: ValidateOptions | None = None,
    config: Config | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[Report, Context]:
    """:func:`validate` of a plain input, with the context the rules shared."""
    cfg = config or Config()
    opts = cfg.validate_options(options) if cfg.options else (options or ValidateOptions())
    ctx = Context(inp, opts)
    issues: list[Issue] = []
    for name, check in CHECKS:
        if progress:
            progress(name)
        t0 = time.perf_counter()
        issues += check(ctx)
        ctx.timings[name] = time.perf_counter() - t0
    issues = one_cause_once(issues)
    render_info: dict[str, Any] = {}
    images: dict[str, Any] = {}
    if opts.render:
        if progress:
            progress("render")
        t0 = time.perf_counter()
        r_issues, render_info, images = render.render_pass(ctx)
        issues += r_issues
        ctx.timings["render"] = time.perf_counter() - t0
    for key, prefix in (("shipping_error_maps", "shipping_error"),):
        if key in ctx.metrics:
            for e, m in ctx.metrics.pop(key).items():
                images[f"{prefix}/{e}"] = m
    images.update(ctx.metrics.pop("fidelity_pictures", {}))  # keyed as the page shows them
    issues, dropped = cfg.apply(issues)
    issues.sort(key=lambda i: (_RANK[i.severity], i.code, i.pointer, i.message))
    report = Report(
        input=describe_input(inp),
        issues=issues,
        metrics=ctx.metrics,
        timings={k: round(v, 4) for k, v in ctx.timings.items()},
        render=render_info,
        images=images,
        ignored=dropped,
    )
    return report, ctx


def _validate_tiles(
    inp: ValidationInput,
    options: ValidateOptions | None,
    config: Config | None,
    progress: Callable[[str], None] | None,
) -> Report:
    """Every tile validated on its own, then one report with the whole face's fidelity
    (:mod:`wrinklepipe.validate.tiles`)."""
    cfg = config or Config()
    per_tile: dict[int, list[Issue]] = {}
    ctxs: list[Context] = []
    metrics: dict[str, Any] = {"tiles": {}}
    timings: dict[str, float] = {}
    poses: dict[str, Any] = {}
    render_rest: dict[str, Any] = {}
    images: dict[str, Any] = {}
    fids: dict[int, Any] = {}
    areas: dict[int, float] = {}
    dropped = 0
    budget_of: tuple[Any, str] | None = None
    for i, (t, one) in enumerate(sorted(inp.tiles.items())):
        report, ctx = _validate_one(one, options, config, progress)
        per_tile[t] = report.issues
        ctxs.append(ctx)
        metrics["tiles"][str(t)] = report.metrics
        for k, v in report.timings.items():
            timings[k] = round(timings.get(k, 0.0) + v, 4)
        got, rest = tiles.tile_render(report.render, t)
        poses.update(got)
        if rest:
            render_rest[str(t)] = rest
        images.update(tiles.tile_images(report.images, t, i == 0))
        dropped += report.ignored
        fid = rules_fidelity.shipped_fidelity(ctx)
        if fid is not None:
            fids[t] = fid
            h, w = rules_fidelity.reference(ctx).shape  # type: ignore[union-attr]
            areas[t] = 1.0 / float(h * w)
            budget_of = budget_of or rules_fidelity.budgets(ctx)
    issues = tiles.merge_issues(per_tile)
    issues += cfg.apply(rules_masks.check_face_sides(ctxs))[0]
    face = tiles.face_fidelity(fids, areas)
    if fids:
        metrics["fidelity_by_tile"] = tiles.by_tile(fids, face)
    if face is not None and budget_of is not None:
        budget, which = budget_of
        metrics["fidelity"] = {**face.to_json(), "budget": budget.to_json(), "applies": which}
        got_issues, _ = cfg.apply(tiles.face_issues(face, budget, which, inp.pointer("textures")))
        issues += got_issues
    issues.sort(key=lambda i: (_RANK[i.severity], i.code, i.pointer, i.message))
    render_info = {"poses": poses, "tiles": render_rest} if poses or render_rest else {}
    return Report(
        input=describe_input(inp),
        issues=issues,
        metrics=metrics,
        timings=timings,
        render=render_info,
        images=images,
        ignored=dropped,
    )
