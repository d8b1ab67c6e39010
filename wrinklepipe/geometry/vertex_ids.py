"""Spatial-hash vertex IDs (Oat, "Real-Time Wrinkles", 2007).

Every render vertex gets the ID of its *position*, so the copies a UV seam or a hard edge splits
share one ID while vertices at different places get different IDs. Used to smooth dynamic wrinkle
weights across seams (:mod:`wrinklepipe.geometry.dynamic`) and written out as
``_WRINKLE_VERTEX_ID`` (glTF) / ``primvars:wrinkle:vertexId`` (USD).

Contract (``tol`` = the tolerance, Chebyshev distance, i.e. per axis):

- two positions closer than ``tol`` always share an ID, also when they straddle a cell border;
- two positions that share an ID without intermediates are at most ``3 * tol`` apart, so
  positions separated by more than ``3 * tol`` get different IDs unless a chain of positions
  each within ``tol`` of the next joins them (which a mesh whose vertices are further apart than
  the tolerance never has);
- ``-0.0`` equals ``0.0``; NaN or infinite positions are refused;
- IDs are ``0 .. n-1`` numbered by first appearance, so the result is deterministic and a
  permutation of the vertex order gives the same partition.

Algorithm: positions are quantised into cells of ``coarse_factor * tol``; the three cell
coordinates and the vertex index are packed into one int64 and sorted once (which groups the
cells and yields each cell's first vertex; wider grids fall back to an int64 cell key with an
indirect sort, then to a lexicographic sort of the rows, and grids finer than 2^52 cells to
linking every point with the k-d tree). A cell whose positions all lie within ``tol / 2`` of
its first position is one cluster; the points of the rare cells that are not are re-gridded at
an eighth of the size, down to cells of ``tol / 2`` (an adaptive octree). Cluster
representatives within ``1.5 * tol`` of a cell face are candidates; on the top level only those
whose cell across that face holds a candidate or is dense are kept (a sorted search). The
candidates are linked with a k-d tree (Chebyshev radius ``2 * tol``) and merged by connected
components. Numbering by first appearance is a prefix sum over "is the first vertex of its
cluster".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from wrinklepipe.errors import input_error
from wrinklepipe.names import noun, plural

NAME = "vertex-ids"
_SPACING_FRACTION = 0.25


@dataclass(frozen=True)
class VertexIdOptions:
    """Options of :func:`compute_vertex_ids`.

    relative_tolerance: tolerance as a fraction of the bounding-box diagonal (default 1e-6),
        used when no absolute ``tolerance`` is given.
    tolerance: absolute tolerance in mesh units (overrides ``relative_tolerance``); 0 or a
        degenerate bounding box falls back to exact equality of positions.
    coarse_factor: hash-cell size in tolerances (default None: automatic, a quarter of the
        expected vertex spacing of a surface filling the bounding box, clamped to 16..4096).
        Larger means fewer border candidates but more cells holding several distinct
        positions; the IDs do not depend on it, only the speed does.
    """

    relative_tolerance: float = 1e-6
    tolerance: float | None = None
    coarse_factor: float | None = None


def _first_appearance(labels: np.ndarray, n_labels: int) -> np.ndarray:
    """Renumber arbitrary non-negative labels ``< n_labels`` to 0..k-1 by first appearance."""
    n = len(labels)
    idx = np.arange(n, dtype=np.int64)
    first = np.full(n_labels, n, dtype=np.int64)
    np.minimum.at(first, labels, idx)
    f = first[labels]
    is_first = f == idx
    number = np.cumsum(is_first, dtype=np.int64) - 1
    return number[f]


# Cell coordinates a hash grid level may have (float64 cell coordinates stay exact integers);
# finer grids fall back to linking every point with the k-d tree.
_MAX_CELLS = float(2**52)
# float32 cell coordinates only while their rounding stays far below the near-face margin.
_MAX_CELLS_FLOAT32 = float(2**14)


_HASH_MUL = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing of packed cell keys


def _cell_hash(keys: np.ndarray, hash_bits: int) -> np.ndarray:
    """Multiplicative hash of int64 cell keys into ``hash_bits`` bits."""
    h = keys.view(np.uint64) * _HASH_MUL  # wraps modulo 2^64
    h >>= np.uint64(64 - hash_bits)
    return h


def _neighbour_occupied(
    q: list[np.ndarray], side: list[np.ndarray], table: np.ndarray, bits: int
) -> np.ndarray:
    """For points in cells ``q`` near the faces ``side`` (-1, 0, +1 per axis): may a cell
    across a near face (or edge, or corner) be one of the packed cell keys ``table``?

    A superset: the keys are hashed into a bitmap about 32 times their number (cache-sized),
    so a few answers are false positives (they only add k-d tree candidates), never false
    negatives. The cells to look at are the non-zero sub-vectors of ``side`` (1 for a point
    near one face, 3 near an edge, 7 near a corner): a loop over the 7 axis masks."""
    hash_bits = max(12, int(32 * len(table)).bit_length())
    occupied = np.zeros(1 << hash_bits, dtype=bool)
    occupied[_cell_hash(np.ascontiguousarray(table, dtype=np.int64), hash_bits)] = True
    hit = np.zeros(len(q[0]), dtype=bool)
    top = (1 << bits) - 1
    nz = [sd != 0 for sd in side]
    for mask in range(1, 8):
        use = [(mask >> a) & 1 for a in range(3)]
        ok = ~hit
        for a in range(3):
            if use[a]:
                ok &= nz[a]
        sel = np.flatnonzero(ok)
        if not len(sel):
            continue
        key = np.zeros(len(sel), dtype=np.int64)
        valid = np.ones(len(sel), dtype=bool)
        for a in range(3):
            c = q[a][sel] + side[a][sel] if use[a] else q[a][sel]
            valid &= (c >= 0) & (c <= top)
            key |= (c & top) << ((2 - a) * bits)
        found = valid & occupied[_cell_hash(key, hash_bits)]
        hit[sel[found]] = True
    return hit


def _cluster(
    cols: list[np.ndarray],
    lo: np.ndarray,
    ext: float,
    cell: float,
    tol: float,
    parent_cell: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """One level of the adaptive hash grid over the points ``cols`` (3 coordinate arrays).

    Returns ``(f, cand)``: ``f[i]`` the (local) index of the first point of i's cluster, and
    the local indices of the cluster representatives that may link across a cell face.
    ``ext``: largest coordinate of these points above ``lo`` (bounds the cell coordinates);
    ``parent_cell``: None for the level that sees every point (only there are candidates
    filtered by the occupancy of the cells across their near faces), else the cell size of
    the level whose dense cells these points fill.
    """
    top = parent_cell is None
    m = len(cols[0])
    local = np.arange(m, dtype=np.int64)
    fine = cell <= 0.5 * tol
    if fine:
        cell = 0.5 * tol  # same cell => within tol / 2: never dense
    n_cells = ext / cell
    if n_cells >= _MAX_CELLS:
        # Tolerance below what a hash grid resolves at this extent: every point is its own
        # node and a candidate; the k-d tree links them (exact, only slower).
        return local, local
    use32 = n_cells < _MAX_CELLS_FLOAT32 and all(c.dtype == np.float32 for c in cols)
    fr, q = _cell_coordinates(cols, lo, 1.0 / cell, use32, top)
    # Rounding of the cell coordinates (a few roundings of eps relative): widen the near-face
    # margin by it so the candidates stay a superset.
    eps = 2.0**-23 if use32 else 2.0**-52
    slack = 8.0 * eps * (n_cells + 1.0)
    qmax = int(n_cells * (1.0 + 1e-9)) + 2 if top else max(int(qa.max()) for qa in q)
    bits = max(1, qmax.bit_length())
    idx_bits = max(1, int(m - 1).bit_length())

    order, cellk, point_key, key_shift = _sort_by_cell(q, local, bits, idx_bits)
    start = np.empty(m, dtype=bool)
    start[0] = True
    if cellk is not None:
        np.not_equal(cellk[1:], cellk[:-1], out=start[1:])
    else:
        start[1:] = False
        for qa in q:
            s = qa[order]
            start[1:] |= s[1:] != s[:-1]
    starts = np.flatnonzero(start)
    # Every point is its own node except the non-first points of a cell (few): those point at
    # their cell's first point (the run start before them; sorted needles: a cheap search).
    f = local  # the index field of the keys is packed already: reuse the array
    dense = None
    dense_cell = None
    if len(starts) < m:
        dup = np.flatnonzero(~start)
        dup_cell = np.searchsorted(starts, dup, side="right") - 1
        di = order[dup]
        ri = order[starts[dup_cell]]
        f[di] = ri
    if not fine and len(starts) < m:
        spread = np.zeros(len(dup))  # only non-first points can lie away from the first
        for c in cols:
            d = c[di].astype(np.float64)
            d -= c[ri]
            np.maximum(spread, np.abs(d), out=spread)
        loose = spread > 0.5 * tol
        if loose.any():
            dense_cell = np.zeros(len(starts), dtype=bool)
            dense_cell[dup_cell[loose]] = True
            is_dense = np.zeros(m, dtype=bool)
            is_dense[order[starts[dense_cell]]] = True
            is_dense[di[dense_cell[dup_cell]]] = True
            dense = np.flatnonzero(is_dense)  # ascending: local firsts stay the lowest index

    # Representatives of settled cells near a cell face may link across it.
    margin = 1.5 * tol / cell + slack
    near = None
    for a in range(3):
        na = fr[a] < margin
        na |= fr[a] > 1.0 - margin
        near = na if near is None else np.logical_or(near, na, out=near)
    cand = np.flatnonzero(near)
    cand = cand[f[cand] == cand]
    if dense is not None:
        cand = cand[~is_dense[cand]]
    if point_key is not None and len(cand) and margin < 0.5:
        # Keep a candidate only when a cell across its near face holds a candidate or is
        # dense (exact: a partner within tol lies in such a cell, and that cell's
        # representative lies within 1.5 tol of the shared face unless the cell is dense).
        ck = point_key[cand] >> key_shift
        table = ck if dense_cell is None else np.concatenate([ck, cellk[starts[dense_cell]]])
        top_q = (1 << bits) - 1
        qs = [(ck >> ((2 - a) * bits)) & top_q for a in range(3)]
        sides = []
        for a in range(3):
            fa = fr[a][cand]
            sides.append((fa > 1.0 - margin).astype(np.int64) - (fa < margin))
        keep = _neighbour_occupied(qs, sides, table, bits)
        if not top:
            # A partner may lie outside these points (beyond the parent cell): keep the
            # candidates near a face of their parent cell too.
            pinv = 1.0 / parent_cell
            for c, o in zip(cols, lo):
                g = np.subtract(c[cand], o, dtype=np.float64)
                g *= pinv
                pm = 1.5 * tol / parent_cell + 8.0 * 2.0**-52 * (float(g.max(initial=0)) + 2.0)
                g -= np.floor(g)  # the fraction within the parent cell
                keep |= (g < pm) | (g > 1.0 - pm)
        cand = cand[keep]
    if dense is None:
        return f, cand
    sub_cols = [c[dense].astype(np.float64) for c in cols]
    sub_ext = max(float(s.max()) - float(o) for s, o in zip(sub_cols, lo))
    sub_f, sub_cand = _cluster(sub_cols, lo, sub_ext, cell / 8.0, tol, cell)
    f[dense] = dense[sub_f]
    return f, np.concatenate([cand, dense[sub_cand]])


def _cell_coordinates(
    cols: list[np.ndarray], lo: np.ndarray, inv: float, use32: bool, top: bool
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per axis, each point's fraction within its cell and its integer cell coordinate (cells
    of size ``1 / inv`` from ``lo``; below the top level, from the lowest occupied cell)."""
    fr: list[np.ndarray] = []
    q: list[np.ndarray] = []
    for c, o in zip(cols, lo):
        if use32:  # exact: lo is one of the float32 values
            ga = np.subtract(c, np.float32(o))
            ga *= np.float32(inv)
        else:
            ga = np.subtract(c, o, dtype=np.float64)
            ga *= inv
        fl = np.floor(ga)
        ga -= fl  # the fraction within the cell (exact)
        if not top:
            fl -= fl.min()
        fr.append(ga)
        q.append(fl.astype(np.int64))
    return fr, q


def _sort_by_cell(
    q: list[np.ndarray], local: np.ndarray, bits: int, idx_bits: int
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, int]:
    """The points in cell order, index ascending within a cell: ``(order, sorted cell keys
    or None, each point's packed cell key or None, the key's index bits)``. Shifts ``q`` in
    place when the key and the index pack into one int64."""
    point_key = None  # packed cell key of every point (original order), when packed
    key_shift = 0
    if 3 * bits + idx_bits <= 63:
        # One sort of (cell key, index) packed in an int64: groups the cells, index ascending.
        np.left_shift(q[0], 2 * bits + idx_bits, out=q[0])
        np.left_shift(q[1], bits + idx_bits, out=q[1])
        np.left_shift(q[2], idx_bits, out=q[2])
        key = q[0]
        key |= q[1]
        key |= q[2]
        key |= local
        cellk = np.sort(key, kind="stable")
        order = cellk & np.int64((1 << idx_bits) - 1)
        np.right_shift(cellk, idx_bits, out=cellk)
        point_key, key_shift = key, idx_bits
    elif 3 * bits <= 63:  # 21 bits or fewer per axis: one int64 key, indirect sort
        key = q[0] << (2 * bits)
        key |= q[1] << bits
        key |= q[2]
        order = np.argsort(key, kind="stable")
        cellk = key[order]
        point_key = key
    else:  # more than 2^21 cells on an axis: sort the rows lexicographically
        order = np.lexsort((q[2], q[1], q[0]))
        cellk = None
    return order, cellk, point_key, key_shift


def _bounds(p: np.ndarray, block: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis min and max (float64, NaN when any is NaN) of ``[V, 3]`` positions, reduced
    over rows of ``block`` vertices (contiguous passes, faster than strided columns)."""
    k = len(p) // block * block
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    if k:
        rows = p[:k].reshape(-1, 3 * block)
        lo = rows.min(axis=0).reshape(block, 3).min(axis=0).astype(np.float64)
        hi = rows.max(axis=0).reshape(block, 3).max(axis=0).astype(np.float64)
    if k < len(p):
        lo = np.minimum(lo, p[k:].min(axis=0))
        hi = np.maximum(hi, p[k:].max(axis=0))
    return lo, hi


def compute_vertex_ids(
    positions: np.ndarray,
    tolerance: float | None = None,
    options: VertexIdOptions | None = None,
    source: str = "positions",
) -> np.ndarray:
    """Spatial-hash vertex IDs of ``positions`` ``[V, 3]`` -> ``[V]`` int64 (see module doc).

    ``tolerance`` (absolute, mesh units) overrides ``options.tolerance``. ``source`` names the
    input in error messages. Raises :class:`~wrinklepipe.errors.InputError` for non-finite
    positions or a wrong shape.
    """
    opts = options or VertexIdOptions()
    if tolerance is not None:
        opts = VertexIdOptions(opts.relative_tolerance, float(tolerance), opts.coarse_factor)
    p = np.asarray(positions)
    if p.ndim != 2 or p.shape[1] != 3:
        raise input_error(source, f"positions must be [V, 3], got shape {list(p.shape)}")
    n = len(p)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if p.dtype not in (np.float32, np.float64):
        p = p.astype(np.float64)
    cols = [p[:, a] for a in range(3)]  # strided views; float32 stays float32
    lo, hi = _bounds(p)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        finite = np.isfinite(p).all(axis=1)
        bad = np.flatnonzero(~finite)
        if len(bad):
            raise input_error(
                source,
                f"{plural(len(bad), 'position')} {noun(len(bad), 'is', 'are')} NaN or infinite "
                f"(first at vertex {int(bad[0])})",
                key=f"vertex {int(bad[0])}",
            )
    if opts.tolerance is not None and not (np.isfinite(opts.tolerance) and opts.tolerance >= 0):
        raise input_error(source, f"tolerance must be a finite number >= 0, got {opts.tolerance}")
    if opts.tolerance is not None:
        tol = float(opts.tolerance)
    else:
        tol = float(np.linalg.norm(hi - lo)) * float(opts.relative_tolerance)
    if tol <= 0.0:
        return _exact_ids(p.astype(np.float64) + 0.0)  # +0.0 turns -0.0 into 0.0

    factor = opts.coarse_factor
    if factor is None:
        ext = hi - lo
        area = 2.0 * float(ext[0] * ext[1] + ext[1] * ext[2] + ext[2] * ext[0])
        spacing = np.sqrt(area / n) if area > 0 else float(ext.max()) / n
        factor = float(np.clip(_SPACING_FRACTION * spacing / tol, 16.0, 4096.0))
    cell = tol * float(factor)
    f, cand = _cluster(cols, lo, float((hi - lo).max()), cell, tol)
    if len(cand) > 1:
        pts = p[cand].astype(np.float64)
        tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)
        # Euclidean query (faster than p=inf), then keep the Chebyshev distance <= 2 tol.
        pairs = tree.query_pairs(2.0 * np.sqrt(3.0) * tol, p=2.0, output_type="ndarray")
        if len(pairs):
            cheb = np.abs(pts[pairs[:, 0]] - pts[pairs[:, 1]]).max(axis=1)
            pairs = pairs[cheb <= 2.0 * tol]
        if len(pairs):
            f = _merge(f, f[cand[pairs[:, 0]]], f[cand[pairs[:, 1]]])
    number = np.cumsum(f == np.arange(n, dtype=np.int64), dtype=np.int64)
    number -= 1
    return number[f]


def _merge(f: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Union the nodes ``a[i]``-``b[i]`` (a node is the index of its first point); every point
    then points at the smallest node of its component."""

    involved, inv = np.unique(np.concatenate([a, b]), return_inverse=True)
    m = len(involved)
    k = len(a)
    graph = coo_matrix((np.ones(k, dtype=np.int8), (inv[:k], inv[k:])), shape=(m, m))
    _, comp = connected_components(graph, directed=False)
    comp_first = np.full(comp.max() + 1, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(comp_first, comp, involved)
    new = comp_first[comp]
    moved = new != involved
    if not moved.any():
        return f
    flag = np.zeros(len(f), dtype=bool)
    flag[involved[moved]] = True
    sel = np.flatnonzero(flag[f])
    out = f.copy()
    out[sel] = new[np.searchsorted(involved, f[sel])]
    return out


def _exact_ids(p: np.ndarray) -> np.ndarray:
    """IDs by exact equality of positions (tolerance 0), numbered by first appearance."""
    _, inv = np.unique(p, axis=0, return_inverse=True)
    inv = inv.reshape(-1).astype(np.int64)
    return _first_appearance(inv, int(inv.max()) + 1)
