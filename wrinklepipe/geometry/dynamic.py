"""Dynamic wrinkle weights from the mesh's own stretch (Oat, "Real-Time Wrinkles", 2007).

Per triangle ``w_t = clamp((A_rest - A_deformed) / A_rest, -1, 1)``: positive when the skin
compresses (the "compress" wrinkle map), negative when it stretches, 0 when the area is kept.
Per vertex the weights are smoothed by the angle-weighted average over the incident triangles of
*every render vertex with the same vertex ID* (:mod:`wrinklepipe.geometry.vertex_ids`), so the
copies a UV seam splits get exactly the same weight. Oat's rest-pose bias (vertex colours) is
added before the final clamp.

:class:`DynamicWeights` builds two sparse operators once (edge differences ``E`` ``[2T, V]`` and
the smoothing operator ``S`` ``[V, T]``); a frame is ``E @ P`` -> areas -> ``S @ w``: two sparse
products and a few vector operations. ``E`` has exactly two entries a row (+1, -1), so it is kept
in index form (the triangles' corner indices) and applied as three gathers and two subtractions
per coordinate: the same product, without reading the constant values (measured faster than a
CSR product); ``S`` is a CSR matrix.

The deformed pose comes from :func:`morph_pose` (morph-target weights) or :func:`skinned_pose`
(linear blend skinning with joint world matrices). Oat's texture-space alternative (rasterise the
per-triangle weights into UV space and blur) is :func:`texture_space_weights`, kept for
comparison: it cannot smooth across UV seams.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.ndimage import gaussian_filter

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.rasterise import rasterise_triangle_ids
from wrinklepipe.geometry.vertex_ids import compute_vertex_ids
from wrinklepipe.names import noun, plural, unknown_names

NAME = "dynamic"


@dataclass(frozen=True)
class DynamicOptions:
    """Options of :class:`DynamicWeights`.

    weighting: ``"angle"`` (Oat: each triangle counts with its inner angle at the vertex, in the
        rest pose) or ``"uniform"`` (plain average of the incident triangles).
    min_rest_area: triangles whose rest area is at most this (mesh units squared) are skipped
        (weight 0, no vote); they are counted in :attr:`DynamicWeights.skipped_triangles`.
    dtype: float type of the per-frame arithmetic (float32 default; float64 for reference).
    """

    weighting: str = "angle"
    min_rest_area: float = 0.0
    dtype: str = "float32"


def triangle_areas(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Areas ``[T]`` (float64) of the triangles ``indices`` ``[T, 3]`` over ``positions``."""
    p = np.asarray(positions, dtype=np.float64)
    tri = p[np.asarray(indices, dtype=np.int64)]
    return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)


def triangle_weights(rest: np.ndarray, deformed: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Per-triangle weight ``clamp((A_rest - A_def) / A_rest, -1, 1)`` ``[T]`` float32.

    Positive when compressing. Zero-area rest triangles get 0.
    """
    a0 = triangle_areas(rest, indices)
    a1 = triangle_areas(deformed, indices)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = np.where(a0 > 0, (a0 - a1) / np.where(a0 > 0, a0, 1.0), 0.0)
    return np.clip(w, -1.0, 1.0).astype(np.float32)


def corner_angles(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Inner angles ``[T, 3]`` (radians, float64) at each corner; 0 for degenerate corners."""
    p = np.asarray(positions, dtype=np.float64)
    tri = p[np.asarray(indices, dtype=np.int64)]
    out = np.zeros(tri.shape[:2])
    for c in range(3):
        a = tri[:, (c + 1) % 3] - tri[:, c]
        b = tri[:, (c + 2) % 3] - tri[:, c]
        cr = np.linalg.norm(np.cross(a, b), axis=1)
        dt = np.einsum("ij,ij->i", a, b)
        out[:, c] = np.arctan2(cr, dt)
    return out


def check_topology(
    positions: np.ndarray, indices: np.ndarray, source: str = "mesh"
) -> tuple[np.ndarray, np.ndarray]:
    """Validate ``[V,3]`` positions and ``[T,3]`` indices; return them as float64 / int64.

    Raises :class:`InputError` for shapes, NaN positions, indices out of range, or no faces.
    """
    p = np.asarray(positions)
    idx = np.asarray(indices)
    if p.ndim != 2 or p.shape[1] != 3:
        raise input_error(source, f"positions must be [V, 3], got {list(p.shape)}")
    if idx.size == 0:
        raise input_error(source, "the mesh has no faces (0 triangles)")
    if idx.ndim != 2 or idx.shape[1] != 3:
        raise input_error(source, f"indices must be [T, 3] triangles, got {list(idx.shape)}")
    idx = idx.astype(np.int64)
    bad = (idx < 0) | (idx >= len(p))
    if bad.any():
        t = int(np.flatnonzero(bad.any(axis=1))[0])
        raise input_error(
            source,
            f"{plural(int(bad.any(axis=1).sum()), 'triangle')} "
            f"{noun(int(bad.any(axis=1).sum()), 'indexes', 'index')} vertices out of range "
            f"0..{len(p) - 1}"
            f" (first: triangle {t} = {idx[t].tolist()})",
            key=f"triangle {t}",
        )
    p64 = p.astype(np.float64)
    finite = np.isfinite(p64).all(axis=1)
    if not finite.all():
        v = int(np.flatnonzero(~finite)[0])
        raise input_error(
            source,
            f"{plural(int((~finite).sum()), 'position')} "
            f"{noun(int((~finite).sum()), 'is', 'are')} NaN or infinite (first: vertex {v})",
            key=f"vertex {v}",
        )
    return p64, idx


@dataclass
class DynamicWeights:
    """Per-vertex dynamic wrinkle weights for one mesh: built once, evaluated per frame.

    Use :meth:`build`; then :meth:`frame` (deformed positions -> ``[V]`` weights in [-1, 1]) and
    :meth:`triangle_frame` (-> ``[T]`` raw per-triangle weights).
    """

    corners: np.ndarray  # [3, T] intp: corner indices; E @ P = (P[c1] - P[c0], P[c2] - P[c0])
    smooth: sp.csr_matrix  # [V, T]: angle weights grouped by vertex ID, rows sum to 1 (or 0)
    inv_rest_area2: np.ndarray  # [T]: 1 / (2 * rest area); 0 for skipped triangles
    valid: np.ndarray  # [T]: 1 for triangles that vote, 0 for skipped ones
    bias: np.ndarray | None  # [V] added before the final clamp
    vertex_ids: np.ndarray  # [V]
    skipped_triangles: int = 0
    notes: list[str] = field(default_factory=list)

    @classmethod
    def build(
        cls,
        rest_positions: np.ndarray,
        indices: np.ndarray,
        vertex_ids: np.ndarray | None = None,
        bias: np.ndarray | None = None,
        options: DynamicOptions | None = None,
        source: str = "mesh",
    ) -> DynamicWeights:
        """Precompute the operators for a rest pose (``[V,3]``) and triangles (``[T,3]``).

        ``vertex_ids`` default to :func:`compute_vertex_ids` of the rest positions. ``bias``
        ``[V]`` is the artist's rest-pose wrinkle weight (e.g. a vertex-colour channel mapped to
        [-1, 1]).
        """

        opts = options or DynamicOptions()
        if opts.weighting not in ("angle", "uniform"):
            raise input_error(source, f"weighting must be 'angle' or 'uniform': {opts.weighting}")
        p, idx = check_topology(rest_positions, indices, source)
        n_v, n_t = len(p), len(idx)
        dtype = np.dtype(opts.dtype)
        ids = compute_vertex_ids(p, source=source) if vertex_ids is None else vertex_ids
        ids = np.asarray(ids, dtype=np.int64)
        if ids.shape != (n_v,):
            raise input_error(source, f"vertex_ids must have shape [{n_v}], got {list(ids.shape)}")
        if bias is not None:
            bias = np.asarray(bias, dtype=dtype).reshape(-1)
            if bias.shape != (n_v,):
                raise input_error(source, f"bias must have one value per vertex ({n_v})")

        corners = np.ascontiguousarray(idx.T, dtype=np.intp)

        area2 = 2.0 * triangle_areas(p, idx)
        ok = area2 > 2.0 * opts.min_rest_area
        skipped = int((~ok).sum())
        inv = np.zeros(n_t)
        inv[ok] = 1.0 / area2[ok]

        if opts.weighting == "angle":
            w = corner_angles(p, idx)
        else:
            w = np.ones((n_t, 3))
        w[~ok] = 0.0
        n_ids = int(ids.max()) + 1 if n_v else 0
        by_id = sp.csr_matrix(
            (w.reshape(-1), (ids[idx].reshape(-1), np.repeat(np.arange(n_t), 3))),
            shape=(n_ids, n_t),
        )
        total = np.asarray(by_id.sum(axis=1)).reshape(-1)
        scale = np.zeros_like(total)
        scale[total > 0] = 1.0 / total[total > 0]
        by_id = sp.diags(scale) @ by_id
        smooth = by_id[ids].astype(dtype).tocsr()
        smooth.sort_indices()
        notes = []
        if skipped:
            notes.append(f"skipped {plural(skipped, 'zero-area triangle')} (weight 0, no vote)")
        valid = ok.astype(dtype)
        return cls(corners, smooth, inv.astype(dtype), valid, bias, ids, skipped, notes)

    @property
    def edges(self) -> sp.csr_matrix:
        """The edge operator ``E`` ``[2T, V]`` as a CSR matrix (row t = p1 - p0, row T + t =
        p2 - p0 of triangle t); frames apply it in index form."""
        c0, c1, c2 = self.corners
        n_t = len(c0)
        rows = np.repeat(np.arange(2 * n_t), 2)
        cols = np.concatenate(
            [np.stack([c1, c0], axis=1).reshape(-1), np.stack([c2, c0], axis=1).reshape(-1)]
        )
        vals = np.tile(np.array([1.0, -1.0], dtype=self.inv_rest_area2.dtype), 2 * n_t)
        shape = (2 * n_t, self.smooth.shape[0])
        return sp.csr_matrix((vals, (rows, cols)), shape=shape)

    def triangle_frame(self, deformed_positions: np.ndarray) -> np.ndarray:
        """Per-triangle weights ``[T]`` for a deformed pose ``[V, 3]`` (first sparse product)."""
        dtype = self.inv_rest_area2.dtype
        p = np.asarray(deformed_positions, dtype=dtype)
        n_v = self.smooth.shape[0]
        if p.shape != (n_v, 3):
            raise input_error("pose", f"deformed positions must be [{n_v}, 3], got {list(p.shape)}")
        c0, c1, c2 = self.corners
        # E @ P per coordinate (contiguous columns): a = p1 - p0, b = p2 - p0.
        ab = []
        for x in np.ascontiguousarray(p.T):
            x0 = x.take(c0)
            a = x.take(c1)
            a -= x0
            b = x.take(c2)
            b -= x0
            ab.append((a, b))
        (ax, bx), (ay, by), (az, bz) = ab
        c = ay * bz
        c -= az * by
        s = c * c
        np.multiply(az, bx, out=c)
        c -= ax * bz
        s += c * c
        np.multiply(ax, by, out=c)
        c -= ay * bx
        s += c * c
        np.sqrt(s, out=s)
        s *= self.inv_rest_area2  # deformed / rest area; skipped triangles: 0
        np.subtract(self.valid, s, out=s)  # 1 - ratio, 0 where skipped
        np.clip(s, -1.0, 1.0, out=s)
        return s

    def frame(self, deformed_positions: np.ndarray) -> np.ndarray:
        """Smoothed per-vertex weights ``[V]`` in [-1, 1] (positive: compressed)."""
        w = self.smooth @ self.triangle_frame(deformed_positions)  # second sparse product
        if self.bias is not None:
            w += self.bias
        np.clip(w, -1.0, 1.0, out=w)
        return w


def morph_pose(mesh: Mesh, weights: dict[str, float], source: str = "") -> np.ndarray:
    """Positions ``[V, 3]`` float64 of ``mesh`` with morph targets applied by name."""
    src = source or mesh.name
    p = np.asarray(mesh.positions, dtype=np.float64).copy()
    if not weights:
        return p
    names = list(mesh.morph_names)
    if mesh.morph_deltas is None or not names:
        raise input_error(src, "the mesh has no morph targets")
    d = mesh.morph_deltas
    if d.ndim != 3 or d.shape[0] != len(names) or d.shape[1:] != p.shape:
        raise input_error(
            src,
            f"morph deltas must be [{len(names)}, {len(p)}, 3] (one per target and vertex),"
            f" got {list(d.shape)}",
        )
    unknown = [n for n in weights if n not in names or "@" in n]
    if unknown:
        raise input_error(src, unknown_names("morph target", unknown, names), key="--morph")
    for name, w in weights.items():
        if not np.isfinite(w):
            raise input_error(src, f"morph weight for {name!r} is not finite", key="--morph")
        p += _shape_offsets(names, d, name, float(w))
    return p


def _shape_offsets(names: list[str], deltas: np.ndarray, name: str, w: float) -> np.ndarray:
    """Offsets of shape ``name`` at weight ``w``, with UsdSkel-style inbetweens.

    Inbetweens are targets named ``"<name>@<weight>"``. The knots (0: no offset, each inbetween,
    1: the primary shape) are interpolated piecewise linearly; outside the knots the nearest
    segment is extrapolated.
    """
    knots = [(0.0, None), (1.0, names.index(name))]
    prefix = name + "@"
    for i, n in enumerate(names):
        if n.startswith(prefix):
            try:
                knots.append((float(n[len(prefix) :]), i))
            except ValueError:
                continue
    if len(knots) == 2:
        return w * deltas[names.index(name)].astype(np.float64)
    knots.sort(key=lambda k: k[0])
    ws = np.array([k[0] for k in knots])
    j = int(np.clip(np.searchsorted(ws, w, side="right") - 1, 0, len(ws) - 2))
    w0, i0 = knots[j]
    w1, i1 = knots[j + 1]
    a = (w - w0) / (w1 - w0)
    d0 = 0.0 if i0 is None else deltas[i0].astype(np.float64)
    d1 = 0.0 if i1 is None else deltas[i1].astype(np.float64)
    return (1.0 - a) * d0 + a * d1


def skinned_pose(mesh: Mesh, joint_matrices: np.ndarray, source: str = "") -> np.ndarray:
    """Linear-blend-skinned positions ``[V, 3]`` (float64).

    ``joint_matrices`` ``[J, 4, 4]`` are the joints' world matrices in the pose; the skin
    matrix of joint j is ``joint_matrices[j] @ mesh.inverse_bind[j]`` (glTF / UsdSkel
    convention, column vectors). Weights are renormalised to sum to 1.
    """
    src = source or mesh.name
    if mesh.joints is None or mesh.skin_weights is None:
        raise input_error(src, "the mesh has no skin (joints and weights)")
    jm = np.asarray(joint_matrices, dtype=np.float64)
    n_j = len(mesh.joint_names) if mesh.joint_names else int(mesh.joints.max()) + 1
    if jm.shape != (n_j, 4, 4):
        raise input_error(src, f"expected {n_j} joint matrices [J,4,4], got {list(jm.shape)}")
    ib = (
        np.asarray(mesh.inverse_bind, dtype=np.float64)
        if mesh.inverse_bind is not None
        else np.broadcast_to(np.eye(4), (n_j, 4, 4))
    )
    skin = jm @ ib  # [J, 4, 4]
    joints = np.asarray(mesh.joints, dtype=np.int64)
    wts = np.asarray(mesh.skin_weights, dtype=np.float64)
    if joints.max(initial=0) >= n_j or joints.min(initial=0) < 0:
        raise input_error(src, f"joint indices out of range 0..{n_j - 1}")
    total = wts.sum(axis=1, keepdims=True)
    wts = np.where(total > 0, wts / np.where(total > 0, total, 1.0), 0.0)
    m = np.einsum("vk,vkij->vij", wts, skin[joints])  # [V, 4, 4]
    p = np.asarray(mesh.positions, dtype=np.float64)
    out = np.einsum("vij,vj->vi", m[:, :3, :3], p) + m[:, :3, 3]
    unskinned = total[:, 0] <= 0
    out[unskinned] = p[unskinned]
    return out


def texture_space_weights(
    uvs: np.ndarray,
    indices: np.ndarray,
    tri_weights: np.ndarray,
    size: int = 256,
    blur_px: float = 4.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Oat's texture-space smoothing: rasterise per-triangle weights into UV space, blur.

    Returns ``(weights [size, size] float32, coverage [size, size] bool)``. The blur is a
    normalised Gaussian (sigma ``blur_px`` texels) over covered texels only, so empty texels do
    not pull the weights towards 0. Row 0 is v = 0 (glTF UV convention). Sample it at vertex UVs
    with :func:`sample_bilinear`.
    """

    tid = rasterise_triangle_ids(uvs, indices, size)
    cov = tid >= 0
    val = np.zeros((size, size), dtype=np.float64)
    val[cov] = np.asarray(tri_weights, dtype=np.float64)[tid[cov]]
    if blur_px > 0:
        num = gaussian_filter(val, blur_px, mode="nearest")
        den = gaussian_filter(cov.astype(np.float64), blur_px, mode="nearest")
        with np.errstate(invalid="ignore", divide="ignore"):
            val = np.where(den > 1e-6, num / np.maximum(den, 1e-12), 0.0)
    return val.astype(np.float32), cov


def sample_bilinear(image: np.ndarray, uvs: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``image`` ``[H, W]`` at ``uvs`` ``[N, 2]`` (texel centres, clamp)."""
    h, w = image.shape
    x = np.clip(np.asarray(uvs[:, 0], dtype=np.float64) * w - 0.5, 0, w - 1)
    y = np.clip(np.asarray(uvs[:, 1], dtype=np.float64) * h - 0.5, 0, h - 1)
    x0 = np.floor(x).astype(np.int64)
    y0 = np.floor(y).astype(np.int64)
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    fx = x - x0
    fy = y - y0
    top = image[y0, x0] * (1 - fx) + image[y0, x1] * fx
    bot = image[y1, x0] * (1 - fx) + image[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def seam_jump(values: np.ndarray, vertex_ids: np.ndarray) -> np.ndarray:
    """Per vertex-ID group with several render vertices: max - min of ``values`` ``[V]``."""
    ids = np.asarray(vertex_ids, dtype=np.int64)
    n = int(ids.max()) + 1
    hi = np.full(n, -np.inf)
    lo = np.full(n, np.inf)
    np.maximum.at(hi, ids, values)
    np.minimum.at(lo, ids, values)
    count = np.bincount(ids, minlength=n)
    return (hi - lo)[count > 1]
