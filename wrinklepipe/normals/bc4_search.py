"""The BC4 endpoint search of :mod:`wrinklepipe.normals.bc4`, per block, compiled by numba.

The functions here are plain Python until :func:`compiled` is first called: it imports numba
(about half a second, which every command that never encodes a BC4 block is spared), compiles
each function marked ``@_kernel`` and puts the compiled function in its place in this module,
so that the kernels call each other compiled. numba caches the machine code beside the module
(``cache=True``): a later process loads it instead of compiling (about 12 s of CPU).

Arithmetic is float32 throughout, operation by operation as the numpy encoder this replaced
did it (no fused multiply-adds: numba does not contract without fastmath); constants are
module-level float32 values, which numba types as float32 (a Python float literal would turn
an expression into float64). Sums over a block's texels run in texel order.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

#: The kernels and their numba options, in definition order (see :func:`compiled`).
_KERNELS: list[tuple[str, dict[str, Any]]] = []
_JIT = {"cache": True, "nogil": True, "error_model": "numpy", "boundscheck": False}
_COMPILED = False
_LOCK = threading.Lock()


def _kernel(**options: Any) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Mark a function to be compiled by :func:`compiled` (with numba ``options``)."""

    def mark(fn: Callable[..., Any]) -> Callable[..., Any]:
        _KERNELS.append((fn.__name__, {**_JIT, **options}))
        return fn

    return mark


def compiled() -> Callable[..., None]:
    """The compiled block encoder :func:`_encode` (each kernel compiled on first use)."""
    global _COMPILED
    with _LOCK:
        if not _COMPILED:
            import numba  # deferred: ~0.5 s to import, needed only when BC4 blocks are encoded

            module = globals()
            for name, options in _KERNELS:
                module[name] = numba.njit(**options)(module[name])
            _COMPILED = True
    return _encode


_F = np.float32
#: Mean truncation of the 8-value palette's interpolants (floor of j r / 7), in levels.
_TRUNC = _F(0.43)
#: Step 4: a block is hard when a texel misses by 2 levels or more (squared error 4); its
#: pairs are then scored with every texel's excess over that times ``HARD_PENALTY``; levels
#: searched outside / inside its range: every ``HARD_STEP``-th pair of that window, then the
#: pairs one level around the best; the blocks still missing by 3 levels or more (squared error
#: ``HARD_TAIL``: the tail the p99 is made of) get every pair of the window.
HARD_TEXEL_ERROR = 4.0
HARD_PENALTY = 1.0
HARD_OUTSIDE = 16
HARD_INSIDE = 8.0
HARD_STEP = 4
HARD_TAIL = 9.0
# float32 constants: numba types a module-level numpy float32 as float32, so arithmetic with
# them stays in float32 (a Python float literal would promote an expression to float64)
_0, _1, _2, _5, _7 = _F(0), _F(1), _F(2), _F(5), _F(7)
_255 = _F(255)
_SEVENTH = _F(1.0 / 7.0)
_DET_MIN = _F(1e-3)
_RANGE_MIN = _F(1e-6)
_INF = _F(np.inf)
_TAU = _F(HARD_TEXEL_ERROR)
_LAM = _F(HARD_PENALTY)
_INSIDE = _F(HARD_INSIDE)
_TAIL = _F(HARD_TAIL)
#: Step 2: (palette position of the block's minimum, of its maximum) for the extended fits.
_EXTENDED = np.array([(0, 6), (1, 7), (1, 6), (0, 5), (2, 7), (2, 6), (1, 5)], np.int64)
#: A palette entry ``floor(j r / n)`` (j <= n, r <= 255 integers; n = 7 or 5) is exactly
#: ``floor(j * fl(r * fl(1 / n)))`` (fl(1/7) and fl(1/5) round up; a test checks every j, r):
#: a multiply per texel instead of a multiply and a divide, and the same value.
_RECIP7 = _1 / _7
_RECIP5 = _1 / _5
#: Blocks searched side by side, one per SIMD lane (16 float32: one AVX-512 register).
LANES = 16
#: The window's widest reach inside a block's range (``ceil(HARD_INSIDE)``).
_TOP = int(np.ceil(HARD_INSIDE))


# --- one block, exactly scored (the final indices, the confirmations, the reference) ---------


@_kernel()
def _clamp(v: float, lo: float, hi: float) -> float:
    v = v if v > lo else lo
    return v if v < hi else hi


@_kernel(inline="always")
def _nearest(u: float, fn: float, rr: float, step: float, rn: float):
    """Squared error and palette position j (0..n) of the entry ``floor(j r / n)`` nearest to
    ``u`` (first of equals): j0 = floor(n u / r) and the next two (the usual answer), then
    ``up - 1`` and ``up`` (``up`` the first j whose entry exceeds u:
    ``ceil((floor(u) + 1) n / r)``). The last two alone are exact; they matter when r is
    small, where truncation puts several positions on one value (r = 1: j = 0..n-1 all give 0).
    ``fn = n``, ``rr = max(r, 1)``, ``step = n / rr``, ``rn = r fl(1 / n)`` (the entry
    ``floor(j r / n)`` is ``floor(j rn)``: see ``_RECIP7``)."""
    j0 = np.floor(u * step)
    j0 = j0 if j0 > _0 else _0
    j0 = j0 if j0 < fn else fn
    up = np.ceil((np.floor(u) + _1) * fn / rr)
    up = up if up > _0 else _0
    up = up if up < fn else fn
    bj = j0
    d = u - np.floor(j0 * rn)
    best = d * d
    j = j0 + _1
    j = j if j < fn else fn
    d = u - np.floor(j * rn)
    e = d * d
    bj = j if e < best else bj
    best = e if e < best else best
    j = j0 + _2
    j = j if j < fn else fn
    d = u - np.floor(j * rn)
    e = d * d
    bj = j if e < best else bj
    best = e if e < best else best
    j = up - _1
    j = j if j > _0 else _0
    d = u - np.floor(j * rn)
    e = d * d
    bj = j if e < best else bj
    best = e if e < best else best
    d = u - np.floor(up * rn)
    e = d * d
    bj = up if e < best else bj
    best = e if e < best else best
    return best, bj


@_kernel()
def _exact8(x: np.ndarray, lo: float, r: float, j: np.ndarray, e: np.ndarray) -> float:
    """Exact squared error of the 8-value palette (lo, r) for the block ``x`` [16]; ``j``
    [16] receives each texel's nearest palette position (0 = lo .. 7 = hi), ``e`` [16] its
    squared error."""
    rr = r if r > _1 else _1
    step = _7 / rr
    for i in range(16):
        e[i], j[i] = _nearest(x[i] - lo, _7, rr, step, r * _RECIP7)
    s = _0
    for i in range(16):
        s += e[i]
    return s


@_kernel()
def _window_exact(x: np.ndarray, st: np.ndarray, outside: int, inside: float) -> None:
    """The exhaustive reference's window for one block: every pair with ``lo`` in
    ``[min - outside, min + inside]`` and ``hi`` in ``[max - inside, max + outside]``, exactly
    scored; keeps the first best in ``st`` = [score, lo, hi] (``lo`` offsets outer)."""
    e = np.empty(16, np.float32)
    j = np.empty(16, np.float32)
    st[0] = _exact8(x, st[1], st[2] - st[1], j, e)
    xmin = x[0]
    xmax = x[0]
    for i in range(1, 16):
        xmin = min(xmin, x[i])
        xmax = max(xmax, x[i])
    fmn, cmx = np.floor(xmin), np.ceil(xmax)
    top = int(np.ceil(inside))
    lo_max = xmin + inside
    lim = xmax - inside
    for dl in range(-outside, top + 1):
        lo = _clamp(fmn + _F(dl), _0, _255)
        if not lo <= lo_max:
            continue
        for dh in range(-top, outside + 1):
            hi = _clamp(cmx + _F(dh), _0, _255)
            if hi >= lo and hi >= lim:
                s = _exact8(x, lo, hi - lo, j, e)
                if s < st[0]:
                    st[0] = s
                    st[1] = lo
                    st[2] = hi


@_kernel()
def _exact6(x: np.ndarray, lo: float, r: float, codes: np.ndarray) -> float:
    """Exact squared error of the 6-value palette (lo, 4 interpolants, hi, 0, 255); ``codes``
    [16] receives each texel's BC4 code."""
    rr = r if r > _1 else _1
    step = _5 / rr
    s = _0
    for i in range(16):
        e, j = _nearest(x[i] - lo, _5, rr, step, r * _RECIP5)
        c = _0 if j == _0 else (_1 if j == _5 else j + _1)
        e0 = x[i] * x[i]
        if e0 < e:
            e, c = e0, _F(6)
        d = x[i] - _255
        e1 = d * d
        if e1 < e:
            e, c = e1, _7
        codes[i] = c
        s += e
    return s


@_kernel()
def _pack(e0: float, e1: float, codes: np.ndarray, out: np.ndarray) -> None:
    out[0] = np.uint8(e0)
    out[1] = np.uint8(e1)
    bits = np.uint64(0)
    for k in range(16):
        bits |= np.uint64(codes[k]) << np.uint64(3 * k)
    for b in range(6):
        out[2 + b] = np.uint8((bits >> np.uint64(8 * b)) & np.uint64(0xFF))


@_kernel()
def _finish(x: np.ndarray, lo: float, hi: float, sse8: float, j: np.ndarray, out: np.ndarray):
    """Step 5 and packing of one block: its pair (lo, hi) with exact nearest positions ``j``
    [16] (as codes: overwritten) and squared error ``sse8``; the six-value mode where it wins
    (blocks that reach below 8 or above 247)."""
    r = hi - lo
    for i in range(16):
        if r == _0:  # lo == hi: six-value mode, every texel e0
            j[i] = _0
        elif j[i] == _7:
            j[i] = _0
        elif j[i] == _0:
            j[i] = _1
        else:
            j[i] = _F(8) - j[i]
    e0, e1 = hi, lo
    xmin = x[0]
    xmax = x[0]
    for i in range(1, 16):
        xmin = min(xmin, x[i])
        xmax = max(xmax, x[i])
    if xmin < _F(8) or xmax > _F(247):
        lo6 = _255
        hi6 = _0
        any_inner = False
        for i in range(16):
            if x[i] > _F(4) and x[i] < _F(251):
                lo6 = min(lo6, x[i])
                hi6 = max(hi6, x[i])
                any_inner = True
        if any_inner:
            lo6, hi6 = np.floor(lo6), np.ceil(hi6)
        else:
            lo6, hi6 = _0, _0
        hi6 = max(hi6, lo6)
        c6 = np.empty(16, np.float32)
        if _exact6(x, lo6, hi6 - lo6, c6) < sse8:
            e0, e1 = lo6, hi6
            for i in range(16):
                j[i] = c6[i]
    _pack(e0, e1, j, out)


# --- LANES blocks side by side: the search (steps 1-4) ---------------------------------------
# A group's texels are X [16, LANES] (texel i of lane b's block at X[i, b]); its state is
# S [3, LANES]: each lane's best score, lo, hi. Every loop over the lanes is straight-line
# code (the per-texel work written out four texels per helper, selects instead of branches),
# which LLVM vectorises: one candidate pair for 16 blocks per pass, each lane summing its
# block's texels in order, as the numpy encoder did per block.


@_kernel(inline="always")
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


@_kernel(inline="always")
def _add4(X: np.ndarray, i: int, b: int, lo: float, r7: float, q: float, acc: float) -> float:
    """``acc`` plus the squared errors of texels i .. i+3 of lane ``b``, added in order."""
    acc += _texel(X[i, b], lo, r7, q)
    acc += _texel(X[i + 1, b], lo, r7, q)
    acc += _texel(X[i + 2, b], lo, r7, q)
    return acc + _texel(X[i + 3, b], lo, r7, q)


@_kernel(inline="always")
def _excess(e: float) -> float:
    t = e - _TAU
    return t if t > _0 else _0


@_kernel(inline="always")
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


@_kernel(inline="always")
def _sse(X: np.ndarray, b: int, lo: float, r: float) -> float:
    """Approximate squared error of (lo, r) for lane ``b``: one rounded index guess per texel."""
    q = _7 / (r if r > _1 else _1)
    r7 = r * _RECIP7
    acc = _add4(X, 0, b, lo, r7, q, _0)
    acc = _add4(X, 4, b, lo, r7, q, acc)
    acc = _add4(X, 8, b, lo, r7, q, acc)
    return _add4(X, 12, b, lo, r7, q, acc)


@_kernel(inline="always")
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


@_kernel(inline="always")
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
            lo = _clamp(B[il, b] + dl, _0, _255)
            hi = _clamp(B[ih, b] + dh, _0, _255)
            C[0, b] = _tail(X, b, lo, hi - lo)
    else:
        for b in range(LANES):
            lo = _clamp(B[il, b] + dl, _0, _255)
            hi = _clamp(B[ih, b] + dh, _0, _255)
            C[0, b] = _sse(X, b, lo, hi - lo)
    for b in range(LANES):
        lo = _clamp(B[il, b] + dl, _0, _255)
        hi = _clamp(B[ih, b] + dh, _0, _255)
        s = C[0, b]
        keep = (hi >= lo) & (s < S[0, b])
        S[0, b] = s if keep else S[0, b]
        S[1, b] = lo if keep else S[1, b]
        S[2, b] = hi if keep else S[2, b]


@_kernel()
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


@_kernel()
def _exact_lanes(X: np.ndarray, S: np.ndarray, J: np.ndarray, E: np.ndarray, W: np.ndarray):
    """Exact nearest positions ``J`` [16, LANES] and squared errors ``E`` of each lane's pair
    ``S[1:3]``; ``W[0]`` their sum (texel order), ``W[1]`` the largest, ``W[2]`` the sum plus
    ``HARD_PENALTY`` times each texel's excess over ``HARD_TEXEL_ERROR``."""
    for i in range(16):
        for b in range(LANES):
            lo = S[1, b]
            r = S[2, b] - lo
            rr = r if r > _1 else _1
            E[i, b], J[i, b] = _nearest(X[i, b] - lo, _7, rr, _7 / rr, r * _RECIP7)
    for b in range(LANES):
        W[0, b] = _0
        W[1, b] = _0
        W[3, b] = _0
    for i in range(16):
        for b in range(LANES):
            W[0, b] += E[i, b]
            W[3, b] += _excess(E[i, b])
            # the error of the exact index as the numpy encoder measured it: x - (lo + entry)
            d = X[i, b] - (S[1, b] + np.floor(J[i, b] * (S[2, b] - S[1, b]) * _RECIP7))
            d = d * d
            W[1, b] = d if d > W[1, b] else W[1, b]
    for b in range(LANES):
        W[2, b] = W[0, b] + _LAM * W[3, b]


@_kernel()
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
        A[0, b] = ((c * p - bb * q) / dd if ok else S[1, b]) + _TRUNC
        A[1, b] = ((a * q - bb * p) / dd if ok else S[2, b]) + _TRUNC
    for b in range(LANES):
        lo = A[0, b]
        hi = A[1, b]
        A[0, b] = np.floor(lo)
        A[1, b] = np.ceil(lo)
        A[2, b] = np.floor(hi)
        A[3, b] = np.ceil(hi)
    for k in range(4):
        _consider(X, A, k // 2, 2 + k % 2, _0, _0, S, C, False)


@_kernel()
def _around(X: np.ndarray, S: np.ndarray, C: np.ndarray, A: np.ndarray, tail: bool) -> None:
    """The eight pairs one level around each lane's best (either endpoint moved by -1, 0, 1)."""
    for b in range(LANES):
        A[0, b] = S[1, b]
        A[1, b] = S[2, b]
    for dl in range(-1, 2):
        for dh in range(-1, 2):
            if dl or dh:
                _consider(X, A, 0, 1, _F(dl), _F(dh), S, C, tail)


@_kernel()
def _search(X, S, R, J, E, W, C, A) -> None:  # noqa: ANN001 (numba kernels: arrays)
    """Steps 1-3 for a group: each lane's 8-value endpoints into ``S``. ``R`` [8, LANES],
    ``J``, ``E`` [16, LANES], ``W`` [4, LANES], ``C`` [3, LANES], ``A`` [5, LANES] are
    scratch."""
    _range(X, R)
    for b in range(LANES):
        R[2, b] = np.floor(R[0, b])
        R[3, b] = np.ceil(R[1, b])
        span = R[1, b] - R[0, b]
        R[4, b] = span if span > _RANGE_MIN else _RANGE_MIN
        S[0, b] = _INF
        S[1, b] = R[2, b]
        S[2, b] = R[3, b]
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
    for _ in range(2):
        _exact_lanes(X, S, J, E, W)
        _fit(X, J, S, C, A)
    for _ in range(2):
        _around(X, S, C, A, False)


@_kernel()
def _window(X, S, R, step: int, C) -> None:  # noqa: ANN001 (numba kernels: arrays)
    """Step 4's window for a group, scored by the tail score: every pair with ``lo`` in
    ``[min - HARD_OUTSIDE, min + inside]`` and ``hi`` in ``[max - inside, max + HARD_OUTSIDE]``
    (every ``step``-th level of each, on a grid anchored at floor(min) and ceil(max)); keeps
    the first best in ``S`` (``lo`` offsets outer, ``hi`` offsets inner). ``R[5]`` holds each
    lane's ``inside``; the lanes run the union of their windows, each taking only its own."""
    _range(X, R)
    for b in range(LANES):
        top = np.ceil(R[5, b])
        R[6, b] = np.ceil(top / _F(step)) * _F(step)  # the lane's own reach inside its range
        R[2, b] = np.floor(R[0, b])
        R[3, b] = np.ceil(R[1, b])
        S[0, b] = _INF
        C[1, b] = S[1, b]
        C[2, b] = S[2, b]
    _consider(X, C, 1, 2, _0, _0, S, C, True)  # the current pair: a pair must beat it
    top = -(-_TOP // step) * step
    out = -(-HARD_OUTSIDE // step) * step
    for dl in range(-out, top + 1, step):
        for dh in range(-top, HARD_OUTSIDE + 1, step):
            _consider_window(X, R, _F(dl), _F(dh), S, C)


@_kernel(inline="always")
def _valid(R: np.ndarray, b: int, dl: float, dh: float) -> bool:
    """Whether the window's pair ``(floor(min) + dl, ceil(max) + dh)`` is in lane ``b``'s own
    window: ``dl`` up to its reach ``R[6]``, ``dh`` from minus it, ``lo <= min + inside``,
    ``hi >= max - inside``, ``hi >= lo`` (clamped to 0..255)."""
    lo = _clamp(R[2, b] + dl, _0, _255)
    hi = _clamp(R[3, b] + dh, _0, _255)
    inside = R[5, b]
    return (
        (dl <= R[6, b])
        & (dh >= -R[6, b])
        & (lo <= R[0, b] + inside)
        & (hi >= R[1, b] - inside)
        & (hi >= lo)
    )


@_kernel(inline="always")
def _consider_window(X, R, dl: float, dh: float, S, C) -> None:  # noqa: ANN001 (arrays)
    """The window's pair ``(floor(min) + dl, ceil(max) + dh)`` per lane (clamped), tail-scored
    and kept where valid for the lane (:func:`_valid`) and strictly below its best."""
    for b in range(LANES):
        lo = _clamp(R[2, b] + dl, _0, _255)
        hi = _clamp(R[3, b] + dh, _0, _255)
        C[0, b] = _tail(X, b, lo, hi - lo)
    for b in range(LANES):
        lo = _clamp(R[2, b] + dl, _0, _255)
        hi = _clamp(R[3, b] + dh, _0, _255)
        s = C[0, b]
        keep = _valid(R, b, dl, dh) & (s < S[0, b])
        S[0, b] = s if keep else S[0, b]
        S[1, b] = lo if keep else S[1, b]
        S[2, b] = hi if keep else S[2, b]


@_kernel()
def _gather(x: np.ndarray, ids: np.ndarray, g: int, X: np.ndarray) -> int:
    """The blocks ``ids[g : g + LANES]`` into the lanes of ``X`` (the last repeated in lanes
    past the end); returns how many are real."""
    n = min(LANES, ids.size - g)
    for b in range(LANES):
        k = ids[g + min(b, n - 1)]
        for i in range(16):
            X[i, b] = x[k, i]
    return n


@_kernel()
def _encode(x: np.ndarray, step: int, reference: int, out: np.ndarray) -> None:
    """BC4 blocks ``out`` [N, 8] of target blocks ``x`` [N, 16]; ``reference`` > 0: the
    exhaustive search with that many levels outside each block's range after the search."""
    n = x.shape[0]
    f = np.float32
    X = np.empty((16, LANES), f)
    S = np.empty((3, LANES), f)
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
    hard = np.zeros(n, np.bool_)
    tail = np.zeros(n, np.bool_)
    every = np.arange(n)
    # steps 1-3, and which blocks are hard (a texel 2 levels or more off)
    for g in range(0, n, LANES):
        m = _gather(x, every, g, X)
        _search(X, S, R, J, E, W, C, A)
        _exact_lanes(X, S, J, E, W)
        for b in range(m):
            k = g + b
            lo[k] = S[1, b]
            hi[k] = S[2, b]
            hard[k] = W[1, b] >= _TAU
            inside[k] = min(np.sqrt(W[0, b]), _INSIDE)
            before[k] = W[2, b]
    # step 4: the hard blocks' window (coarse), the pairs around its best
    ids = np.flatnonzero(hard)
    for g in range(0, ids.size, LANES):
        m = _gather(x, ids, g, X)
        for b in range(LANES):
            k = ids[g + min(b, m - 1)]
            S[1, b] = lo[k]
            S[2, b] = hi[k]
            R[5, b] = inside[k]
        _window(X, S, R, step, C)
        if step > 1:
            _around(X, S, C, A, True)
        _exact_lanes(X, S, J, E, W)
        for b in range(m):
            k = ids[g + b]
            tail[k] = step > 1 and W[1, b] >= _TAIL
            if not tail[k] and W[2, b] < before[k]:  # the scorer's guess, confirmed exactly
                lo[k] = S[1, b]
                hi[k] = S[2, b]
            wlo[k] = S[1, b]
            whi[k] = S[2, b]
    # ... and the whole window for the blocks still 3 levels or more off
    ids = np.flatnonzero(tail)
    for g in range(0, ids.size, LANES):
        m = _gather(x, ids, g, X)
        for b in range(LANES):
            k = ids[g + min(b, m - 1)]
            S[1, b] = wlo[k]
            S[2, b] = whi[k]
            R[5, b] = inside[k]
        _window(X, S, R, 1, C)
        _exact_lanes(X, S, J, E, W)
        for b in range(m):
            k = ids[g + b]
            if W[2, b] < before[k]:
                lo[k] = S[1, b]
                hi[k] = S[2, b]
    # the exhaustive reference: every pair of a wide window, exactly scored
    if reference > 0:
        j = np.empty(16, f)
        e = np.empty(16, f)
        st = np.empty(3, f)
        for k in range(n):
            xb = x[k]
            st[1] = lo[k]
            st[2] = hi[k]
            sse = _exact8(xb, lo[k], hi[k] - lo[k], j, e)
            _window_exact(xb, st, reference, np.sqrt(sse))
            lo[k] = st[1]
            hi[k] = st[2]
    # step 5 and packing: exact indices of each block's pair
    codes = np.empty(16, f)
    for g in range(0, n, LANES):
        m = _gather(x, every, g, X)
        for b in range(LANES):
            k = g + min(b, m - 1)
            S[1, b] = lo[k]
            S[2, b] = hi[k]
        _exact_lanes(X, S, J, E, W)
        for b in range(m):
            for i in range(16):
                codes[i] = J[i, b]
            _finish(x[g + b], S[1, b], S[2, b], W[0, b], codes, out[g + b])
