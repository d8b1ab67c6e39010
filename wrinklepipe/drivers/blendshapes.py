"""``blendshapes``: morph-target weights -> region weights through piecewise-linear rows.

The rows are MetaHuman RigLogic's conditional table ``(input, output, from, to, slope, cut)``:
for each row whose input weight ``x`` satisfies ``from < x <= to``, ``slope * x + cut`` is added to
the output; the outputs are then clamped to [0, 1] (as RigLogic does). Several rows on one input
and output make a piecewise-linear curve; rows from several inputs into one output sum (so a
negative slope cancels, as in Jimenez et al.'s Fig. 1.5).

Spec::

    kind = "blendshapes"
    preset = "arkit52"                               # and/or explicit rows:
    rows = [["browInnerUp", "forehead_inner_l", 0, 1, 1, 0], ...]
    file = "performance.glb"                         # morph-weight animation (or CSV/JSON keys)
    [drivers.keys]                                   # or keys per blend shape
    browInnerUp = [[0, 0], [1, 1]]
    [drivers.morphs]                                 # or one static pose
    browInnerUp = 0.5

An output is a region (every state it drives) or ``region:state``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wrinklepipe.drivers.base import (
    DriverContext,
    DriverResult,
    frame_times,
    register,
    resolve,
    spec_problem,
)
from wrinklepipe.drivers.curves import (
    curves_to_weights,
    keys_range,
    load_keys,
    morph_clip_animation,
    sample_keys,
)
from wrinklepipe.errors import InputError, Problem
from wrinklepipe.names import unknown_names
from wrinklepipe.presets import arkit
from wrinklepipe.suffixes import is_gltf


@dataclass(frozen=True)
class Row:
    """A conditional-table row: adds ``slope * x + cut`` to ``output`` when ``from_ < x <= to``."""

    input: str
    output: str
    from_: float
    to: float
    slope: float
    cut: float


def rows_from_lists(raw: Sequence[Sequence[Any]], where: str = "<rows>") -> list[Row]:
    """``[[input, output, from, to, slope, cut], ...]`` -> rows (checked)."""
    rows = []
    problems = []
    for i, r in enumerate(raw):
        try:
            inp, out, a, b, s, c = r
            row = Row(str(inp), str(out), float(a), float(b), float(s), float(c))
        except (TypeError, ValueError):
            problems.append(
                Problem(where, "expected [input, output, from, to, slope, cut]", f"rows[{i}]")
            )
            continue
        if not row.from_ < row.to:
            problems.append(Problem(where, f"'from' {row.from_} must be below 'to'", f"rows[{i}]"))
        rows.append(row)
    if problems:
        raise InputError(problems)
    return rows


def evaluate_rows(
    inputs: np.ndarray,
    input_names: Sequence[str],
    rows: Sequence[Row],
    output_names: Sequence[str],
    clamp: bool = True,
    where: str = "<rows>",
) -> np.ndarray:
    """Blend-shape weights ``[F, M]`` -> outputs ``[F, O]`` (RigLogic conditional table)."""
    x = np.asarray(inputs, np.float64)
    in_pos = {n: i for i, n in enumerate(input_names)}
    out_pos = {n: i for i, n in enumerate(output_names)}
    problems = []
    for i, r in enumerate(rows):
        if r.input not in in_pos:
            problems.append(
                Problem(
                    where,
                    "row names an " + unknown_names("blend shape", [r.input], input_names),
                    f"rows[{i}]",
                )
            )
        if r.output not in out_pos:
            problems.append(
                Problem(
                    where,
                    "row names an " + unknown_names("output", [r.output], output_names),
                    f"rows[{i}]",
                )
            )
    if problems:
        raise InputError(problems)
    f = x.shape[0]
    if not rows:
        return np.zeros((f, len(output_names)), np.float32)
    ii = np.array([in_pos[r.input] for r in rows])
    oo = np.array([out_pos[r.output] for r in rows])
    lo = np.array([r.from_ for r in rows])
    hi = np.array([r.to for r in rows])
    slope = np.array([r.slope for r in rows])
    cut = np.array([r.cut for r in rows])
    xv = x[:, ii]  # [F, N]
    active = (lo < xv) & (xv <= hi)
    contrib = np.where(active, slope * xv + cut, 0.0)
    onehot = np.zeros((len(rows), len(output_names)))
    onehot[np.arange(len(rows)), oo] = 1.0
    out = contrib @ onehot
    if clamp:
        out = np.clip(out, 0.0, 1.0)
    return out.astype(np.float32)


def _rows(ctx: DriverContext, spec: Mapping[str, Any], notes: list[str]) -> list[Row]:
    rows: list[Row] = []
    preset = spec.get("preset")
    if preset is not None:
        if preset not in arkit.PRESETS:
            raise spec_problem(
                ctx, f"unknown preset {preset!r} ({', '.join(arkit.PRESETS)})", "preset"
            )
        all_rows = rows_from_lists(arkit.PRESETS[preset], f"preset {preset}")
        kept = [r for r in all_rows if r.output.partition(":")[0] in ctx.regions]
        missing = sorted({r.output for r in all_rows} - {r.output for r in kept})
        if missing:
            notes.append(f"preset {preset}: skipped rows for regions this asset lacks: {missing}")
        rows += kept
    if "rows" in spec:
        rows += rows_from_lists(spec["rows"], ctx.source)
    if not rows:
        raise spec_problem(ctx, "blendshapes driver needs 'rows' or a 'preset'", "rows")
    return rows


def _outputs(ctx: DriverContext, rows: Sequence[Row]) -> list[str]:
    outs = list(dict.fromkeys(r.output for r in rows))
    problems = []
    for n in outs:
        region, _, state = n.partition(":")
        if region not in ctx.regions:
            problems.append(
                Problem(
                    ctx.source,
                    "row output names an " + unknown_names("region", [region], ctx.regions),
                    "rows",
                )
            )
        elif state and state not in ctx.states:
            problems.append(
                Problem(
                    ctx.source,
                    "row output names an " + unknown_names("state", [state], ctx.states),
                    "rows",
                )
            )
    if problems:
        raise InputError(problems)
    return outs


@register("blendshapes")
def blendshapes_driver(
    ctx: DriverContext, spec: Mapping[str, Any], times: np.ndarray | None
) -> DriverResult:
    notes: list[str] = []
    rows = _rows(ctx, spec, notes)
    outputs = _outputs(ctx, rows)
    fps = float(spec.get("fps", ctx.fps))
    mesh_names = tuple(ctx.mesh.morph_names) if ctx.mesh is not None else ()
    file = spec.get("file")
    read = {"from": "keys"}
    wanted = tuple(dict.fromkeys(r.input for r in rows))  # the blend shapes the rows read
    if file is not None and is_gltf(file):
        times, names, x, clip = morph_clip_animation(
            ctx, resolve(ctx, str(file)), times, fps, spec.get("clip"), wanted
        )
        read = {"from": "file", **({"clip": clip.to_json()} if clip is not None else {})}
        universe = mesh_names or names
        inputs = np.zeros((len(times), len(universe)))
        for j, n in enumerate(names):
            if n in universe:
                inputs[:, list(universe).index(n)] = x[:, j]
    elif "morphs" in spec and "keys" not in spec and file is None:
        morphs = {str(k): float(v) for k, v in spec["morphs"].items()}
        universe = mesh_names or tuple(morphs)
        unknown = [n for n in morphs if n not in universe]
        if unknown:
            raise spec_problem(ctx, unknown_names("blend shape", unknown, universe), "morphs")
        times = np.zeros(1) if times is None else times
        inputs = np.array([[morphs.get(n, 0.0) for n in universe]] * len(times))
        read = {"from": "morphs"}
    else:
        keys, interp, _ = load_keys(ctx, spec)
        if not keys:
            raise spec_problem(ctx, "blendshapes driver needs keys, morphs or a file", "keys")
        universe = mesh_names or tuple(keys)
        unknown = [n for n in keys if n not in universe]
        if unknown:
            raise spec_problem(
                ctx, "keys for an " + unknown_names("blend shape", unknown, universe), "keys"
            )
        if times is None:
            times = frame_times(*keys_range(keys), fps)
        inputs = sample_keys(keys, universe, times, interp)
    if not mesh_names and spec.get("preset") is not None:
        # No mesh to say which shapes exist: the preset's own names are known (weight 0 if absent).

        extra = [n for n in arkit.NAMES if n not in universe]
        universe = (*universe, *extra)
        inputs = np.concatenate([inputs, np.zeros((inputs.shape[0], len(extra)))], axis=1)
    out = evaluate_rows(inputs, universe, rows, outputs, clamp=True, where=ctx.source)
    w = curves_to_weights(ctx, outputs, out.astype(np.float64), "rows")
    states = ("signed",) if ctx.policy == "signed" else ctx.states
    peak = np.abs(np.asarray(inputs, np.float64)).max(axis=0, initial=0.0)
    moving = [n for n in wanted if n in universe and peak[list(universe).index(n)] > 0]
    source = {**read, "inputs": list(wanted), "moving": moving}
    return DriverResult(
        "blendshapes", np.asarray(times), w, ctx.regions, states, notes=notes, source=source
    )
