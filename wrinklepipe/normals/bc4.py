"""BC4 / BC5 encoding near the quality limit, in vectorised numpy.

A BC4 block stores two 8-bit endpoints and a 3-bit index per texel. With ``e0 > e1`` the
palette is the endpoints and six interpolants ``lo + floor(j r / 7)`` (``lo = e1``,
``r = e0 - e1``, j = 1..6); with ``e0 <= e1`` it is the endpoints, four interpolants
``lo + floor(j r / 5)``, 0 and 255. Interpolants are truncated as texture2ddecoder and Mesa
decode them (hardware that interpolates in float is within one level). BC5 is two BC4 blocks
(R, then G); a DXT5nm block's alpha half is a BC4 block too.

The encoder minimises each block's squared error to *float* targets in texel units (0..255):
an 8-bit map's own texels, or the unrounded texels of a map still in floating point (closer to
the source). All blocks are searched together, one candidate endpoint pair at a time:

1. pairs just inside the block's range: ``lo`` in ``min + [0, 2]``, ``hi`` in ``max - [0, 2]``;
2. least-squares endpoints for index assignments that put the block's extremes on inner
   palette positions (extended palettes: a cluster then lands exactly on an interpolant), then
   two Lloyd rounds (reassign indices, refit), each fit rounded four ways;
3. two rounds of moving either endpoint by one level;
4. the hard blocks (those with a texel 2 levels or more off) search the pairs up to 16 levels
   outside their range (and up to 8 inside), scored by squared error plus every texel's
   excess over that threshold: a little mean error is traded for a lower tail, so the p99
   ends at or below the exhaustive search's. Every 4th pair of that window first, then the
   pairs one level around the best; the blocks still 3 levels or more off (about a quarter of
   them) then get every pair (the whole window for every hard block costs 2.2 times more for
   the same quality);
5. the six-value mode for blocks that reach 0 or 255 (its palette holds both extremes).

Candidates are scored with one rounded index guess per texel (offset by the interpolants'
mean truncation); the chosen pair then gets exact nearest indices. :func:`reference_bc4` is the
exhaustive search the tests and ``wrinklepipe bench normals`` compare with (slow; small crops).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wrinklepipe.normals._chunks import pool, threads

_F = np.float32
#: Mean truncation of the 8-value palette's interpolants (floor of j r / 7), in levels.
_TRUNC = _F(0.43)
#: Blocks per vectorised batch of the search (every [16, N] temporary stays in the cache).
BATCH = 4096
#: Step 2: (palette position of the block's minimum, of its maximum) for the extended fits.
_EXTENDED = ((0, 6), (1, 7), (1, 6), (0, 5), (2, 7), (2, 6), (1, 5))
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
#: Hard blocks per batch of step 4.
HARD_BATCH = 4096


#: Arrays up to this many values are clamped by two ufunc calls (see :func:`_clamp`).
_SMALL = 1 << 14


def _clamp(a: np.ndarray, lo: float, hi: float, out: np.ndarray | None = None) -> np.ndarray:
    """``np.clip(a, lo, hi, out=out)``. Small arrays take two ufunc calls instead (the same
    values, NaN stays NaN): np.clip's Python-level dispatch costs more than the work on a small
    map's blocks (an encode of 16 blocks makes ~2000 calls), while on large arrays its single
    pass over memory is faster than two."""
    if a.size > _SMALL:
        return np.clip(a, lo, hi, out=out)
    out = np.maximum(a, lo, out=out)
    return np.minimum(out, hi, out=out)


def blocks_of(plane: np.ndarray) -> np.ndarray:
    """[H, W] (multiples of 4) -> [16, N] texel columns, blocks in row-major block order."""
    h, w = plane.shape
    return np.ascontiguousarray(
        plane.reshape(h // 4, 4, w // 4, 4).transpose(1, 3, 0, 2).reshape(16, -1)
    )


class _Scorer:
    """Approximate squared error of 8-value palettes for a batch of blocks ``x`` [16, N]."""

    def __init__(self, x: np.ndarray) -> None:
        self.x = x
        self.u = np.empty_like(x)
        self.j = np.empty_like(x)

    def tail8(self, lo: np.ndarray, r: np.ndarray, tau: float, lam: float) -> np.ndarray:
        """:meth:`sse8` plus ``lam`` times each texel's excess over ``tau``."""
        e = self._errors(lo, r)
        total = e.sum(axis=0)
        e -= _F(tau)
        np.maximum(e, _F(0), out=e)
        total += _F(lam) * e.sum(axis=0)
        return total

    def sse8(self, lo: np.ndarray, r: np.ndarray) -> np.ndarray:
        return self._errors(lo, r).sum(axis=0)

    def _errors(self, lo: np.ndarray, r: np.ndarray) -> np.ndarray:
        u, j = self.u, self.j
        np.subtract(self.x, lo, out=u)
        np.add(u, _TRUNC, out=j)
        j *= _F(7) / np.maximum(r, _F(1))
        np.rint(j, out=j)
        _clamp(j, _F(0), _F(7), out=j)
        j *= r
        j /= _F(7)  # j r is an exact integer; the quotient's floor is exact too
        np.floor(j, out=j)
        np.subtract(u, j, out=j)
        j *= j
        return j


def _positions(u: np.ndarray, r: np.ndarray, n: int) -> list[np.ndarray]:
    """Palette positions j (0..n) that can hold the entry ``floor(j r / n)`` nearest to ``u``:
    j0 = floor(n u / r) and the next two (the usual answer), then ``up`` (the first j whose
    entry exceeds u: ``ceil((floor(u) + 1) n / r)``) and ``up - 1`` (the largest entry at or
    below u). The last two alone are exact; they matter when r is small, where truncation
    puts several positions on one value (r = 1: j = 0..n-1 all give 0)."""
    rr = np.maximum(r, _F(1))
    j0 = _clamp(np.floor(u * (_F(n) / rr)), _F(0), _F(n))
    up = _clamp(np.ceil((np.floor(u) + _F(1)) * _F(n) / rr), _F(0), _F(n))
    near = [np.minimum(j0 + _F(dj), _F(n)) for dj in (0, 1, 2)]
    return near + [np.maximum(up - _F(1), _F(0)), up]


def _exact8(x: np.ndarray, lo: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact squared error and nearest palette position j (0 = lo .. 7 = hi), 8-value mode."""
    u = x - lo
    best = bj = None
    for j in _positions(u, r, 7):
        e = u - np.floor(j * r / _F(7))
        e *= e
        if best is None:
            best, bj = e, j
        else:
            m = e < best
            np.copyto(best, e, where=m)
            np.copyto(bj, j, where=m)
    return best.sum(axis=0), bj


def _exact6(x: np.ndarray, lo: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact squared error and BC4 code of 6-value palettes (lo, 4 interpolants, hi, 0, 255)."""
    u = x - lo
    best = bc = None
    for j in _positions(u, r, 5):
        e = u - np.floor(j * r / _F(5))
        e *= e
        code = np.where(j == 0, _F(0), np.where(j == 5, _F(1), j + _F(1)))
        if best is None:
            best, bc = e, code
        else:
            m = e < best
            np.copyto(best, e, where=m)
            np.copyto(bc, code, where=m)
    for value, code in ((0.0, 6.0), (255.0, 7.0)):
        e = (x - _F(value)) ** 2
        m = e < best
        np.copyto(best, e, where=m)
        np.copyto(bc, _F(code), where=m)
    return best.sum(axis=0), bc


def _search(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steps 1-3: endpoints (lo, hi) [N] of the 8-value mode for a batch ``x`` [16, N].

    The candidates come in groups that do not depend on each other (step 1's nine pairs, one
    fit's four roundings, one round's eight neighbours); each group is scored in one
    :func:`_keep_best` pass, which keeps what considering its pairs one at a time in order
    keeps (a small map's blocks: a few passes instead of 61 sets of numpy calls)."""
    sc = _Scorer(x)
    xmin, xmax = x.min(axis=0), x.max(axis=0)
    mn, mx = np.floor(xmin), np.ceil(xmax)
    best = np.full(x.shape[1], np.inf, _F)
    blo, bhi = mn.copy(), mx.copy()

    def score(xb: np.ndarray, lo: np.ndarray, r: np.ndarray) -> np.ndarray:
        return (sc if xb is x else _Scorer(xb)).sse8(lo, r)

    def consider(los: list[np.ndarray], his: list[np.ndarray]) -> None:
        """The pairs ``(los[k], his[k])`` (each [N], clamped to 0..255), in that order."""
        lo = _clamp(np.stack(los), 0, 255)
        hi = _clamp(np.stack(his), 0, 255)
        ok = hi >= lo

        def pairs(k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            return lo[k], hi[k], ok[k]

        _keep_best(x, blo, bhi, best, pairs, len(los), score)

    def fit(j: np.ndarray) -> None:
        """Least-squares endpoints for palette positions ``j`` [16, N], rounded four ways."""
        w = j * _F(1.0 / 7.0)
        v = _F(1) - w
        a, b, c = (v * v).sum(axis=0), (v * w).sum(axis=0), (w * w).sum(axis=0)
        p, q = (v * x).sum(axis=0), (w * x).sum(axis=0)
        det = a * c - b * b
        ok = det > _F(1e-3)
        dd = np.where(ok, det, _F(1))
        lo = np.where(ok, (c * p - b * q) / dd, blo) + _TRUNC
        hi = np.where(ok, (a * q - b * p) / dd, bhi) + _TRUNC
        rounded = [(fl(lo), fh(hi)) for fl in (np.floor, np.ceil) for fh in (np.floor, np.ceil)]
        consider([r[0] for r in rounded], [r[1] for r in rounded])

    steps = [(a, b) for a in range(3) for b in range(3)]
    consider([mn + _F(a) for a, _ in steps], [mx - _F(b) for _, b in steps])
    frac = (x - xmin) / np.maximum(xmax - xmin, _F(1e-6))
    for j0, j1 in _EXTENDED:
        fit(np.rint(frac * _F(j1 - j0)) + _F(j0))
    for _ in range(2):
        fit(_exact8(x, blo, bhi - blo)[1])
    moves = [(dl, dh) for dl in (-1, 0, 1) for dh in (-1, 0, 1) if dl or dh]
    for _ in range(2):
        lo0, hi0 = blo.copy(), bhi.copy()
        consider([lo0 + _F(dl) for dl, _ in moves], [hi0 + _F(dh) for _, dh in moves])
    return blo, bhi


def _exact8_tail(
    x: np.ndarray, lo: np.ndarray, r: np.ndarray, tau: float, lam: float
) -> np.ndarray:
    """Squared error plus ``lam`` times each texel's excess over ``tau`` (a tail penalty)."""
    u = x - lo
    best = None
    for j in _positions(u, r, 7):
        e = u - np.floor(j * r / _F(7))
        e *= e
        best = e if best is None else np.minimum(best, e)
    return best.sum(axis=0) + _F(lam) * np.maximum(best - _F(tau), _F(0)).sum(axis=0)


#: Candidate pairs times blocks scored per vectorised pass of a window (the scorer's
#: ``[16, pairs, blocks]`` temporaries stay at 256 KB, in the cache): the ~600 pairs of a
#: small map's window take a few passes instead of one each (a fixed ~30 ms per encode before,
#: whatever the block count); with more than WINDOW_PASS / 8 blocks, one pair per pass.
WINDOW_PASS = 1 << 12


def _keep_best(
    x: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    best: np.ndarray,
    pairs: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]],
    count: int,
    score: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
) -> None:
    """Score ``count`` candidate pairs per block (``pairs(k)`` -> ``lo``, ``hi``, ``ok``
    ``[len(k), N]`` for pair numbers ``k``) and keep, in place, each block's first best pair
    that beats ``best``: what trying them one at a time in order with a strict ``<`` keeps.
    Every block is scored on its own (block-local); several pairs share one numpy pass."""
    n = x.shape[1]
    if n == 0 or count == 0:
        return
    per = WINDOW_PASS // n
    if per < 8:  # enough blocks that one pair per pass costs no more than its numpy work
        for k in range(count):
            l2, h2, ok = (a[0] for a in pairs(np.array([k])))
            e = score(x, l2, h2 - l2)
            m = ok & (e < best)
            np.copyto(best, e, where=m)
            np.copyto(lo, l2, where=m)
            np.copyto(hi, h2, where=m)
        return
    cols = np.arange(n)
    for s in range(0, count, per):
        k = np.arange(s, min(s + per, count))
        l2, h2, ok = pairs(k)
        xb = np.broadcast_to(x[:, None, :], (x.shape[0], k.size, n))
        e = score(xb, l2, h2 - l2)
        np.copyto(e, _F(np.inf), where=~ok)
        first = np.argmin(e, axis=0)  # the first minimum, as a strict < in order keeps
        e_min = e[first, cols]
        m = e_min < best
        np.copyto(best, e_min, where=m)
        np.copyto(lo, l2[first, cols], where=m)
        np.copyto(hi, h2[first, cols], where=m)


def _window(
    x: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    outside: int,
    inside: np.ndarray,
    score: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    step: int = 1,
) -> np.ndarray:
    """Every pair with ``lo`` in ``[min - outside, min + inside]`` and ``hi`` in
    ``[max - inside, max + outside]`` (every ``step``-th level of each), scored by
    ``score(x, lo, r)``; keeps the best (in place; ties: the lowest ``lo`` offset, then the
    lowest ``hi`` offset) and returns its score. Each ``lo`` offset works on the blocks it is
    valid for only, with all its ``hi`` offsets in one pass."""
    best = score(x, lo, hi - lo)
    xmin, xmax = x.min(axis=0), x.max(axis=0)
    fmn, cmx = np.floor(xmin), np.ceil(xmax)
    top = int(np.ceil(float(inside.max()))) if inside.size else 0
    # offsets on a grid anchored at 0, so that a block's pairs do not depend on its batch
    top, out = -(-top // step) * step, -(-outside // step) * step
    dhs = np.arange(-top, outside + 1, step).astype(_F)
    for dl in range(-out, top + 1, step):
        l_all = _clamp(fmn + _F(dl), 0, 255)
        sel = np.flatnonzero(l_all <= xmin + inside)
        if sel.size == 0:
            continue
        xs = np.ascontiguousarray(x[:, sel])
        l2, b2, lo2, hi2 = l_all[sel], best[sel], lo[sel], hi[sel]
        pairs = _hi_offsets(l2, cmx[sel], xmax[sel] - inside[sel], dhs)
        _keep_best(xs, lo2, hi2, b2, pairs, dhs.size, score)
        best[sel], lo[sel], hi[sel] = b2, lo2, hi2
    return best


def _hi_offsets(
    lo: np.ndarray, cmx: np.ndarray, lim: np.ndarray, dhs: np.ndarray
) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """The pairs of one ``lo`` per block with ``hi = ceil(max) + dhs[k]`` (valid when
    ``hi >= lo`` and ``hi >= lim``), for :func:`_keep_best`."""

    def pairs(k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        h2 = _clamp(cmx + dhs[k, None], 0, 255)
        ls = np.broadcast_to(lo, h2.shape)
        return ls, h2, (h2 >= ls) & (h2 >= lim)

    return pairs


def _polish(
    x: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    best: np.ndarray,
    radius: int,
    score: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
) -> None:
    """Every pair within ``radius`` levels of each block's (lo, hi), scored; keeps the best
    (in place): the levels a coarse window stepped over."""
    d = np.arange(-radius, radius + 1).astype(_F)
    dl, dh = np.repeat(d, d.size), np.tile(d, d.size)
    moved = (dl != 0) | (dh != 0)
    dl, dh = dl[moved], dh[moved]
    lo0, hi0 = lo.copy(), hi.copy()

    def pairs(k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        l2 = _clamp(lo0 + dl[k, None], 0, 255)
        h2 = _clamp(hi0 + dh[k, None], 0, 255)
        return l2, h2, h2 >= l2

    _keep_best(x, lo, hi, best, pairs, dl.size, score)


def _refine_hard(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, step: int = HARD_STEP) -> None:
    """Step 4 (in place): the hard blocks' pairs are searched again, scored by squared error
    plus ``HARD_PENALTY`` times every texel's excess over ``HARD_TEXEL_ERROR``, which trades a
    little mean error for a lower tail (p99). Every step is block-local."""
    sse, j = _exact8(x, lo, hi - lo)
    if sse.size == 0:
        return
    err = x - (lo + np.floor(j * (hi - lo) / _F(7)))
    err *= err
    tau = HARD_TEXEL_ERROR
    idx = np.flatnonzero(err.max(axis=0) >= _F(tau))  # a block-local test: any split of a map
    # into pieces (row chunks, a few blocks) encodes every block the same
    for s in range(0, idx.size, HARD_BATCH):  # batches that stay in the cache
        _refine_blocks(x, lo, hi, idx[s : s + HARD_BATCH], sse, step)


def _refine_blocks(
    x: np.ndarray, lo: np.ndarray, hi: np.ndarray, idx: np.ndarray, sse: np.ndarray, step: int
) -> None:
    """:func:`_refine_hard` on the blocks ``idx`` (``step`` 1: the whole window at once)."""
    tau = HARD_TEXEL_ERROR
    xs = np.ascontiguousarray(x[:, idx])
    l2, h2 = lo[idx].copy(), hi[idx].copy()
    inside = np.minimum(np.sqrt(sse[idx]), _F(HARD_INSIDE))

    def score(xb: np.ndarray, lb: np.ndarray, rb: np.ndarray) -> np.ndarray:
        return _Scorer(xb).tail8(lb, rb, tau, HARD_PENALTY)

    best = _window(xs, l2, h2, HARD_OUTSIDE, inside, score, step)
    if step > 1:
        _polish(xs, l2, h2, best, 1, score)
        _, j = _exact8(xs, l2, h2 - l2)
        e = xs - (l2 + np.floor(j * (h2 - l2) / _F(7)))
        tail = np.flatnonzero((e * e).max(axis=0) >= _F(HARD_TAIL))
        if tail.size:
            xt = np.ascontiguousarray(xs[:, tail])
            lt, ht = l2[tail], h2[tail]  # copies (fancy indexing)
            _window(xt, lt, ht, HARD_OUTSIDE, inside[tail], score)
            l2[tail], h2[tail] = lt, ht
    # the scorer's guess, confirmed with exact indices
    before = _exact8_tail(xs, lo[idx], hi[idx] - lo[idx], tau, HARD_PENALTY)
    keep = _exact8_tail(xs, l2, h2 - l2, tau, HARD_PENALTY) < before
    lo[idx[keep]], hi[idx[keep]] = l2[keep], h2[keep]


def _pack(e0: np.ndarray, e1: np.ndarray, codes: np.ndarray) -> np.ndarray:
    """[N] endpoints and [16, N] codes -> [N, 8] uint8 BC4 blocks."""
    c = codes.astype(np.uint64)
    bits = np.zeros(c.shape[1], np.uint64)
    for k in range(16):
        bits |= c[k] << np.uint64(3 * k)
    out = np.empty((c.shape[1], 8), np.uint8)
    out[:, 0] = e0
    out[:, 1] = e1
    out[:, 2:] = bits.astype("<u8").view(np.uint8).reshape(-1, 8)[:, :6]
    return out


def _blocks(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Exact indices for the chosen pairs, the six-value mode where it wins, packed."""
    r = hi - lo
    sse8, j = _exact8(x, lo, r)
    codes = np.where(j == 7, _F(0), np.where(j == 0, _F(1), _F(8) - j))
    codes = np.where(r == 0, _F(0), codes)  # lo == hi: six-value mode, every texel e0
    e0, e1 = hi.copy(), lo.copy()
    edge = (x.min(axis=0) < 8) | (x.max(axis=0) > 247)
    if edge.any():
        xe = x[:, edge]
        inner = (xe > 4) & (xe < 251)
        lo6 = np.floor(np.where(inner, xe, _F(255)).min(axis=0))
        hi6 = np.ceil(np.where(inner, xe, _F(0)).max(axis=0))
        none = ~inner.any(axis=0)
        lo6 = np.where(none, _F(0), lo6)
        hi6 = np.maximum(np.where(none, _F(0), hi6), lo6)
        s6, c6 = _exact6(xe, lo6, hi6 - lo6)
        better = s6 < sse8[edge]
        idx = np.flatnonzero(edge)[better]
        e0[idx], e1[idx] = lo6[better], hi6[better]
        codes[:, idx] = c6[:, better]
    return _pack(e0.astype(np.uint8), e1.astype(np.uint8), codes)


def _targets(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values)
    if v.ndim != 2:
        raise ValueError(f"BC4 encodes one channel [H, W], got shape {v.shape}")
    h, w = v.shape
    if h % 4 or w % 4 or h == 0 or w == 0:
        raise ValueError(f"block formats need sizes that are multiples of 4, got {w} x {h}")
    return blocks_of(np.clip(v.astype(_F), _F(0), _F(255)))


def bc4_blocks(values: np.ndarray, hard_step: int = HARD_STEP) -> np.ndarray:
    """BC4 blocks [N, 8] (row-major block order) of one channel ``values`` [H, W] (multiples
    of 4): uint8 texels, or float targets in texel units 0..255. ``hard_step=1`` searches the
    hard blocks' whole window at once (the encoder before the coarse-to-fine step 4; the
    bench compares the two)."""
    return _encode_blocks(_targets(values), hard_step)


def _encode_blocks(x: np.ndarray, hard_step: int = HARD_STEP) -> np.ndarray:
    """BC4 blocks [N, 8] of target blocks ``x`` [16, N]. Every step is block-local: a block
    encodes the same whatever other blocks share the call."""
    n = x.shape[1]
    lo, hi = np.empty(n, _F), np.empty(n, _F)
    for s in range(0, n, BATCH):
        lo[s : s + BATCH], hi[s : s + BATCH] = _search(np.ascontiguousarray(x[:, s : s + BATCH]))
    _refine_hard(x, lo, hi, hard_step)
    return _blocks(x, lo, hi)


def encode_bc4(values: np.ndarray) -> bytes:
    """BC4 data of one channel [H, W] (see :func:`bc4_blocks`)."""
    return bc4_blocks(values).tobytes()


#: Maps of at most this many blocks have BC5's two channels encoded in one pass (the same
#: blocks, the encoder being block-local): each pass has a fixed cost of numpy calls (~7 ms)
#: whatever the block count, which dominates small maps and mip levels.
ONE_PASS_BLOCKS = 4096


def encode_bc5(x: np.ndarray, y: np.ndarray, hard_step: int = HARD_STEP) -> bytes:
    """BC5 data of two channels [H, W] (R = ``x``, G = ``y``; texels or float targets); the two
    channels are encoded on two threads (small maps: both in one pass). ``hard_step``: see
    :func:`bc4_blocks`."""
    tx, ty = _targets(x), _targets(y)
    n = tx.shape[1]
    if threads() > 1 and n > ONE_PASS_BLOCKS:
        bx, by = pool().map(lambda t: _encode_blocks(t, hard_step), (tx, ty))
    else:
        both = _encode_blocks(np.concatenate([tx, ty], axis=1), hard_step)
        bx, by = both[:n], both[n:]
    return np.concatenate([bx, by], axis=1).tobytes()


def encode_bc5_many(maps: list[tuple[np.ndarray, np.ndarray]]) -> list[bytes]:
    """:func:`encode_bc5` of each ``(x, y)`` pair (e.g. the levels of a mip chain), every
    block of every map in one pass: the same bytes as one call each, without the fixed cost
    of a pass per map."""
    planes = [_targets(c) for xy in maps for c in xy]
    if not planes:
        return []
    ends = np.cumsum([p.shape[1] for p in planes])
    blocks = np.split(_encode_blocks(np.concatenate(planes, axis=1)), ends[:-1])
    return [
        np.concatenate([blocks[2 * i], blocks[2 * i + 1]], axis=1).tobytes()
        for i in range(len(maps))
    ]


def reference_bc4(values: np.ndarray, outside: int = 32) -> np.ndarray:
    """The exhaustive endpoint search (tests and benchmarks only: slow, use small crops).

    For each block, every 8-value pair with ``lo`` from ``outside`` levels below the block's
    minimum up to ``min + sqrt(E)`` and ``hi`` from ``max - sqrt(E)`` up to ``outside`` above
    its maximum, exactly scored, where ``E`` is the error :func:`bc4_blocks` reached (a palette
    whose nearest entry misses the block's extreme texel by more than ``sqrt(E)`` cannot beat
    ``E``, so no pair within the outside window is left out), plus the six-value mode as
    :func:`bc4_blocks` tries it. Returns BC4 blocks [N, 8] like :func:`bc4_blocks`.
    """
    x = _targets(values)
    n = x.shape[1]
    lo, hi = np.empty(n, _F), np.empty(n, _F)
    for s in range(0, n, BATCH):
        lo[s : s + BATCH], hi[s : s + BATCH] = _search(np.ascontiguousarray(x[:, s : s + BATCH]))
    _refine_hard(x, lo, hi)
    sse, _ = _exact8(x, lo, hi - lo)

    def score(xb: np.ndarray, lb: np.ndarray, rb: np.ndarray) -> np.ndarray:
        return _exact8(xb, lb, rb)[0]

    _window(x, lo, hi, outside, np.sqrt(sse), score)
    return _blocks(x, lo, hi)
