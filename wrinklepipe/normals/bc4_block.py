"""The BC4 encoder's kernels for one block, exactly scored: nearest palette entries, the final
indices and the six-value mode (step 5), packing, and the exhaustive reference's window.

Compiled by numba on first use (:mod:`wrinklepipe.normals.bc4_jit`)."""

from __future__ import annotations

import numpy as np

from wrinklepipe.normals.bc4_jit import (
    _F,
    _RECIP5,
    _RECIP7,
    _0,
    _1,
    _2,
    _5,
    _7,
    _255,
    kernel,
)


@kernel()
def clamp(v: float, lo: float, hi: float) -> float:
    v = v if v > lo else lo
    return v if v < hi else hi


@kernel(inline="always")
def nearest(u: float, fn: float, rr: float, step: float, rn: float) -> tuple[float, float]:
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


@kernel()
def exact8(x: np.ndarray, lo: float, r: float, j: np.ndarray, e: np.ndarray) -> float:
    """Exact squared error of the 8-value palette (lo, r) for the block ``x`` [16]; ``j``
    [16] receives each texel's nearest palette position (0 = lo .. 7 = hi), ``e`` [16] its
    squared error."""
    rr = r if r > _1 else _1
    step = _7 / rr
    for i in range(16):
        e[i], j[i] = nearest(x[i] - lo, _7, rr, step, r * _RECIP7)
    s = _0
    for i in range(16):
        s += e[i]
    return s


@kernel()
def window_exact(x: np.ndarray, st: np.ndarray, outside: int, inside: float) -> None:
    """The exhaustive reference's window for one block: every pair with ``lo`` in
    ``[min - outside, min + inside]`` and ``hi`` in ``[max - inside, max + outside]``, exactly
    scored; keeps the first best in ``st`` = [score, lo, hi] (``lo`` offsets outer)."""
    e = np.empty(16, np.float32)
    j = np.empty(16, np.float32)
    st[0] = exact8(x, st[1], st[2] - st[1], j, e)
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
        lo = clamp(fmn + _F(dl), _0, _255)
        if not lo <= lo_max:
            continue
        for dh in range(-top, outside + 1):
            hi = clamp(cmx + _F(dh), _0, _255)
            if hi >= lo and hi >= lim:
                s = exact8(x, lo, hi - lo, j, e)
                if s < st[0]:
                    st[0] = s
                    st[1] = lo
                    st[2] = hi


@kernel()
def exact6(x: np.ndarray, lo: float, r: float, codes: np.ndarray) -> float:
    """Exact squared error of the 6-value palette (lo, 4 interpolants, hi, 0, 255); ``codes``
    [16] receives each texel's BC4 code."""
    rr = r if r > _1 else _1
    step = _5 / rr
    s = _0
    for i in range(16):
        e, j = nearest(x[i] - lo, _5, rr, step, r * _RECIP5)
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


@kernel()
def pack(e0: float, e1: float, codes: np.ndarray, out: np.ndarray) -> None:
    out[0] = np.uint8(e0)
    out[1] = np.uint8(e1)
    bits = np.uint64(0)
    for k in range(16):
        bits |= np.uint64(codes[k]) << np.uint64(3 * k)
    for b in range(6):
        out[2 + b] = np.uint8((bits >> np.uint64(8 * b)) & np.uint64(0xFF))


@kernel()
def finish(
    x: np.ndarray, lo: float, hi: float, sse8: float, j: np.ndarray, out: np.ndarray
) -> None:
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
        if exact6(x, lo6, hi6 - lo6, c6) < sse8:
            e0, e1 = lo6, hi6
            for i in range(16):
                j[i] = c6[i]
    pack(e0, e1, j, out)
