"""The normal's in-plane orientation: the paper's rule, and two priors that resolve its ambiguity.

The ratio image gives the tilt of the wrinkled normal (``N'_z``), not which way it leans. Dutreve
et al. (equation 3) lean it along the normalised gradient of R: ``(N'_x, N'_y) = G sqrt(1 -
N'_z^2)``. Under a light at the camera the ratio depends only on the tilt, so a slope and its
mirror image give the same R: across a furrow R dips on both flanks (where the slope is steepest)
and the gradient of R points *towards* the steepest line. That is the right way on the inner half
of each flank and the wrong way on the outer half; concave and convex creases are
indistinguishable (``h`` and ``-h`` give the same R). Methods here:

``gradient``
    The paper: ``G = grad R / |grad R|``.
``furrow``
    Prior "creases are furrows": the axis is the dominant orientation of ``grad R`` (structure
    tensor, well defined where ``grad R`` vanishes at the steepest line) and the sign makes the
    normal lean towards the crease's centre line, the ridge of the darkness ``1 - R`` blurred at
    the crease scale (``furrow_sigma``). Per pixel, no segmentation.
``integrable``
    Prior "the slope field is the gradient of a smooth height field". A smooth surface's signed
    slope changes sign only by passing through zero, where ``R = 1/sqrt(1 + slope^2)`` peaks
    (a furrow's floor, a shoulder's crest), never at a minimum of R (the steepest line, where
    the paper's gradient flips). So the lean is propagated pixel to pixel over a maximum
    spanning tree of the crease pixels, continuing across every pair except those across which
    R has a concave peak along the crease axis, where it flips (flip links enter the tree first,
    then the steepest pairs). That leaves one free sign per connected crease: the
    concave/convex ambiguity proper (``h`` and ``-h`` are equally integrable and give the same
    R). It is set by integrating the crease's slope field alone (Poisson, on its bounding box)
    and choosing the sign that makes it a dent below its flat surroundings (``crease_sign =
    "dent"``; ``"vote"`` uses the furrow rule's slope-weighted majority instead). One decision
    per crease is far more robust than the furrow rule per pixel, and right on shoulders and
    wide creases where the per-pixel rule fails.

    Known limits: where two creases meet (a "V" of crow's feet) or at a crease's end the
    propagation can take a path that misses the floor line, leaving part of a crease flipped;
    a shoulder separated from its furrow by a flat gap (wider than the deadband) is its own
    crease and is made a dent too.

:func:`integrability_residual` reports how far a normal map is from a gradient field (Poisson
integration with Neumann borders, solved with a DCT), a diagnostic for any of the three.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import fft, ndimage, sparse
from scipy.sparse import csgraph

#: The rules of this module (they need R alone).
PRIORS: tuple[str, ...] = ("gradient", "furrow", "integrable")
#: Every orientation method; ``sfs`` (:mod:`.sfs`) also needs the neutral's shape and runs in
#: :func:`wrinklepipe.capture.pipeline.capture`.
METHODS: tuple[str, ...] = PRIORS + ("sfs",)


@dataclass(frozen=True)
class OrientationOptions:
    """Parameters of the orientation step, with the defaults ``wrinklepipe capture`` uses."""

    #: Which method orients the normal: ``auto`` (``sfs`` when the neutral's normals are given,
    #: else ``integrable``), ``sfs`` (shape from shading), ``integrable``, ``furrow`` or
    #: ``gradient`` (the paper).
    method: str = "auto"
    #: Gaussian window (pixels) of the structure tensor giving the crease-normal axis.
    structure_sigma: float = 1.5
    #: Gaussian (pixels) that merges a crease's two dark flanks into one centre line; about the
    #: crease's half-width.
    furrow_sigma: float = 3.0
    #: Pixels tilted less than this (degrees) are not part of a crease segment.
    min_tilt_deg: float = 2.0
    #: ``integrable``: how the one free sign per crease is chosen: ``dent`` (the crease,
    #: integrated, lies below its surroundings) or ``vote`` (the furrow rule's slope-weighted
    #: majority over the crease).
    crease_sign: str = "dent"


def _grad(r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient in the pixel frame: (d/dcol, d/drow)."""
    d_row, d_col = np.gradient(np.asarray(r, np.float64))
    return d_col, d_row


def structure_axis(r: np.ndarray, sigma: float) -> np.ndarray:
    """Dominant gradient axis of ``r`` (unit, sign arbitrary) ``[H, W, 2]`` in the pixel frame."""
    gx, gy = _grad(r)
    jxx = ndimage.gaussian_filter(gx * gx, sigma)
    jxy = ndimage.gaussian_filter(gx * gy, sigma)
    jyy = ndimage.gaussian_filter(gy * gy, sigma)
    theta = 0.5 * np.arctan2(2.0 * jxy, jxx - jyy)
    return np.stack([np.cos(theta), np.sin(theta)], axis=-1)


def _to_normals(direction: np.ndarray, nz: np.ndarray) -> np.ndarray:
    """Unit normals (+Y up) from a pixel-frame direction ``[H, W, 2]`` and ``N'_z``."""
    z = np.clip(np.asarray(nz, np.float64), 0.0, 1.0)
    st = np.sqrt(1.0 - z * z)
    n = np.stack([direction[..., 0] * st, -direction[..., 1] * st, z], axis=-1)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return (n / np.maximum(norm, 1e-12)).astype(np.float32)


def gradient_direction(r: np.ndarray) -> np.ndarray:
    """The paper's ``G``: unit ``grad R`` in the pixel frame (zero where R is flat)."""
    gx, gy = _grad(r)
    mag = np.hypot(gx, gy)
    safe = np.maximum(mag, 1e-12)
    return np.stack([np.where(mag > 0, gx / safe, 0.0), np.where(mag > 0, gy / safe, 0.0)], -1)


def furrow_direction(r: np.ndarray, axis: np.ndarray, furrow_sigma: float) -> np.ndarray:
    """Axis signed towards the ridge of the blurred darkness ``1 - R`` (the crease centre)."""
    dark = ndimage.gaussian_filter(1.0 - np.asarray(r, np.float64), furrow_sigma)
    dx, dy = _grad(dark)
    sign = np.where(axis[..., 0] * dx + axis[..., 1] * dy < 0, -1.0, 1.0)
    return axis * sign[..., None]


#: Strength multiplier of flip links (R peaks) in the spanning tree.
FLIP_PRIORITY = 100.0


def _edge_preferences(
    r: np.ndarray, axis: np.ndarray, mag: np.ndarray, member: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Pixel pairs ``(a, b)``, whether their axes point the same way, whether the lean flips
    between them, and the strength of that link.

    The signed slope ``u`` of a smooth surface changes sign only through zero, where
    ``R = 1 / sqrt(1 + u^2)`` has a local *maximum* across the crease (a furrow's centre, a
    shoulder's crest, however much the blur fills it); at a local *minimum* (the steepest line,
    where the paper's gradient flips) the lean continues. So a pair flips iff R peaks between
    them along the step, counted only for steps across the crease (``|e . axis| > 0.5``); steps
    along the crease continue. Strength is the pair's summed slope (strong pixels link first).
    """
    h, w = member.shape
    idx = np.arange(h * w).reshape(h, w)
    rr = np.asarray(r, np.float64)
    d_row, d_col = np.gradient(rr)
    # Curvature of R along the axis (on R smoothed a little more): a real peak is concave;
    # noise wiggles on the flat bottom of a steepest line (where R is convex) are not peaks.
    rs = rr
    s_row, s_col = np.gradient(rs)
    s_rr, s_rc = np.gradient(s_row)
    _, s_cc = np.gradient(s_col)
    ax, ay = axis[..., 0], axis[..., 1]
    concave = (ax * ax * s_cc + 2 * ax * ay * s_rc + ay * ay * s_rr) < 0
    out_a, out_b, out_f, out_s = [], [], [], []
    for dr, dc, g in ((0, 1, d_col), (1, 0, d_row)):
        hh, ww = h - dr, w - dc
        ok = member[:hh, :ww] & member[dr:, dc:]
        gi = g[:hh, :ww][ok]
        gj = g[dr:, dc:][ok]
        across = np.abs(axis[..., 1 if dr else 0])[:hh, :ww][ok] > 0.5
        peak = concave[:hh, :ww][ok] | concave[dr:, dc:][ok]
        out_a.append(idx[:hh, :ww][ok])
        out_b.append(idx[dr:, dc:][ok])
        flip = across & (gi > 0) & (gj < 0) & peak
        out_f.append(flip)
        # Peaks are the decisive evidence: linked first (before any path around a crease end).
        out_s.append((mag[:hh, :ww][ok] + mag[dr:, dc:][ok]) * np.where(flip, FLIP_PRIORITY, 1.0))
    a = np.concatenate(out_a)
    b = np.concatenate(out_b)
    flat = axis.reshape(-1, 2)
    aligned = np.einsum("ic,ic->i", flat[a], flat[b]) >= 0
    return a, b, aligned, np.concatenate(out_f), np.concatenate(out_s)


def orient_axis_field(
    r: np.ndarray, axis: np.ndarray, mag: np.ndarray, member: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Lean each member pixel's axis so the slope field is smooth; one free sign per region.

    The edges of :func:`_edge_preferences` that are confident enough form a graph; its maximum
    spanning tree (strongest preferences first) carries the lean from a root to every pixel of
    its region, accumulated by pointer jumping (``log2`` depth vectorised passes). Returns the
    leaned axes ``[H, W, 2]`` and region labels (``-1`` outside ``member``).
    """
    h, w = member.shape
    n = h * w
    a, b, aligned, flips, strength = _edge_preferences(r, axis, mag, member)
    members = np.flatnonzero(member.ravel())
    root = n
    # A virtual root joined (most expensively) to every member pixel: one BFS covers the forest.
    cost = 1.0 / (strength + 1e-12)
    top_cost = 2.0 * float(cost.max()) + 1.0 if len(cost) else 1.0
    rows = np.concatenate([a, np.full(len(members), root)])
    cols = np.concatenate([b, members])
    vals = np.concatenate([cost, np.full(len(members), top_cost)])
    graph = sparse.coo_matrix((vals, (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    tree = csgraph.minimum_spanning_tree(graph)
    _, pred = csgraph.breadth_first_order(tree, root, directed=False, return_predecessors=True)
    parent = np.where(pred >= 0, pred, np.arange(n + 1))
    parent[root] = root
    top = parent == root  # region roots (children of the virtual root) and the root itself
    # Parity of each tree edge (child, parent): axes opposed XOR preference for a flip.
    key = np.minimum(a, b) * (n + 1) + np.maximum(a, b)
    par_e = (~aligned) ^ flips
    order = np.argsort(key)
    key_sorted = key[order]
    child = np.flatnonzero(~top)
    ck = np.minimum(child, parent[child]) * (n + 1) + np.maximum(child, parent[child])
    pos = np.clip(np.searchsorted(key_sorted, ck), 0, max(len(key_sorted) - 1, 0))
    parity = np.zeros(n + 1, np.int8)
    if len(key_sorted):
        parity[child] = par_e[order][pos].astype(np.int8)
    region_root = np.where(top, np.arange(n + 1), parent)
    ptr = parent.copy()
    ptr[top] = np.flatnonzero(top)
    for _ in range(int(np.ceil(np.log2(n + 2))) + 1):  # pointer jumping: log2(depth) passes
        parity = parity ^ parity[ptr]
        region_root = region_root[ptr]
        ptr = ptr[ptr]
    labels = np.full(n, -1, np.int64)
    _, dense = np.unique(region_root[members], return_inverse=True)
    labels[members] = dense
    sign = np.where(parity[:n] == 1, -1.0, 1.0)
    return axis * sign.reshape(h, w)[..., None], labels.reshape(h, w)


#: Regions (largest slope mass first) whose sign is set by integrating them; the rest vote.
MAX_INTEGRATED_REGIONS = 256
#: Flat margin (pixels) around a region's bounding box when it is integrated.
REGION_MARGIN = 4


def _dent_signs(fields: np.ndarray, labels: np.ndarray, n: int, signs: np.ndarray) -> np.ndarray:
    """Per region: the sign that makes the region's integrated height a dent.

    Each region's slope field alone (zero around it) is integrated (Poisson, on its bounding box
    with a flat margin); the crease is a furrow when its pixels lie below the flat margin, so
    the sign is flipped where the mean height of the region, relative to the margin, is > 0.
    Regions beyond ``MAX_INTEGRATED_REGIONS`` keep their furrow vote.
    """
    h, w = labels.shape
    out = signs.copy()
    member = labels >= 0
    mag = np.hypot(fields[..., 0], fields[..., 1])
    mass = np.bincount(labels[member], weights=mag[member], minlength=n)
    objs = ndimage.find_objects(labels + 1)  # slices per region (label k at index k)
    order = np.argsort(-mass, kind="stable")[:MAX_INTEGRATED_REGIONS]
    for k in order:  # one small Poisson solve per region (bounded count), not per pixel
        sl = objs[k] if k < len(objs) else None
        if sl is None or mass[k] <= 0:
            continue
        m = REGION_MARGIN
        r0, r1 = max(sl[0].start - m, 0), min(sl[0].stop + m, h)
        c0, c1 = max(sl[1].start - m, 0), min(sl[1].stop + m, w)
        inside = labels[r0:r1, c0:c1] == k
        f = np.where(inside[..., None], fields[r0:r1, c0:c1], 0.0) * signs[k]
        hh = integrate_poisson(-f[..., 0], -f[..., 1])
        ring = ~member[r0:r1, c0:c1]
        if not ring.any() or not inside.any():
            continue
        depth = float(hh[inside].mean() - hh[ring].mean())
        if depth > 0:
            out[k] = -signs[k]
    return out


def integrable_direction(
    r: np.ndarray,
    nz: np.ndarray,
    axis: np.ndarray,
    options: OrientationOptions,
    roi: np.ndarray | None = None,
) -> np.ndarray:
    """Directions from the integrability prior (see the module docstring)."""
    z = np.clip(np.asarray(nz, np.float64), 0.0, 1.0)
    tan_t = np.sqrt(1.0 - z * z) / np.maximum(z, 1e-3)
    member = tan_t > np.tan(np.radians(options.min_tilt_deg))
    if roi is not None:
        member &= np.asarray(roi) > 0.5
    fallback = furrow_direction(r, axis, options.furrow_sigma)
    if not member.any():
        return fallback
    oriented, labels = orient_axis_field(r, axis, tan_t, member)
    n = int(labels.max()) + 1
    lab = labels[member]
    votes = np.bincount(
        lab,
        weights=tan_t[member] * np.einsum("ic,ic->i", oriented[member], fallback[member]),
        minlength=n,
    )
    signs = np.where(votes < 0, -1.0, 1.0)
    if options.crease_sign == "dent":
        signs = _dent_signs(oriented * (tan_t * member)[..., None], labels, n, signs)
    out = fallback.copy()
    out[member] = oriented[member] * signs[lab][:, None]
    return out


def orient(
    r: np.ndarray,
    nz: np.ndarray,
    options: OrientationOptions | None = None,
    roi: np.ndarray | None = None,
) -> np.ndarray:
    """Wrinkled normals ``[H, W, 3]`` (+Y up) from the ratio image and ``N'_z``.

    ``roi`` (0..1) limits the crease regions of the ``integrable`` method.
    """
    o = options or OrientationOptions()
    if o.method not in PRIORS:
        raise ValueError(f"orient() runs {', '.join(PRIORS)}, not {o.method!r}")
    if o.method == "gradient":
        return _to_normals(gradient_direction(r), nz)
    axis = structure_axis(r, o.structure_sigma)
    if o.method == "furrow":
        return _to_normals(furrow_direction(r, axis, o.furrow_sigma), nz)
    return _to_normals(integrable_direction(r, nz, axis, o, roi), nz)


def integrate_poisson(gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """Least-squares height ``h`` with ``grad h ~ (gx, gy)`` (pixel frame), Neumann borders.

    Solves the discrete Poisson equation ``lap h = div g`` with a DCT-II (Simchony et al.); the
    mean of ``h`` is 0.
    """
    gx = np.asarray(gx, np.float64)
    gy = np.asarray(gy, np.float64)
    h, w = gx.shape
    # Divergence with backward differences, matching forward-difference gradients.
    div = np.zeros((h, w))
    div[:, :-1] += gx[:, :-1]
    div[:, 1:] -= gx[:, :-1]
    div[:-1, :] += gy[:-1, :]
    div[1:, :] -= gy[:-1, :]
    d = fft.dctn(div, type=2, norm="ortho")
    ky = 2.0 * np.cos(np.pi * np.arange(h) / h) - 2.0
    kx = 2.0 * np.cos(np.pi * np.arange(w) / w) - 2.0
    denom = ky[:, None] + kx[None, :]
    denom[0, 0] = 1.0
    d = d / denom
    d[0, 0] = 0.0
    return fft.idctn(d, type=2, norm="ortho")


def integrability_residual(normals: np.ndarray, roi: np.ndarray | None = None) -> float:
    """RMS of ``grad h - p`` over RMS of ``p``, ``p`` the slopes of a normal map (0: integrable).

    ``h`` is the Poisson integration of ``p``; slopes use forward differences.
    """
    n = np.asarray(normals, np.float64)
    z = np.maximum(n[..., 2], 1e-3)
    gx = -n[..., 0] / z  # dh/dcol
    gy = n[..., 1] / z  # dh/drow (+Y up is against the rows)
    hh = integrate_poisson(gx, gy)
    rx = np.zeros_like(gx)
    ry = np.zeros_like(gy)
    rx[:, :-1] = (hh[:, 1:] - hh[:, :-1]) - gx[:, :-1]
    ry[:-1, :] = (hh[1:, :] - hh[:-1, :]) - gy[:-1, :]
    wgt = np.ones_like(gx) if roi is None else (np.asarray(roi, np.float64) > 0.5).astype(float)
    num = float(np.sum(wgt * (rx * rx + ry * ry)))
    den = float(np.sum(wgt * (gx * gx + gy * gy)))
    return float(np.sqrt(num / den)) if den > 0 else 0.0
