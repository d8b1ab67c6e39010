"""Polygon soup -> render triangles, the steps every mesh reader shares (array in, array out).

- :func:`weld_corners`: the render vertices of a polygon mesh are its distinct corners (a
  point with its UV and normal); a corner that differs in any of them splits the vertex.
- :func:`fan_triangles`: every polygon of ``counts`` corners as a fan ``(s, s+k+1, s+k+2)``.
- :func:`drop_degenerate`: triangles with a repeated index or zero area left out.

The OBJ and USD readers use all three; the glTF readers (triangles, strips and fans already
indexed) the last.
"""

from __future__ import annotations

import numpy as np


def weld_corners(key: np.ndarray, point: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Number the distinct rows of ``key`` ``[C, k]`` (one per polygon corner): returns each
    corner's render vertex ``[C]`` and, per render vertex, one corner it comes from ``[V]``.

    Vertices are numbered by first appearance; with ``point`` (``[C]``, each corner's point)
    by point first, so that a mesh without splits keeps its points' order."""
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    order = np.argsort(first, kind="stable") if point is None else np.lexsort((first, point[first]))
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    return rank[inv], first[order]


def fan_triangles(counts: np.ndarray) -> np.ndarray:
    """``[T, 3]`` corner indices (into the polygons' concatenated corners) of every polygon
    of ``counts[i] >= 3`` corners, fan-triangulated from its first corner."""
    counts = np.asarray(counts, np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    n_tri = counts - 2
    poly = np.repeat(np.arange(len(counts)), n_tri)
    k = np.arange(n_tri.sum()) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri)
    s = starts[poly]
    return np.stack([s, s + k + 1, s + k + 2], axis=1)


def drop_degenerate(positions: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, int]:
    """Remove triangles with repeated indices or zero area; return (kept, removed count)."""
    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(tris, dtype=np.int64)
    rep = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
    tri = p[t]
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    keep = ~rep & (area2 > 0)
    return t[keep], int((~keep).sum())
