"""Work done once per conversion: the run-scoped memo (wrinklepipe.reuse) and the separable
resize (OpenImageIO's weights, rows then columns) against OpenImageIO's own resize."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from wrinklepipe import reuse
from wrinklepipe.demo import demo_asset
from wrinklepipe.geometry.tangents import mikktspace_tangents_report
from wrinklepipe.io.png import png_bytes
from wrinklepipe.normals.resample import axis_weights, oiio_resize, resize

# ------------------------------------------------------------------------------------------------
# separable resize


def _lanczos3(x: np.ndarray) -> np.ndarray:
    x = np.abs(x)
    return np.where(x < 3.0, np.sinc(x) * np.sinc(x / 3.0), 0.0)


def test_axis_weights_are_the_published_filters():
    # box at half size: each output texel is the mean of its two source texels
    box = axis_weights(8, 4, "box").toarray()
    assert np.array_equal(box, np.kron(np.eye(4), [[0.5, 0.5]]))
    # triangle at twice the size is bilinear: 3/4 of the nearer texel, 1/4 of the other,
    # the edge texels clamped
    tri = axis_weights(4, 8, "triangle").toarray()
    assert np.allclose(tri[1], [0.75, 0.25, 0, 0]) and np.allclose(tri[4], [0, 0.25, 0.75, 0])
    assert np.allclose(tri[0], [1, 0, 0, 0]) and np.allclose(tri[7], [0, 0, 0, 1])
    # lanczos3 at half size: L(d) = sinc(d) sinc(d/3) at the distance d (in output texels) from
    # the output centre to each source centre, normalised; output 5 of 32 -> 16 sits at 11.0
    lz = axis_weights(32, 16, "lanczos3").toarray()[5]
    d = (np.arange(32) + 0.5 - 11.0) / 2.0
    want = _lanczos3(d)
    assert np.allclose(lz, want / want.sum(), atol=2e-6)
    # every row of every filter is normalised
    for f in ("lanczos3", "triangle", "box", "blackman-harris"):
        for n_in, n_out in ((16, 5), (5, 16), (7, 7), (1, 3)):
            assert np.allclose(axis_weights(n_in, n_out, f).sum(axis=1), 1.0, atol=1e-6)


@settings(max_examples=25, deadline=None)
@given(
    h=st.integers(1, 24),
    w=st.integers(1, 24),
    th=st.integers(1, 40),
    tw=st.integers(1, 40),
    c=st.integers(1, 3),
    f=st.sampled_from(["lanczos3", "triangle", "box", "blackman-harris"]),
    seed=st.integers(0, 2**16),
)
def test_resize_equals_openimageio(h, w, th, tw, c, f, seed):
    assume((th, tw) != (h, w))  # the same size is a copy (OpenImageIO would filter it)
    a = np.random.default_rng(seed).standard_normal((h, w, c)).astype(np.float32)
    got = resize(a, (th, tw), f)
    ref = oiio_resize(a, th, tw, f)
    assert got.shape == ref.shape == (th, tw, c) and got.dtype == np.float32
    assert np.abs(got - ref).max() <= 4e-6 * max(1.0, float(np.abs(a).max()))


def test_resize_equals_openimageio_at_the_sizes_convert_uses():
    a = np.random.default_rng(3).uniform(-1, 1, (512, 512, 2)).astype(np.float32)
    for size in (256, (512, 200), 1024, (300, 1024)):
        got = resize(a, size)
        h, w = (size, size) if isinstance(size, int) else size
        assert np.abs(got - oiio_resize(a, h, w)).max() < 2e-6
    # OpenImageIO sizes its y taps from the x filter: rows magnified 2 -> 3 with x kept weigh
    # the middle row 0.487 / 0.513, with x magnified too 0.5 / 0.5; both as OpenImageIO does
    b = np.array([[[1.0]], [[0.0]]], np.float32)
    for w in (1, 2, 3):
        ref = oiio_resize(np.repeat(b, w, axis=1), 3, max(w, 1) * (2 if w > 1 else 1))
        got = resize(np.repeat(b, w, axis=1), ref.shape[:2])
        assert np.abs(got - ref).max() < 1e-6


# ------------------------------------------------------------------------------------------------
# the memo


@reuse.reused
def _double(a: np.ndarray, k: int | dict = 2) -> np.ndarray:
    _double.calls += 1  # type: ignore[attr-defined]
    return a * (k if isinstance(k, int) else k["a"])


_double.calls = 0  # type: ignore[attr-defined]


@pytest.fixture
def counted():
    _double.calls = 0  # type: ignore[attr-defined]
    return _double


def test_reuse_computes_each_content_once_and_hands_out_shared_read_only_results(counted):
    a = np.arange(1 << 15, dtype=np.float32)  # 128 KB, over MIN_INPUT_BYTES
    with reuse.reuse() as memo:
        first = counted(a)
        again = counted(a.copy())  # another object, the same bytes
        assert counted.calls == 1 and np.array_equal(first, again)
        # one stored array, handed out as read-only views (no copy per hit)
        assert np.shares_memory(first, again) and first is not again
        assert not first.flags.writeable and not again.flags.writeable
        with pytest.raises(ValueError, match="read-only"):
            again[:] = -1
        assert np.array_equal(counted(a), a * 2) and counted.calls == 1
        counted(a, k=3)  # other arguments, another result
        counted(a.astype(np.float64))  # same values, another dtype
        counted(a.reshape(2, -1))  # same bytes, another shape
        assert counted.calls == 4
        assert memo.hits[f"{__name__}._double"] == 2
    counted(a)
    assert counted.calls == 5  # outside reuse(): it just runs
    assert reuse.active() is None


@reuse.reused
def _halves(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return a, a[: len(a) // 2] * 2  # the argument itself, and a new array


@dataclasses.dataclass
class _Pair:
    x: np.ndarray
    cache: dict = dataclasses.field(default_factory=dict)


@reuse.reused
def _pair(a: np.ndarray) -> _Pair:
    return _Pair(a + 1)


def test_reuse_copies_a_result_that_is_its_argument_and_shares_dataclasses():
    a = np.arange(1 << 15, dtype=np.float32)
    with reuse.reuse():
        same, half = _halves(a)
        assert not np.shares_memory(same, a)  # stored as a copy: the caller's a may change
        a[:] = 7
        assert np.array_equal(_halves(np.arange(1 << 15, dtype=np.float32))[0], np.arange(1 << 15))
        assert np.array_equal(half, np.arange(1 << 14, dtype=np.float32) * 2)
        p, q = _pair(a), _pair(a.copy())
        assert p is not q and p.cache is not q.cache and np.shares_memory(p.x, q.x)
        p.cache["k"] = 1  # a caller's own container
        p.x = np.zeros(3)  # and its own attribute
        r = _pair(a)
        assert r.cache == {} and np.array_equal(r.x, a + 1) and not r.x.flags.writeable


def test_reuse_skips_small_unkeyable_and_bounds_its_memory(counted):
    with reuse.reuse():
        small = np.ones(8, np.float32)
        counted(small), counted(small)
        assert counted.calls == 2  # below MIN_INPUT_BYTES: not worth a key
        big = np.ones(1 << 15, np.float32)
        counted(big, k={"a": 2})  # a dict: not keyed by content, it just runs
        counted(big, k={"a": 2})
        assert counted.calls == 4
    a, b = np.zeros(1 << 15, np.float32), np.ones(1 << 15, np.float32)
    with reuse.reuse(max_bytes=(1 << 17) + 10) as memo:  # room for one result
        counted(a), counted(b), counted(a)
        assert counted.calls == 7  # a was dropped for b and memo.stored_bytes <= memo.max_bytes
        with reuse.reuse() as inner:  # nested: the same memo
            assert inner is memo


def test_png_bytes_are_the_same_from_the_memo():
    px = (np.arange(256 * 256 * 3) % 253).astype(np.uint8).reshape(256, 256, 3)
    plain = png_bytes(px)
    with reuse.reuse() as memo:
        assert png_bytes(px) == plain and png_bytes(px.copy()) == plain
        assert png_bytes(px, level=1) != plain  # the level is part of the key
    assert memo.hits["wrinklepipe.io.png._png"] == 1
    with reuse.reuse() as memo:
        assert png_bytes(px, shared=False) == plain  # a picture: the same bytes, not keyed
        assert png_bytes(px, shared=False) == plain and not memo.hits and not memo.misses


def test_map_threads_keeps_order():
    imgs = [
        (np.arange(128 * 128 * 3) % (7 + k)).astype(np.uint8).reshape(128, 128, 3) for k in range(5)
    ]
    got = reuse.map_threads(functools.partial(png_bytes, level=1), imgs, workers=2)
    assert got == [png_bytes(i, level=1) for i in imgs]  # in order
    with pytest.raises(ZeroDivisionError):
        reuse.map_threads(lambda x: 1 // x, [1, 0, 2], workers=2)


def test_warm_fills_the_memo_for_the_later_calls(counted, monkeypatch):
    monkeypatch.setenv(reuse.THREADS_ENV, "2")
    a = np.arange(1 << 15, dtype=np.float32)
    assert reuse.warm([lambda: counted(a)])() is None and counted.calls == 0  # no memo: no-op
    with reuse.reuse() as memo:
        wait = reuse.warm([lambda: counted(a), lambda: counted(a, k=3)])
        wait()
        assert counted.calls == 2
        assert np.array_equal(counted(a), a * 2) and np.array_equal(counted(a, k=3), a * 3)
        assert counted.calls == 2 and memo.hits[f"{__name__}._double"] == 2


def test_dataclass_arguments_are_keyed_by_content_and_results_shared_read_only():
    from dataclasses import dataclass

    @dataclass
    class Box:
        name: str
        values: np.ndarray

    calls = []

    @reuse.reused
    def wrap(b: Box) -> Box:
        calls.append(1)
        return Box(b.name + "!", b.values + 1)

    v = np.zeros(1 << 15, np.float32)
    with reuse.reuse():
        first = wrap(Box("a", v))
        again = wrap(Box("a", v.copy()))  # equal content: a hit
        assert len(calls) == 1 and again.name == "a!" and np.array_equal(again.values, v + 1)
        with pytest.raises(ValueError, match="read-only"):
            again.values[:] = 7  # shared with the next caller: read-only
        again.name = "mine"  # the caller's own dataclass
        assert np.array_equal(wrap(Box("a", v)).values, v + 1) and first.values[0] == 1
        assert wrap(Box("a", v)).name == "a!" and np.shares_memory(first.values, again.values)
        wrap(Box("b", v))
        assert len(calls) == 2


# ------------------------------------------------------------------------------------------------
# the thread budget (a batch worker's share of the cores)


def test_thread_budget_comes_from_the_environment_and_caps_every_pool(counted, monkeypatch):
    import os
    import threading

    from wrinklepipe.normals import _chunks

    for text, want in [("1", 1), ("3", 3), (" 6 ", 6), ("", None), ("0", None), ("two", None)]:
        monkeypatch.setenv(reuse.THREADS_ENV, text)
        assert reuse.thread_budget() == (want or os.cpu_count() or 1)
    monkeypatch.setenv(reuse.THREADS_ENV, "6")
    assert _chunks.threads() == 4  # the row-chunk pool's own cap
    monkeypatch.setenv(reuse.THREADS_ENV, "1")
    assert _chunks.threads() == 1
    names = reuse.map_threads(lambda _: threading.current_thread().name, range(3))
    assert names == [threading.current_thread().name] * 3  # one thread: the caller's
    a = np.arange(1 << 15, dtype=np.float32)
    with reuse.reuse() as memo:
        reuse.warm([lambda: counted(a)])()
        assert counted.calls == 0  # nothing beside the caller's work
        assert np.array_equal(counted(a), a * 2) and counted.calls == 1 and not memo.hits


def test_the_block_copies_are_the_same_bytes_on_one_thread_or_several(monkeypatch):
    from wrinklepipe.normals.compress import encode_bc, pack_rgba

    rng = np.random.default_rng(7)
    q = rng.integers(0, 256, (272, 256, 2), dtype=np.uint8)  # 4352 blocks: BC5 on two threads
    got = {}
    for n in ("1", "2"):
        monkeypatch.setenv(reuse.THREADS_ENV, n)
        got[n] = [encode_bc(pack_rgba(q, fmt), fmt) for fmt in ("bc5", "bc7")]
    assert got["1"] == got["2"]


def test_tangents_of_one_mesh_are_computed_once_whatever_the_index_dtype():
    """The validator reads indices back as uint32 where convert holds int64: one key."""
    mesh = demo_asset(16).mesh
    args = (mesh.positions, mesh.normals, mesh.uvs)
    plain, plain_rep = mikktspace_tangents_report(*args, mesh.indices.astype(np.int64))
    with reuse.reuse() as memo:
        t64, _ = mikktspace_tangents_report(*args, mesh.indices.astype(np.int64))
        with pytest.raises(ValueError, match="read-only"):
            t64[:] = 0  # shared with the next caller
        t32, rep = mikktspace_tangents_report(*args, mesh.indices.astype(np.uint32))
    assert memo.misses == {"wrinklepipe.geometry.tangents._mikktspace": 1}
    assert memo.hits == {"wrinklepipe.geometry.tangents._mikktspace": 1}
    assert np.array_equal(t32, plain) and rep == plain_rep


def test_footprint_is_kept_as_flags_and_shared_whatever_the_index_dtype():
    """The search's UV footprint and the validator's (indices read back as uint32) are one memo
    entry, a flag map (1 byte a texel), not the int64 triangle ids it is drawn from."""
    from wrinklepipe.fidelity.reference import footprint
    from wrinklepipe.geometry.rasterise import triangle_ids

    n = 41  # a 40 x 40 grid of quads over the lower-left quarter of the UV square
    g = np.linspace(0.0, 0.5, n)
    uvs = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    q = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).reshape(-1)
    idx = np.concatenate([np.stack([q, q + 1, q + n], 1), np.stack([q + 1, q + n + 1, q + n], 1)])
    plain = footprint(uvs, idx, (64, 64))
    with reuse.reuse() as memo:
        a = footprint(uvs, idx.astype(np.int64), (64, 64))
        b = footprint(uvs, idx.astype(np.uint32), (64, 64))
    assert memo.misses == {"wrinklepipe.fidelity.reference._footprint": 1}
    assert memo.hits == {"wrinklepipe.fidelity.reference._footprint": 1}
    assert [v.dtype for v in memo.entries.values()] == [np.dtype(bool)]
    assert np.array_equal(a, plain) and np.array_equal(b, plain)
    # texel centres (x + 0.5) / 64 inside [0, 0.5]: the 32 x 32 texels of that quarter
    assert plain[:32, :32].all() and plain.sum() == 32 * 32
    assert np.array_equal(plain, triangle_ids(uvs, idx, 64) >= 0)


def test_forget_rows_drops_the_row_stores_only():
    """After ``forget_rows`` no row is found (a miss computes it), and the memo's entries stay."""
    keys = np.arange(24, dtype=np.uint8).reshape(4, 6)
    hashes = np.array([3, 1, 4, 2], np.uint64)
    values = keys[:, :2].astype(np.float32) * 2
    with reuse.reuse() as memo:
        reuse.remember_rows("rows", hashes, keys, values)
        found, got = reuse.known_rows("rows", hashes, keys)
        assert found.all() and np.array_equal(got, values)
        memo.put(("k",), np.ones(3))
        reuse.forget_rows()
        found, got = reuse.known_rows("rows", hashes, keys)
        assert not found.any() and got is None
        assert memo.get(("k",))[0]
    reuse.forget_rows()  # outside a run: nothing to drop
