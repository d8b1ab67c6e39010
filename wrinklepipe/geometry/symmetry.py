"""The mesh's plane of left/right symmetry, and each vertex's mirror partner.

Faces are modelled symmetric about a plane through the nose; the pipeline's convention puts the
character's left at +X (glTF: +Y up, facing +Z), so the search looks at planes whose normal lies
within 45 degrees of +X: first a coarse grid of 21 x 21 normals, each through the median of
the points along it, scored by the median distance from a reflected point to its nearest
point (on at most 2000 of the points), then the best refined as a reflective ICP (iterative
closest point):

1. reflect every (welded) vertex across the current plane and find the vertex nearest to its
   reflection (a k-d tree);
2. keep the pairs whose distance is at most the median (the best-matched half);
3. the plane's normal is the principal direction of the pairs' differences ``p - p'`` (a
   mirror pair differs along the normal only), oriented towards +X; its offset is the median of
   the pairs' midpoints along it.

It stops when the normal moves less than 1e-9 rad and the offset less than 1e-9 of the size,
or after ``iterations``. :attr:`SymmetryPlane.residual` is the median distance between a
reflected vertex and its nearest vertex, relative to the bounding-box diagonal: about 0 for a
symmetric mesh; a large value says the mesh is not symmetric (the split is then only as good as
the plane ``x = median``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: The convention's left-right axis (the character's left is +X).
LEFT_AXIS = np.array([1.0, 0.0, 0.0])


@dataclass(frozen=True)
class SymmetryPlane:
    """``dot(normal, p) = offset``; ``normal`` (unit) points to the character's left."""

    normal: np.ndarray
    offset: float
    residual: float
    iterations: int = 0

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distances ``[N]`` of ``points`` ``[N, 3]`` (positive: the character's left)."""
        return np.asarray(points, np.float64) @ self.normal - self.offset

    def reflect(self, points: np.ndarray) -> np.ndarray:
        """``points`` ``[N, 3]`` mirrored across the plane."""
        p = np.asarray(points, np.float64)
        return p - 2.0 * self.distance(p)[:, None] * self.normal[None, :]


def symmetry_plane(positions: np.ndarray, iterations: int = 20) -> SymmetryPlane:
    """The mesh's symmetry plane (see the module doc) from its positions ``[V, 3]``."""
    p = np.unique(np.asarray(positions, np.float64), axis=0)
    diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) if len(p) else 0.0
    normal = LEFT_AXIS.copy()
    offset = float(np.median(p[:, 0])) if len(p) else 0.0
    if len(p) < 4 or diag <= 0:
        return SymmetryPlane(normal, offset, 0.0, 0)
    tree = cKDTree(p)
    normal, offset = _coarse(p, tree)
    done = 0
    for _ in range(iterations):
        done += 1
        plane = SymmetryPlane(normal, offset, 0.0)
        dist, j = tree.query(plane.reflect(p))
        keep = dist <= max(float(np.median(dist)), 1e-12 * diag)
        d = p[keep] - p[j[keep]]
        big = np.linalg.norm(d, axis=1) > 1e-9 * diag
        if big.sum() < 3:
            break
        _, _, vt = np.linalg.svd(d[big], full_matrices=False)
        n = vt[0] / np.linalg.norm(vt[0])
        if n @ LEFT_AXIS < 0:
            n = -n
        mid = 0.5 * (p[keep] + p[j[keep]])
        o = float(np.median(mid @ n))
        step = float(np.arccos(np.clip(n @ normal, -1.0, 1.0)))
        moved = abs(o - offset)
        normal, offset = n, o
        if step < 1e-9 and moved < 1e-9 * diag:
            break
    plane = SymmetryPlane(normal, offset, 0.0)
    dist, _ = tree.query(plane.reflect(p))
    return SymmetryPlane(normal, offset, float(np.median(dist)) / diag, done)


def _coarse(p: np.ndarray, tree: cKDTree) -> tuple[np.ndarray, float]:
    """The best of a 21 x 21 grid of normals within 45 degrees of +X (see the module doc)."""
    sub = p[:: max(1, len(p) // 2000)]
    a = np.linspace(-1.0, 1.0, 21)
    best = (np.inf, LEFT_AXIS.copy(), 0.0)
    for ay in a:
        for az in a:
            n = np.array([1.0, ay, az]) / np.sqrt(1.0 + ay * ay + az * az)
            o = float(np.median(sub @ n))
            dist, _ = tree.query(SymmetryPlane(n, o, 0.0).reflect(sub))
            score = float(np.median(dist))
            if score < best[0]:
                best = (score, n, o)
    return best[1], best[2]


def mirror_partners(positions: np.ndarray, plane: SymmetryPlane) -> tuple[np.ndarray, np.ndarray]:
    """Per vertex: the vertex nearest to its reflection ``[V]`` int64, and that distance."""
    p = np.asarray(positions, np.float64)
    dist, j = cKDTree(p).query(plane.reflect(p))
    return j.astype(np.int64), dist
