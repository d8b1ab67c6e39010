"""The BC4 / BC5 encoder against texture2ddecoder, hand-made blocks and the exhaustive search."""

from __future__ import annotations

import hashlib
from pathlib import Path

import etcpak
import numpy as np
import pytest
import texture2ddecoder as t2d
from hypothesis import example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from wrinklepipe import codec
from wrinklepipe.demo import character
from wrinklepipe.metrics import angle_deg
from wrinklepipe.normals import bc4, bc4_block, bc4_search

SAMPLES = Path(__file__).resolve().parents[2] / "shared" / "data" / "gltf-samples"


def _decode4(data: bytes, h: int, w: int) -> np.ndarray:
    return np.frombuffer(t2d.decode_bc4(data, w, h), np.uint8).reshape(h, w, 4)[..., 2]


def _decode5(data: bytes, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    px = np.frombuffer(t2d.decode_bc5(data, w, h), np.uint8).reshape(h, w, 4)  # BGRA
    return px[..., 2], px[..., 1]


def test_hand_made_blocks_are_exact():
    # two plateaus: the endpoints land on them; 0 and 255 only: the six-value mode's extremes
    a = np.array([[10] * 4, [10] * 4, [80] * 4, [80] * 4], np.uint8)
    data = bc4.encode_bc4(a)
    assert len(data) == 8 and sorted(data[:2]) == [10, 80]
    assert np.array_equal(_decode4(data, 4, 4), a)
    # 0, 255 and a tight cluster: only the six-value mode (e0 <= e1: lo, hi, 4 interpolants,
    # 0 and 255) holds all of them exactly (lo = 100, hi = 110: interpolants 102 ... 108)
    b = np.array([[0] * 4, [100, 102, 104, 106], [108, 110, 110, 100], [255] * 4], np.uint8)
    data = bc4.encode_bc4(b)
    assert (data[0], data[1]) == (100, 110)
    assert np.array_equal(_decode4(data, 4, 4), b)
    c = np.full((4, 8), 77, np.uint8)
    assert np.array_equal(_decode4(bc4.encode_bc4(c), 4, 8), c)


@settings(max_examples=4, deadline=None)
@given(
    hnp.arrays(np.uint8, (8, 12)),
    hnp.arrays(np.uint8, (4, 8)),
    hnp.arrays(np.uint8, (4, 4)),
)
def test_the_encoder_is_block_local(a, b, c):
    """Law: a block encodes the same whatever else shares the call: BC5 in one pass and every
    map of a list in one pass (encode_bc5_many: mip chains) give the blocks each channel gets
    alone. The spread on the 8 x 12 map (pairs 60 apart, hard blocks) exercises the windows."""
    a = a.astype(np.float32) * np.float32(0.5) + np.float32(60) * (np.arange(12) % 3)
    pairs = [(a, a[::-1]), (b, c.repeat(2, axis=1)), (c, c)]

    def alone(x: np.ndarray, y: np.ndarray) -> bytes:
        return np.concatenate([bc4.bc4_blocks(x), bc4.bc4_blocks(y)], axis=1).tobytes()

    want = [alone(x, y) for x, y in pairs]
    assert [bc4.encode_bc5(x, y) for x, y in pairs] == want
    assert bc4.encode_bc5_many(pairs) == want
    assert bc4.encode_bc5_many([]) == []


@settings(max_examples=40, deadline=None)
@given(
    hnp.arrays(np.uint8, (8, 8)),
    st.sampled_from(["raw", "smooth", "float"]),
)
# found by hypothesis: a ramp 100.47..100.75 on the pair (100, 101), where truncation puts six
# of the eight positions on 100; the nearest entry (101 at j = 7) is three positions up
@example(np.full((8, 8), 129, np.uint8), "smooth")
def test_blocks_decode_to_the_palette_the_search_scored(values, kind):
    """texture2ddecoder's decode of every block is the palette entry the encoder assigned:
    the truncated interpolants of the search are the decoder's."""
    v = values.astype(np.float32)
    if kind == "smooth":
        v = np.clip(100 + np.cumsum(v - 127.5, axis=1) / 16, 0, 255).astype(np.float32)
    elif kind == "float":
        v = v + np.float32(0.37)
    blocks = bc4.bc4_blocks(v)
    dec = _decode4(blocks.tobytes(), 8, 8).astype(np.float32)
    # the error the encoder minimised (its own palette model) equals the decoded error
    x = bc4.blocks_of(np.clip(v, 0, 255))
    e0, e1 = blocks[:, 0].astype(np.float32), blocks[:, 1].astype(np.float32)
    model = []
    for k in range(x.shape[1]):
        if e0[k] > e1[k]:
            pal = [e0[k], e1[k]] + [
                np.floor(((8 - i) * e0[k] + (i - 1) * e1[k]) / 7) for i in range(2, 8)
            ]
        else:
            pal = (
                [e0[k], e1[k]]
                + [np.floor(((6 - i) * e0[k] + (i - 1) * e1[k]) / 5) for i in range(2, 6)]
                + [0, 255]
            )
        pal = np.array(pal, np.float32)
        model.append(np.min((x[:, k, None] - pal[None]) ** 2, axis=1).sum())
    got = ((bc4.blocks_of(dec) - x) ** 2).sum(axis=0)
    np.testing.assert_allclose(got, model, atol=1e-3)


def test_flat_pd_through_bc5_is_exact():
    """A zero slope is texel 128 under mapping v2; BC5 stores it exactly: (0, 0, 1)."""
    q, _ = codec.encode("pd", np.zeros((8, 8, 2), np.float32), "bc5", param=0.5)
    x, y = _decode5(bc4.encode_bc5(q[..., 0], q[..., 1]), 8, 8)
    assert np.all(x == 128) and np.all(y == 128)
    n = codec.to_normal("pd", codec.decode("pd", np.stack([x, y], -1), "rg", param=0.5))
    assert np.array_equal(n, np.tile(np.array([0, 0, 1], np.float32), (8, 8, 1)))


def _bc5_error(data: bytes, ref: np.ndarray) -> tuple[float, float]:
    h, w = ref.shape[:2]
    x, y = _decode5(data, h, w)
    n = codec.decode("full", np.stack([x, y], -1), "rg")
    a = angle_deg(n, ref.astype(np.float32)).astype(np.float64).ravel()
    return float(a.mean()), float(np.percentile(a, 99, method="inverted_cdf"))


def _near_limit(targets: np.ndarray, ref: np.ndarray) -> dict[str, tuple[float, float]]:
    ours = bc4.encode_bc5(targets[..., 0], targets[..., 1])
    exhaustive = np.concatenate(
        [bc4.reference_bc4(targets[..., 0]), bc4.reference_bc4(targets[..., 1])], axis=1
    ).tobytes()
    h, w = targets.shape[:2]
    rgba = np.zeros((h, w, 4), np.uint8)
    rgba[..., :2] = np.clip(np.floor(targets + 0.5), 0, 255)
    rgba[..., 3] = 255
    return {
        "ours": _bc5_error(ours, ref),
        "exhaustive": _bc5_error(exhaustive, ref),
        "etcpak": _bc5_error(etcpak.compress_bc5(rgba, w, h), ref),
    }


def _assert_near_limit(r: dict[str, tuple[float, float]]) -> None:
    (mean, p99), (emean, ep99) = r["ours"], r["exhaustive"]
    assert mean <= 1.03 * emean, r
    assert p99 <= ep99, r
    assert mean < r["etcpak"][0] and p99 < r["etcpak"][1], r


@pytest.fixture(scope="module")
def demo_base() -> np.ndarray:
    return character.generate(1024).base_normal.astype(np.float32)


def test_bc5_within_3_percent_of_exhaustive_on_the_demo_base(demo_base):
    n = demo_base[448:576, 448:576]  # pores and the scar's edge
    targets = (np.float32(127.5) + np.float32(127.5) * n[..., :2]).astype(np.float32)
    _assert_near_limit(_near_limit(targets, n))


def glb_normal_texels(glb: Path, tmp_path: Path) -> np.ndarray:
    """The 8-bit texels [H, W, 3] of a GLB's first normal texture (decoded by OpenImageIO)."""
    import OpenImageIO as oiio
    import pygltflib

    g = pygltflib.GLTF2().load(str(glb))
    mat = next(m for m in g.materials if m.normalTexture is not None)
    img = g.images[g.textures[mat.normalTexture.index].source]
    bv = g.bufferViews[img.bufferView]
    start = bv.byteOffset or 0
    suffix = ".jpg" if "jpeg" in (img.mimeType or "") else ".png"
    path = tmp_path / f"{glb.stem}_normal{suffix}"
    path.write_bytes(g.binary_blob()[start : start + bv.byteLength])
    return np.asarray(oiio.ImageBuf(str(path)).get_pixels(oiio.UINT8))[..., :3]


def busiest_crop(texels: np.ndarray, size: int) -> np.ndarray:
    """The ``size``-square window (on a grid of ``size / 2`` steps) whose x, y vary most."""
    h, w = texels.shape[:2]
    best, where = -1.0, (0, 0)
    for y in range(0, h - size + 1, size // 2):
        for x in range(0, w - size + 1, size // 2):
            v = float(texels[y : y + size, x : x + size, :2].astype(np.float32).std())
            if v > best:
                best, where = v, (y, x)
    y, x = where
    return texels[y : y + size, x : x + size]


@pytest.mark.shared
@pytest.mark.parametrize("name", ["DamagedHelmet", "NormalTangentTest"])
def test_bc5_within_3_percent_of_exhaustive_on_real_normal_maps(tmp_path, name):
    """On the busiest 128^2 window of each real normal map (NormalTangentMirrorTest ships the
    very texture of NormalTangentTest, so it is covered by it)."""
    glb = SAMPLES / name / "glTF-Binary" / f"{name}.glb"
    if not glb.exists():
        pytest.skip(f"{glb} not present")
    if name == "NormalTangentTest":
        mirror = SAMPLES / "NormalTangentMirrorTest" / "glTF-Binary" / "NormalTangentMirrorTest.glb"
        if mirror.exists():
            a = glb_normal_texels(glb, tmp_path)
            (tmp_path / "mirror").mkdir()
            assert np.array_equal(a, glb_normal_texels(mirror, tmp_path / "mirror"))
    q = busiest_crop(glb_normal_texels(glb, tmp_path), 128)
    # the source is 8-bit: BC5 reproduces its x, y (z rebuilt), measured against that normal
    ref = codec.decode("full", q[..., :2], "rg")
    _assert_near_limit(_near_limit(q[..., :2].astype(np.float32), ref))


def test_every_block_is_encoded_on_its_own(demo_base):
    """Blocks are independent: a map's blocks encode the same alone as in the whole map (so a
    map can be encoded in pieces, and the fidelity search encodes only the blocks it reads)."""
    v = np.float32(127.5) + np.float32(127.5) * demo_base[448:512, 448:512, 0]
    whole = bc4.bc4_blocks(v).reshape(16, 16, 8)
    part = bc4.bc4_blocks(v[16:32, 8:40]).reshape(4, 8, 8)
    assert np.array_equal(part, whole[4:8, 2:10])


#: sha256 (first 16 hex digits) of the blocks the vectorised numpy encoder (this module before
#: numba, commit 5ab9915) made of :func:`_digest_cases`: the compiled search is the same search.
NUMPY_ENCODER_DIGESTS = {
    "demo_x": "cb02f1dc3dc67d58",
    "demo_y": "7c8ca3f7d0d2a26b",
    "noisy": "55a3dd40449142e0",
    "noisy_step1": "7362029fd7569fef",
    "ints": "bf93260ce3216976",
    "edge": "580ae66c10921ea6",
    "reference": "b5bbd7b4cdb795f4",
}


def _digest_cases() -> dict[str, object]:
    d = character.generate(512).base_normal.astype(np.float32)
    demo = np.float32(127.5) + np.float32(127.5) * d[192:320, 192:320, :2]
    rng = np.random.default_rng(42)
    noisy = np.clip(rng.normal(128, 40, (64, 64)), 0, 255).astype(np.float32)
    ints = rng.integers(0, 256, (32, 64)).astype(np.uint8)
    edge = np.where(
        rng.random((32, 32)) < 0.4,
        rng.choice([0, 255], (32, 32)),
        rng.integers(0, 256, (32, 32)),
    ).astype(np.float32)
    return {
        "demo_x": lambda: bc4.bc4_blocks(demo[..., 0]),
        "demo_y": lambda: bc4.bc4_blocks(demo[..., 1]),
        "noisy": lambda: bc4.bc4_blocks(noisy),
        "noisy_step1": lambda: bc4.bc4_blocks(noisy, hard_step=1),
        "ints": lambda: bc4.bc4_blocks(ints),
        "edge": lambda: bc4.bc4_blocks(edge),
        "reference": lambda: bc4.reference_bc4(noisy[:16, :32]),
    }


def test_blocks_are_byte_identical_to_the_numpy_encoders():
    """The demo base (float targets: every float32 rounding of the search matters), noisy
    float targets (hard blocks, the tail windows), 8-bit texels, blocks at 0 and 255 (the
    six-value mode), the whole-window variant and the exhaustive reference: the same bytes as
    the numpy encoder made."""
    got = {k: hashlib.sha256(fn().tobytes()).hexdigest()[:16] for k, fn in _digest_cases().items()}
    assert got == NUMPY_ENCODER_DIGESTS


def test_palette_entries_by_reciprocal_multiply_are_exact():
    """floor(j r / n) == floor(j * fl(r * fl(1/n))) for every palette position j <= n and range
    r <= 255 (n = 7, 5): the search's multiply in place of a divide changes no entry."""
    f = np.float32
    r = np.arange(256, dtype=f)[None, :]
    for n in (7, 5):
        j = np.arange(n + 1, dtype=f)[:, None]
        want = (np.arange(n + 1)[:, None] * np.arange(256)[None, :]) // n
        assert np.array_equal(np.floor(j * (r * (f(1) / f(n)))), want.astype(f))


def _every_round(x: np.ndarray, hard_step: int) -> np.ndarray:
    """BC4 blocks of target blocks ``x`` [N, 16] by the encoder's kernels run as plain Python
    with nothing skipped: every round of steps 2-3 (``_moved`` always answers yes, so the
    exact positions are recomputed after the search too) and every pair of the tail window
    (no coarse grid left out)."""
    bc4_search.compiled()
    out = np.empty((x.shape[0], 8), np.uint8)
    window = bc4_search._window.py_func
    with pytest.MonkeyPatch.context() as mp:
        for mod in (bc4_search, bc4_block):
            for name, fn in list(vars(mod).items()):
                if hasattr(fn, "py_func"):  # a compiled kernel: back to its Python
                    mp.setattr(mod, name, fn.py_func)
        mp.setattr(bc4_search, "_moved", lambda s, c: True)
        mp.setattr(bc4_search, "_window", lambda *a: window(*a[:-1], 0))
        bc4_search._encode(x, hard_step, 0, out)
    return out


@settings(max_examples=8, deadline=None)
@given(
    hnp.arrays(np.uint8, (8, 32)),
    st.sampled_from(["raw", "smooth", "float"]),
    st.sampled_from([1, 4]),
)
def test_skipped_rounds_and_kept_positions_change_no_block(values, kind, hard_step):
    """The compiled search skips a Lloyd or neighbour round after one that changed no lane's
    best and, in the tail window, the coarse window's pairs; it packs each block with the
    exact positions computed when its pair was chosen: the same blocks as every round and
    every pair run and the positions computed again (random blocks: flat, smooth and wild
    ones, hard blocks and the tail windows)."""
    v = values.astype(np.float32)
    if kind == "smooth":
        v = np.clip(100 + np.cumsum(v - 127.5, axis=1) / 16, 0, 255).astype(np.float32)
    elif kind == "float":
        v = v * np.float32(0.25) + np.float32(60.37)
    want = _every_round(bc4._targets(v), hard_step)
    assert np.array_equal(bc4.bc4_blocks(v, hard_step=hard_step), want)
