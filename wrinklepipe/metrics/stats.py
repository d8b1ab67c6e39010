"""Weighted statistics of per-texel errors (mean, p99, max) and the budget verdict.

The p99 is the **weighted nearest rank**: the smallest error ``x`` whose cumulative weight
``W(e <= x)`` reaches 99 % of the total (a relative tolerance of 1e-12 absorbs the rounding of
float sums, so the last texel is never missed). With unit weights it is the ``ceil(0.99 n)``-th
smallest error (``numpy.percentile(e, 99, method="inverted_cdf")``). Texels of zero (or
negative) weight never count; a NaN error (a texel that decodes to nothing) counts as
:data:`NAN_DEG`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: The quantile every report calls p99.
P99 = 0.99
#: Decimals of a degree the reports print statistics with, and the verdict compares them at.
DECIMALS = 4
#: What a NaN error counts as: a texel that decodes to nothing is as wrong as can be.
NAN_DEG = 180.0
#: Relative slack on the quantile's target weight (float sums round; never miss the last texel).
_SLACK = 1.0 - 1e-12
#: Unit-weight arrays above this many errors find their p99 among a sampled tail.
_SAMPLE_ABOVE = 1 << 16


@dataclass(frozen=True)
class Stats:
    """Weighted error statistics in degrees over ``texels`` texels of total ``weight``."""

    mean: float
    p99: float
    max: float
    texels: int
    weight: float

    def to_json(self) -> dict[str, float | int]:
        return {
            "mean_deg": round(self.mean, DECIMALS),
            "p99_deg": round(self.p99, DECIMALS),
            "max_deg": round(self.max, DECIMALS),
            "texels": self.texels,
            "weight": round(self.weight, 3),
        }

    def within(self, budget: Budget) -> bool:
        """:meth:`Budget.ok`: the verdict."""
        return budget.ok(self)


#: The statistics of nothing (no texel of positive weight).
EMPTY = Stats(0.0, 0.0, 0.0, 0, 0.0)


def _finite(e: np.ndarray) -> np.ndarray:
    """``e`` with NaN errors counted as :data:`NAN_DEG` (a copy only when there are some)."""
    bad = np.isnan(e)
    if not bad.any():
        return e
    return np.where(bad, e.dtype.type(NAN_DEG), e)


def weighted_stats(
    errors: np.ndarray, weights: np.ndarray | None = None, overwrite: bool = False
) -> Stats:
    """Weighted mean, p99 (nearest rank) and max of ``errors`` (degrees) over the texels of
    positive weight; every weight 1 when ``weights`` is None (then ``overwrite`` lets the
    errors be reordered in place: the caller's own temporary)."""
    e = np.asarray(errors).ravel()
    if weights is None:
        return _unit_stats(e, overwrite)
    w = np.asarray(weights).ravel()
    if w.size != e.size:
        raise ValueError(f"{e.size} errors but {w.size} weights")
    keep = w > 0
    if not keep.all():
        e, w = e[keep], w[keep]
    if e.size == 0:
        return EMPTY
    total = float(w.sum(dtype=np.float64))
    if total <= 0.0:
        return EMPTY
    mean = float(np.dot(e.astype(np.float64), w.astype(np.float64)) / total)
    if not math.isfinite(mean):
        e = _finite(e)
        mean = float(np.dot(e.astype(np.float64), w.astype(np.float64)) / total)
    lo, hi = float(e.min()), float(e.max())
    return Stats(mean, _quantile(e, w, P99, lo, hi, total), hi, int(e.size), total)


def _unit_stats(e: np.ndarray, overwrite: bool) -> Stats:
    """:func:`weighted_stats` with every weight 1, without the weights' arrays: the mean is the
    float64 sum over the count (equal to the weighted mean to rounding), the p99 the
    ``ceil(0.99 n)``-th smallest error (the weighted nearest rank of unit weights, with the
    same slack), found by selection among the errors at or above a sampled threshold."""
    n = int(e.size)
    if n == 0:
        return EMPTY
    total = float(e.sum(dtype=np.float64))
    if not math.isfinite(total):
        e, overwrite = _finite(e), True
        total = float(e.sum(dtype=np.float64))
    k = min(max(math.ceil(P99 * n * _SLACK), 1), n)  # the rank of the p99 (1-based)
    hi = float(e.max())
    cand, below = e, 0
    if n > _SAMPLE_ABOVE:
        # a fixed pseudo-random sample (a stride could alias with image columns) puts a
        # threshold safely below the p99 (the sample's 98th percentile: ten standard errors
        # below); only the errors at or above it (about 2 %) are selected among
        sample = e[np.random.default_rng(0x5EED).integers(0, n, _SAMPLE_ABOVE)]
        r = int(0.98 * _SAMPLE_ABOVE)
        lo = np.partition(sample, r)[r]
        tail = e[e >= lo]
        if n - tail.size < k:  # the threshold is below the p99 (else: select among all)
            cand, below, overwrite = tail, n - tail.size, True
    r = k - 1 - below
    if overwrite:
        cand.partition(r)
        p99 = float(cand[r])
    else:
        p99 = float(np.partition(cand, r)[r])
    return Stats(total / n, p99, hi, n, float(n))


def weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """The weighted ``q``-quantile: the smallest value ``x`` with ``W(v <= x) >= q W(all)``
    (the nearest rank; ``q = 0.5`` with unit weights is the lower median). Exact, in linear
    time: a weighted histogram finds the bin that holds it, and only that bin is sorted.
    Texels of zero weight never count. Returns 0 when the total weight is 0."""
    v = np.asarray(values).ravel()
    w = np.asarray(weights).ravel()
    keep = w > 0
    if not keep.all():
        v, w = v[keep], w[keep]
    if v.size == 0:
        return 0.0
    total = float(w.sum(dtype=np.float64))
    if total <= 0.0:
        return 0.0
    return _quantile(v, w, q, float(v.min()), float(v.max()), total)


def _quantile(v: np.ndarray, w: np.ndarray, q: float, lo: float, hi: float, total: float) -> float:
    """:func:`weighted_quantile` of positive weights whose min, max and sum are known."""
    if hi <= lo:
        return lo
    target = q * total * _SLACK
    nb = int(min(max(v.size // 64, 16), 1 << 16))
    scale = nb / (hi - lo)
    # a range of a few denormals makes the scale overflow float32 (inf * 0 -> NaN bins): such
    # values are binned in float64, where the scale of any float32 range is finite
    small = v.dtype != np.float64 and scale >= float(np.finfo(np.float32).max) / 4
    vv = v.astype(np.float64) if small else v
    b = ((vv - lo) * scale).astype(np.int64)
    np.minimum(b, nb - 1, out=b)
    cum = np.cumsum(np.bincount(b, weights=w, minlength=nb))
    k = min(int(np.searchsorted(cum, target, side="left")), nb - 1)
    below = float(cum[k - 1]) if k > 0 else 0.0
    sel = b == k
    vb, wb = v[sel], w[sel]
    order = np.argsort(vb, kind="stable")
    c = below + np.cumsum(wb[order], dtype=np.float64)
    j = int(np.searchsorted(c, target, side="left"))
    return float(vb[order][min(j, vb.size - 1)])


def weighted_stats_many(errors: np.ndarray, weights: np.ndarray) -> list[Stats]:
    """:func:`weighted_stats` of one error array under each row of ``weights`` ``[G, n]`` (the
    regions of a pose), with one sort for all rows.

    Each row is read on its own texels of positive weight only: their places in the one
    stable sort of the errors, sorted, give the row's values and weights in order, whose
    float64 running sum is the one over the whole sorted row (the texels left out add 0). The
    mean is the row's dot product over those texels (equal to :func:`weighted_stats`'s to
    rounding); p99, max and texels are the same values."""
    e = _finite(np.asarray(errors).ravel())
    w = np.asarray(weights)
    if e.size == 0:  # no texel (a pose with nothing on one UDIM tile): every row is empty
        return [EMPTY] * (w.shape[0] if w.ndim > 1 else 1)
    w = w.reshape(-1, e.size)
    order = np.argsort(e, kind="stable")
    rank = np.empty(e.size, np.int64)  # each texel's place in the sorted order
    rank[order] = np.arange(e.size)
    out = []
    for g in range(w.shape[0]):
        pos = np.flatnonzero(w[g] > 0)
        if pos.size == 0:
            out.append(EMPTY)
            continue
        at = order[np.sort(rank[pos])]  # the row's texels in the sorted order
        wg = w[g][at].astype(np.float64)
        es = e[at].astype(np.float64)
        cw = np.cumsum(wg)
        total = float(cw[-1])
        j = min(int(np.searchsorted(cw, P99 * total * _SLACK, side="left")), pos.size - 1)
        out.append(
            Stats(float(np.dot(es, wg) / total), float(es[j]), float(es[-1]), pos.size, total)
        )
    return out


def _units(value: float) -> int:
    """``value`` in units of the last printed decimal, rounded half up."""
    return math.floor(value * 10**DECIMALS + 0.5)


@dataclass(frozen=True)
class Budget:
    """The largest allowed mean / p99 / max error in degrees (None: not limited)."""

    mean: float | None = None
    p99: float | None = None
    max: float | None = None

    @classmethod
    def from_dict(cls, d: dict[str, float] | None, prefix: str = "") -> Budget:
        """From a manifest's ``[budget]`` keys (``max_mean_deg``...; ``prefix`` e.g.
        ``"compressed_"``)."""
        d = d or {}
        return cls(
            d.get(f"{prefix}max_mean_deg"),
            d.get(f"{prefix}max_p99_deg"),
            d.get(f"{prefix}max_max_deg"),
        )

    @property
    def empty(self) -> bool:
        """True when no statistic is limited."""
        return self.mean is None and self.p99 is None and self.max is None

    def _pairs(self, s: Stats) -> list[tuple[str, float, float]]:
        return [
            (n, v, float(lim))
            for n, v, lim in (
                ("mean", s.mean, self.mean),
                ("p99", s.p99, self.p99),
                ("max", s.max, self.max),
            )
            if lim is not None
        ]

    def over(self, s: Stats) -> list[str]:
        """The statistics of ``s`` the verdict finds over their limits (``"mean"``, ``"p99"``,
        ``"max"``): compared at :data:`DECIMALS` decimals, as the reports print them."""
        return [n for n, v, lim in self._pairs(s) if _units(v) > _units(lim)]

    def ok(self, s: Stats) -> bool:
        """The verdict (the validator's): every limited statistic, at :data:`DECIMALS`
        decimals, at most its limit at :data:`DECIMALS` decimals."""
        return not self.over(s)

    def inside(self, s: Stats) -> bool:
        """The automatic choices' test: every limited statistic at most its limit, unrounded.
        Rounding is monotonic, so what is inside is ok; and a choice keeps a margin of half a
        printed unit (5e-5 degrees) that the verdict's rounding cannot cross."""
        return all(v <= lim for _, v, lim in self._pairs(s))

    def excess(self, s: Stats) -> str:
        """``"mean 0.5003 > 0.5"``: the statistics the verdict finds over their limits, printed
        at :data:`DECIMALS` decimals (so a value is never shown equal to the limit it breaks)."""
        return ", ".join(
            f"{n} {v:.{DECIMALS}f} > {lim:g}" for n, v, lim in self._pairs(s) if n in self.over(s)
        )

    def describe(self) -> str:
        """``"mean 0.5, p99 1"``: the limits that are set."""
        items = (("mean", self.mean), ("p99", self.p99), ("max", self.max))
        return ", ".join(f"{n} {v:g}" for n, v in items if v is not None)

    def to_json(self) -> dict[str, float]:
        """The manifest's keys of the limits that are set."""
        items = (("max_mean_deg", self.mean), ("max_p99_deg", self.p99), ("max_max_deg", self.max))
        return {k: v for k, v in items if v is not None}
