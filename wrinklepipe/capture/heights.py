"""Heights the shape-from-shading solve starts from (:mod:`wrinklepipe.capture.sfs`): the neutral
surface's height from its slopes (a Poisson solve), and the eikonal height of a mask (the
``integrable`` prior)."""

from __future__ import annotations

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse import linalg as spla
from threadpoolctl import threadpool_limits

from wrinklepipe.capture.grid import (
    _multigrid,
)


def neutral_height(mask: np.ndarray, g0: np.ndarray) -> np.ndarray:
    """The neutral's height (pixels, up to a constant) over ``mask`` from its slopes ``g0``
    ``[H, W, 2]`` (pixel frame): least squares over the forward differences between pixels of
    the mask (the slopes outside it are not used); 0 outside."""
    h, w = mask.shape
    flat = np.flatnonzero(mask.ravel())
    col_of = np.full(h * w, -1, np.int64)
    col_of[flat] = np.arange(len(flat))
    r, c = np.divmod(flat, w)
    rows, cols, data, rhs = [], [], [], []
    e = 0
    for dr, dc, axis in ((0, 1, 0), (1, 0, 1)):  # the two forward differences
        rr, cc = r + dr, c + dc
        ok = (rr < h) & (cc < w)
        nb = np.full(len(flat), -1, np.int64)
        nb[ok] = col_of[rr[ok] * w + cc[ok]]
        k = np.flatnonzero(nb >= 0)
        m = len(k)
        idx = np.arange(e, e + m)
        rows += [idx, idx]
        cols += [k, nb[k]]
        data += [np.full(m, -1.0), np.ones(m)]
        gv = g0[..., axis].ravel()
        rhs.append(0.5 * (gv[flat[k]] + gv[flat[nb[k]]]))  # the slope midway
        e += m
    d = sparse.csr_matrix(
        (np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=(e, len(flat))
    )
    a = (d.T @ d + 1e-6 * sparse.identity(len(flat))).tocsr()
    with threadpool_limits(1):
        x, _ = spla.cg(a, d.T @ np.concatenate(rhs), rtol=1e-8, maxiter=500, M=_multigrid(a))
    out = np.zeros(h * w)
    out[flat] = x - x.mean()
    return out.reshape(h, w)


def eikonal_height(
    slope: np.ndarray, mask: np.ndarray, border: np.ndarray, upward: bool = True
) -> np.ndarray:
    """The viscosity solution of ``|grad u| = slope`` over ``mask`` with ``u = border`` on the
    mask's border pixels (Rouy-Tourin upwind scheme, Jacobi sweeps to convergence).

    ``upward``: the largest solution (every critical point inside is a maximum: the surface
    climbs from the border wherever the slopes allow), else the smallest (minima). Where the
    true surface has no critical point of the other kind, its slope magnitudes and border values
    determine it: on a neutral turned from the camera this is where the expression's surface
    (neutral + crease) keeps climbing or falling through the crease, i.e. where the sign of the
    crease's slope is in the photos.
    """
    big = 1e30
    sgn = 1.0 if upward else -1.0
    f = np.where(mask, np.maximum(np.asarray(slope, np.float64), 0.0), 0.0)
    fixed = ~mask | (mask & ~ndimage.binary_erosion(mask))  # outside and the border ring
    u = np.where(fixed & mask, sgn * np.asarray(border, np.float64), big)
    u = np.where(mask, u, big)
    h, w = mask.shape
    for it in range(4 * (h + w)):  # upwind sweeps until nothing changes (about the diameter)
        p = np.pad(u, 1, constant_values=big)
        a = np.minimum(p[1:-1, :-2], p[1:-1, 2:])
        b = np.minimum(p[:-2, 1:-1], p[2:, 1:-1])
        d = np.abs(a - b)
        two = 0.5 * (a + b + np.sqrt(np.maximum(2.0 * f * f - d * d, 0.0)))
        new = np.where(d >= f, np.minimum(a, b) + f, two)
        new = np.where(fixed, u, np.minimum(u, new))
        if it % 8 == 7 and float(np.max(np.abs(np.where(mask, new - u, 0.0)))) < 1e-9:
            u = new
            break
        u = new
    return np.where(mask & (u < 0.5 * big), sgn * u, 0.0)
