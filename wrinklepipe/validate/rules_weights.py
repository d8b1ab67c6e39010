"""Rules on weights: expression tables, drivers and per-vertex weights (WP-WGT-*)."""

from __future__ import annotations

import numpy as np

from wrinklepipe.geometry.dynamic import DynamicWeights
from wrinklepipe.model import POLICY_WEIGHT_RANGE
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context


def group_spread(groups: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per vertex: max minus min of ``values`` ``[V, C]`` over its group (0 for singletons)."""
    v = np.asarray(values, np.float64).reshape(len(groups), -1)
    n = int(groups.max()) + 1 if len(groups) else 0
    hi = np.full((n, v.shape[1]), -np.inf)
    lo = np.full((n, v.shape[1]), np.inf)
    np.maximum.at(hi, groups, v)
    np.minimum.at(lo, groups, v)
    return (hi - lo).max(axis=1)[groups]


def dynamic_weights(mesh: object, max_targets: int = 16) -> dict[str, np.ndarray]:
    """Oat's dynamic wrinkle weights of each morph target at full weight, smoothed over the
    mesh's vertex IDs by :mod:`wrinklepipe.geometry.dynamic` (empty when not applicable)."""
    if (
        max_targets <= 0
        or mesh.vertex_ids is None
        or mesh.morph_deltas is None
        or len(mesh.morph_names) != len(mesh.morph_deltas)
        or np.asarray(mesh.morph_deltas).shape[1:] != np.asarray(mesh.positions).shape
    ):
        return {}

    rest = np.asarray(mesh.positions, np.float64)
    op = DynamicWeights.build(rest, np.asarray(mesh.indices), np.asarray(mesh.vertex_ids))
    out = {}
    for name, delta in list(zip(mesh.morph_names, mesh.morph_deltas))[:max_targets]:
        out[f"dynamic:{name}"] = np.asarray(op.frame(rest + np.asarray(delta, np.float64)))
    return out


def check_weights(ctx: Context) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    out: list[Issue] = []
    rng = POLICY_WEIGHT_RANGE.get(a.policy)
    names = set(a.region_names)
    for expr in sorted(a.expressions):
        for region, w in sorted(a.expressions[expr].items()):
            ptr = inp.pointer("expressions") + f"/{expr}/{region}"
            if region not in names:
                out.append(
                    make_issue(
                        "WP-WGT-002", f"expression {expr!r} weights unknown region {region!r}", ptr
                    )
                )
            if rng is not None and not (rng.low <= float(w) <= rng.high):
                out.append(
                    make_issue(
                        "WP-WGT-001",
                        f"expression {expr!r}, region {region!r}: weight {float(w):g} outside "
                        f"[{rng.low:g}, {rng.high:g}] of policy {a.policy!r}",
                        ptr,
                    )
                )
    # Weight curves (animated region weights, [T, R]) must stay in the policy's range.
    for name, vals in sorted(inp.weight_curves.items()):
        v = np.asarray(vals, np.float64)
        if rng is None or v.ndim != 2 or v.shape[1] != len(a.regions):
            continue
        bad = ~np.isfinite(v) | (v < rng.low) | (v > rng.high)
        if bad.any():
            f, r = np.unravel_index(int(np.flatnonzero(bad)[0]), v.shape)
            out.append(
                make_issue(
                    "WP-WGT-001",
                    f"weight curve {name!r}: {int(bad.sum())} keys outside [{rng.low:g}, "
                    f"{rng.high:g}] of policy {a.policy!r}; first: key {f}, region "
                    f"{a.region_names[r]!r} = {v[f, r]:g}",
                    inp.pointer("drivers") + f"/curves/{name}",
                )
            )
    # Per-vertex weights (dynamic wrinkles, painted bias): seam twins must agree.
    mesh = a.mesh
    per_vertex = dict(inp.vertex_weights)
    if mesh is not None:
        per_vertex.update(dynamic_weights(mesh, max_targets=ctx.options.dynamic_targets))
    if mesh is not None and per_vertex:
        groups = ctx.vertex_groups
        for name, vals in sorted(per_vertex.items()):
            vals = np.asarray(vals)
            if vals.shape[0] != mesh.vertex_count:
                continue
            spread = group_spread(groups, vals)
            bad = spread > 1e-3
            if bad.any():
                first = int(np.flatnonzero(bad)[0])
                out.append(
                    make_issue(
                        "WP-WGT-003",
                        f"per-vertex weights {name!r} differ between UV-seam twins at "
                        f"{int(bad.sum())} vertices (largest jump {spread.max():.3f}); first "
                        f"vertex {first}",
                        inp.pointer("mesh") + f" vertex {first}",
                    )
                )
    return out
