"""PD / diff / full encodings against analytic normals and hand counts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.normals import encode as enc


def sphere_cap(size: int, radius: float, r_max_frac: float) -> tuple[np.ndarray, np.ndarray]:
    """Analytic normals of a sphere cap h = sqrt(R^2 - r^2) (OpenGL, rows down) and a mask."""
    c = np.arange(size) - (size - 1) / 2.0
    x = c[None, :].repeat(size, 0)  # columns: +x
    y = -c[:, None].repeat(size, 1)  # rows run down, +y is up
    r2 = x * x + y * y
    inside = r2 <= (radius * r_max_frac) ** 2
    z = np.sqrt(np.maximum(radius**2 - r2, 1e-9))
    n = np.stack([x, y, z], axis=-1) / radius
    n[~inside] = (0.0, 0.0, 1.0)
    return n.astype(np.float32), inside


def angle_deg64(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1)))


def test_quantisation_bound_is_the_hand_value():
    # s = 1, 8 bits, mapping v2 (128 + 127 t): half a step is 1/254 in slope; diagonal
    # sqrt(2)/254 rad; the legacy v1 (0.5 + 0.5 t) half step is 1/255
    assert enc.quantization_bound_deg(1.0, 8) == pytest.approx(math.degrees(math.sqrt(2) / 254))
    assert enc.quantization_bound_deg(1.0, 8, 1) == pytest.approx(math.degrees(math.sqrt(2) / 255))
    assert enc.cone_deg(1.0) == pytest.approx(45.0)
    assert enc.cone_deg(2.0) == pytest.approx(math.degrees(math.atan(2.0)))


@pytest.mark.parametrize("scale", [1.0, 2.0])
def test_sphere_cap_pd_8bit_within_quantisation_bound(scale):
    # cap out to r = 0.7 R: slope r / h = 0.7 / sqrt(1 - 0.49) = 0.98 < 1 (inside the 45 deg cone)
    n, inside = sphere_cap(96, 60.0, 0.7)
    q, s, clipped = enc.encode_pd_u8(n, scale)
    assert s == scale and clipped == 0
    back = enc.decode_pd(q, scale)
    err = angle_deg64(back, n)
    bound = enc.quantization_bound_deg(scale, 8)
    assert err.max() <= bound + 1e-4
    # and rounding really is to nearest: the error is not always ~0 (the test has teeth)
    assert err[inside].max() > 0.3 * bound


def test_sphere_cap_pd_16bit_within_bound():
    n, _ = sphere_cap(64, 40.0, 0.7)
    r = enc.encode_pd(n, 1.0, bits=16)
    assert r.texels.dtype == np.uint16
    back = enc.decode_pd(r.texels, 1.0)
    assert angle_deg64(back, n).max() <= enc.quantization_bound_deg(1.0, 16) + 1e-4


def _normals_from_slopes(px: np.ndarray, py: np.ndarray) -> np.ndarray:
    v = np.stack([px, py, np.ones_like(px)], axis=-1)
    return (v / np.linalg.norm(v, axis=-1, keepdims=True)).astype(np.float32)


def test_clipped_count_equals_hand_count():
    # slopes chosen by hand; with s = 1 these texels leave the cone:
    px = np.array([[0.0, 0.5, 1.5, -2.0], [0.9, -0.99, 0.2, 3.0], [0.0, 0.0, 0.3, -1.2]])
    py = np.array([[0.0, 0.5, 0.0, 0.0], [1.1, 0.0, -1.4, 3.0], [0.99, -0.5, 0.3, 0.1]])
    # hand count (|px| > 1 or |py| > 1): (0,2) (0,3) (1,0) (1,2) (1,3) (2,3) = 6
    n = _normals_from_slopes(px, py)
    assert enc.pd_clipped_count(n, 1.0) == 6
    assert enc.encode_pd(n, 1.0).clipped == 6
    assert enc.encode_pd_u8(n, 1.0)[2] == 6
    # with s = 2 only |slope| > 2: (0,3)? |-2.0| is not > 2; (1,3) = 1 texel
    assert enc.encode_pd_u8(n, 2.0)[2] == 1
    # clipped texels saturate: (0,2) has px = 1.5 -> 255, (0,3) px = -2 -> 1 (t = -1 under v2;
    # 0 is never written), the flat texel (0,0) sits on 128 exactly
    q, _, _ = enc.encode_pd_u8(n, 1.0)
    assert q[0, 2, 0] == 255 and q[0, 3, 0] == 1 and q[0, 0].tolist() == [128, 128]
    assert np.array_equal(enc.encode_pd(n, 1.0).texels, q)
    q1, _, _ = enc.encode_pd_u8(n, 1.0, version=1)
    assert q1[0, 3, 0] == 0 and q1[0, 0].tolist() == [128, 128]  # 127.5 rounds up


def test_auto_scale_is_power_of_two_above_p999():
    rng = np.random.default_rng(3)
    px = rng.uniform(-1.7, 1.7, size=(200, 200))
    n = _normals_from_slopes(px, np.zeros_like(px))
    # p99.9 of |px| is about 1.7 -> smallest power of two above: 2
    assert enc.auto_pd_scale(n) == 2.0
    assert enc.auto_pd_scale(_normals_from_slopes(px * 0.2, px * 0.1)) == 0.5
    flat = np.zeros((8, 8, 3), np.float32)
    flat[..., 2] = 1
    assert enc.auto_pd_scale(flat) == enc.MIN_PD_SCALE


def test_diff_roundtrip_and_gain():
    rng = np.random.default_rng(5)
    b = _normals_from_slopes(rng.normal(0, 0.1, (16, 16)), rng.normal(0, 0.1, (16, 16)))
    w = _normals_from_slopes(rng.normal(0, 0.1, (16, 16)), rng.normal(0, 0.1, (16, 16)))
    d = enc.encode_diff(w, b)
    np.testing.assert_array_equal(d.texels, np.rint(128 + 127 * (w - b)).astype(np.uint8))
    np.testing.assert_allclose(enc.decode_diff(d.texels), w - b, atol=0.5 / 127 + 1e-6)
    g = enc.encode_diff(w, b, gain="auto")
    assert g.gain >= 1 and math.log2(g.gain).is_integer()
    assert g.clipped <= 0.002 * 256 + 1
    np.testing.assert_allclose(enc.decode_diff(g.texels, g.gain), w - b, atol=2e-3)


def test_full_two_channel_rebuilds_z():
    n = _normals_from_slopes(np.array([[0.3, -0.8]]), np.array([[0.1, 0.4]]))
    v = enc.encode_full(n, 2)
    assert v.shape == (1, 2, 2) and v.dtype == np.uint8
    np.testing.assert_array_equal(v, np.rint(255 * (0.5 + 0.5 * n[..., :2])).astype(np.uint8))
    # z rebuilt from the 8-bit x, y: within the quantisation of x and y
    assert angle_deg64(enc.decode_full(v), n).max() < math.degrees(2 / 255)


def test_quantize_hand_values():
    q = enc.quantize(np.array([0.0, 0.5, 1.0, 1.2, -0.1, 0.002]), 8)
    assert q.tolist() == [0, 128, 255, 255, 0, 1]  # 0.5 * 255 = 127.5 -> 128
    assert enc.quantize(np.array([1.0]), 16).tolist() == [65535]


@settings(max_examples=40, deadline=None)
@given(st.floats(-0.99, 0.99), st.floats(-0.99, 0.99), st.sampled_from([0.5, 1.0, 2.0, 4.0]))
def test_pd_roundtrip_law(px, py, scale):
    """Any slope inside the cone decodes back within the quantisation bound."""
    px, py = px * scale, py * scale
    n = _normals_from_slopes(np.array([[px]]), np.array([[py]]))
    q, _, clipped = enc.encode_pd_u8(n, scale)
    assert clipped == 0
    back = enc.decode_pd(q, scale)
    assert angle_deg64(back, n).max() <= enc.quantization_bound_deg(scale, 8) + 2e-4
