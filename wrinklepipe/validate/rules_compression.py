"""Rules on texture formats, compression error, resolution and footprint (WP-TEX-*)."""

from __future__ import annotations

import numpy as np

from wrinklepipe import fidelity as fd
from wrinklepipe import model
from wrinklepipe.metrics import DECIMALS, Budget, Stats, angle_deg, weighted_stats
from wrinklepipe.names import noun, plural
from wrinklepipe.validate import rules_fidelity
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context


def check_formats(ctx: Context) -> list[Issue]:
    out: list[Issue] = []
    for t in ctx.inp.textures:
        if t.srgb and t.role in ("base", "state"):
            out.append(make_issue("WP-TEX-001", f"{t.role} map {t.name!r} is tagged sRGB", t.where))
        if t.srgb and t.role == "mask":
            out.append(make_issue("WP-TEX-002", f"mask texture {t.name!r} is tagged sRGB", t.where))
        if t.is_block and (t.width % 4 or t.height % 4):
            out.append(
                make_issue(
                    "WP-TEX-003",
                    f"{t.fmt} texture {t.name!r} is {t.width}x{t.height}, not a multiple of 4",
                    t.where,
                )
            )
        if len(t.data) < t.expected_size():
            out.append(
                make_issue(
                    "WP-TEX-004",
                    f"{t.fmt} {t.width}x{t.height} needs {t.expected_size()} bytes, "
                    f"{t.name!r} has {len(t.data)}",
                    t.where,
                )
            )
    for p in ctx.inp.extra.get("copy_problems", []):  # every compressed copy, read back whole
        name = str(p.get("file", "")).replace("\\", "/").rsplit("/", 1)[-1]
        out.append(make_issue("WP-TEX-004", f"{name}: {p.get('message', '')}", str(p["file"])))
    return out


def _budget(ctx: Context) -> Budget:
    """The budget the shipped textures are judged by: the compressed copies' when a base or
    state texture is block-compressed (as the fidelity rules and the automatic choices judge
    them), else the maps' (:func:`wrinklepipe.validate.rules_fidelity.budgets`)."""
    return rules_fidelity.budgets(ctx)[0]


def shipping_errors(
    ctx: Context, shipped: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> dict[str, tuple[Stats, np.ndarray]]:
    """Per expression: the statistics and the error map of shipped vs source on the grid."""
    a = ctx.asset
    src = ctx.source_on_grid
    out = {}
    for expr in ctx.expressions():
        w = ctx.weights(expr)
        n_src = model.blend(src[0], src[1], src[2], w, a.encoding, a.policy)
        n_ship = model.blend(shipped[0], shipped[1], shipped[2], w, a.encoding, a.policy)
        err = angle_deg(n_ship, n_src)
        out[expr or "neutral"] = (weighted_stats(err), err)
    return out


def check_compression(ctx: Context) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    out: list[Issue] = []
    if (
        ctx.source_on_grid is None
        or ctx.shipped_on_grid is None
        or a.policy not in model.POLICIES
        or (a.policy == "signed" and len(a.state_names) != 2)
        or not a.regions
        or not a.state_names
    ):
        return out
    budget = _budget(ctx)
    errs = shipping_errors(ctx, ctx.shipped_on_grid)
    ctx.metrics["shipping_error_deg"] = {
        e: {k: round(v, DECIMALS) for k, v in (("mean", s.mean), ("p99", s.p99), ("max", s.max))}
        for e, (s, _) in errs.items()
    }
    ctx.metrics["shipping_error_maps"] = {e: v[1] for e, v in errs.items()}
    over = [(e, s) for e, (s, _) in errs.items() if not budget.ok(s)]
    if over:
        worst = max(over, key=lambda x: x[1].p99)
        out.append(
            make_issue(
                "WP-TEX-005",
                f"{len(over)} of {len(errs)} poses over the budget ({budget.describe()} "
                f"degrees); worst {worst[0]}: mean {worst[1].mean:.2f}, p99 {worst[1].p99:.2f}",
                inp.pointer("textures"),
            )
        )
    elif ctx.options.half_res_check:
        out += _half_resolution(ctx, budget)
    return out


def _half_resolution(ctx: Context, budget_grid: Budget) -> list[Issue]:
    """Would the states at half size still meet the budget? Then the extra bytes are wasted.
    Not asked without a pose to judge by (a dead rig: WP-WGT-004 says so)."""
    a = ctx.asset
    if not rules_fidelity.poses(ctx):
        return []
    texs = ctx.inp.state_textures()
    if not texs or any(t is None for t in texs) or ctx.shipped_states is None:
        return []
    h, w = ctx.shipped_states[0].shape[:2]
    if h < 8 or w < 8 or h % 2 or w % 2:
        return []
    halves = [s.reshape(h // 2, 2, w // 2, 2, -1).mean(axis=(1, 3)) for s in ctx.shipped_states]
    samples = rules_fidelity.shipped_samples(ctx, np.stack(halves))
    if samples is not None:
        # the one measure (fd.measure: the full-resolution source inside each pose's active
        # region) of the halved states with the shipped base and masks; only the poses decide
        fid = fd.evaluate(rules_fidelity.reference(ctx), samples, regions=False)
        budget, _ = rules_fidelity.budgets(ctx)
        ok, worst = fid.meets(budget), fid.worst_p99()
    else:
        base, _, masks = ctx.shipped_on_grid
        half = []
        for small in halves:
            g = ctx.to_grid(small)
            if a.encoding in ("full", "composite"):
                g = model.normalize(g)
            half.append(g)
        errs = shipping_errors(ctx, (base, np.stack(half).astype(np.float32), masks))
        ok = all(budget_grid.ok(s) for s, _ in errs.values())
        worst = max(s.p99 for s, _ in errs.values())
    if ok:
        wasted = sum(len(t.data) for t in texs) * 3 // 4
        return [
            make_issue(
                "WP-TEX-006",
                f"the {plural(len(texs), 'state map')} at {w // 2}x{h // 2} instead of {w}x{h} "
                f"still {noun(len(texs), 'meets', 'meet')} the budget (worst p99 {worst:.2f} "
                f"degrees); {wasted} bytes wasted",
                ctx.inp.pointer("textures"),
                wasted_bytes=int(wasted),
            )
        ]
    return []


def check_footprint(ctx: Context) -> list[Issue]:
    texs = ctx.inp.textures
    if not texs:
        return []
    per_role: dict[str, int] = {}
    for t in texs:
        per_role[t.role] = per_role.get(t.role, 0) + len(t.data)
    total = sum(per_role.values())
    ctx.metrics["footprint_bytes"] = {"total": total, **per_role}
    parts = ", ".join(f"{r} {b}" for r, b in sorted(per_role.items()))
    return [
        make_issue(
            "WP-TEX-007",
            f"{len(texs)} textures, {total} bytes ({total / 1024:.1f} KiB) at level 0: {parts}",
            ctx.inp.pointer("textures"),
            bytes=total,
        )
    ]


__all__ = ["check_formats", "check_compression", "check_footprint", "shipping_errors", "tx"]
