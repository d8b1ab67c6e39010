"""Check a set of region masks: coverage per region, where masks overlap past 1, empty regions.

These are findings, not errors: a sum above 1 is legal (the policy decides what happens there) but
an artist usually wants to know where and by how much. Hard errors (sizes, range, names) are raised
by :func:`wrinklepipe.masks.read.stack_masks` and :func:`mask_from_pixels`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class CheckOptions:
    """``eps``: a texel covers a region when its mask exceeds ``eps``; the sum of masks overlaps
    when it exceeds ``1 + eps``."""

    eps: float = 1e-6


@dataclass
class RegionCoverage:
    """One region: the fraction of texels it covers (> eps), its mean and its peak value."""

    name: str
    coverage: float
    mean: float
    peak: float


@dataclass
class MaskReport:
    """What :func:`check_masks` found. ``to_json()`` is deterministic."""

    size: tuple[int, int]  # (height, width)
    regions: list[RegionCoverage]
    empty: list[str]  # regions that cover nothing
    overlap_texels: int  # texels where sum_r M_r > 1 + eps
    overlap_max: float  # largest sum_r M_r
    overlap_worst: tuple[int, int] | None  # (x, y) of the largest sum, if it exceeds 1
    uncovered_fraction: float  # texels no region covers
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "size": list(self.size),
            "regions": [
                {
                    "name": r.name,
                    "coverage": round(r.coverage, 6),
                    "mean": round(r.mean, 6),
                    "peak": round(r.peak, 6),
                }
                for r in self.regions
            ],
            "empty": list(self.empty),
            "overlap": {
                "texels": self.overlap_texels,
                "max_sum": round(self.overlap_max, 6),
                "worst_texel": list(self.overlap_worst) if self.overlap_worst else None,
            },
            "uncovered_fraction": round(self.uncovered_fraction, 6),
            "warnings": list(self.warnings),
        }


def check_masks(
    masks: np.ndarray, names: Sequence[str], options: CheckOptions | None = None
) -> MaskReport:
    """Coverage, overlap (sum above 1) and empty regions of ``masks`` ``[R, H, W]`` in [0, 1]."""
    opt = options or CheckOptions()
    m = np.asarray(masks, dtype=np.float32)
    r, h, w = m.shape
    flat = m.reshape(r, -1)
    covered = flat > opt.eps
    coverage = covered.mean(axis=1)
    means = flat.mean(axis=1)
    peaks = flat.max(axis=1)
    regions = [
        RegionCoverage(str(n), float(c), float(mu), float(p))
        for n, c, mu, p in zip(names, coverage, means, peaks)
    ]
    empty = [str(n) for n, c in zip(names, covered.any(axis=1)) if not c]
    total = flat.sum(axis=0, dtype=np.float64)
    over = total > 1.0 + opt.eps
    n_over = int(over.sum())
    worst = int(np.argmax(total))
    max_sum = float(total[worst])
    worst_xy = (worst % w, worst // w) if n_over else None
    uncovered = float((~covered.any(axis=0)).mean())
    warnings = [f"region {n!r} covers nothing (its mask is 0 everywhere)" for n in empty]
    if n_over:
        warnings.append(
            f"masks sum above 1 at {n_over} texels ({100.0 * n_over / total.size:.2f}%), up to "
            f"{max_sum:.4f} at texel (x={worst_xy[0]}, y={worst_xy[1]})"
        )
    return MaskReport((h, w), regions, empty, n_over, max_sum, worst_xy, uncovered, warnings)
