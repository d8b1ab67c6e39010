"""A small vectorised triangle rasteriser in UV space (numpy, no GL).

Used by the texture-space variant of dynamic weights (Oat's first attempt) and for UV coverage.
Texel ``(row y, column x)`` has its centre at ``u = (x + 0.5) / size``, ``v = (y + 0.5) / size``
(row 0 is v = 0, the glTF convention). A texel belongs to a triangle when its centre lies inside
or on an edge; where UV triangles overlap the highest triangle index wins (deterministic).
"""

from __future__ import annotations

import numpy as np

#: Candidate texels processed per chunk (bounds memory on large triangles).
CHUNK_TEXELS = 4_000_000


def rasterise_triangle_ids(uvs: np.ndarray, indices: np.ndarray, size: int) -> np.ndarray:
    """Triangle index per texel ``[size, size]`` int64, -1 where no triangle covers it."""
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
    nx = np.where(finite, np.maximum(hi[:, 0] - lo[:, 0] + 1, 0), 0)
    ny = np.where(finite, np.maximum(hi[:, 1] - lo[:, 1] + 1, 0), 0)
    count = nx * ny
    ends = np.cumsum(count)
    starts = ends - count
    total = int(ends[-1]) if len(ends) else 0
    # Chunks of triangles with about CHUNK_TEXELS candidate texels (a loop over chunks only).
    n_t = len(idx)
    cuts = np.searchsorted(ends, np.arange(1, total // CHUNK_TEXELS + 1) * CHUNK_TEXELS) + 1
    edges = np.unique(np.concatenate([[0], np.minimum(cuts, n_t), [n_t]]))
    for t0, t1 in zip(edges[:-1], edges[1:]):
        sel = np.arange(t0, t1)
        c = count[sel]
        n = int(c.sum())
        if n == 0:
            continue
        t = np.repeat(sel, c)
        k = np.arange(n) - np.repeat(starts[sel] - starts[t0], c)
        x = lo[t, 0] + k % nx[t]
        y = lo[t, 1] + k // nx[t]
        inside = _inside(tri[t], x.astype(np.float64), y.astype(np.float64))
        np.maximum.at(out, (y * size + x)[inside], t[inside])
    return out.reshape(size, size)


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
