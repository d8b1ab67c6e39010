"""One measure: the angle error, the weighted statistics and the budget verdict.

Every number that judges a loss (the automatic choices of convert, the validator's rules, the
reports' tables, the benchmarks) comes from here, so a choice made inside a budget is inside it
for the validator too:

- :func:`angle_deg` / :func:`angle_deg_planes`: the angle between two vectors in degrees
  (float32, ``atan2(|a x b|, a . b)``: accurate near 0 and 180 degrees, for vectors of any
  length).
- :func:`weighted_stats`: the weighted mean, p99 and max of per-texel errors as one
  :class:`Stats` (unit weights when none are given); :func:`weighted_stats_many` for several
  weight rows over one error array; :func:`weighted_quantile` for any other quantile.
  **The p99 is the weighted nearest rank**: the smallest error ``x`` with
  ``W(e <= x) >= 0.99 W(all)`` (texels of zero weight never count); with unit weights, the
  ``ceil(0.99 n)``-th smallest error. No interpolation: the p99 is always a measured error.
- :class:`Budget`: the largest allowed mean / p99 / max; :meth:`Budget.ok` is the verdict
  (statistics and limits compared at :data:`DECIMALS` decimals, the precision every report
  prints), :meth:`Budget.inside` the automatic choices' stricter test (unrounded: at least half
  a printed unit inside what :meth:`Budget.ok` accepts).

- :func:`delta_e` / :func:`delta_e_lab` / :func:`linear_to_lab`: CIEDE2000 between linear
  sRGB colours (colour-science, loaded on first use), the colour states' error.

numpy only (the core layer), but for the CIEDE2000 functions' deferred colour-science.
"""

from __future__ import annotations

from wrinklepipe.metrics.angles import angle_deg, angle_deg_planes
from wrinklepipe.metrics.delta_e import delta_e, delta_e_lab, linear_to_lab
from wrinklepipe.metrics.stats import (
    DECIMALS,
    EMPTY,
    NAN_DEG,
    P99,
    Budget,
    Stats,
    weighted_quantile,
    weighted_stats,
    weighted_stats_many,
)

__all__ = [
    "DECIMALS",
    "EMPTY",
    "NAN_DEG",
    "P99",
    "Budget",
    "Stats",
    "angle_deg",
    "angle_deg_planes",
    "delta_e",
    "delta_e_lab",
    "linear_to_lab",
    "weighted_quantile",
    "weighted_stats",
    "weighted_stats_many",
]
