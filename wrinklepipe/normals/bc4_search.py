"""The BC4 endpoint search of :mod:`wrinklepipe.normals.bc4` (steps 1-4), 16 blocks side by side.

Compiled by numba on first use (:mod:`wrinklepipe.normals.bc4_jit`); :func:`compiled` returns
the block encoder. The one-block kernels (exact scores, step 5, packing, the reference's
window) are :mod:`wrinklepipe.normals.bc4_block`.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wrinklepipe.normals import bc4_block
from wrinklepipe.normals.bc4_jit import (
    _DET_MIN,
    _EXTENDED,
    _F,
    _INF,
    _INSIDE,
    _LAM,
    _RANGE_MIN,
    _RECIP7,
    _SEVENTH,
    _TAIL,
    _TAU,
    _TOP,
    _TRUNC,
    HARD_OUTSIDE,
    LANES,
    _0,
    _1,
    _7,
    _255,
    compile_kernels,
    kernel,
)

#: Offsets of each lane's lo and hi in the state ``S`` (its best score at 0).
_LO, _HI = LANES, 2 * LANES


def compiled() -> Callable[..., None]:
    """The compiled block encoder :func:`_encode` (every kernel compiled on first use)."""
    compile_kernels()
    return _encode


# --- LANES blocks side by side: the search (steps 1-4) ---------------------------------------
# A group's texels are X [16, LANES] (texel i of lane b's block at X[i, b]); its state is
# S [3 * LANES]: each lane's best score, lo (from ``_LO``), hi (from ``_HI``): one flat array,
# so that the loop keeping a better pair stores at constant offsets (no aliasing checks between
# its three stores: it vectorises). Every loop over the lanes is straight-line
# code (the per-texel work written out four texels per helper, selects instead of branches),
# which LLVM vectorises: one candidate pair for 16 blocks per pass, each lane summing its
# block's texels in order, as the numpy encoder did per block.


@kernel(inline="always")
def _texel(xi: float, lo: float, r7: float, q: float) -> float:
    """Squared error of one texel ``xi`` on the 8-value palette (lo, r) under the rounded
    index guess (``q = 7 / max(r, 1)``, offset by the interpolants' mean truncation);
    ``r7 = r fl(1/7)``: the entry ``floor(j r / 7)`` is ``floor(j r7)`` (see ``_RECIP7``)."""
    u = xi - lo
    j = np.rint((u + _TRUNC) * q)
    j = j if j > _0 else _0
    j = j if j < _7 else _7
    d = u - np.floor(j * r7)
    return d * d


@kernel(inline="always")
def _add4(X: np.ndarray, i: int, b: int, lo: float, r7: float, q: float, acc: float) -> float:
    """``acc`` plus the squared errors of texels i .. i+3 of lane ``b``, added in order."""
    acc += _texel(X[i, b], lo, r7, q)
    acc += _texel(X[i + 1, b], lo, r7, q)
    acc += _texel(X[i + 2, b], lo, r7, q)
    return acc + _texel(X[i + 3, b], lo, r7, q)


@kernel(inline="always")
def _excess(e: float) -> float:
    t = e - _TAU
    return t if t > _0 else _0


@kernel(inline="always")
def _add4_tail(
    X: np.ndarray, i: int, b: int, lo: float, r7: float, q: float, acc: float, ex: float
):
    """:func:`_add4` and the sum of the same texels' excess over ``HARD_TEXEL_ERROR``."""
    e = _texel(X[i, b], lo, r7, q)
    acc += e
    ex += _excess(e)
    e = _texel(X[i + 1, b], lo, r7, q)
    acc += e
    ex += _excess(e)
    e = _texel(X[i + 2, b], lo, r7, q)
    acc += e
    ex += _excess(e)
    e = _texel(X[i + 3, b], lo, r7, q)
    return acc + e, ex + _excess(e)


@kernel(inline="always")
def _sse(X: np.ndarray, b: int, lo: float, r: float) -> float:
    """Approximate squared error of (lo, r) for lane ``b``: one rounded index guess per texel."""
    q = _7 / (r if r > _1 else _1)
    r7 = r * _RECIP7
    acc = _add4(X, 0, b, lo, r7, q, _0)
    acc = _add4(X, 4, b, lo, r7, q, acc)
    acc = _add4(X, 8, b, lo, r7, q, acc)
    return _add4(X, 12, b, lo, r7, q, acc)


@kernel(inline="always")
def _tail(X: np.ndarray, b: int, lo: float, r: float) -> float:
    """:func:`_sse` plus ``HARD_PENALTY`` times each texel's excess over
    ``HARD_TEXEL_ERROR`` (the tail score of step 4)."""
    q = _7 / (r if r > _1 else _1)
    r7 = r * _RECIP7
    acc, ex = _add4_tail(X, 0, b, lo, r7, q, _0, _0)
    acc, ex = _add4_tail(X, 4, b, lo, r7, q, acc, ex)
    acc, ex = _add4_tail(X, 8, b, lo, r7, q, acc, ex)
    acc, ex = _add4_tail(X, 12, b, lo, r7, q, acc, ex)
    return acc + _LAM * ex


@kernel(inline="always")
def _consider(
    X: np.ndarray,
    B: np.ndarray,
    il: int,
    ih: int,
    dl: float,
    dh: float,
    S: np.ndarray,
    C: np.ndarray,
    tail: bool,
) -> None:
    """One candidate pair per lane, ``(B[il, b] + dl, B[ih, b] + dh)`` clamped to 0..255 and
    valid when hi >= lo, scored (approximate squared error, ``tail``: the tail score) and
    kept in ``S`` where strictly below the lane's best. The scores go to ``C[0]`` first: a
    loop whose only store is one row vectorises (LLVM checks few aliases). Rows are passed as
    indices, not views: a view costs reference counting on every call."""
    if tail:
        for b in range(LANES):
            lo = bc4_block.clamp(B[il, b] + dl, _0, _255)
            hi = bc4_block.clamp(B[ih, b] + dh, _0, _255)
            C[0, b] = _tail(X, b, lo, hi - lo)
    else:
        for b in range(LANES):
            lo = bc4_block.clamp(B[il, b] + dl, _0, _255)
            hi = bc4_block.clamp(B[ih, b] + dh, _0, _255)
            C[0, b] = _sse(X, b, lo, hi - lo)
    for b in range(LANES):
        lo = bc4_block.clamp(B[il, b] + dl, _0, _255)
        hi = bc4_block.clamp(B[ih, b] + dh, _0, _255)
        s = C[0, b]
        keep = (hi >= lo) & (s < S[b])
        S[b] = s if keep else S[b]
        S[_LO + b] = lo if keep else S[_LO + b]
        S[_HI + b] = hi if keep else S[_HI + b]


@kernel()
def _range(X: np.ndarray, R: np.ndarray) -> None:
    """Each lane's texel minimum and maximum into ``R[0]``, ``R[1]``."""
    for b in range(LANES):
        R[0, b] = X[0, b]
        R[1, b] = X[0, b]
    for i in range(1, 16):
        for b in range(LANES):
            v = X[i, b]
            R[0, b] = v if v < R[0, b] else R[0, b]
            R[1, b] = v if v > R[1, b] else R[1, b]


@kernel()
def _exact_lanes(X: np.ndarray, S: np.ndarray, J: np.ndarray, E: np.ndarray, W: np.ndarray):
    """Exact nearest positions ``J`` [16, LANES] and squared errors ``E`` of each lane's pair
    (lo, hi) in ``S``; ``W[0]`` their sum (texel order), ``W[1]`` the largest, ``W[2]`` the
    sum plus ``HARD_PENALTY`` times each texel's excess over ``HARD_TEXEL_ERROR``."""
    for i in range(16):
        for b in range(LANES):
            lo = S[_LO + b]
            r = S[_HI + b] - lo
            rr = r if r > _1 else _1
            E[i, b], J[i, b] = bc4_block.nearest(X[i, b] - lo, _7, rr, _7 / rr, r * _RECIP7)
    for b in range(LANES):
        W[0, b] = _0
        W[1, b] = _0
        W[3, b] = _0
    for i in range(16):
        for b in range(LANES):
            W[0, b] += E[i, b]
            W[3, b] += _excess(E[i, b])
            # the error of the exact index as the numpy encoder measured it: x - (lo + entry)
            d = X[i, b] - (S[_LO + b] + np.floor(J[i, b] * (S[_HI + b] - S[_LO + b]) * _RECIP7))
            d = d * d
            W[1, b] = d if d > W[1, b] else W[1, b]
    for b in range(LANES):
        W[2, b] = W[0, b] + _LAM * W[3, b]


@kernel()
def _fit(X: np.ndarray, J: np.ndarray, S: np.ndarray, C: np.ndarray, A: np.ndarray) -> None:
    """Least-squares endpoints for palette positions ``J`` [16, LANES], rounded four ways and
    considered in turn; a degenerate fit (every texel on one position) falls back to the best
    pair so far. ``A`` [5, LANES] is scratch."""
    for b in range(LANES):
        for k in range(5):
            A[k, b] = _0
    for i in range(16):
        for b in range(LANES):
            w = J[i, b] * _SEVENTH
            v = _1 - w
            x = X[i, b]
            A[0, b] += v * v
            A[1, b] += v * w
            A[2, b] += w * w
            A[3, b] += v * x
            A[4, b] += w * x
    for b in range(LANES):
        a, bb, c, p, q = A[0, b], A[1, b], A[2, b], A[3, b], A[4, b]
        det = a * c - bb * bb
        ok = det > _DET_MIN
        dd = det if ok else _1
        A[0, b] = ((c * p - bb * q) / dd if ok else S[_LO + b]) + _TRUNC
        A[1, b] = ((a * q - bb * p) / dd if ok else S[_HI + b]) + _TRUNC
    for b in range(LANES):
        lo = A[0, b]
        hi = A[1, b]
        A[0, b] = np.floor(lo)
        A[1, b] = np.ceil(lo)
        A[2, b] = np.floor(hi)
        A[3, b] = np.ceil(hi)
    for k in range(4):
        _consider(X, A, k // 2, 2 + k % 2, _0, _0, S, C, False)


@kernel()
def _around(X: np.ndarray, S: np.ndarray, C: np.ndarray, A: np.ndarray, tail: bool) -> None:
    """The eight pairs one level around each lane's best (either endpoint moved by -1, 0, 1)."""
    for b in range(LANES):
        A[0, b] = S[_LO + b]
        A[1, b] = S[_HI + b]
    for dl in range(-1, 2):
        for dh in range(-1, 2):
            if dl or dh:
                _consider(X, A, 0, 1, _F(dl), _F(dh), S, C, tail)


@kernel(inline="always")
def _mark(S: np.ndarray, C: np.ndarray) -> None:
    """Each lane's best score into ``C[3]`` (for :func:`_moved`)."""
    for b in range(LANES):
        C[3, b] = S[b]


@kernel(inline="always")
def _moved(S: np.ndarray, C: np.ndarray) -> bool:
    """Whether any lane's best changed since :func:`_mark` (a new best scores strictly lower
    than the one it replaces)."""
    n = 0
    for b in range(LANES):
        n += 1 if S[b] != C[3, b] else 0
    return n > 0


@kernel()
def _search(X, S, R, J, E, W, C, A) -> bool:  # noqa: ANN001 (numba kernels: arrays)
    """Steps 1-3 for a group: each lane's 8-value endpoints into ``S``. ``R`` [8, LANES],
    ``J``, ``E`` [16, LANES], ``W`` [4, LANES], ``C`` [4, LANES], ``A`` [5, LANES] are
    scratch. Returns whether ``J``, ``E``, ``W`` hold :func:`_exact_lanes` of ``S`` (no best
    changed after the last Lloyd round's)."""
    _range(X, R)
    for b in range(LANES):
        R[2, b] = np.floor(R[0, b])
        R[3, b] = np.ceil(R[1, b])
        span = R[1, b] - R[0, b]
        R[4, b] = span if span > _RANGE_MIN else _RANGE_MIN
        S[b] = _INF
        S[_LO + b] = R[2, b]
        S[_HI + b] = R[3, b]
    for a in range(3):
        for c in range(3):
            _consider(X, R, 2, 3, _F(a), -_F(c), S, C, False)
    for i in range(16):  # each texel's place in the block's range, 0..1
        for b in range(LANES):
            E[i, b] = (X[i, b] - R[0, b]) / R[4, b]
    for k in range(_EXTENDED.shape[0]):
        j0 = _F(_EXTENDED[k, 0])
        d = _F(_EXTENDED[k, 1] - _EXTENDED[k, 0])
        for i in range(16):
            for b in range(LANES):
                J[i, b] = np.rint(E[i, b] * d) + j0
        _fit(X, J, S, C, A)
    # Two Lloyd rounds, then two rounds around the best. A round after one that changed no
    # lane's best would score the same pairs again (the same scores, none strictly lower than
    # the best): it is skipped.
    _exact_lanes(X, S, J, E, W)
    _mark(S, C)
    _fit(X, J, S, C, A)
    if _moved(S, C):
        _exact_lanes(X, S, J, E, W)
        _mark(S, C)
        _fit(X, J, S, C, A)
    current = not _moved(S, C)  # J, E, W still hold the exact positions of each lane's best
    _mark(S, C)
    _around(X, S, C, A, False)
    if _moved(S, C):
        _around(X, S, C, A, False)
        current = False
    return current


@kernel()
def _window(X, S, R, step: int, C, coarse: int) -> None:  # noqa: ANN001 (numba kernels: arrays)
    """Step 4's window for a group, scored by the tail score: every pair with ``lo`` in
    ``[min - HARD_OUTSIDE, min + inside]`` and ``hi`` in ``[max - inside, max + HARD_OUTSIDE]``
    (every ``step``-th level of each, on a grid anchored at floor(min) and ceil(max)); keeps
    the first best in ``S`` (``lo`` offsets outer, ``hi`` offsets inner). ``R[5]`` holds each
    lane's ``inside``; the lanes run the union of their windows, each taking only its own.

    ``coarse`` > 1: ``S`` holds the best of this window searched every ``coarse``-th level
    (and around it). The pairs on that grid are skipped: each was scored there (a lane's own
    window only grows with the step) and is not below that best, which is the first pair
    scored here, so none of them could replace it."""
    _range(X, R)
    for b in range(LANES):
        top = np.ceil(R[5, b])
        R[6, b] = np.ceil(top / _F(step)) * _F(step)  # the lane's own reach inside its range
        R[2, b] = np.floor(R[0, b])
        R[3, b] = np.ceil(R[1, b])
        S[b] = _INF
        C[1, b] = S[_LO + b]
        C[2, b] = S[_HI + b]
    _consider(X, C, 1, 2, _0, _0, S, C, True)  # the current pair: a pair must beat it
    top = -(-_TOP // step) * step
    out = -(-HARD_OUTSIDE // step) * step
    for dl in range(-out, top + 1, step):
        for dh in range(-top, HARD_OUTSIDE + 1, step):
            if coarse > 1 and dl % coarse == 0 and dh % coarse == 0:
                continue
            _consider_window(X, R, _F(dl), _F(dh), S, C)


@kernel(inline="always")
def _valid(R: np.ndarray, b: int, dl: float, dh: float) -> bool:
    """Whether the window's pair ``(floor(min) + dl, ceil(max) + dh)`` is in lane ``b``'s own
    window: ``dl`` up to its reach ``R[6]``, ``dh`` from minus it, ``lo <= min + inside``,
    ``hi >= max - inside``, ``hi >= lo`` (clamped to 0..255)."""
    lo = bc4_block.clamp(R[2, b] + dl, _0, _255)
    hi = bc4_block.clamp(R[3, b] + dh, _0, _255)
    inside = R[5, b]
    return (
        (dl <= R[6, b])
        & (dh >= -R[6, b])
        & (lo <= R[0, b] + inside)
        & (hi >= R[1, b] - inside)
        & (hi >= lo)
    )


@kernel(inline="always")
def _consider_window(X, R, dl: float, dh: float, S, C) -> None:  # noqa: ANN001 (arrays)
    """The window's pair ``(floor(min) + dl, ceil(max) + dh)`` per lane (clamped), tail-scored
    and kept where valid for the lane (:func:`_valid`) and strictly below its best."""
    for b in range(LANES):
        lo = bc4_block.clamp(R[2, b] + dl, _0, _255)
        hi = bc4_block.clamp(R[3, b] + dh, _0, _255)
        C[0, b] = _tail(X, b, lo, hi - lo)
    for b in range(LANES):
        lo = bc4_block.clamp(R[2, b] + dl, _0, _255)
        hi = bc4_block.clamp(R[3, b] + dh, _0, _255)
        s = C[0, b]
        keep = _valid(R, b, dl, dh) & (s < S[b])
        S[b] = s if keep else S[b]
        S[_LO + b] = lo if keep else S[_LO + b]
        S[_HI + b] = hi if keep else S[_HI + b]


@kernel()
def _gather(x: np.ndarray, ids: np.ndarray, g: int, X: np.ndarray) -> int:
    """The blocks ``ids[g : g + LANES]`` into the lanes of ``X`` (the last repeated in lanes
    past the end); returns how many are real."""
    n = min(LANES, ids.size - g)
    for b in range(LANES):
        k = ids[g + min(b, n - 1)]
        for i in range(16):
            X[i, b] = x[k, i]
    return n


@kernel(inline="always")
def _keep(J: np.ndarray, W: np.ndarray, b: int, codes: np.ndarray, sse: np.ndarray, k: int):
    """Lane ``b``'s exact positions ``J`` and squared error ``W[0]`` as block ``k``'s."""
    for i in range(16):
        codes[k, i] = J[i, b]
    sse[k] = W[0, b]


@kernel()
def _encode(x: np.ndarray, step: int, reference: int, out: np.ndarray) -> None:
    """BC4 blocks ``out`` [N, 8] of target blocks ``x`` [N, 16]; ``reference`` > 0: the
    exhaustive search with that many levels outside each block's range after the search."""
    n = x.shape[0]
    f = np.float32
    X = np.empty((16, LANES), f)
    S = np.empty(3 * LANES, f)
    R = np.empty((8, LANES), f)
    J = np.empty((16, LANES), f)
    E = np.empty((16, LANES), f)
    W = np.empty((4, LANES), f)
    C = np.empty((4, LANES), f)
    A = np.empty((5, LANES), f)
    lo = np.empty(n, f)  # the search's pair
    hi = np.empty(n, f)
    wlo = np.empty(n, f)  # step 4's pair (hard blocks)
    whi = np.empty(n, f)
    inside = np.empty(n, f)
    before = np.empty(n, f)  # the search pair's exact tail score
    codes = np.empty((n, 16), f)  # the exact nearest positions of each block's pair ...
    sse = np.empty(n, f)  # ... and their squared error (kept: packing needs no second pass)
    hard = np.zeros(n, np.bool_)
    tail = np.zeros(n, np.bool_)
    every = np.arange(n)
    # steps 1-3, and which blocks are hard (a texel 2 levels or more off)
    for g in range(0, n, LANES):
        m = _gather(x, every, g, X)
        if not _search(X, S, R, J, E, W, C, A):
            _exact_lanes(X, S, J, E, W)
        for b in range(m):
            k = g + b
            lo[k] = S[_LO + b]
            hi[k] = S[_HI + b]
            _keep(J, W, b, codes, sse, k)
            hard[k] = W[1, b] >= _TAU
            inside[k] = min(np.sqrt(W[0, b]), _INSIDE)
            before[k] = W[2, b]
    # step 4: the hard blocks' window (coarse), the pairs around its best
    ids = np.flatnonzero(hard)
    for g in range(0, ids.size, LANES):
        m = _gather(x, ids, g, X)
        for b in range(LANES):
            k = ids[g + min(b, m - 1)]
            S[_LO + b] = lo[k]
            S[_HI + b] = hi[k]
            R[5, b] = inside[k]
        _window(X, S, R, step, C, 0)
        if step > 1:
            _around(X, S, C, A, True)
        _exact_lanes(X, S, J, E, W)
        for b in range(m):
            k = ids[g + b]
            tail[k] = step > 1 and W[1, b] >= _TAIL
            if not tail[k] and W[2, b] < before[k]:  # the scorer's guess, confirmed exactly
                lo[k] = S[_LO + b]
                hi[k] = S[_HI + b]
                _keep(J, W, b, codes, sse, k)
            wlo[k] = S[_LO + b]
            whi[k] = S[_HI + b]
    # ... and the whole window for the blocks still 3 levels or more off
    ids = np.flatnonzero(tail)
    for g in range(0, ids.size, LANES):
        m = _gather(x, ids, g, X)
        for b in range(LANES):
            k = ids[g + min(b, m - 1)]
            S[_LO + b] = wlo[k]
            S[_HI + b] = whi[k]
            R[5, b] = inside[k]
        _window(X, S, R, 1, C, step)
        _exact_lanes(X, S, J, E, W)
        for b in range(m):
            k = ids[g + b]
            if W[2, b] < before[k]:
                lo[k] = S[_LO + b]
                hi[k] = S[_HI + b]
                _keep(J, W, b, codes, sse, k)
    # the exhaustive reference: every pair of a wide window, exactly scored
    if reference > 0:
        j = np.empty(16, f)
        e = np.empty(16, f)
        st = np.empty(3, f)
        for k in range(n):
            xb = x[k]
            st[1] = lo[k]
            st[2] = hi[k]
            s8 = bc4_block.exact8(xb, lo[k], hi[k] - lo[k], j, e)
            bc4_block.window_exact(xb, st, reference, np.sqrt(s8))
            lo[k] = st[1]
            hi[k] = st[2]
        for g in range(0, n, LANES):  # the exact positions of the reference's pairs
            m = _gather(x, every, g, X)
            for b in range(LANES):
                k = g + min(b, m - 1)
                S[_LO + b] = lo[k]
                S[_HI + b] = hi[k]
            _exact_lanes(X, S, J, E, W)
            for b in range(m):
                _keep(J, W, b, codes, sse, g + b)
    # step 5 and packing: each block's pair with the exact positions kept when it was chosen
    for k in range(n):
        bc4_block.finish(x[k], lo[k], hi[k], sse[k], codes[k], out[k])
