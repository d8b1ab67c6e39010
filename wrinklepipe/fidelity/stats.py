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
    v = np.asarray(values, np.float64).ravel()
    w = np.asarray(weights, np.float64).ravel()
    keep = w > 0
    if not keep.all():
        v, w = v[keep], w[keep]
    total = float(w.sum())
    if v.size == 0 or total <= 0.0:
        return 0.0
    target = q * total
    lo, hi = float(v.min()), float(v.max())
    if hi <= lo:
        return lo
    nb = int(min(max(v.size // 64, 16), 1 << 16))
    b = np.minimum(((v - lo) * (nb / (hi - lo))).astype(np.int64), nb - 1)
    cum = np.cumsum(np.bincount(b, weights=w, minlength=nb))
    k = int(np.searchsorted(cum, target * (1.0 - 1e-12), side="left"))
    k = min(k, nb - 1)
    below = float(cum[k - 1]) if k > 0 else 0.0
    sel = b == k
    vb, wb = v[sel], w[sel]
    order = np.argsort(vb, kind="stable")
    c = below + np.cumsum(wb[order])
    j = int(np.searchsorted(c, target * (1.0 - 1e-12), side="left"))
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
    e = np.asarray(err, np.float64).ravel()
    w = np.asarray(weights, np.float64).ravel()
    keep = w > 0
    e, w = e[keep], w[keep]
    total = float(w.sum())
    if e.size == 0 or total <= 0.0:
        return EMPTY
    return Stats(
        mean=float(np.dot(e, w) / total),
        p99=weighted_quantile(e, w, 0.99),
        max=float(e.max()),
        texels=int(e.size),
        weight=total,
    )


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
        parts = [
            f"{n} {v:g}" for n, v in (("mean", self.mean), ("p99", self.p99), ("max", self.max))
        ]
        return ", ".join(p for p, v in zip(parts, (self.mean, self.p99, self.max)) if v is not None)
