"""Weighted statistics of angular errors, and error budgets."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def weighted_quantile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """The weighted ``q``-quantile: the smallest value ``x`` with ``W(v <= x) >= q W(all)``.

    Exact, in linear time: a weighted histogram finds the bin that holds the quantile, and only
    that bin's values are sorted. ``q = 0.5`` with unit weights is the lower median. Texels of
    zero weight never count. Returns 0 when the total weight is 0.
    """
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
    target = q * total * (1.0 - 1e-12)  # cumulative sums round; never miss the last texel
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


@dataclass(frozen=True)
class Stats:
    """Activation-weighted angular error in degrees over ``texels`` texels of total ``weight``."""

    mean: float
    p99: float
    max: float
    texels: int
    weight: float

    def to_json(self) -> dict[str, float | int]:
        return {
            "mean_deg": round(self.mean, 4),
            "p99_deg": round(self.p99, 4),
            "max_deg": round(self.max, 4),
            "texels": self.texels,
            "weight": round(self.weight, 3),
        }

    def within(self, budget: Budget) -> bool:
        return budget.ok(self)


EMPTY = Stats(0.0, 0.0, 0.0, 0, 0.0)


def weighted_stats(err: np.ndarray, weights: np.ndarray) -> Stats:
    """Weighted mean, p99 and max of ``err`` (degrees) over texels of positive weight."""
    e = np.asarray(err).ravel()
    w = np.asarray(weights).ravel()
    keep = w > 0
    if not keep.all():
        e, w = e[keep], w[keep]
    if e.size == 0:
        return EMPTY
    total = float(w.sum(dtype=np.float64))
    if total <= 0.0:
        return EMPTY
    lo, hi = float(e.min()), float(e.max())
    return Stats(
        mean=float(np.dot(e.astype(np.float64), w.astype(np.float64)) / total),
        p99=_quantile(e, w, 0.99, lo, hi, total),
        max=hi,
        texels=int(e.size),
        weight=total,
    )


def unit_stats(err: np.ndarray, overwrite: bool = False) -> Stats:
    """:func:`weighted_stats` of ``err`` with every weight 1 (the base over the face) without
    the weights' arrays: the total is the count, the mean the float64 sum over it (pairwise,
    converted as it goes: no float64 copies; equal to the weighted mean to rounding), and the
    p99 the weighted quantile of unit weights, which is an order statistic (the
    ``ceil(0.99 n (1 - 1e-12))``-th smallest, found by selection: the same value).
    ``overwrite``: ``err`` may be reordered in place (the caller's own temporary)."""
    e = np.asarray(err).ravel()
    if e.size == 0:
        return EMPTY
    total = float(e.size)
    target = 0.99 * total * (1.0 - 1e-12)  # as _quantile: the first rank whose count reaches it
    k = min(max(int(np.ceil(target)), 1), e.size)
    mean = float(e.sum(dtype=np.float64)) / total
    hi = float(e.max())
    if overwrite:
        e.partition(k - 1)
        p99 = float(e[k - 1])
    else:
        p99 = float(np.partition(e, k - 1)[k - 1])
    return Stats(mean=mean, p99=p99, max=hi, texels=int(e.size), weight=total)


def weighted_stats_many(err: np.ndarray, weights: np.ndarray) -> list[Stats]:
    """:func:`weighted_stats` of one error array under each row of ``weights`` ``[G, n]`` (the
    regions of a pose), with one sort for all rows: vectorised weighted percentiles.

    Each row is read on its own texels of positive weight only (a region covers a small part
    of a pose's active texels): their places in the one stable sort of ``err``, sorted, give
    the row's values and weights in that order, whose float64 running sum is the one over the
    whole sorted row (the texels left out add 0). Max, p99 and texels are those of the whole
    row; the mean is its dot product over those texels (equal to rounding)."""
    e = np.asarray(err).ravel()
    w = np.asarray(weights).reshape(-1, e.size)
    if e.size == 0:
        return [EMPTY] * w.shape[0]
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
        # the first texel where the cumulative weight reaches 99 %
        j = int(np.searchsorted(cw, 0.99 * total * (1.0 - 1e-12), side="left"))
        j = min(j, pos.size - 1)
        out.append(
            Stats(
                mean=float(np.dot(es, wg) / total),
                p99=float(es[j]),
                max=float(es[-1]),
                texels=int(pos.size),
                weight=total,
            )
        )
    return out


@dataclass(frozen=True)
class Budget:
    """Largest allowed mean / p99 / max degrees (None: not limited)."""

    mean: float | None = None
    p99: float | None = None
    max: float | None = None

    @classmethod
    def from_dict(cls, d: dict[str, float] | None, prefix: str = "") -> Budget:
        d = d or {}
        return cls(
            d.get(f"{prefix}max_mean_deg"),
            d.get(f"{prefix}max_p99_deg"),
            d.get(f"{prefix}max_max_deg"),
        )

    def ok(self, s: Stats) -> bool:
        return (
            (self.mean is None or s.mean <= self.mean)
            and (self.p99 is None or s.p99 <= self.p99)
            and (self.max is None or s.max <= self.max)
        )

    def describe(self) -> str:
        """``"mean 0.5, p99 1"``: the limits that are set."""
        items = (("mean", self.mean), ("p99", self.p99), ("max", self.max))
        return ", ".join(f"{n} {v:g}" for n, v in items if v is not None)
