"""Fidelity: the shipped asset against the full-resolution source, where the wrinkles are.

One measure (DESIGN.md section 8), used by every automatic choice and every check that judges a
loss: :mod:`.reference` (the full-resolution side, prepared once), :mod:`.sampling` (the
shipped maps read at its texels), :mod:`.metric` (per pose and region, activation-weighted, the
base over the face); its statistics and budgets are :mod:`wrinklepipe.metrics`'s.
"""

from __future__ import annotations

from wrinklepipe.fidelity.metric import (
    Fidelity,
    PoseFidelity,
    Samples,
    TexelErrors,
    base_fidelity,
    describe,
    evaluate,
    measure,
    merge,
    pooled,
    sample,
)
from wrinklepipe.fidelity.reference import (
    Pose,
    Reference,
    expression_poses,
    footprint,
    prepare,
    source_states,
)
from wrinklepipe.fidelity.sampling import sample_at, sample_masks_at

__all__ = [
    "Fidelity",
    "Pose",
    "PoseFidelity",
    "Reference",
    "Samples",
    "TexelErrors",
    "base_fidelity",
    "describe",
    "evaluate",
    "expression_poses",
    "footprint",
    "measure",
    "merge",
    "pooled",
    "prepare",
    "sample",
    "sample_at",
    "sample_masks_at",
    "source_states",
]
