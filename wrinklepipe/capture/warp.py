"""Thin-plate-spline warps between landmark sets (Dutreve et al. section 3.1 and 3.2).

Coordinates are in pixels with the origin at the top-left *corner* of the image, x to the right
and y down, so the centre of pixel ``(row, col)`` is ``(col + 0.5, row + 0.5)``. A warp maps a
position in the *destination* image (the one we fill) to the position in the *source* image we
sample, so a fitted warp is used as a backward map: ``dst[p] = src[warp(p)]``.

The spline is scipy's :class:`~scipy.interpolate.RBFInterpolator` with the ``thin_plate_spline``
kernel, zero smoothing and a degree-1 polynomial: it passes through every landmark and
reproduces any affine map exactly. For speed the map is evaluated on a coarse grid (every
``step`` pixels) and refined with cubic interpolation; the landmark residual of the refined map
is reported so the approximation is never hidden.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.interpolate import RBFInterpolator

#: Landmark sets must span 2-D: the smallest singular value of the centred points, relative to the
#: largest, below which they are called collinear.
COLLINEAR_TOL = 1e-3

#: Extra coarse-grid cells evaluated beyond each image edge by :func:`dense_map`.
COARSE_MARGIN = 4

#: ``dense_map(step=0)`` evaluates the spline at every pixel up to this many pixels, on a
#: 2-pixel grid above.
EXACT_PIXELS = 1024 * 1024


@dataclass(frozen=True)
class TpsWarp:
    """A fitted thin-plate spline ``dst -> src`` (both ``[N, 2]`` pixel positions)."""

    dst: np.ndarray
    src: np.ndarray
    interp: RBFInterpolator

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Source positions ``[M, 2]`` of destination positions ``[M, 2]`` (float64)."""
        return np.asarray(self.interp(np.asarray(points, np.float64)), np.float64)


def is_collinear(points: np.ndarray) -> bool:
    """True when the points do not span the plane (a thin-plate spline needs 3 non-collinear)."""
    p = np.asarray(points, np.float64)
    if len(p) < 3:
        return True
    sv = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    return bool(sv[0] == 0 or sv[1] / sv[0] < COLLINEAR_TOL)


def fit_tps(dst: np.ndarray, src: np.ndarray) -> TpsWarp:
    """Fit the interpolating thin-plate spline with ``warp(dst[i]) == src[i]``."""
    d = np.asarray(dst, np.float64)
    s = np.asarray(src, np.float64)
    interp = RBFInterpolator(d, s, kernel="thin_plate_spline", smoothing=0.0, degree=1)
    return TpsWarp(d, s, interp)


def dense_map(warp: TpsWarp, shape: tuple[int, int], step: int = 0) -> np.ndarray:
    """Source position of every destination pixel centre: ``[H, W, 2]`` (x, y) float64.

    ``step = 1`` evaluates the spline at every pixel (``0``: every pixel up to
    ``EXACT_PIXELS``, every second above); larger steps evaluate a uniform coarse
    grid (with a margin beyond the edges) and refine with cubic B-spline interpolation: exact
    for affine maps up to rounding, far below a pixel for smooth ones (see
    ``landmark_residuals``).
    """
    h, w = shape
    if step <= 0:
        step = 1 if h * w <= EXACT_PIXELS else 2
    gy, gx = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    if step == 1:
        return warp(np.stack([gx.ravel(), gy.ravel()], axis=-1)).reshape(h, w, 2)
    # A uniform coarse grid reaching COARSE_MARGIN cells beyond every edge (the spline is
    # defined everywhere), so the cubic refinement has full support inside the image. Its
    # affine part is removed before the refinement and added back exactly.
    m = COARSE_MARGIN
    rows = np.arange(-m * step, h - 1 + (m + 1) * step, step, dtype=np.float64)
    cols = np.arange(-m * step, w - 1 + (m + 1) * step, step, dtype=np.float64)
    cy, cx = np.meshgrid(rows + 0.5, cols + 0.5, indexing="ij")
    pts = np.stack([cx.ravel(), cy.ravel()], axis=-1)
    vals = warp(pts)
    design = np.column_stack([pts, np.ones(len(pts))])
    aff, *_ = np.linalg.lstsq(design, vals, rcond=None)
    coarse = (vals - design @ aff).reshape(len(rows), len(cols), 2)
    fr, fc = np.meshgrid(
        (np.arange(h) - rows[0]) / step, (np.arange(w) - cols[0]) / step, indexing="ij"
    )
    out = np.empty((h, w, 2), np.float64)
    for c in range(2):
        out[..., c] = ndimage.map_coordinates(coarse[..., c], [fr, fc], order=3, mode="nearest")
        out[..., c] += aff[0, c] * gx + aff[1, c] * gy + aff[2, c]
    return out


def sample(
    image: np.ndarray, positions: np.ndarray, order: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Sample ``image`` ``[H, W]`` or ``[H, W, C]`` at pixel positions ``[..., 2]`` (x, y).

    Returns the samples and a boolean mask of positions that fell inside the image (outside
    samples are 0). Linear interpolation by default.
    """
    img = np.asarray(image, np.float32)
    pos = np.asarray(positions, np.float64)
    h, w = img.shape[:2]
    r = pos[..., 1] - 0.5
    c = pos[..., 0] - 0.5
    inside = (r >= -0.5) & (r <= h - 0.5) & (c >= -0.5) & (c <= w - 0.5)
    coords = [np.clip(r, 0, h - 1), np.clip(c, 0, w - 1)]
    if img.ndim == 2:
        out = ndimage.map_coordinates(img, coords, order=order, mode="nearest")
    else:
        out = np.stack(
            [
                ndimage.map_coordinates(img[..., k], coords, order=order, mode="nearest")
                for k in range(img.shape[2])
            ],
            axis=-1,
        )
    out = np.where(inside[..., None] if img.ndim == 3 else inside, out, 0.0)
    return out.astype(np.float32), inside


def map_at(field: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Interpolate a dense map ``[H, W, 2]`` (from :func:`dense_map`) at pixel positions."""
    vals, _ = sample(field.astype(np.float32), points, order=3)
    return vals.astype(np.float64)


def landmark_residuals(field: np.ndarray, dst: np.ndarray, src: np.ndarray) -> np.ndarray:
    """Distance in pixels between the dense map at each ``dst`` landmark and its ``src`` ``[N]``."""
    return np.linalg.norm(map_at(field, dst) - np.asarray(src, np.float64), axis=-1)


def leave_one_out(dst: np.ndarray, src: np.ndarray) -> np.ndarray:
    """Per landmark: distance between ``src[i]`` and the spline fitted without landmark ``i``.

    The interpolating spline has zero residual at every landmark by construction, so this is
    the number that flags a mis-placed landmark. Needs 4 or more landmarks (NaN otherwise).
    """
    d = np.asarray(dst, np.float64)
    s = np.asarray(src, np.float64)
    n = len(d)
    out = np.full(n, np.nan)
    if n < 4:
        return out
    for i in range(n):  # one small fit per landmark (tens of them), not per pixel
        keep = np.arange(n) != i
        if is_collinear(d[keep]):
            continue
        out[i] = float(np.linalg.norm(fit_tps(d[keep], s[keep])(d[i : i + 1])[0] - s[i]))
    return out


def jacobian_rotation(field: np.ndarray) -> np.ndarray:
    """Local rotation of a dense map ``[H, W, 2]``: ``(cos, sin)`` per pixel ``[H, W, 2]``.

    The rotation is the orthogonal factor of the polar decomposition of the 2x2 Jacobian
    ``d src / d dst`` (for ``J = [[a, b], [c, d]]`` its angle is ``atan2(c - b, a + d)``). Scale
    and shear are dropped: a tangent-space normal is relative to unit tangent vectors.
    """
    f = np.asarray(field, np.float64)
    dx_dr, dx_dc = np.gradient(f[..., 0])
    dy_dr, dy_dc = np.gradient(f[..., 1])
    # J columns: d/dx_dst (= d/dcol) and d/dy_dst (= d/drow).
    a, b, c, d = dx_dc, dx_dr, dy_dc, dy_dr
    ang = np.arctan2(c - b, a + d)
    return np.stack([np.cos(ang), np.sin(ang)], axis=-1)


def rotate_normals(normals: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Express photo-space normals (+Y up) in the texture's tangent frame.

    ``rot`` is :func:`jacobian_rotation` of the texture -> photo map: the texture's tangent axes,
    seen in the photo (pixel frame, y down), are the rotation's columns; the normal's in-plane
    part is projected on them (``Q^T v``). Z is unchanged.
    """
    n = np.asarray(normals, np.float32)
    cos, sin = rot[..., 0], rot[..., 1]
    vx = n[..., 0]
    vy = -n[..., 1]  # to the pixel frame (y down)
    tx = cos * vx + sin * vy
    ty = -sin * vx + cos * vy
    return np.stack([tx, -ty, n[..., 2]], axis=-1).astype(np.float32)
