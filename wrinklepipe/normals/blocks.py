"""The 4x4 blocks of a block-compressed map, each distinct one encoded once.

Every BC format encodes each 4x4 block on its own: a block's bytes depend on its 16 texels only,
not on where it lies or what surrounds it (the encoders here, ispc_texcomp's BC7, quicktex's
BC1 / BC3 and :mod:`wrinklepipe.normals.bc4`, keep to that). And most of a wrinkle state is the
same block over and over: outside the wrinkles the stored slope or difference is flat. So
:func:`encode_distinct` encodes the distinct blocks once, side by side in one tile, and lays
their bytes out where each block occurs: the same bytes as encoding the whole map, for a
fraction of the work (the demo's 512^2 states: about 1 000 distinct blocks of 16 384). Inside a
conversion (:func:`wrinklepipe.reuse.reuse`) the blocks encoded are also remembered, so a block
the searches' round trips already encoded is not encoded again by the compressed copy.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wrinklepipe import reuse

#: Encode the distinct blocks alone when they are at most this fraction of all blocks (else the
#: whole map: hashing the blocks is cheap next to encoding them, regrouping is not free).
MAX_DISTINCT_FRACTION = 0.75

_MIX = np.uint64(0x9E3779B97F4A7C15)


def to_blocks(a: np.ndarray) -> np.ndarray:
    """``[H, W, C]`` (H, W multiples of 4) -> ``[N, 4, 4, C]`` blocks in row-major block order."""
    h, w, c = a.shape
    return a.reshape(h // 4, 4, w // 4, 4, c).transpose(0, 2, 1, 3, 4).reshape(-1, 4, 4, c)


def tile(blocks: np.ndarray) -> np.ndarray:
    """``[N, 4, 4, C]`` blocks side by side in a square map ``[4s, 4s, C]`` (row-major block
    order; the last block repeated to fill it): block ``i`` of the tile is ``blocks[i]``."""
    n, _, _, c = blocks.shape
    side = max(1, int(np.ceil(np.sqrt(n))))
    pad = np.repeat(blocks[-1:], side * side - n, axis=0)
    t = np.concatenate([blocks, pad]).reshape(side, side, 4, 4, c).transpose(0, 2, 1, 3, 4)
    return np.ascontiguousarray(t.reshape(side * 4, side * 4, c))


def _padded(blocks: np.ndarray) -> np.ndarray:
    """Each block's bytes as a row [N, K] (K a multiple of 8: zeros after the bytes)."""
    rows = np.ascontiguousarray(blocks.reshape(blocks.shape[0], -1))
    if rows.shape[1] % 8:
        rows = np.pad(rows, ((0, 0), (0, -rows.shape[1] % 8)))
    return rows


def _blocks_at(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Blocks ``idx`` (row-major block order) of ``a`` ``[H, W, C]`` as ``[k, 4, 4, C]``,
    gathered from a view of the map (``to_blocks(a)[idx]`` without a copy of every block)."""
    h, w, c = a.shape
    v = a.reshape(h // 4, 4, w // 4, 4, c).transpose(0, 2, 1, 3, 4)
    return v[idx // (w // 4), idx % (w // 4)]


#: Block rows hashed at a time by :func:`encode_distinct` (a band's blocks copied, not all).
HASH_BLOCK_ROWS = 256


def _hashes(a: np.ndarray) -> np.ndarray:
    """:func:`_rows`' hashes of every block of ``a``, a band of block rows at a time."""
    step = 4 * HASH_BLOCK_ROWS
    return np.concatenate(
        [_rows(to_blocks(a[r : r + step]))[1] for r in range(0, a.shape[0], step)]
    )


def _rows(blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each block's bytes as a row [N, K] (K a multiple of 8) and a 64-bit hash of them."""
    n = blocks.shape[0]
    rows = _padded(blocks)
    words = rows.view(np.uint64)
    h = np.zeros(n, np.uint64)
    for k in range(words.shape[1]):
        h = (h ^ words[:, k]) * _MIX
        h ^= h >> np.uint64(29)
    return rows, h


def _group(
    rows: np.ndarray | Callable[[np.ndarray], np.ndarray], h: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(first, inverse)`` of the blocks' ``rows`` (or a function giving the rows of given
    blocks) with hashes ``h``."""
    n = len(h)
    _, first, inverse = np.unique(h, return_index=True, return_inverse=True)
    rows_at = rows if callable(rows) else rows.__getitem__
    if not _same_rows(rows_at, first[inverse]):  # a hash collision: no regrouping
        return np.arange(n), np.arange(n)
    order = np.argsort(first, kind="stable")  # distinct blocks in order of first occurrence
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return first[order], rank[inverse.reshape(-1)]


#: Rows compared at a time when checking the hashes against the bytes.
_CHECK_ROWS = 1 << 16


def _same_rows(rows_at: Callable[[np.ndarray], np.ndarray], source: np.ndarray) -> bool:
    """Whether the rows ``rows_at(source)`` equal the rows of every block in order, compared a
    slice of rows at a time (no copy of every row)."""
    for r0 in range(0, len(source), _CHECK_ROWS):
        r = np.arange(r0, min(len(source), r0 + _CHECK_ROWS))
        if not np.array_equal(rows_at(source[r]), rows_at(r)):
            return False
    return True


def distinct(blocks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(first, inverse)``: the index of each distinct block's first occurrence (in order of
    first occurrence) and, for every block, which of them it is (``blocks[first][inverse]``
    equals ``blocks``; exact: hashes are checked against the bytes)."""
    return _group(*_rows(blocks))


def encode_distinct(
    a: np.ndarray,
    encode: Callable[[np.ndarray], bytes],
    block_bytes: int,
    memo_name: str | None = None,
) -> bytes:
    """``encode(a)`` (``a``: ``[H, W, C]`` uint8, H and W multiples of 4; ``encode`` a BC
    encoder returning row-major blocks of ``block_bytes``), each distinct block encoded once.
    ``memo_name``: the encoder's name in this run's memo (:func:`wrinklepipe.reuse.known_rows`):
    blocks an earlier call of this run encoded (the searches' partial round trips, a map's
    other levels) are taken from it, and the ones encoded here are stored in it."""
    # the blocks' rows gathered where they are needed, hashed a band at a time (no block-order
    # copy of the map: 64 MiB for a 4096² RGBA map); the same rows, hashes and groups
    h = _hashes(a)
    n = h.size
    k = (16 * a.shape[2] + 7) // 8 * 8  # a row's bytes (padded)

    def rows_at(idx: np.ndarray) -> np.ndarray:
        return _padded(_blocks_at(a, idx))

    first, inverse = _group(rows_at, h)
    d_h = h[first]
    # the distinct rows are copied only when the memo has room for them
    memo_name = memo_name if memo_name and reuse.rows_room(memo_name, k * first.size) else None
    d_rows = rows_at(first) if memo_name else np.zeros((0, k), np.uint8)
    found, known = np.zeros(first.size, bool), None
    if memo_name:
        found, known = reuse.known_rows(memo_name, d_h, d_rows)
    todo = np.flatnonzero(~found)
    if not found.any() and first.size > MAX_DISTINCT_FRACTION * n:
        data = encode(a)  # few repeats and nothing known: the whole map as it is
        if memo_name:
            out = np.frombuffer(data, np.uint8).reshape(n, block_bytes)
            reuse.remember_rows(memo_name, d_h, d_rows, out[first])
        return data
    values = known if known is not None else np.zeros((first.size, block_bytes), np.uint8)
    if todo.size:
        got = np.frombuffer(encode(tile(_blocks_at(a, first[todo]))), np.uint8)
        values[todo] = got.reshape(-1, block_bytes)[: todo.size]
        if memo_name:
            reuse.remember_rows(memo_name, d_h[todo], d_rows[todo], values[todo])
    return values[inverse].tobytes()
