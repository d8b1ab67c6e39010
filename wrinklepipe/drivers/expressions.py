"""``expressions``: expression weights x an expression table (Jimenez et al., Table 1.1).

``w_r(t) = sum_e x_e(t) * T[e, r]``: linear, so negative table entries cancel positive ones (their
Fig. 1.5: surprise + anger leaves the inner forehead at 0.8 - 0.8 = 0). The policy then acts per
texel on ``sum_r M_r w_r`` (under ``clamp01`` sums above 1 are clamped, as the paper does).

Spec::

    kind = "expressions"
    interpolation = "linear"
    fps = 24
    preset = "jimenez"             # optional: the table; default the manifest's [expressions]
    [drivers.keys]                 # expression weight curves
    joy = [[0, 0], [1, 1], [2, 0]]
    [drivers.morphs]               # or one static mix (a single frame)
    surprise = 1.0
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from wrinklepipe.drivers.base import (
    DriverContext,
    DriverResult,
    frame_times,
    register,
    spec_problem,
)
from wrinklepipe.drivers.curves import keys_range, load_keys, sample_keys
from wrinklepipe.errors import InputError, Problem
from wrinklepipe.names import unknown_names
from wrinklepipe.presets import jimenez


def expression_matrix(
    table: Mapping[str, Mapping[str, float]], regions: Sequence[str], where: str = "<expressions>"
) -> tuple[tuple[str, ...], np.ndarray]:
    """Table ``{expression: {region: w}}`` -> (expression names, ``[E, R]`` float32)."""

    names = tuple(table)
    mat = np.zeros((len(names), len(regions)), np.float32)
    problems = []
    for i, e in enumerate(names):
        for region, w in table[e].items():
            if region not in regions:
                problems.append(
                    Problem(
                        where,
                        unknown_names("region", [region], regions),
                        f"expressions.{e}.{region}",
                    )
                )
                continue
            mat[i, list(regions).index(region)] = np.float32(w)
    if problems:
        raise InputError(problems)
    return names, mat


def weights(mix: np.ndarray, matrix: np.ndarray, region_states: np.ndarray) -> np.ndarray:
    """Expression mix ``[F, E]`` x table ``[E, R]`` -> linear weights ``[F, R, K]``."""
    per_region = np.asarray(mix, np.float64) @ np.asarray(matrix, np.float64)
    return (per_region[..., None] * np.asarray(region_states, np.float64)[None]).astype(np.float32)


def _table(ctx: DriverContext, spec: Mapping[str, Any]) -> Mapping[str, Mapping[str, float]]:
    preset = spec.get("preset")
    if preset is None:
        if not ctx.expressions:
            raise spec_problem(ctx, "no expression table: set preset = 'jimenez' or [expressions]")
        return ctx.expressions
    if preset != "jimenez":
        raise spec_problem(ctx, f"unknown expression preset {preset!r} (jimenez)", "preset")

    return jimenez.expression_table()


@register("expressions")
def expressions_driver(
    ctx: DriverContext, spec: Mapping[str, Any], times: np.ndarray | None
) -> DriverResult:
    table = _table(ctx, spec)
    names, matrix = expression_matrix(table, ctx.regions, ctx.source)
    fps = float(spec.get("fps", ctx.fps))
    if "morphs" in spec and "keys" not in spec and "file" not in spec:
        mix_raw = spec["morphs"]
        unknown = [e for e in mix_raw if e not in names]
        if unknown:
            raise spec_problem(ctx, unknown_names("expression", unknown, names), "morphs")
        times = np.zeros(1) if times is None else times
        mix = np.array([[float(mix_raw.get(e, 0.0)) for e in names]] * len(times))
    else:
        keys, interp, _ = load_keys(ctx, spec)
        if not keys:
            raise spec_problem(ctx, "expressions driver needs 'keys' (or 'morphs')", "keys")
        unknown = [e for e in keys if e not in names]
        if unknown:
            raise spec_problem(ctx, unknown_names("expression", unknown, names), "keys")
        if times is None:
            times = frame_times(*keys_range(keys), fps)
        mix = sample_keys(keys, names, times, interp)
    if ctx.policy == "signed":
        w = (mix @ matrix.astype(np.float64))[..., None].astype(np.float32)
        states: tuple[str, ...] = ("signed",)
    else:
        w = weights(mix, matrix, ctx.region_states)
        states = ctx.states
    return DriverResult("expressions", np.asarray(times, np.float64), w, ctx.regions, states)
