"""The packaged form: encode/quantise/decode bounds (properties), channel tables, PNG round trip."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from wrinklepipe import model
from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.io.png import png_bytes, png_pixels
from wrinklepipe.metrics import angle_deg
from wrinklepipe.pipeline.package import (
    PackOptions,
    asset_from_package,
    decode_state,
    encode_state,
    package_from_asset,
)

finite = st.floats(-1.0, 1.0, width=32, allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float32, (4, 4, 2), elements=st.floats(-0.625, 0.625, width=32)),
    arrays(np.float32, (4, 4, 2), elements=finite),
    st.sampled_from([0.25, 0.5, 1.0, 2.0]),
    st.sampled_from([8, 16]),
    st.sampled_from([1, 2]),
)
def test_pd_slope_error_at_most_half_a_step(base_slopes, unit, scale, bits, version):
    # wrinkle-only slopes inside the cone [-s, s]; t = d / s stored with the mapping's
    # h steps per unit (v1: top / 2, v2: 2^(bits-1) - 1): |d - d'| <= s / (2 h)
    d = (unit * np.float32(scale)).astype(np.float32)
    base = model.pd_to_normal(base_slopes)
    wrinkled = model.pd_to_normal(model.normal_to_pd(base) + d)
    q = encode_state(base, wrinkled, "pd", scale, bits, version)
    assert q.dtype == (np.uint8 if bits == 8 else np.uint16) and np.all(q[..., 2] == 0)
    back = decode_state(base, q, "pd", scale, version)
    d_back = model.normal_to_pd(back) - model.normal_to_pd(base)
    h = ((1 << bits) - 1) / 2 if version == 1 else (1 << (bits - 1)) - 1
    assert np.abs(d_back - d).max() <= scale / (2 * h) + 2e-5 * (1 + scale)


def test_flat_pd_state_decodes_to_the_base_exactly():
    base = model.pd_to_normal(np.array([[[0.3, -0.2]]], np.float32))
    for bits in (8, 16):
        q = encode_state(base, base, "pd", 0.5, bits)
        assert q[0, 0].tolist() == [1 << (bits - 1), 1 << (bits - 1), 0]
        # adds exactly zero slope: the base's own slopes come back bit for bit
        same = model.pd_to_normal(model.normal_to_pd(base))
        assert np.array_equal(decode_state(base, q, "pd", 0.5), same)


@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float32, (3, 3, 2), elements=st.floats(-0.5, 0.5, width=32)),
    arrays(np.float32, (3, 3, 2), elements=st.floats(-0.5, 0.5, width=32)),
)
def test_diff_and_full_decode_within_half_a_step(base_slopes, w_slopes):
    base = model.pd_to_normal(base_slopes)
    wrinkled = model.pd_to_normal(w_slopes)
    # diff (v2): q = 128 + 127 (W - B) -> W' = B + (q - 128) / 127: within 0.5 / 127
    q = encode_state(base, wrinkled, "diff", 1.0)
    raw = base + (q.astype(np.float64) - 128) / 127
    assert np.abs(raw - wrinkled).max() <= 0.5 / 127 + 1e-6
    assert np.allclose(decode_state(base, q, "diff", 1.0), model.normalize(raw), atol=1e-6)
    # full: the glTF mapping 0.5 + 0.5 W at every version
    q = encode_state(base, wrinkled, "full", 1.0)
    assert np.abs((2 * q.astype(np.float64) / 255 - 1) - wrinkled).max() <= 1 / 255 + 1e-6


def test_legacy_v1_assets_still_decode():
    # an asset without a mapping field: v = 0.5 + 0.5 d / s; slope 0.25 at s = 0.5 -> 191.25
    base = model.pd_to_normal(np.zeros((1, 1, 2), np.float32))
    q = np.array([[[191, 128, 0]]], np.uint8)
    back = decode_state(base, q, "pd", 0.5, None)
    d = model.normal_to_pd(back)[0, 0]
    assert d[0] == pytest.approx((2 * 191 / 255 - 1) * 0.5, abs=1e-6)
    assert d[1] == pytest.approx((2 * 128 / 255 - 1) * 0.5, abs=1e-6)


@settings(max_examples=40, deadline=None)
@given(
    st.integers(1, 9),
    st.sampled_from(["rgba", "array"]),
    st.integers(0, 2**31 - 1),
)
def test_masks_survive_packing_exactly(n_regions, layout, seed):
    # 8-bit-representable masks come back bit for bit through pack -> PNG -> unpack
    rng = np.random.default_rng(seed)
    masks = (rng.integers(0, 256, (n_regions, 4, 4)) / 255).astype(np.float32)
    asset = _asset(masks)
    pkg = package_from_asset(asset, PackOptions(mask_layout=layout))
    for t in pkg.textures:
        assert np.array_equal(png_pixels(png_bytes(t.pixels)), t.pixels)
    back = asset_from_package(pkg)
    assert np.array_equal(np.rint(back.masks * 255), np.rint(masks * 255))
    table = pkg.meta.masks.table
    assert [e.region for e in table] == [f"r{i}" for i in range(n_regions)]
    if layout == "rgba":
        assert len(pkg.meta.masks.textures) == (n_regions + 3) // 4
        assert table[min(5, n_regions - 1)].channel == "rgba"[min(5, n_regions - 1) % 4]


def _asset(masks: np.ndarray) -> WrinkleAsset:
    n = masks.shape[0]
    base = np.zeros((4, 4, 3), np.float32)
    base[..., 2] = 1
    mesh = Mesh(
        positions=np.eye(3, dtype=np.float32),
        indices=np.array([[0, 1, 2]], np.uint32),
        uvs=np.array([[0, 0], [1, 0], [0, 1]], np.float32),
    )
    return WrinkleAsset(
        name="t",
        base=base,
        states=base[None].copy(),
        state_names=("s",),
        masks=masks,
        regions=tuple(Region(f"r{i}") for i in range(n)),
        mesh=mesh,
    )


def test_sixteen_bit_maps(tmp_path):
    masks = np.full((1, 4, 4), 0.5, np.float32)
    pkg = package_from_asset(_asset(masks), PackOptions(bits=16))
    base = pkg.texture("base_normal")
    assert base.pixels.dtype == np.uint16 and base.pixels[0, 0].tolist() == [32768, 32768, 65535]
    assert np.array_equal(png_pixels(png_bytes(base.pixels)), base.pixels)
    assert pkg.texture("mask_0").pixels.dtype == np.uint8


@pytest.mark.parametrize("encoding", ["pd", "diff", "full", "composite"])
def test_demo_decode_error_small(encoding):
    # 8-bit storage of the demo's states: mean error well below the demo budget (0.5 deg)
    from wrinklepipe.demo.package import demo_package

    pkg = demo_package(64, encoding=encoding)
    from wrinklepipe.demo import demo_asset

    truth = demo_asset(64, encoding=encoding)
    back = asset_from_package(pkg)
    for k in range(len(truth.state_names)):
        err = angle_deg(truth.states[k], back.states[k])
        assert err.mean() < 0.5, (encoding, k, err.mean())
