"""The packaged form: encode/quantise/decode bounds (properties), channel tables, PNG round trip."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from wrinklepipe import model
from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.io.package import (
    PackOptions,
    asset_from_package,
    decode_state,
    encode_state,
    package_from_asset,
    png_bytes,
    png_pixels,
)

finite = st.floats(-1.0, 1.0, width=32, allow_nan=False)


def _q8(v: np.ndarray) -> np.ndarray:
    return np.rint(np.clip(v, 0, 1) * 255) / 255


@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float32, (4, 4, 2), elements=st.floats(-0.625, 0.625, width=32)),
    arrays(np.float32, (4, 4, 2), elements=finite),
    st.sampled_from([0.25, 0.5, 1.0, 2.0]),
)
def test_pd_slope_error_at_most_scale_over_255(base_slopes, unit, scale):
    # wrinkle-only slopes inside the cone [-s, s]; stored v = 0.5 + 0.5 d / s, q = rint(255 v)
    d = (unit * np.float32(scale)).astype(np.float32)
    base = model.pd_to_normal(base_slopes)
    wrinkled = model.pd_to_normal(model.normal_to_pd(base) + d)
    stored = _q8(encode_state(base, wrinkled, "pd", scale)).astype(np.float32)
    back = decode_state(base, stored, "pd", scale)
    d_back = model.normal_to_pd(back) - model.normal_to_pd(base)
    # |d - d'| = 2 s |v - q/255| <= s / 255 (plus float32 rounding of the slopes)
    assert np.abs(d_back - d).max() <= scale / 255 + 2e-5 * (1 + scale)


@settings(max_examples=60, deadline=None)
@given(
    arrays(np.float32, (3, 3, 2), elements=st.floats(-0.5, 0.5, width=32)),
    arrays(np.float32, (3, 3, 2), elements=st.floats(-0.5, 0.5, width=32)),
)
def test_diff_and_full_decode_within_one_level(base_slopes, w_slopes):
    base = model.pd_to_normal(base_slopes)
    wrinkled = model.pd_to_normal(w_slopes)
    # diff: D = 0.5 + 0.5 (W - B) -> W' = B + (2 q/255 - 1): per component within 1/255
    stored = _q8(encode_state(base, wrinkled, "diff", 1.0)).astype(np.float32)
    raw = base + (2 * stored - 1)
    assert np.abs(raw - wrinkled).max() <= 1 / 255 + 1e-6
    assert np.allclose(decode_state(base, stored, "diff", 1.0), model.normalize(raw), atol=1e-6)
    # full: 0.5 + 0.5 W
    stored = _q8(encode_state(base, wrinkled, "full", 1.0)).astype(np.float32)
    assert np.abs((2 * stored - 1) - wrinkled).max() <= 1 / 255 + 1e-6


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
    table = pkg.meta["masks"]["table"]
    assert [e["region"] for e in table] == [f"r{i}" for i in range(n_regions)]
    if layout == "rgba":
        assert len(pkg.meta["masks"]["textures"]) == (n_regions + 3) // 4
        assert table[min(5, n_regions - 1)]["channel"] == "rgba"[min(5, n_regions - 1) % 4]


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
    from wrinklepipe.pipeline import demo_package

    pkg = demo_package(64, encoding=encoding)
    from wrinklepipe.demo import demo_asset

    truth = demo_asset(64, encoding=encoding)
    back = asset_from_package(pkg)
    for k in range(len(truth.state_names)):
        err = model.angular_error_deg(truth.states[k], back.states[k])
        assert err.mean() < 0.5, (encoding, k, err.mean())
