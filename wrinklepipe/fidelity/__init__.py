"""Fidelity: the shipped asset against the full-resolution source, where the wrinkles are.

One measure (DESIGN.md section 8), used by every automatic choice and every check that judges a
loss: :mod:`.metric` (per pose and region, activation-weighted, the base over the face),
its statistics and budgets are :mod:`wrinklepipe.metrics`'s.
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

__all__ = [
    "Fidelity",
    "Pose",
    "PoseFidelity",
    "Reference",
    "Samples",
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
]
