"""The grid operators of the shape-from-shading solve (:mod:`wrinklepipe.capture.sfs`): the
ROI as a grid of unknowns with its finite differences, the blur of the ratio image on it, the
algebraic-multigrid preconditioner, the integration of a slope field into a height, and the
down/up-sampling between the solve's levels."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyamg
from scipy import ndimage, sparse
from scipy.sparse import linalg as spla


@dataclass(frozen=True)
class _Grid:
    """Unknowns (ROI pixels), data rows, and the difference operators restricted to them."""

    shape: tuple[int, int]
    unknown: np.ndarray  # flat indices of the unknown pixels
    dx: sparse.csr_matrix  # central d/dcol at the unknown pixels, [U, U] (0 outside)
    dy: sparse.csr_matrix  # central d/drow
    reg: sparse.csr_matrix  # forward differences (both axes, stacked), [E, U]
    #: the integration system's preconditioner, set up once per grid (it depends on the grid only)
    cache: dict = field(default_factory=dict, compare=False, repr=False)
    free: bool = False  # the border is free (not tied to c = 0 outside)


def _grid(mask: np.ndarray, free: bool = False) -> _Grid:
    """The operators on the unknown pixels of ``mask``. ``free``: the height is not tied to 0
    outside the mask (one-sided differences at its border, no smoothness edge across it)."""
    h, w = mask.shape
    flat = np.flatnonzero(mask.ravel())
    col_of = np.full(h * w, -1, np.int64)
    col_of[flat] = np.arange(len(flat))
    r, c = np.divmod(flat, w)

    def neighbour(dr: int, dc: int) -> np.ndarray:
        rr, cc = r + dr, c + dc
        ok = (rr >= 0) & (rr < h) & (cc >= 0) & (cc < w)
        out = np.full(len(flat), -1, np.int64)
        out[ok] = col_of[rr[ok] * w + cc[ok]]
        return out  # -1: outside the unknowns (c = 0 there)

    rows = np.arange(len(flat))
    n = len(flat)

    def central(plus: np.ndarray, minus: np.ndarray) -> sparse.csr_matrix:
        ip, im = plus >= 0, minus >= 0
        if not free:  # c = 0 outside: central differences with zeros there
            data = np.concatenate([np.full(ip.sum(), 0.5), np.full(im.sum(), -0.5)])
            rr = np.concatenate([rows[ip], rows[im]])
            cc = np.concatenate([plus[ip], minus[im]])
            return sparse.csr_matrix((data, (rr, cc)), shape=(n, n))
        # free border: central inside, one-sided where one neighbour is outside, 0 where both
        both, only_p, only_m = ip & im, ip & ~im, im & ~ip
        half = np.where(both, 0.5, 1.0)
        use_p, use_m = ip & (both | only_p), im & (both | only_m)
        data = np.concatenate(
            [half[use_p], -half[use_m], -np.ones(only_p.sum()), np.ones(only_m.sum())]
        )
        rr = np.concatenate([rows[use_p], rows[use_m], rows[only_p], rows[only_m]])
        cc = np.concatenate([plus[use_p], minus[use_m], rows[only_p], rows[only_m]])
        return sparse.csr_matrix((data, (rr, cc)), shape=(n, n))

    dx = central(neighbour(0, 1), neighbour(0, -1))
    dy = central(neighbour(1, 0), neighbour(-1, 0))
    regs = []
    for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0)):
        nb = neighbour(dr, dc)
        # every edge from an unknown to its neighbour; edges to the outside (c = 0) count once
        # each way, edges between two unknowns only in the +col / +row direction
        keep = (nb < 0) | ((dr, dc) in ((0, 1), (1, 0)))
        if free:  # no edge to the outside
            keep &= nb >= 0
        k = np.flatnonzero(keep)
        m = len(k)
        inside = nb[k] >= 0
        data = np.concatenate([np.full(m, -1.0), np.ones(inside.sum())])
        rr = np.concatenate([np.arange(m), np.arange(m)[inside]])
        cc = np.concatenate([k, nb[k][inside]])
        regs.append(sparse.csr_matrix((data, (rr, cc)), shape=(m, n)))
    return _Grid((h, w), flat, dx, dy, sparse.vstack(regs).tocsr(), free=free)


@dataclass(frozen=True)
class _Blur:
    """The Gaussian blur R was measured with, as an operator on values at the unknown pixels
    (0 elsewhere; symmetric, so it is its own adjoint)."""

    shape: tuple[int, int]
    unknown: np.ndarray
    sigma: float

    def __call__(self, v: np.ndarray) -> np.ndarray:
        img = np.zeros(self.shape[0] * self.shape[1])
        img[self.unknown] = v
        out = ndimage.gaussian_filter(img.reshape(self.shape), self.sigma, mode="constant")
        return out.ravel()[self.unknown]

    def ratio(self, rho: np.ndarray) -> np.ndarray:
        """The blurred model ratio: outside the unknowns the crease is 0 and the ratio 1."""
        return 1.0 + self(rho - 1.0)


def _blur_on_grid(sigma: float, k: int, grid: _Grid) -> _Blur | None:
    """R's blur (``sigma`` photo pixels) on the grid downsampled by ``k``, with the box filter
    of the downsampling itself (variance (1 - 1/k^2) / 12 grid pixels^2)."""
    var = (sigma / k) ** 2 + (1.0 - 1.0 / (k * k)) / 12.0
    return _Blur(grid.shape, grid.unknown, float(np.sqrt(var))) if var > 1e-4 else None


def _downsample(img: np.ndarray, k: int) -> np.ndarray:
    if k == 1:
        return img
    h, w = img.shape[:2]
    hh, ww = h // k, w // k
    x = img[: hh * k, : ww * k]
    return x.reshape((hh, k, ww, k) + img.shape[2:]).mean(axis=(1, 3))


def _extend(c: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``c`` outside ``mask`` replaced by its nearest value inside (so that differences at the
    mask's border are one-sided, as the free border's operators are)."""
    if mask.all() or not mask.any():
        return c
    _, (ri, ci) = ndimage.distance_transform_edt(~mask, return_indices=True)
    return c[ri, ci]


def _up_nearest(img: np.ndarray, k: int, shape: tuple[int, int]) -> np.ndarray:
    """A solve grid's image at full resolution (nearest; edge rows repeated)."""
    if k == 1:
        return img
    rows = np.minimum(np.arange(shape[0]) // k, img.shape[0] - 1)
    cols = np.minimum(np.arange(shape[1]) // k, img.shape[1] - 1)
    return img[np.ix_(rows, cols)]


def _to_full(
    c_small: np.ndarray,
    unknown: np.ndarray,
    small: tuple[int, int],
    k: int,
    shape: tuple[int, int],
    in_roi: np.ndarray,
    free: bool = False,
) -> np.ndarray:
    """A solve grid's unknown heights back at full resolution: heights scale with the pixel
    size, bilinear in between, 0 outside the ROI (``free``: the border's heights extended
    outwards before the interpolation)."""
    c = np.zeros(small)
    c.ravel()[unknown] = c_small
    if k == 1:
        return c
    if free:
        inside = np.zeros(small, bool)
        inside.ravel()[unknown] = True
        c = _extend(c, inside)
    h, w = shape
    rows = (np.arange(h) + 0.5) / k - 0.5
    cols = (np.arange(w) + 0.5) / k - 0.5
    yy, xx = np.meshgrid(rows, cols, indexing="ij")
    c = ndimage.map_coordinates(c, [yy, xx], order=1, mode="nearest") * k
    return np.where(in_roi, c, 0.0)


def _integrate(grid: _Grid, qx: np.ndarray, qy: np.ndarray) -> np.ndarray:
    """Least-squares height with central-difference slopes ``q`` and ``c = 0`` outside."""
    if "integrate" not in grid.cache:
        a = grid.dx.T @ grid.dx + grid.dy.T @ grid.dy + 1e-3 * (grid.reg.T @ grid.reg)
        if grid.free:  # the height's constant is free: a tiny shrink fixes it
            a = a + 1e-6 * sparse.identity(a.shape[0])
        a = a.tocsr()
        grid.cache["integrate"] = (a, _multigrid(a))
    a, precond = grid.cache["integrate"]
    b = grid.dx.T @ qx + grid.dy.T @ qy
    x, _ = spla.cg(a, b, rtol=1e-6, maxiter=300, M=precond)
    return x


def _multigrid(a: sparse.csr_matrix) -> spla.LinearOperator:
    """A smoothed-aggregation V-cycle preconditioner, set up deterministically: pyamg estimates
    spectral radii from a random start drawn from numpy's global generator, which is seeded
    for the setup and restored after (byte-identical outputs on a rerun)."""
    state = np.random.get_state()
    try:
        np.random.seed(0x5F5)
        ml = pyamg.smoothed_aggregation_solver(a, symmetry="hermitian", max_coarse=200)
    finally:
        np.random.set_state(state)
    return ml.aspreconditioner(cycle="V")
