"""BC4 / BC5 encoding near the quality limit, compiled per block with numba.

A BC4 block stores two 8-bit endpoints and a 3-bit index per texel. With ``e0 > e1`` the
palette is the endpoints and six interpolants ``lo + floor(j r / 7)`` (``lo = e1``,
``r = e0 - e1``, j = 1..6); with ``e0 <= e1`` it is the endpoints, four interpolants
``lo + floor(j r / 5)``, 0 and 255. Interpolants are truncated as texture2ddecoder and Mesa
decode them (hardware that interpolates in float is within one level). BC5 is two BC4 blocks
(R, then G); a DXT5nm block's alpha half is a BC4 block too.

The encoder minimises each block's squared error to *float* targets in texel units (0..255):
an 8-bit map's own texels, or the unrounded texels of a map still in floating point (closer to
the source). Each block is searched on its own, one candidate endpoint pair at a time:

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
mean truncation); the chosen pair then gets exact nearest indices. A candidate replaces the
block's best pair only when it scores strictly lower, so the first best pair in the order above
is kept. :func:`reference_bc4` is the exhaustive search the tests and ``wrinklepipe bench
normals`` compare with.

The search is the one the earlier vectorised numpy encoder ran (the same candidates in the
same order, the same float32 arithmetic operation by operation): its blocks are byte-identical
(a test holds digests of that encoder's output). It is compiled by numba
(:mod:`wrinklepipe.normals.bc4_search`) and searches 16 blocks side by side, one per SIMD
lane: about 12 times the numpy encoder's speed on one core (``wrinklepipe bench normals``).
Work that cannot change a block is skipped (a round after one that changed no best, the tail
window's pairs the coarse window scored, a second exact pass for the indices: docs/scale.md).
Blocks are encoded on the worker threads of :mod:`wrinklepipe.normals._chunks` (the compiled
kernel releases the GIL).
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.normals import bc4_search
from wrinklepipe.normals._chunks import on_pool, pool, threads
from wrinklepipe.normals.bc4_jit import (
    HARD_INSIDE,
    HARD_OUTSIDE,
    HARD_PENALTY,
    HARD_STEP,
    HARD_TAIL,
    HARD_TEXEL_ERROR,
)

__all__ = [
    "HARD_INSIDE",
    "HARD_OUTSIDE",
    "HARD_PENALTY",
    "HARD_STEP",
    "HARD_TAIL",
    "HARD_TEXEL_ERROR",
    "bc4_blocks",
    "blocks_of",
    "encode_bc4",
    "encode_bc5",
    "encode_bc5_many",
    "reference_bc4",
]

_F = np.float32
#: Blocks per task on the worker threads (a few ms of work each: the threads share the load
#: evenly, the per-task overhead is negligible).
TASK_BLOCKS = 4096


def blocks_of(plane: np.ndarray) -> np.ndarray:
    """[H, W] (multiples of 4) -> [16, N] texel columns, blocks in row-major block order."""
    h, w = plane.shape
    return np.ascontiguousarray(
        plane.reshape(h // 4, 4, w // 4, 4).transpose(1, 3, 0, 2).reshape(16, -1)
    )


def _shape(v: np.ndarray) -> tuple[int, int]:
    if v.ndim != 2:
        raise ValueError(f"BC4 encodes one channel [H, W], got shape {v.shape}")
    h, w = v.shape
    if h % 4 or w % 4 or h == 0 or w == 0:
        raise ValueError(f"block formats need sizes that are multiples of 4, got {w} x {h}")
    return h, w


def _stack(planes: list[np.ndarray]) -> np.ndarray:
    """Target blocks [N, 16] (float32, clipped to 0..255; row-major block order) of each plane
    [H, W] (multiples of 4) in turn: one pass over each plane, written in place (the same
    values as clipping its float32 copy)."""
    vs = [np.asarray(p) for p in planes]
    shapes = [_shape(v) for v in vs]
    out = np.empty((sum(h * w // 16 for h, w in shapes), 16), _F)
    k = 0
    for v, (h, w) in zip(vs, shapes, strict=True):
        n = h * w // 16
        blocks = v.reshape(h // 4, 4, w // 4, 4).transpose(0, 2, 1, 3)
        np.clip(blocks, _F(0), _F(255), out=out[k : k + n].reshape(h // 4, w // 4, 4, 4))
        k += n
    return out


def _targets(values: np.ndarray) -> np.ndarray:
    """[H, W] (multiples of 4) -> [N, 16] float32 target blocks (row-major block order)."""
    return _stack([values])


def _encode_blocks(x: np.ndarray, hard_step: int = HARD_STEP, reference: int = 0) -> np.ndarray:
    """BC4 blocks [N, 8] of target blocks ``x`` [N, 16] (float32, 0..255), on the worker
    threads in tasks of ``TASK_BLOCKS``. Every block is encoded on its own."""
    n = x.shape[0]
    out = np.empty((n, 8), np.uint8)
    if n == 0:
        return out
    tasks = [slice(s, min(s + TASK_BLOCKS, n)) for s in range(0, n, TASK_BLOCKS)]
    encode = bc4_search.compiled()

    def run(s: slice) -> None:
        encode(x[s], hard_step, reference, out[s])

    if len(tasks) == 1 or threads() == 1 or on_pool():
        for s in tasks:
            run(s)
    else:
        list(pool().map(run, tasks))
    return out


def bc4_blocks(values: np.ndarray, hard_step: int = HARD_STEP) -> np.ndarray:
    """BC4 blocks [N, 8] (row-major block order) of one channel ``values`` [H, W] (multiples
    of 4): uint8 texels, or float targets in texel units 0..255. ``hard_step=1`` searches the
    hard blocks' whole window at once (the encoder before the coarse-to-fine step 4; the
    bench compares the two)."""
    return _encode_blocks(_targets(values), hard_step)


def encode_bc4(values: np.ndarray) -> bytes:
    """BC4 data of one channel [H, W] (see :func:`bc4_blocks`)."""
    return bc4_blocks(values).tobytes()


def encode_bc5(x: np.ndarray, y: np.ndarray, hard_step: int = HARD_STEP) -> bytes:
    """BC5 data of two channels [H, W] (R = ``x``, G = ``y``; texels or float targets), both
    channels' blocks in one pass over the worker threads. ``hard_step``: see
    :func:`bc4_blocks`."""
    both = _encode_blocks(_stack([x, y]), hard_step)
    n = both.shape[0] // 2
    return np.concatenate([both[:n], both[n:]], axis=1).tobytes()


def encode_bc5_many(maps: list[tuple[np.ndarray, np.ndarray]]) -> list[bytes]:
    """:func:`encode_bc5` of each ``(x, y)`` pair (e.g. the levels of a mip chain), every
    block of every map in one pass: the same bytes as one call each."""
    planes = [c for xy in maps for c in xy]
    if not planes:
        return []
    ends = np.cumsum([np.asarray(p).size // 16 for p in planes])
    blocks = np.split(_encode_blocks(_stack(planes)), ends[:-1])
    return [
        np.concatenate([blocks[2 * i], blocks[2 * i + 1]], axis=1).tobytes()
        for i in range(len(maps))
    ]


def reference_bc4(values: np.ndarray, outside: int = 32) -> np.ndarray:
    """The exhaustive endpoint search (tests and benchmarks: about 100 times the encoder's
    work; use crops).

    For each block, every 8-value pair with ``lo`` from ``outside`` levels below the block's
    minimum up to ``min + sqrt(E)`` and ``hi`` from ``max - sqrt(E)`` up to ``outside`` above
    its maximum, exactly scored, where ``E`` is the error :func:`bc4_blocks` reached (a palette
    whose nearest entry misses the block's extreme texel by more than ``sqrt(E)`` cannot beat
    ``E``, so no pair within the outside window is left out), plus the six-value mode as
    :func:`bc4_blocks` tries it. Returns BC4 blocks [N, 8] like :func:`bc4_blocks`.
    """
    if outside < 1:
        raise ValueError(f"outside must be at least 1, got {outside}")
    return _encode_blocks(_targets(values), HARD_STEP, outside)
