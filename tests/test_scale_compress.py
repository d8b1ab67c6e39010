"""Film scale, the "compressing" stage one map and one level at a time (docs/scale.md): every
banded step against the whole-image computation it replaces, bit for bit."""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from wrinklepipe import codec, reuse
from wrinklepipe.normals import blocks, mips
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals.resample import mip_chain, resize, resize_bands


@pytest.mark.parametrize(
    ("shape", "size", "filter"),
    [
        ((64, 64, 3), (32, 32), "box"),
        ((37, 50, 2), (18, 25), "box"),
        ((64, 48, 3), (20, 13), "lanczos3"),
        ((30, 30, 1), (45, 45), "triangle"),  # a magnification
        ((9, 7, 2), (4, 3), "box"),  # odd sizes: three source rows per output row
    ],
)
@pytest.mark.parametrize("rows", [1, 3, 1000])
def test_resize_by_bands_is_the_whole_resize(shape, size, filter, rows):
    """Output rows made in bands of ``rows``, each band reading only the source rows its
    weights reach, are :func:`resize` of the whole image bit for bit."""
    rng = np.random.default_rng(rows)
    a = rng.standard_normal(shape).astype(np.float32)
    read_rows: list[int] = []

    def read(r: slice) -> np.ndarray:
        read_rows.append(r.stop - r.start)
        return a[r]

    got = np.full((*size, shape[2]), np.nan, np.float32)
    for r, band in resize_bands(read, shape, size, filter, rows):
        got[r] = band
    want = resize(a, size, filter).reshape(got.shape)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    if rows == 1 and filter == "box" and shape[0] % 2 == 0:
        assert max(read_rows) == 2  # a 2:1 box reads two source rows per output row


def _whole_levels(encoding: str, x: np.ndarray) -> list[np.ndarray]:
    """The chain as it was made before: every level of the whole quantity, then normalised."""
    levels = mip_chain(x, min_size=1, filter="box")[1:]
    return [codec.normalize(lv) for lv in levels] if encoding == "full" else levels


@pytest.mark.parametrize(("encoding", "shape"), [("full", (32, 20, 3)), ("pd", (17, 8, 2))])
def test_mip_levels_one_at_a_time_are_the_whole_chain(encoding, shape):
    """Level 1 from bands of 2 rows of level 0, each next level from the one before: the
    whole chain's values bit for bit, down to 1 x 1; the box average by hand at one texel."""
    rng = np.random.default_rng(3)
    x = rng.normal(0, 0.4, shape).astype(np.float32)
    if encoding == "full":
        x = codec.normalize(x + np.array([0, 0, 1], np.float32))
    want = _whole_levels(encoding, x)
    got = list(mips.levels_of(encoding, lambda r: x[r], x.shape, rows=2))
    assert len(got) == len(want) == mips.level_count(shape[1], shape[0]) - 1
    for g, w in zip(got, want):
        assert g.shape == w.shape and np.array_equal(g.view(np.uint32), w.view(np.uint32))
    if encoding == "pd":  # level 1 texel (2, 3): the mean of the 2 x 2 source texels
        assert np.allclose(got[0][2, 3], x[4:6, 6:8].mean(axis=(0, 1)), atol=1e-6)


@pytest.mark.parametrize("fmt", ["bc1", "bc5"])
def test_block_levels_from_row_bands_are_the_whole_chains(fmt):
    """The copies' mip levels, level 0 read band by band from the stored texels, are the bytes
    of the chain made from the whole decoded quantity."""
    rng = np.random.default_rng(5)
    enc = "full" if fmt == "bc1" else "pd"
    comps = 3 if enc == "full" else 2
    texels = rng.integers(90, 166, (24, 16, comps)).astype(np.uint8)
    where = "rgb" if comps == 3 else "rg"
    whole = codec.decode(enc, texels, where)
    want = [
        cmp.encode_bc(cmp.pack_rgba(cmp.pad_to_blocks(q)[0], fmt), fmt)
        for q in (
            codec.layouts.unpack(
                codec.encode(enc, lv, codec.storage_format(fmt).layout_for(enc), bits=8)[0],
                codec.storage_format(fmt).layout_for(enc),
            )
            for lv in _whole_levels(enc, whole)
        )
    ]

    def read(r: slice) -> np.ndarray:
        return codec.decode(enc, texels[r], where)

    got = mips.block_levels_of(enc, read, whole.shape, fmt)
    assert got == want and len(got) == mips.level_count(16, 24) - 1


@pytest.mark.parametrize("fmt", ["bc1", "bc5", "bc3nm"])
def test_check_against_the_map_itself_is_the_check_against_its_decoded_whole(fmt):
    """``compress_and_check`` with no reference (the uncompressed map, decoded band by band)
    gives the check made against the whole map decoded first: the same error statistics, PSNR
    and bytes; PSNR by hand from the decoded blocks."""
    rng = np.random.default_rng(9)
    n = codec.normalize(rng.normal(0, 0.3, (20, 12, 3)).astype(np.float32) + [0, 0, 1])
    comps = 3 if fmt == "bc1" else 2
    q = codec.encode("full", n, "rgb" if comps == 3 else "rg", bits=8)[0][..., :comps]
    q = np.ascontiguousarray(q.astype(np.uint8))
    dec = cmp.decoder_for("full")
    ref = dec(q, slice(0, 20))
    a = cmp.compress_and_check(q, ref, fmt, dec, keep_decoded=True)
    b = cmp.compress_and_check(q, None, fmt, dec, keep_decoded=False)
    assert a.data == b.data and b.decoded is None
    assert a.error == b.error == b.compression_error == a.compression_error
    assert a.psnr_db == b.psnr_db
    d = a.decoded.astype(np.float64)
    mse = ((q.astype(np.float64) - d) ** 2).reshape(-1, comps).mean(axis=0)
    for got, m in zip(b.psnr_db, mse):
        assert got == (np.inf if m == 0 else pytest.approx(10 * np.log10(255.0**2 / m), 1e-12))


def test_psnr_from_band_sums_is_the_whole_mean():
    """PSNR from int64 sums over bands equals the float64 mean over every texel, bit for bit."""
    rng = np.random.default_rng(2)
    r = rng.integers(0, 256, (300, 70, 3)).astype(np.uint8)
    d = np.clip(r.astype(int) + rng.integers(-9, 10, r.shape), 0, 255).astype(np.uint8)
    d[..., 2] = r[..., 2]
    e = (r.reshape(-1, 3).astype(np.int32) - d.reshape(-1, 3).astype(np.int32)).astype(np.float64)
    whole = [float(np.mean(e[:, c] ** 2)) for c in range(3)]
    want = [np.inf if m == 0 else 10.0 * np.log10(255.0**2 / m) for m in whole]
    sse = sum(cmp.squared_errors(r[i : i + 7], d[i : i + 7]) for i in range(0, 300, 7))
    got = cmp.psnr_of(sse, 300 * 70)
    assert got[2] == np.inf and got[:2] == [float(x) for x in want[:2]]
    assert cmp.psnr(r, d) == got


def test_png_of_a_large_image_is_made_by_bands_with_the_whole_bytes(monkeypatch):
    """``png_bytes`` of an image taller than a band (a 16M working set) streams it band by
    band: the bytes of one zlib stream over the whole image's filtered rows."""
    from wrinklepipe.io import png

    monkeypatch.setenv("WRINKLEPIPE_WORKING_SET", "16M")
    rng = np.random.default_rng(4)
    px = (rng.integers(0, 3, (1000, 700, 3)) * 40).astype(np.uint8)
    assert png.band_rows(700, 12) < 1000
    want = zlib.compress(png._filtered(px, None), 6)
    data = png.png_bytes(px, 6, shared=False)
    at = data.index(b"IDAT")
    assert data[at + 4 : at + 4 + len(want)] == want
    assert data == png._head(700, 1000, 3, 8, False) + png._chunk(b"IDAT", want) + png._chunk(
        b"IEND", b""
    )


def _sorted_store(batches):
    """The memo's row store as it was made: every batch appended, re-sorted, first kept."""
    h = k = v = None
    for hh, kk, vv in batches:
        if h is not None:
            hh, kk, vv = (np.concatenate(p) for p in ((h, hh), (k, kk), (v, vv)))
        o = np.argsort(hh, kind="stable")
        hh, kk, vv = hh[o], kk[o], vv[o]
        f = np.ones(len(hh), bool)
        f[1:] = hh[1:] != hh[:-1]
        h, k, v = hh[f], kk[f], vv[f]
    return h, k, v


def test_row_store_merged_in_place_is_the_sorted_store():
    """Rows remembered batch by batch (repeated hashes within and across batches) are merged
    into the store with the stored rows first: the store a full re-sort made."""
    rng = np.random.default_rng(0)
    for _ in range(50):
        batches = []
        for _ in range(int(rng.integers(1, 5))):
            n = int(rng.integers(1, 40))
            batches.append(
                (
                    rng.integers(0, 30, n).astype(np.uint64),
                    rng.integers(0, 255, (n, 8)).astype(np.uint8),
                    rng.integers(0, 255, (n, 4)).astype(np.uint8),
                )
            )
        with reuse.reuse() as memo:
            for b in batches:
                reuse.remember_rows("x", *b)
            got = memo.rows["x"]
        h, k, v = _sorted_store(batches)
        assert np.array_equal(got.hashes, h) and np.array_equal(got.keys, k)
        assert np.array_equal(got.values, v)


def test_row_store_refuses_a_first_batch_over_its_share():
    """The first batch is bounded like the later ones (a quarter of the memo)."""
    with reuse.reuse(max_bytes=4000) as memo:
        keys = np.zeros((100, 16), np.uint8)
        assert not reuse.rows_room("x", keys.nbytes)
        reuse.remember_rows("x", np.arange(100, dtype=np.uint64), keys, keys[:, :8])
        assert "x" not in memo.rows
        assert reuse.rows_room("x", 500)


def test_distinct_blocks_checked_in_slices(monkeypatch):
    """The hash check compares the rows a slice at a time: a collision is still found."""
    monkeypatch.setattr(blocks, "_CHECK_ROWS", 3)
    rows = np.arange(40, dtype=np.uint8).reshape(10, 4)
    assert blocks._same_rows(rows.__getitem__, np.arange(10))
    src = np.arange(10)
    src[8] = 7
    assert not blocks._same_rows(rows.__getitem__, src)


@pytest.mark.parametrize("fmt", ["bc1", "bc3nm"])
def test_quicktex_candidates_are_not_kept_by_the_memo(fmt):
    """Picking quicktex's best blocks decodes each candidate level's band once, outside the
    memo (it kept every level's decoded band: about 128 MiB at 4096²); the blocks are the same
    as without a memo, and each picked block's squared error is the least of the levels'."""
    rng = np.random.default_rng(21)
    h, w = 256, 512  # a band's blocks above the memo's smallest input (64 KiB)
    a = rng.integers(0, 256, (h, w, 4)).astype(np.uint8)
    plain = cmp._quicktex_best(a, fmt)
    with reuse.reuse() as memo:
        got = cmp._quicktex_best(a, fmt)
    assert np.array_equal(got, plain)
    assert not any("decode_bc_bgra" in name for name in {**memo.hits, **memo.misses})
    # the picked block's error against each level's own blocks, decoded alone
    err = []
    for level in cmp.QUICKTEX_LEVELS:
        tex = cmp.quicktex.RawTexture.frombytes(a.tobytes(), w, h)
        with cmp._quicktex_encoder(fmt, level) as enc:
            data = bytes(enc.encode(tex).tobytes())
        d = cmp._decode_bgra(data, w, h, fmt)[..., 2::-1].astype(np.int64) - a[..., :3]
        err.append((d * d).reshape(h // 4, 4, w // 4, 4, 3).sum(axis=(1, 3, 4)).ravel())
    d = cmp._decode_bgra(got.tobytes(), w, h, fmt)[..., 2::-1].astype(np.int64) - a[..., :3]
    picked = (d * d).reshape(h // 4, 4, w // 4, 4, 3).sum(axis=(1, 3, 4)).ravel()
    if fmt == "bc1":  # BC3's alpha half is the caller's: only BC1's blocks are whole here
        assert np.array_equal(picked, np.min(err, axis=0))


@pytest.mark.parametrize("band", [1, 3, 1000])
@pytest.mark.parametrize("channels", [4, 2, 1])
def test_encode_distinct_gathers_blocks_from_the_map(monkeypatch, band, channels):
    """encode_distinct hashes the blocks a band of block rows at a time and gathers the rows it
    needs from the map (no block-order copy of the map): the same hashes, rows, groups, tile
    and bytes as the whole block array's, and the memo stores the same rows."""
    rng = np.random.default_rng(8)
    pal = rng.integers(0, 256, (5, 4, 4, channels), dtype=np.uint8)
    bh, bw = 7, 9
    pick = pal[rng.integers(0, 5, bh * bw)]
    a = np.ascontiguousarray(
        pick.reshape(bh, bw, 4, 4, channels).transpose(0, 2, 1, 3, 4).reshape(4 * bh, 4 * bw, -1)
    )
    whole = blocks.to_blocks(a)
    rows, h = blocks._rows(whole)
    monkeypatch.setattr(blocks, "HASH_BLOCK_ROWS", band)
    assert np.array_equal(blocks._hashes(a), h)
    idx = rng.permutation(bh * bw)[:20]
    assert np.array_equal(blocks._blocks_at(a, idx), whole[idx])
    assert np.array_equal(blocks._padded(blocks._blocks_at(a, idx)), rows[idx])
    first, inverse = blocks.distinct(whole)
    assert first.size == 5 and np.array_equal(whole[first][inverse], whole)
    calls = []

    def enc(t: np.ndarray) -> bytes:  # a stand-in encoder: each block's bytes, one per block
        calls.append(t.shape)
        return blocks._padded(blocks.to_blocks(t))[:, :8].tobytes()

    want = rows[:, :8].tobytes()
    with reuse.reuse():
        assert blocks.encode_distinct(a, enc, 8, "t") == want
        assert blocks.encode_distinct(a, enc, 8, "t") == want  # every block known
        found, known = reuse.known_rows("t", h[first], rows[first])
        assert found.all() and np.array_equal(known, rows[first, :8])  # the rows stored
    assert calls == [(12, 12, channels)]  # 5 distinct blocks in a 3 x 3 tile, encoded once


def test_resize_bands_default_band_counts_the_source_rows_read(monkeypatch):
    """By default a band's share of the working set counts the source rows each output row
    reads and what the reader makes from them (a 2:1 halving: twice the output rows, with a
    decode's temporaries), not the output rows alone; the values are the whole resize's."""
    from wrinklepipe.normals import resample

    monkeypatch.setattr(resample, "band_rows", lambda width, per: (1 << 20) // (width * per))
    shape, size = (256, 64, 3), (128, 32)
    a = np.random.default_rng(3).standard_normal(shape).astype(np.float32)
    read_rows: list[int] = []

    def read(r: slice) -> np.ndarray:
        read_rows.append(r.stop - r.start)
        return a[r]

    got = np.full((*size, 3), np.nan, np.float32)
    for r, band in resize_bands(read, shape, size, "box"):
        got[r] = band
    assert np.array_equal(got.view(np.uint32), resize(a, size, "box").view(np.uint32))
    per = 8 * 3 + (resample.READ_BYTES_PER_TEXEL + 12) * 2  # 144 bytes per output texel
    out_rows = (1 << 20) // (64 * per)  # 113 output rows a band: 226 source rows
    assert read_rows[0] == 2 * out_rows and len(read_rows) == -(-128 // out_rows)
