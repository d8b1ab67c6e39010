"""Per-vertex fields rendered into a UV layout: supersampled, padded, optionally blurred.

The texture-space half of authoring (masks from blend shapes, normal maps baked from sculpts):

- :func:`uv_samples`: the supersampled sample points of a ``size`` x ``size`` map that the
  mesh's UV triangles cover. Sample ``(i, j)`` of texel ``(row y, column x)`` sits at
  ``u = (x + (j + 0.5) / s) / size``, ``v = (y + (i + 0.5) / s) / size`` (``s`` the
  supersampling factor; row 0 is v = 0, the glTF convention of
  :mod:`wrinklepipe.geometry.rasterise`, which decides coverage). Each covered sample carries
  its triangle and barycentric coordinates, so any per-vertex attribute is interpolated there
  exactly (:func:`interpolate`).
- :func:`resolve`: per-sample values averaged into texels (a box filter over the texel's
  ``s x s`` samples: the anti-aliasing) and the covered fraction of every texel. A texel half
  covered keeps the average of its covered samples: island borders are not darkened.
- :func:`blur_covered`: a Gaussian of ``sigma`` texels as a normalised convolution over the
  covered texels (``G * (c f) / G * c``, ``c`` the coverage), so empty texels never pull values
  towards 0 and the blur of a constant island is that constant.
- :func:`pad_islands`: every empty texel within ``pixels`` of an island takes the value of its
  nearest covered texel (Euclidean distance, ties to the lowest index), as bakers' "edge
  padding" does, so bilinear filtering and mip maps across island borders read the island's
  own values.

Where UV islands overlap, the triangle that comes last in ``order`` (default: the last
triangle) owns the sample: callers put the triangles they care about last.

:func:`render_sparse` does all four for many per-vertex fields that are zero on most of the
mesh (a mask per blend shape): each field is rendered in the window around the samples of the
triangles it is non-zero on, widened by ``2 * ceil(3 sigma) + 2 * padding + 2`` texels (the
blur's reach twice and the padding's twice, so every texel that can differ from 0 sees exactly
the samples, coverage and nearest island texels it would see in the whole map); outside the
window the field is 0, as the whole-map computation gives. Its cost follows the fields' area,
not their number times the map's.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from wrinklepipe.geometry.rasterise import rasterise_triangle_ids

#: Samples whose attributes are interpolated at once (bounds the working set of callers).
CHUNK_SAMPLES = 1 << 20


@dataclass(frozen=True)
class UvSamples:
    """The covered sample points of a ``size`` x ``size`` map at ``supersample`` per axis."""

    size: int
    supersample: int
    texel: np.ndarray  # [S] int64: flat texel index (row * size + column)
    triangle: np.ndarray  # [S] int32: index into the mesh's triangles
    bary: np.ndarray  # [S, 3] float32: barycentric coordinates in that triangle (sum 1)

    @property
    def count(self) -> int:
        return int(len(self.texel))

    def chunks(self, n: int = CHUNK_SAMPLES) -> Iterator[slice]:
        """Slices of at most ``n`` samples, in order."""
        for s in range(0, self.count, n):
            yield slice(s, min(s + n, self.count))


def tiles(size: int, tile: int) -> Iterator[tuple[int, int, int, int]]:
    """Texel windows ``(r0, r1, c0, c1)`` (half-open) of at most ``tile`` x ``tile`` covering a
    ``size`` x ``size`` map, row by row."""
    for r0 in range(0, size, tile):
        for c0 in range(0, size, tile):
            yield r0, min(r0 + tile, size), c0, min(c0 + tile, size)


def uv_samples(
    uvs: np.ndarray,
    indices: np.ndarray,
    size: int,
    supersample: int = 2,
    order: np.ndarray | None = None,
    window: tuple[int, int, int, int] | None = None,
) -> UvSamples:
    """The covered samples of a ``size`` x ``size`` map (see the module doc), or of the texel
    ``window`` ``(r0, r1, c0, c1)`` of it (the same samples the whole map has there; texel
    indices stay those of the whole map).

    ``uvs`` ``[V, 2]`` (glTF convention), ``indices`` ``[T, 3]``. ``order`` ``[T]`` (a
    permutation of the triangles) sets who owns a sample where UV triangles overlap: the one
    that comes last. Samples are listed texel by texel, row by row."""
    if size <= 0 or supersample <= 0:
        raise ValueError(f"size and supersample must be positive, got {size}, {supersample}")
    s = int(supersample)
    n = size * s
    r0, r1, c0, c1 = window or (0, size, 0, size)
    th, tw = r1 - r0, c1 - c0
    uv = np.asarray(uvs, np.float64)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    perm = np.arange(len(idx)) if order is None else np.asarray(order, dtype=np.int64)
    if (th, tw) != (size, size):
        # a window: the triangles that reach it (fine-grid bounding boxes, a sample of margin)
        corner = uv[idx[perm]] * n - 0.5
        lo, hi = corner.min(axis=1), corner.max(axis=1)
        near = (hi[:, 0] >= c0 * s - 1) & (lo[:, 0] <= c1 * s) & (hi[:, 1] >= r0 * s - 1)
        near &= lo[:, 1] <= r1 * s
        perm = perm[near]
    side = max(th, tw) * s
    # the window's fine grid as a square raster of its own: x' = uv n - c0 s (exact shift)
    whole = (th, tw) == (size, size)
    shifted = uv if whole else (uv * n - np.array([c0 * s, r0 * s], np.float64)) / side
    ids = rasterise_triangle_ids(shifted, idx[perm], side)[: th * s, : tw * s]
    # sample (row r, column c) of the fine grid -> texel (r // s, c // s); list texel by texel
    fine = ids.reshape(th, s, tw, s).transpose(0, 2, 1, 3).reshape(-1)
    del ids
    hit = np.flatnonzero(fine >= 0)
    tri = perm[fine[hit]]
    del fine
    local = hit // (s * s)
    k = hit - local * (s * s)
    del hit
    row = r0 + local // tw
    col = c0 + local % tw
    px = (col * s + k % s + 0.5) / n
    py = (row * s + k // s + 0.5) / n
    del k
    bary = barycentric_in(uv, idx, tri, px, py)
    return UvSamples(size, s, row * size + col, tri.astype(np.int32), bary)


def barycentric_in(
    uvs: np.ndarray, indices: np.ndarray, tri: np.ndarray, px: np.ndarray, py: np.ndarray
) -> np.ndarray:
    """Barycentric coordinates ``[N, 3]`` float32 of the points ``(px, py)`` in the UV
    triangles ``tri`` (clipped to [0, 1] and renormalised: samples on an edge stay on it),
    through each triangle's inverse edge matrix (computed once per triangle, float64)."""
    corner = uvs[indices]  # [T, 3, 2]
    a = corner[:, 0]
    e = np.stack([corner[:, 1] - a, corner[:, 2] - a], axis=-1)  # [T, 2, 2]: columns edges
    det = e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0]
    inv_det = np.where(det != 0, 1.0 / np.where(det != 0, det, 1.0), 0.0)
    # rows of the inverse: (wb, wc) = inv @ (p - a)
    m = np.stack(
        [e[:, 1, 1] * inv_det, -e[:, 0, 1] * inv_det, -e[:, 1, 0] * inv_det, e[:, 0, 0] * inv_det],
        axis=-1,
    )
    dx = px - a[tri, 0]
    dy = py - a[tri, 1]
    mt = m[tri]
    out = np.empty((len(tri), 3), np.float32)
    out[:, 1] = mt[:, 0] * dx + mt[:, 1] * dy
    out[:, 2] = mt[:, 2] * dx + mt[:, 3] * dy
    out[:, 0] = 1.0 - out[:, 1] - out[:, 2]
    np.clip(out, 0.0, 1.0, out=out)
    out /= np.maximum(out.sum(axis=1, keepdims=True), np.float32(1e-30))
    return out


def interpolate(
    samples: UvSamples, indices: np.ndarray, values: np.ndarray, part: slice | None = None
) -> np.ndarray:
    """Per-vertex ``values`` ``[V, C]`` (or ``[V]``) at the samples ``part`` (all by default):
    ``[S, C]``, barycentric interpolation; float32 values stay float32, others are float64."""
    sel = part if part is not None else slice(None)
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    vals = np.asarray(values)
    vals = vals if vals.dtype == np.float32 else vals.astype(np.float64)
    flat = vals.ndim == 1
    vals = vals[:, None] if flat else vals
    corners = idx[samples.triangle[sel]]  # [S, 3]
    w = samples.bary[sel].astype(vals.dtype, copy=False)
    out = vals[corners[:, 0]] * w[:, 0:1]
    out += vals[corners[:, 1]] * w[:, 1:2]
    out += vals[corners[:, 2]] * w[:, 2:3]
    return out[:, 0] if flat else out


def resolve(samples: UvSamples, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Texels ``[size, size, C]`` (mean of each texel's covered samples, 0 where none) and the
    covered fraction ``[size, size]`` in [0, 1], from the values ``[S, C]`` of every sample
    (for chunks: :func:`accumulate`, then :func:`finish`)."""
    vals = np.asarray(values, dtype=np.float64)
    vals = vals[:, None] if vals.ndim == 1 else vals
    sums, counts = empty_sums(samples, vals.shape[1])
    accumulate(samples, vals, slice(0, samples.count), sums, counts)
    return finish(samples, sums, counts)


def empty_sums(samples: UvSamples, channels: int) -> tuple[np.ndarray, np.ndarray]:
    """Zeroed running sums ``[size*size, channels]`` and counts ``[size*size]``."""
    n_tex = samples.size * samples.size
    return np.zeros((n_tex, channels)), np.zeros(n_tex)


def accumulate(
    samples: UvSamples, values: np.ndarray, part: slice, sums: np.ndarray, counts: np.ndarray
) -> None:
    """Add the values ``[S', C]`` of the samples ``part`` into ``sums`` and ``counts``."""
    vals = np.asarray(values, dtype=np.float64)
    vals = vals[:, None] if vals.ndim == 1 else vals
    n_tex = len(counts)
    texel = samples.texel[part]
    for c in range(vals.shape[1]):
        sums[:, c] += np.bincount(texel, vals[:, c], minlength=n_tex)
    counts += np.bincount(texel, minlength=n_tex)


def finish(
    samples: UvSamples, sums: np.ndarray, counts: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The texels ``[size, size, C]`` and coverage ``[size, size]`` of running sums."""
    size = samples.size
    img = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], 0.0)
    cover = counts / float(samples.supersample**2)
    return img.reshape(size, size, -1), cover.reshape(size, size)


def blur_covered(image: np.ndarray, coverage: np.ndarray, sigma: float) -> np.ndarray:
    """Normalised Gaussian blur of ``image`` ``[H, W, C]`` over covered texels (``coverage``
    ``[H, W]`` in [0, 1] weights each texel); texels with no coverage stay 0. ``sigma`` in
    texels; 0 returns the image unchanged."""
    if sigma <= 0:
        return np.asarray(image, dtype=np.float64)
    img = np.asarray(image, dtype=np.float64)
    cov = np.asarray(coverage, dtype=np.float64)
    den = ndimage.gaussian_filter(cov, sigma, mode="constant", truncate=3.0)
    out = np.zeros_like(img)
    ok = (cov > 0) & (den > 1e-12)
    for c in range(img.shape[2]):
        num = ndimage.gaussian_filter(img[..., c] * cov, sigma, mode="constant", truncate=3.0)
        out[..., c] = np.where(ok, num / np.where(ok, den, 1.0), 0.0)
    return out


def pad_islands(
    image: np.ndarray, covered: np.ndarray, pixels: int, fill: np.ndarray | float = 0.0
) -> np.ndarray:
    """``image`` ``[H, W, C]`` with every uncovered texel within ``pixels`` (Euclidean) of a
    covered one set to its nearest covered texel's value; farther texels get ``fill``."""
    img = np.asarray(image)
    cov = np.asarray(covered, dtype=bool)
    out = np.array(img, copy=True)
    if cov.all():
        return out
    out[~cov] = fill
    if not cov.any() or pixels <= 0:
        return out
    dist, (ri, ci) = ndimage.distance_transform_edt(~cov, return_indices=True)
    near = ~cov & (dist <= pixels)
    out[near] = img[ri[near], ci[near]]
    return out


def render_sparse(
    samples: UvSamples,
    indices: np.ndarray,
    values: np.ndarray,
    blur: float,
    padding: int,
) -> np.ndarray:
    """Per-vertex fields ``values`` ``[R, V]`` (each mostly 0) as maps ``[R, size, size]``
    float32: supersampled, blurred over covered texels (``blur`` sigma in texels), padded by
    ``padding`` texels (see the module doc)."""
    size = samples.size
    idx = np.asarray(indices, dtype=np.int64).reshape(-1, 3)
    vals = np.asarray(values, dtype=np.float64)
    out = np.zeros((len(vals), size, size), np.float32)
    n_tex = size * size
    counts = np.bincount(samples.texel, minlength=n_tex).reshape(size, size).astype(np.float64)
    cover_all = counts / float(samples.supersample**2)
    # the samples of each triangle, as runs of one stable order
    order = np.argsort(samples.triangle, kind="stable")
    first = np.searchsorted(samples.triangle[order], np.arange(len(idx) + 1))
    reach = 2 * int(np.ceil(3.0 * blur)) + 2 * int(padding) + 2
    for r, field_r in enumerate(vals):
        hot = np.flatnonzero((field_r[idx] != 0).any(axis=1))
        n = first[hot + 1] - first[hot]
        if not n.sum():
            continue
        pick = order[np.repeat(first[hot] - np.cumsum(n) + n, n) + np.arange(int(n.sum()))]
        texel = samples.texel[pick]
        rows, cols = texel // size, texel % size
        r0, r1 = max(int(rows.min()) - reach, 0), min(int(rows.max()) + reach + 1, size)
        c0, c1 = max(int(cols.min()) - reach, 0), min(int(cols.max()) + reach + 1, size)
        w = c1 - c0
        corners = idx[samples.triangle[pick]]
        v = np.einsum("sk,sk->s", samples.bary[pick], field_r[corners])
        local = (rows - r0) * w + (cols - c0)
        sums = np.bincount(local, v, minlength=(r1 - r0) * w).reshape(r1 - r0, w)
        cnt = counts[r0:r1, c0:c1]
        img = np.where(cnt > 0, sums / np.maximum(cnt, 1.0), 0.0)[..., None]
        cover = cover_all[r0:r1, c0:c1]
        img = blur_covered(img, cover, blur)
        img = pad_islands(img, cover > 0, padding)
        out[r, r0:r1, c0:c1] = img[..., 0]
    return out
