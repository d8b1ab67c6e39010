"""A small vectorised triangle rasteriser in UV space (numpy, no GL).

Used by the texture-space variant of dynamic weights (Oat's first attempt) and for UV coverage.
Texel ``(row y, column x)`` has its centre at ``u = (x + 0.5) / size``, ``v = (y + 0.5) / size``
(row 0 is v = 0, the glTF convention). A texel belongs to a triangle when its centre lies inside
or on an edge; where UV triangles overlap the highest triangle index wins (deterministic).
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.reuse import reused
from wrinklepipe.workset import band_rows

#: Bytes of temporaries per candidate texel (its triangle's corners, coordinates and edge
#: functions in float64, indices): a chunk of candidates takes a band's share of the working set
#: (:func:`wrinklepipe.workset.band_rows`; 4M candidates took about 500 MiB).
CANDIDATE_BYTES = 192


def triangle_ids(uvs: np.ndarray, indices: np.ndarray, size: int) -> np.ndarray:
    """Triangle index per texel ``[size, size]`` int64, -1 where no triangle covers it
    (:func:`rasterise_triangle_ids` without the run's memo: for a raster used once, which the
    memo would keep at 8 bytes a texel).

    Candidates are, per triangle and texel row of its bounding box, the texels of that row's
    span (each edge function is linear along the row: the span is where all three are on the
    inside, widened by one texel each way against rounding), so only a border of candidates
    around the covered texels is tested; every candidate is then tested exactly (edge
    functions, :func:`_inside`). The candidates hold every texel the test accepts, so the
    result is the test applied to every texel of every bounding box."""
    uv = np.asarray(uvs, dtype=np.float64) * size - 0.5  # texel-centre coordinates
    idx = np.asarray(indices, dtype=np.int64)
    out = np.full(size * size, -1, dtype=np.int64)
    if len(idx) == 0:
        return out.reshape(size, size)
    tri = uv[idx]  # [T, 3, 2]
    lo = np.ceil(tri.min(axis=1) - 1e-9).astype(np.int64)
    hi = np.floor(tri.max(axis=1) + 1e-9).astype(np.int64)
    lo = np.clip(lo, 0, size - 1)
    hi = np.clip(hi, -1, size - 1)
    finite = np.isfinite(tri).all(axis=(1, 2))
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    nx = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    ny = np.where(finite & (area != 0) & (nx > 0), np.maximum(hi[:, 1] - lo[:, 1] + 1, 0), 0)
    # one span per (triangle, row)
    rows_t = np.repeat(np.arange(len(idx)), ny)
    first = np.cumsum(ny) - ny
    y = lo[rows_t, 1] + np.arange(len(rows_t)) - np.repeat(first, ny)
    x0, x1 = _row_spans(tri[rows_t], area[rows_t], y.astype(np.float64))
    x0 = np.maximum(x0, lo[rows_t, 0])
    x1 = np.minimum(x1, hi[rows_t, 0])
    count = np.maximum(x1 - x0 + 1, 0)
    ends = np.cumsum(count)
    starts = ends - count
    total = int(ends[-1]) if len(ends) else 0
    # Chunks of spans with about `chunk` candidate texels (a loop over chunks only; each
    # candidate is tested on its own and the highest index kept: any chunking, the same ids).
    n_s = len(rows_t)
    chunk = band_rows(1, CANDIDATE_BYTES)
    cuts = np.searchsorted(ends, np.arange(1, total // chunk + 1) * chunk) + 1
    edges = np.unique(np.concatenate([[0], np.minimum(cuts, n_s), [n_s]]))
    for s0, s1 in zip(edges[:-1], edges[1:]):
        sel = np.arange(s0, s1)
        cnt = count[sel]
        n = int(cnt.sum())
        if n == 0:
            continue
        span = np.repeat(sel, cnt)
        t = rows_t[span]
        px = x0[span] + np.arange(n) - np.repeat(starts[sel] - starts[s0], cnt)
        py = y[span]
        inside = _inside(tri[t], px.astype(np.float64), py.astype(np.float64))
        np.maximum.at(out, (py * size + px)[inside], t[inside])
    return out.reshape(size, size)


def _row_spans(tri: np.ndarray, area: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per triangle (``[N, 3, 2]``, non-zero ``area``) and row ``y``: the texel columns
    ``[x0, x1]`` that can pass :func:`_inside`, widened by a texel each way. Edge ``p -> q``'s
    function along the row is ``e(x) = (q_x - p_x)(y - p_y) - (q_y - p_y)(x - p_x)``; inside is
    ``sign(area) e(x) >= -eps`` for all three, a half-line each (no bound for an edge along
    the row: the exact test decides)."""
    s = np.sign(area)
    eps = 1e-12 * np.maximum(np.abs(area), 1e-300)
    lo = np.full(len(y), -np.inf)
    hi = np.full(len(y), np.inf)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        p, q = tri[:, i], tri[:, j]
        k = -(q[:, 1] - p[:, 1]) * s  # s e(x) = k x + m
        m = ((q[:, 0] - p[:, 0]) * (y - p[:, 1]) + (q[:, 1] - p[:, 1]) * p[:, 0]) * s
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = (-eps - m) / k
        lo = np.where(k > 0, np.maximum(lo, bound), lo)
        hi = np.where(k < 0, np.minimum(hi, bound), hi)
    big = float(1 << 40)
    x0 = np.floor(np.clip(lo, -big, big)) - 1
    x1 = np.ceil(np.clip(hi, -big, big)) + 1
    return x0.astype(np.int64), x1.astype(np.int64)


def _inside(tri: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Point-in-triangle by edge functions, either winding, edges inclusive."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]

    def edge(p: np.ndarray, q: np.ndarray) -> np.ndarray:
        return (q[:, 0] - p[:, 0]) * (y - p[:, 1]) - (q[:, 1] - p[:, 1]) * (x - p[:, 0])

    e0, e1, e2 = edge(a, b), edge(b, c), edge(c, a)
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    eps = 1e-12 * np.maximum(np.abs(area), 1e-300)
    pos = (e0 >= -eps) & (e1 >= -eps) & (e2 >= -eps)
    neg = (e0 <= eps) & (e1 <= eps) & (e2 <= eps)
    return (pos | neg) & (area != 0)


#: :func:`triangle_ids` through the run's memo (:mod:`wrinklepipe.reuse`): a raster asked again in
#: one conversion is computed once.
rasterise_triangle_ids = reused(triangle_ids)
