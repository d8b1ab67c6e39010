"""Fidelity: the shipped asset against the full-resolution source, where the wrinkles are.

One measure (DESIGN.md section 8), used by every automatic choice and every check that judges a
loss: :mod:`.metric` (per pose and region, activation-weighted, the base over the face),
:mod:`.stats` (exact weighted percentiles, budgets).
"""

from __future__ import annotations

from wrinklepipe.fidelity.metric import (
    Fidelity,
    Pose,
    PoseFidelity,
    Reference,
    Samples,
    base_fidelity,
    describe,
    evaluate,
    expression_poses,
    footprint,
    measure,
    merge,
    prepare,
    sample,
    sample_at,
    sample_masks_at,
    source_states,
)
from wrinklepipe.fidelity.stats import Budget, Stats, weighted_quantile, weighted_stats

__all__ = [
    "Budget",
    "Fidelity",
    "Pose",
    "PoseFidelity",
    "Reference",
    "Samples",
    "Stats",
    "base_fidelity",
    "describe",
    "evaluate",
    "expression_poses",
    "footprint",
    "measure",
    "merge",
    "prepare",
    "sample",
    "sample_at",
    "sample_masks_at",
    "source_states",
    "weighted_quantile",
    "weighted_stats",
]
