"""The codec's declarations and its one encode / decode, against hand-computed texels."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from wrinklepipe import codec
from wrinklepipe.codec import layouts, mappings

_F = np.float32

# ---------------------------------------------------------------------------------------------
# value mappings: hand-computed texels


def test_v2_hand_computed_texels():
    m = codec.mapping(2)
    t = np.array([-1.0, -0.5, 0.0, 0.5, 1.0], _F)
    # 128 + 127 t: -1 -> 1, -0.5 -> 64.5 -> 65 (half up), 0 -> 128, 0.5 -> 191.5 -> 192
    assert m.encode(t, 8).tolist() == [1, 65, 128, 192, 255]
    assert m.encode(t, 16).tolist() == [1, 16385, 32768, 49152, 65535]
    assert m.decode(np.array([1, 128, 255], np.uint8)).tolist() == [-1.0, 0.0, 1.0]
    assert m.decode(np.array([0], np.uint8)).tolist() == [-1.0]  # clamps like SNORM
    assert m.decode(np.array([192], np.uint8))[0] == _F(64 / 127)
    assert m.decode(np.array([32768, 65535, 1], np.uint16)).tolist() == [0.0, 1.0, -1.0]


def test_v1_is_the_legacy_half_offset_mapping():
    m = codec.mapping(None)
    assert m.version == 1 == codec.LEGACY_VERSION
    # 0.5 + 0.5 * 0 = 127.5: zero is not representable; 128 decodes to 1/255
    assert m.encode(np.array([0.0, 1.0, -1.0], _F), 8).tolist() == [128, 255, 0]
    assert m.decode(np.array([128], np.uint8))[0] == pytest.approx(1 / 255, abs=1e-7)
    back = m.decode(np.array([0, 255], np.uint16)).tolist()
    assert back == [-1.0, pytest.approx(-1 + 2 * 255 / 65535)]


def test_unknown_mapping_version_is_refused():
    with pytest.raises(ValueError, match="mapping version 3"):
        codec.mapping(3)


@given(version=st.sampled_from(codec.VERSIONS), bits=st.sampled_from([8, 16]), data=st.data())
@settings(max_examples=60, deadline=None)
def test_mapping_round_trips(version, bits, data):
    """decode(encode(t)) is within half a step of t; encode(decode(q)) == q for written q."""
    m = codec.mapping(version)
    t = data.draw(hnp.arrays(_F, 64, elements=st.floats(-1, 1, width=32)))
    c, h = m.centre(bits)
    back = m.decode(m.encode(t, bits))
    assert np.max(np.abs(back - t)) <= 0.5 / h + 1e-6
    lo = 1 if version == 2 else 0
    q = np.arange(lo, 1 << bits, max(1, (1 << bits) // 4096)).astype(
        np.uint8 if bits == 8 else np.uint16
    )
    assert np.array_equal(m.encode(m.decode(q), bits), q)


@pytest.mark.parametrize("bits", [8, 16])
def test_sampled_decode_matches_integer_decode(bits):
    top = (1 << bits) - 1
    q = np.arange(0, top + 1, max(1, top // 2000)).astype(np.uint8 if bits == 8 else np.uint16)
    for v in codec.VERSIONS:
        m = codec.mapping(v)
        exact = m.decode(q)
        sampled = m.decode_unorm(q.astype(np.float64) / top, bits)
        assert np.max(np.abs(exact - sampled)) < 2e-6


# ---------------------------------------------------------------------------------------------
# zero is exact: a flat PD texel decodes to exactly (0, 0, 1)


@pytest.mark.parametrize("fmt", ["png8", "png16", "bc5", "bc1", "bc7", "bc3nm"])
def test_flat_pd_texel_is_exactly_up(fmt):
    q, clipped = codec.encode("pd", np.zeros((4, 4, 2), _F), fmt, param=0.25)
    assert clipped == 0
    d = codec.decode("pd", q, fmt, param=0.25)
    assert np.array_equal(d, np.zeros((4, 4, 2), _F))
    n = codec.to_normal("pd", d)
    assert np.array_equal(n, np.tile(np.array([0, 0, 1], _F), (4, 4, 1)))


def test_flat_pd_under_v1_is_tilted_by_half_a_step():
    q, _ = codec.encode("pd", np.zeros((1, 2), _F), "png8", param=1.0, version=1)
    d = codec.decode("pd", q, "png8", param=1.0, version=1)
    assert np.allclose(d, 1 / 255)  # the 0.31-degree tilt of issue 14 at s = 1... per axis


def test_pd_hand_computed():
    # slope 0.25 at s = 0.5: t = 0.5 -> 128 + 63.5 = 191.5 -> 192 (half up); (64 / 127) * 0.5
    q, _ = codec.encode("pd", np.array([[0.25, -0.5]], _F), "png8", param=0.5)
    assert q.tolist() == [[192, 1, 0, 255]]
    d = codec.decode("pd", q, "png8", param=0.5)
    assert d[0, 0] == _F(64 / 127) * _F(0.5) and d[0, 1] == _F(-0.5)


def test_pd_clipping_is_counted():
    q, clipped = codec.encode("pd", np.array([[3.0, 0.0], [0.1, 0.1], [0.0, -2.0]], _F), param=1.0)
    assert clipped == 2
    assert q[:, 0].tolist() == [255, 128 + 13, 128]


def test_diff_gain_and_delta():
    delta = np.array([[0.25, -0.125, 0.0]], _F)
    q, _ = codec.encode("diff", delta, "png8", param=2.0)
    # t = 2 * delta = (0.5, -0.25, 0) -> 191.5 -> 192, 128 - 31.75 = 96.25 -> 96, 128
    assert q.tolist() == [[192, 96, 128, 255]]
    back = codec.decode("diff", q, "png8", param=2.0)
    assert np.allclose(back, [[64 / 127 / 2, -32 / 127 / 2, 0.0]])


# ---------------------------------------------------------------------------------------------
# layouts (issue 19)


def test_layouts_per_format():
    f = codec.storage_format
    assert f("bc1").layout_for("full").name == "rgb"
    assert f("bc7").layout_for("full").name == "rgb"
    assert f("bc7xy").layout_for("full").name == "rg" and f("bc7xy").explicit
    assert f("bc5").layout_for("full").name == "rg"
    assert f("bc3nm").layout_for("full").name == "ag"
    assert f("bc3nm").layout_for("pd").name == "ag"
    assert f("png8").layout_for("diff").name == "rgb"
    with pytest.raises(ValueError, match="three"):
        f("bc5").layout_for("diff")
    assert [f(n).dxgi for n in ("bc1", "bc3nm", "bc5", "bc7")] == [71, 77, 83, 98]
    assert [f(n).vk_format for n in ("bc1", "bc3nm", "bc5", "bc7")] == [131, 137, 141, 145]
    assert codec.layout("ag").swizzle == "ag01"
    assert codec.layout("rgb").swizzle == "rgb1"
    assert codec.layout("rg").swizzle == "rg01"


def test_normal_maps_store_z_in_b_for_rgb_formats():
    n = np.array([[0.6, 0.0, 0.8]], _F)
    for fmt in ("bc1", "bc7", "png8", "uastc"):
        q, _ = codec.encode("full", n, fmt)
        # glTF mapping 0.5 + 0.5 n: 0.8 -> 229.5 -> 230 (half up), 0 -> 127.5 -> 128
        assert q.tolist() == [[204, 128, 230, 255]], fmt
    q, _ = codec.encode("full", n, "bc3nm")
    assert q.tolist() == [[255, 128, 0, 204]]  # DXT5nm: (1, y, 0, x)
    q, _ = codec.encode("full", n, "bc5")
    assert q.tolist() == [[204, 128, 0, 255]]


@given(
    n=hnp.arrays(_F, (16, 3), elements=st.floats(-1, 1, width=32)),
    fmt=st.sampled_from(["png8", "png16", "bc1", "bc3nm", "bc5", "bc7", "bc7xy", "exr"]),
)
@settings(max_examples=80, deadline=None)
def test_normal_round_trip_within_quantisation(n, fmt):
    n = n.copy()
    n[:, 2] = np.abs(n[:, 2]) + 0.3  # facing out, away from the horizon
    n = codec.normalize(n)
    f = codec.storage_format(fmt)
    q, _ = codec.encode("full", n, fmt)
    back = codec.decode("full", q, fmt)
    chord = np.linalg.norm(back.astype(np.float64) - n, axis=-1)
    err = np.degrees(2 * np.arcsin(np.minimum(chord / 2, 1)))
    # half a step per component; rebuilding z from x, y amplifies it near the horizon
    step = {8: 1 / 127.5, 16: 1 / 32767.5, 0: 1e-3}[f.bits]
    z = n[:, 2]
    bound = np.degrees(step * np.sqrt(3) / np.where(f.layout_for("full").stores_z, 1.0, z)) + 1e-4
    assert np.all(err <= bound)


def test_pack_unpack_is_the_layout():
    comp = np.array([[10, 20]], np.uint8)
    assert layouts.pack(comp, codec.AG).tolist() == [[255, 20, 0, 10]]
    assert layouts.unpack(np.array([[255, 20, 0, 10]], np.uint8), codec.AG).tolist() == [[10, 20]]
    with pytest.raises(ValueError, match="reads channel a"):
        layouts.unpack(np.zeros((1, 3), np.uint8), codec.AG)


def test_quantization_bound():
    assert mappings.quantization_bound(8, 2) == pytest.approx(0.5 / 127)
    assert mappings.quantization_bound(16, 1) == pytest.approx(0.5 / 32767.5)
