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

Algorithm: positions are quantised into cells of ``coarse_factor * tol`` and grouped by one
sort of ``(cell key, vertex index)`` packed in an int64 (which also yields each cell's first
vertex). A cell whose positions all lie within ``tol / 2`` of its first position is one cluster;
the points of the rare cells that are not are re-gridded at an eighth of the size, down to cells
of ``tol / 2`` (an adaptive octree). Cluster representatives within ``1.5 * tol`` of a cell face
are linked with a k-d tree (Chebyshev radius ``2 * tol``) and merged by connected components.
Numbering by first appearance is a prefix sum over "is the first vertex of its cluster".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wrinklepipe.errors import input_error

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


def resolve_tolerance(positions: np.ndarray, options: VertexIdOptions) -> float:
    """The absolute tolerance for ``positions`` (Chebyshev distance, mesh units)."""
    if options.tolerance is not None:
        return float(options.tolerance)
    if len(positions) == 0:
        return 0.0
    p = np.asarray(positions, dtype=np.float64)
    diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    return diag * float(options.relative_tolerance)


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


def _cell_firsts(q: list[np.ndarray], n: int) -> tuple[np.ndarray, np.ndarray | None, int]:
    """For every point, the index of the first point (lowest index) in its grid cell; also the
    sorted unique packed cell keys and the bits per axis (None, 0 when keys were not packed)."""
    bits = max(1, int(max(int(a.max()) for a in q)).bit_length())
    idx_bits = max(1, int(n - 1).bit_length())
    if 3 * bits + idx_bits <= 63:
        # One sort of (cell key, index) packed in an int64: groups cells, index ascending.
        key = q[0] << (2 * bits + idx_bits)
        key |= q[1] << (bits + idx_bits)
        key |= q[2] << idx_bits
        key |= np.arange(n, dtype=np.int64)
        key.sort(kind="stable")
        order = key & np.int64((1 << idx_bits) - 1)
        cellk = key >> idx_bits
    elif bits <= 21:
        key = (q[0] << 42) | (q[1] << 21) | q[2]
        order = np.argsort(key, kind="stable")
        cellk = key[order]
    else:  # tolerance tiny against the extent: exact grouping of rows
        _, inv = np.unique(np.stack(q, axis=1), axis=0, return_inverse=True)
        order = np.argsort(inv.reshape(-1), kind="stable")
        cellk = inv.reshape(-1)[order]
        bits = 0
    start = np.empty(n, dtype=bool)
    start[0] = True
    np.not_equal(cellk[1:], cellk[:-1], out=start[1:])
    run_start = np.where(start, np.arange(n, dtype=np.int64), 0)
    np.maximum.accumulate(run_start, out=run_start)
    rep = np.empty(n, dtype=np.int64)
    rep[order] = order[run_start]
    return rep, (cellk[start] if bits else None), bits


def _neighbour_occupied(
    q: list[np.ndarray], side: list[np.ndarray], ukeys: np.ndarray, bits: int
) -> np.ndarray:
    """For points in cells ``q`` near the faces ``side`` (-1, 0, +1 per axis): is any cell
    across a near face (or edge, or corner) occupied? ``ukeys``: sorted packed cell keys.

    The cells to look at are the non-zero sub-vectors of ``side`` (1 for a point near one
    face, 3 near an edge, 7 near a corner): a loop over the 7 axis masks, not over points."""
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
            key |= c << ((2 - a) * bits)
        pos = np.searchsorted(ukeys, key)
        found = valid & (pos < len(ukeys))
        found[found] = ukeys[pos[found]] == key[found]
        hit[sel[found]] = True
    return hit


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
    cols = [np.ascontiguousarray(p[:, a]) for a in range(3)]  # float32 stays float32
    lo = np.array([c.min() for c in cols], dtype=np.float64)
    hi = np.array([c.max() for c in cols], dtype=np.float64)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        finite = np.isfinite(p).all(axis=1)
        bad = np.flatnonzero(~finite)
        if len(bad):
            raise input_error(
                source,
                f"{len(bad)} position(s) are NaN or infinite (first at vertex {int(bad[0])})",
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
    f = np.arange(n, dtype=np.int64)  # node of every point: the first point of its cluster
    cands = []
    active = None  # None: all points
    while True:
        fine = cell <= 0.5 * tol
        if fine:
            cell = 0.5 * tol  # same cell => within tol / 2: never dense
        sub_cols = cols if active is None else [c[active].astype(np.float64) for c in cols]
        m = len(sub_cols[0])
        inv = 1.0 / cell
        g = []
        q = []
        for c, o in zip(sub_cols, lo):
            if c.dtype == np.float32:  # exact: lo is one of the float32 values
                ga = np.subtract(c, np.float32(o))
                ga *= np.float32(inv)
            else:
                ga = np.subtract(c, o)
                ga *= inv
            qa = ga.astype(np.int64)  # ga >= 0: truncation is floor
            if active is not None:
                q0 = qa.min()
                qa -= q0
                ga -= q0
            g.append(ga)
            q.append(qa)
        # Rounding of the cell coordinates (float32 at most 4 roundings of 2^-24 relative):
        # widen the near-face margin by it so the candidates stay a superset.
        slack = 4.0 * 2.0**-23 * float(max(a.max() for a in g)) if g[0].dtype == np.float32 else 0.0
        local = np.arange(m, dtype=np.int64)
        rep, ukeys, bits = _cell_firsts(q, m)
        is_rep = rep == local
        dense_pt = None
        if not fine:
            dup = np.flatnonzero(~is_rep)  # only non-first points can lie away from the first
            r = rep[dup]
            spread = np.zeros(len(dup))
            for c in sub_cols:
                d = c[dup].astype(np.float64)
                d -= c[r]
                np.maximum(spread, np.abs(d), out=spread)
            loose = spread > 0.5 * tol
            if loose.any():
                dense_cell = np.zeros(m, dtype=bool)
                dense_cell[r[loose]] = True
                dense_pt = dense_cell[rep]
        # Representatives of settled cells that lie near a cell face may link across it.
        rep_idx = np.flatnonzero(is_rep if dense_pt is None else is_rep & ~dense_pt)
        margin = 1.5 * tol / cell + slack
        # Near a face: |frac - 1/2| > 1/2 - margin on some axis (contiguous passes, no gathers).
        dist = None
        for a in range(3):
            fr = g[a] - np.floor(g[a])
            fr -= 0.5
            np.abs(fr, out=fr)
            dist = fr if dist is None else np.maximum(dist, fr, out=dist)
        near_all = dist > 0.5 - margin
        rep_idx = rep_idx[near_all[rep_idx]]
        if active is None and ukeys is not None and len(rep_idx):
            # Level 0 sees every point: keep only candidates whose neighbour cell across a
            # near face is occupied at all (exact: a partner within tol lies in such a cell).
            sides = []
            for a in range(3):
                ga = g[a][rep_idx]
                fr = ga - np.floor(ga)
                sides.append((fr > 1.0 - margin).astype(np.int64) - (fr < margin))
            qs = [qa[rep_idx] for qa in q]
            rep_idx = rep_idx[_neighbour_occupied(qs, sides, ukeys, bits)]
        to_global = local if active is None else active
        if active is None:
            f = rep
            if dense_pt is not None:
                f = rep.copy()
                dense_idx = np.flatnonzero(dense_pt)
                f[dense_idx] = dense_idx  # unsettled: resolved at the finer levels
        else:
            keep = np.flatnonzero(~dense_pt) if dense_pt is not None else local
            f[to_global[keep]] = to_global[rep[keep]]
        cands.append(to_global[rep_idx])
        if dense_pt is None:
            break
        active = to_global[np.flatnonzero(dense_pt)]
        cell = cell / 8.0

    cand = np.concatenate(cands)
    if len(cand) > 1:
        from scipy.spatial import cKDTree

        pts = p[cand].astype(np.float64)
        tree = cKDTree(pts, balanced_tree=False, compact_nodes=False)
        # Euclidean query (faster than p=inf), then keep the Chebyshev distance <= 2 tol.
        pairs = tree.query_pairs(2.0 * np.sqrt(3.0) * tol, p=2.0, output_type="ndarray")
        if len(pairs):
            cheb = np.abs(pts[pairs[:, 0]] - pts[pairs[:, 1]]).max(axis=1)
            pairs = pairs[cheb <= 2.0 * tol]
        if len(pairs):
            f = _merge(f, f[cand[pairs[:, 0]]], f[cand[pairs[:, 1]]])
    idx = np.arange(n, dtype=np.int64)
    is_first = f == idx
    number = np.cumsum(is_first, dtype=np.int64) - 1
    return number[f]


def _merge(f: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Union the nodes ``a[i]``-``b[i]`` (a node is the index of its first point); every point
    then points at the smallest node of its component."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

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
