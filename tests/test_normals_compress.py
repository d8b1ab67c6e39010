"""Block compression checks: BC5 vs BC1 vs BC3nm on the demo, independent decoding, metrics."""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import pytest
import quicktex
from hypothesis import given, settings
from hypothesis import strategies as st
from quicktex.s3tc.bc1 import BC1Encoder
from quicktex.s3tc.bc3 import BC3Encoder

from wrinklepipe.demo import character
from wrinklepipe.metrics import Budget, angle_deg
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals import dds, pd_fused
from wrinklepipe.normals import encode as enc


@pytest.fixture(scope="module")
def demo():
    return character.generate(256)


@pytest.fixture(scope="module")
def demo_checks(demo):
    """PD wrinkle-only maps of both demo states through every two-channel format."""
    out = {}
    for k in range(2):
        n = demo.wrinkle_only_normal(k).astype(np.float32)
        q, s, _ = enc.encode_pd_u8(n, "auto")
        dec = cmp.decoder_for("pd", s)
        out[k] = {
            f: cmp.compress_and_check(q, n, f, dec, budget=Budget(p99=2.0)) for f in cmp.FORMATS
        }
    return out


def test_bc5_beats_bc1_and_bc3nm_on_demo_wrinkle_maps(demo_checks):
    for _k, checks in demo_checks.items():
        bc5, bc1, bc3 = checks["bc5"].error, checks["bc1"].error, checks["bc3nm"].error
        assert bc5.mean < bc1.mean
        assert bc5.mean < bc3.mean
        # and the codec's own share is small (BC5 stores each channel with 8-bit endpoints)
        assert checks["bc5"].compression_error.mean < 0.5
        assert checks["bc5"].bytes == 256 * 256  # 1 byte per texel
        assert checks["bc1"].bytes == 256 * 256 // 2


def test_error_stats_match_numpy_reference():
    rng = np.random.default_rng(0)
    a = rng.gamma(2.0, 0.3, size=300_000).astype(np.float32)
    e = cmp.error_stats(a)
    assert e.mean == pytest.approx(float(a.astype(np.float64).mean()), rel=1e-6)
    assert e.p99 == pytest.approx(float(np.percentile(a, 99, method="inverted_cdf")))
    assert e.max == pytest.approx(float(a.max()))
    small = np.array([3.0, 1.0, 2.0], np.float32)
    assert cmp.error_stats(small).p99 == 3.0  # nearest rank ceil(0.99 * 3) = 3


def test_angle_deg_hand_values():
    a = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]], np.float32)
    b = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [math.sin(1e-3), 0.0, math.cos(1e-3)]])
    got = angle_deg(a, b.astype(np.float32))
    np.testing.assert_allclose(got, [90.0, 0.0, math.degrees(1e-3)], rtol=1e-4, atol=1e-6)


def test_psnr_hand_value():
    r = np.zeros((4, 4, 2), np.uint8)
    d = r.copy()
    d[0, 0, 0] = 16  # mse = 256 / 16 = 16 on channel 0
    p = cmp.psnr(r, d)
    assert p[0] == pytest.approx(10 * math.log10(255**2 / 16))
    assert p[1] == math.inf


def test_bc3nm_swizzle_puts_x_in_alpha_y_in_green():
    q = np.zeros((4, 4, 2), np.uint8)
    q[..., 0] = 200
    q[..., 1] = 60
    rgba = cmp.pack_rgba(q, "bc3nm")
    assert rgba[0, 0].tolist() == [255, 60, 0, 200]
    dec = cmp.decode_bc(cmp.encode_bc(rgba, "bc3nm"), 4, 4, "bc3nm")
    xy = cmp.unpack_u8(dec, "bc3nm")
    assert np.abs(xy.astype(int) - [200, 60]).max() <= 1


def test_texture2ddecoder_bgra_is_turned_into_rgba():
    q = np.zeros((4, 4, 2), np.uint8)
    q[..., 0] = 250  # x -> R
    q[..., 1] = 10  # y -> G
    rgba = cmp.decode_bc(cmp.encode_bc(cmp.pack_rgba(q, "bc5"), "bc5"), 4, 4, "bc5")
    assert abs(int(rgba[0, 0, 0]) - 250) <= 1 and abs(int(rgba[0, 0, 1]) - 10) <= 1


@pytest.mark.parametrize("fmt", ["bc5", "bc1", "bc3nm", "bc7"])
def test_fused_pd_path_equals_plain_calls(demo, fmt):
    n = demo.wrinkled_normal(1)[:, :200].astype(np.float32)  # 256 x 200
    s = 1.0
    q, _, clipped = enc.encode_pd_u8(n, s)
    # the BC4-based encoders fit the unrounded texels 128 + 127 t
    t = np.clip(n[..., :2] / n[..., 2:3] / s, -1, 1)
    targets = (128 + 127 * t).astype(np.float32)
    data = cmp.encode_bc(cmp.pack_rgba(q, fmt), fmt, targets)
    angles = np.empty(n.shape[:2], np.float32)
    r = pd_fused.pd_compress_check(n, s, fmt, angles_out=angles)
    assert r.data == data  # chunked packing == one call
    assert r.clipped == clipped == enc.pd_clipped_count(n, s)
    dec = enc.decode_pd(cmp.unpack_u8(cmp.decode_bc(data, 200, 256, fmt), fmt), s)
    chord = np.linalg.norm(dec.astype(np.float64) - n, axis=-1)
    ref = np.degrees(2 * np.arcsin(np.minimum(chord / 2, 1)))  # float64 reference
    np.testing.assert_allclose(angles, ref, atol=2e-2)
    assert r.error.mean == pytest.approx(ref.mean(), abs=2e-3)
    assert r.error.max == pytest.approx(ref.max(), abs=2e-2)


def test_padding_and_refusal():
    n = np.zeros((6, 10, 3), np.float32)
    n[..., 2] = 1
    r = pd_fused.pd_compress_check(n, 1.0, "bc5")
    assert r.padded and len(r.data) == 2 * 3 * 16  # 8 x 12 padded -> 2 x 3 blocks
    with pytest.raises(ValueError, match="multiples of 4"):
        pd_fused.pd_compress_check(n, 1.0, "bc5", pad=False)
    with pytest.raises(ValueError, match="multiples of 4"):
        cmp.encode_bc(np.zeros((6, 10, 4), np.uint8), "bc5")


@pytest.mark.parametrize(
    "fmt,dx10", [("bc5", None), ("bc5", False), ("bc1", None), ("bc3nm", None)]
)
def test_written_dds_decoded_independently_gives_the_measured_texels(
    tmp_path: Path, demo, demo_checks, fmt, dx10
):
    """OpenImageIO's own DDS decoder (not texture2ddecoder) reads what the check measured."""
    check = demo_checks[1][fmt]
    path = tmp_path / f"m_{fmt}.dds"
    path.write_bytes(dds.dds_bytes(fmt, 256, 256, [check.data], dx10=dx10))
    buf = oiio.ImageBuf(str(path))
    px = np.asarray(buf.get_pixels(oiio.UINT8))
    assert not buf.has_error
    if fmt == "bc3nm":
        xy = px[..., [3, 1]]
    else:
        xy = px[..., :2]
    # decoders may round the interpolants differently by one step: BC4-style blocks rarely
    # differ; BC1's 1/3 and 2/3 colours are rounded by OpenImageIO, truncated by
    # texture2ddecoder (one level on many texels; the reported error still agrees, below)
    diff = np.abs(xy.astype(int) - check.decoded.astype(int))
    assert diff.max() <= 1
    if fmt != "bc1":
        assert np.mean(diff > 0) < 0.2
    # the error the check reported is what the independently decoded texels give
    n = demo.wrinkle_only_normal(1).astype(np.float32)
    s = enc.auto_pd_scale(n)
    ind = enc.decode_pd(xy.astype(np.uint8), s)
    e = cmp.angular_error_stats(ind, n)
    # BC1's interpolated colours round differently in the two decoders (one level on about a
    # third of the texels of this smooth map: 0.2 degrees at its PD scale); the others agree
    tol = (0.25, 0.2) if fmt == "bc1" else (0.02, 0.1)
    assert e.mean == pytest.approx(check.error.mean, abs=tol[0])
    assert e.p99 == pytest.approx(check.error.p99, abs=tol[1])


def test_choose_format_picks_smallest_within_budget(demo_checks):
    checks = list(demo_checks[1].values())
    loose = Budget(p99=90.0)
    assert cmp.choose_format(checks, loose).format == "bc1"  # 4 bpp
    tight = Budget(p99=1e-6)
    assert cmp.choose_format(checks, tight) is None


@settings(max_examples=25, deadline=None)
@given(
    st.integers(1, 200_000),
    st.floats(0.1, 5.0),
    st.integers(0, 2**31 - 1),
)
def test_error_stats_law(n, spread, seed):
    """p99 is the exact nearest-rank value and max/mean match numpy, for any size."""
    a = (np.random.default_rng(seed).gamma(1.5, spread, n)).astype(np.float32)
    e = cmp.error_stats(a)
    assert e.p99 == float(np.percentile(a, 99, method="inverted_cdf"))
    assert e.max == float(a.max())
    assert e.mean == pytest.approx(float(a.astype(np.float64).mean()), rel=1e-6)


#: A near-flat block (a diff map's texels, found by the codec's property test) that quicktex's
#: level 5 alone stores as one colour 6 / 2 / 14 levels off (R 134, G 24, B 85).
_FLAT_BLOCK = [
    [127, 22, 99], [127, 24, 96], [128, 25, 95], [128, 25, 95],
    [127, 23, 98], [127, 24, 96], [128, 25, 95], [128, 25, 95],
    [127, 24, 96], [128, 25, 95], [128, 25, 95], [129, 24, 96],
    [127, 24, 96], [128, 25, 95], [128, 25, 95], [129, 24, 97],
]  # fmt: skip


@pytest.mark.parametrize("fmt", ["bc1", "bc3nm"])
def test_colour_blocks_keep_the_better_of_two_quicktex_levels(fmt):
    """By hand: in RGB565 the block's red 127-129 lies between 123 and 132 (steps of 8.2), blue
    95-99 between 90 and 99, green 22-25 between 20 and 24 (steps of 4): with the two thirds
    between endpoints every texel is within 3 levels; the shipped encoder gets there."""
    rgb = np.array(_FLAT_BLOCK, np.uint8).reshape(4, 4, 3)
    if fmt == "bc3nm":  # DXT5nm colour half: R = 1, B = 0, y in G
        rgb = np.stack([np.full((4, 4), 255), rgb[..., 1], np.zeros((4, 4))], -1).astype(np.uint8)
    a = np.concatenate([rgb, np.full((4, 4, 1), 255, np.uint8)], -1)
    got = cmp.decode_bc(cmp.encode_bc(a, fmt), 4, 4, fmt)[..., :3].astype(int)
    assert np.abs(got - rgb).max() <= 3
    if fmt == "bc1":  # what level 5 alone gives (the reason for the second level)
        tex = quicktex.RawTexture.frombytes(a.tobytes(), 4, 4)
        alone = cmp.decode_bc(bytes(BC1Encoder(5).encode(tex).tobytes()), 4, 4, "bc1")
        assert np.abs(alone[..., :3].astype(int) - rgb).max() >= 10


@pytest.mark.parametrize("fmt", ["bc1", "bc3nm"])
def test_a_kept_quicktex_encoder_gives_a_new_encoders_bytes(fmt):
    """The encoders are kept for reuse (their tables cost 20-27 ms): on four threads at once,
    after encoding other maps of other sizes, every kept encoder's bytes equal those of an
    encoder built afresh; one thread after another gets the same encoder back; two threads at
    once never share one."""
    new = {"bc1": BC1Encoder, "bc3nm": BC3Encoder}[fmt]
    rng = np.random.default_rng(7)
    maps = [rng.integers(0, 256, (s, s, 4), dtype=np.uint8) for s in (4, 16, 8, 32, 4) * 4]

    def kept_and_new(a: np.ndarray) -> list[tuple[bytes, bytes]]:
        tex = quicktex.RawTexture.frombytes(a.tobytes(), a.shape[1], a.shape[0])
        out = []
        for level in cmp.QUICKTEX_LEVELS:
            with cmp._quicktex_encoder(fmt, level) as e:
                out.append(
                    (bytes(e.encode(tex).tobytes()), bytes(new(level).encode(tex).tobytes()))
                )
        return out

    with ThreadPoolExecutor(4) as pool:
        for pairs in pool.map(kept_and_new, maps):
            for kept, fresh in pairs:
                assert kept == fresh
    with cmp._quicktex_encoder(fmt, 5) as first:
        pass
    with cmp._quicktex_encoder(fmt, 5) as again:
        assert again is first
        with cmp._quicktex_encoder(fmt, 5) as other:  # the first is in use: another one
            assert other is not first
