"""Each distinct 4x4 block encoded once: the same bytes as encoding the whole map, in every
block format, against the encoders called on the whole map (independent: the library's own)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.normals import blocks as nb
from wrinklepipe.normals import compress as nc

FORMATS = ("bc1", "bc3nm", "bc5", "bc7", "bc7xy")


def _map(seed: int, bh: int, bw: int, palette: int) -> np.ndarray:
    """RGBA8 [4 bh, 4 bw, 4]: blocks drawn from ``palette`` random blocks (many repeats), some
    blocks random of their own."""
    rng = np.random.default_rng(seed)
    pal = rng.integers(0, 256, (palette, 4, 4, 4), dtype=np.uint8)
    pick = pal[rng.integers(0, palette, bh * bw)]
    own = rng.random(bh * bw) < 0.1
    pick[own] = rng.integers(0, 256, (int(own.sum()), 4, 4, 4), dtype=np.uint8)
    return np.ascontiguousarray(
        pick.reshape(bh, bw, 4, 4, 4).transpose(0, 2, 1, 3, 4).reshape(bh * 4, bw * 4, 4)
    )


@settings(max_examples=12, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    bh=st.integers(1, 9),
    bw=st.integers(1, 9),
    palette=st.integers(1, 4),
    fmt=st.sampled_from(FORMATS),
)
def test_distinct_blocks_encode_to_the_whole_maps_bytes(seed, bh, bw, palette, fmt):
    a = _map(seed, bh, bw, palette)
    whole = nc._encode_bc(a, fmt, None)  # the encoder on the whole map, as it was called
    assert nc.encode_bc(a, fmt) == whole


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_flat_map_with_a_wrinkle_encodes_like_the_whole_map(fmt):
    a = np.full((64, 96, 4), 128, np.uint8)  # 384 blocks: one flat block and a few others
    yy, xx = np.mgrid[0:64, 0:96]
    bump = (40 * np.exp(-((yy - 30.0) ** 2 + (xx - 50.0) ** 2) / 60.0)).astype(np.uint8)
    a[..., 0] += bump
    a[..., 1] -= bump // 2
    first, inverse = nb.distinct(nb.to_blocks(a))
    assert first.size < 0.25 * inverse.size  # regrouped
    assert nc.encode_bc(a, fmt) == nc._encode_bc(a, fmt, None)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(1, 300), palette=st.integers(1, 20))
def test_distinct_finds_every_repeat_in_first_occurrence_order(seed, n, palette):
    rng = np.random.default_rng(seed)
    pal = rng.integers(0, 256, (palette, 4, 4, 2), dtype=np.uint8)
    blocks = pal[rng.integers(0, palette, n)]
    first, inverse = nb.distinct(blocks)
    assert np.array_equal(blocks[first][inverse], blocks)
    assert np.all(np.diff(first) > 0) and first[0] == 0
    # distinct means distinct: no two chosen blocks are equal
    rows = {bytes(b) for b in blocks}
    assert first.size == len(rows)
    # the tile holds block i at block position i
    t = nb.tile(blocks[first])
    assert np.array_equal(nb.to_blocks(t)[: first.size], blocks[first])


def test_a_hash_collision_falls_back_to_every_block(monkeypatch):
    monkeypatch.setattr(nb, "_MIX", np.uint64(0))  # every block hashes to 0
    a = _map(3, 4, 4, 2)
    first, inverse = nb.distinct(nb.to_blocks(a))
    assert np.array_equal(first, np.arange(16)) and np.array_equal(inverse, np.arange(16))
    assert nc.encode_bc(a, "bc7") == nc._encode_bc(a, "bc7", None)


def test_inside_a_run_blocks_encoded_before_are_not_encoded_again():
    from wrinklepipe import reuse

    a = _map(11, 8, 8, 3)  # 64 blocks
    b = a.copy()
    b[:8] = _map(12, 2, 8, 50)  # its first two block rows new, the rest as in a
    encoded = []

    def counting(t: np.ndarray) -> bytes:
        encoded.append(t.shape[0] * t.shape[1] // 16)
        return nc._encode_bc(t, "bc7", None)

    with reuse.reuse():
        assert nb.encode_distinct(a, counting, 16, "t") == nc._encode_bc(a, "bc7", None)
        n_a = len(nb.distinct(nb.to_blocks(a))[0])
        new = {bytes(x) for x in nb.to_blocks(b)} - {bytes(x) for x in nb.to_blocks(a)}
        assert nb.encode_distinct(b, counting, 16, "t") == nc._encode_bc(b, "bc7", None)
        assert nb.encode_distinct(b, counting, 16, "t") == nc._encode_bc(b, "bc7", None)
    # a: its distinct blocks in a tile (padded to a square); b: only its new blocks; b again:
    # nothing (every block known)
    side = lambda k: int(np.ceil(np.sqrt(k))) ** 2  # noqa: E731
    assert encoded == [side(n_a), side(len(new))]
    encoded.clear()
    assert nb.encode_distinct(b, counting, 16, "t") == nc._encode_bc(b, "bc7", None)
    assert len(encoded) == 1  # outside the run nothing is remembered


def test_rows_are_found_by_their_bytes_not_only_their_hash():
    from wrinklepipe import reuse

    keys = np.arange(24, dtype=np.uint8).reshape(3, 8)
    h = np.array([5, 7, 5], np.uint64)  # rows 0 and 2 share a hash
    vals = np.array([[1], [2], [3]], np.uint8)
    reuse.remember_rows("r", h, keys, vals)  # outside a run: nothing kept
    with reuse.reuse():
        assert reuse.known_rows("r", h, keys)[1] is None
        reuse.remember_rows("r", h, keys, vals)
        found, got = reuse.known_rows("r", h, keys)
        assert found.tolist() == [True, True, False]  # row 2: same hash, other bytes
        assert got[:2, 0].tolist() == [1, 2]
        reuse.remember_rows("r", h[2:], keys[2:], vals[2:])  # its hash is taken: not stored
        assert reuse.known_rows("r", h, keys)[0].tolist() == [True, True, False]
