"""The wrinkle model against analytic normals, hand-computed texels and published tables."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from wrinklepipe import model
from wrinklepipe.metrics import angle_deg

# ---------------------------------------------------------------------------------------------
# pd: exactly the normal of base height + sum of weight x wrinkle height


def _analytic_field(n: int = 64):
    """Three height fields with closed-form gradients on an n x n grid (x right, y up)."""
    c = np.arange(n, dtype=np.float64)
    x, row = np.meshgrid(c, c, indexing="xy")
    y = (n - 1) - row  # +Y points up while rows run down
    fields = [
        (0.3 * np.sin(0.21 * x) * np.cos(0.17 * y), None),
        (1.5 * np.sin(0.35 * y + 0.2), None),  # horizontal lines
        (0.8 * np.cos(0.4 * x) * np.exp(-(((y - 30) / 20) ** 2)), None),
    ]
    grads = [
        (
            0.3 * 0.21 * np.cos(0.21 * x) * np.cos(0.17 * y),
            -0.3 * 0.17 * np.sin(0.21 * x) * np.sin(0.17 * y),
        ),
        (np.zeros_like(x), 1.5 * 0.35 * np.cos(0.35 * y + 0.2)),
        (
            -0.8 * 0.4 * np.sin(0.4 * x) * np.exp(-(((y - 30) / 20) ** 2)),
            0.8 * np.cos(0.4 * x) * np.exp(-(((y - 30) / 20) ** 2)) * (-2 * (y - 30) / 400),
        ),
    ]
    return [f for f, _ in fields], grads


def _analytic_normal(gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    n = np.stack([-gx, -gy, np.ones_like(gx)], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


@pytest.mark.parametrize("weights", [(0.0, 0.0), (1.0, 0.0), (0.5, 0.7), (1.0, 1.0), (-0.4, 0.9)])
def test_pd_equals_analytic_normal_of_summed_heights(weights):
    _, grads = _analytic_field()
    (bx, by), (w1x, w1y), (w2x, w2y) = grads
    base = _analytic_normal(bx, by).astype(np.float32)
    states = np.stack(
        [
            model.normal_to_pd(_analytic_normal(w1x, w1y).astype(np.float32)),
            model.normal_to_pd(_analytic_normal(w2x, w2y).astype(np.float32)),
        ]
    )
    masks = np.ones((1,) + bx.shape, np.float32)
    w = np.array([weights], np.float32)
    got = model.blend(base, states, masks, w, encoding="pd", policy="additive")
    a1, a2 = weights
    truth = _analytic_normal(bx + a1 * w1x + a2 * w2x, by + a1 * w1y + a2 * w2y)
    assert got.dtype == np.float32
    assert np.max(np.abs(got - truth)) < 1e-5


def test_pd_with_a_region_mask_matches_heights_inside_the_region():
    _, grads = _analytic_field()
    (bx, by), (w1x, w1y), _ = grads
    base = _analytic_normal(bx, by).astype(np.float32)
    states = model.normal_to_pd(_analytic_normal(w1x, w1y).astype(np.float32))[None]
    masks = np.zeros((2,) + bx.shape, np.float32)
    masks[0, :, :32] = 1.0  # left half: region 0
    masks[1, :, 32:] = 1.0  # right half: region 1
    w = np.array([[0.8], [0.0]], np.float32)
    got = model.blend(base, states, masks, w, encoding="pd", policy="clamp01")
    truth_left = _analytic_normal(bx + 0.8 * w1x, by + 0.8 * w1y)
    assert np.max(np.abs(got[:, :32] - truth_left[:, :32])) < 1e-5
    assert np.array_equal(got[:, 32:], base[:, 32:])  # inactive: the base, bit for bit


def test_height_to_normal_is_exact_on_a_quadratic():
    n = 16
    c = np.arange(n, dtype=np.float64)
    x, row = np.meshgrid(c, c, indexing="xy")
    h = 0.01 * x**2 + 0.02 * row  # central differences are exact for quadratics
    got = model.height_to_normal(h)[1:-1, 1:-1]
    # dh/dx = 0.02 x; dh/dy (y up) = -dh/drow = -0.02
    truth = _analytic_normal(0.02 * x, -0.02 * np.ones_like(x))[1:-1, 1:-1]
    assert np.max(np.abs(got - truth)) < 1e-6


def test_pd_cone_is_45_degrees_at_slope_one():
    n = model.pd_to_normal(np.array([1.0, 0.0], np.float32))
    assert math.degrees(math.acos(n[2])) == pytest.approx(45.0, abs=1e-4)


# ---------------------------------------------------------------------------------------------
# diff, full, composite: hand-computed texels


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


B = _unit([0.2, -0.1, 1.0])
W = _unit([-0.3, 0.4, 1.0])


def test_diff_texel_by_hand():
    d = model.normal_to_diff(W.astype(np.float32), B.astype(np.float32))
    # 0.5 + 0.5 (w - b), component by component
    assert d == pytest.approx([0.5 + 0.5 * (W[i] - B[i]) for i in range(3)], abs=1e-7)
    a = 0.6
    got = model.combine(B.astype(np.float32), d[None], np.array([a], np.float32), "diff")
    expected = _unit([B[i] + a * (W[i] - B[i]) for i in range(3)])
    assert got == pytest.approx(expected, abs=1e-6)


def test_full_texel_by_hand_two_states():
    w2 = _unit([0.5, 0.0, 1.0])
    a1, a2 = 0.25, 0.5
    states = np.stack([W, w2]).astype(np.float32)
    got = model.combine(B.astype(np.float32), states, np.array([a1, a2], np.float32), "full")
    expected = _unit([B[i] + a1 * (W[i] - B[i]) + a2 * (w2[i] - B[i]) for i in range(3)])
    assert got == pytest.approx(expected, abs=1e-6)


def test_composite_texel_by_hand():
    # Oat: add x and y, multiply z (then renormalise).
    got = model.composite_detail(B.astype(np.float32), W.astype(np.float32))
    expected = _unit([B[0] + W[0], B[1] + W[1], B[2] * W[2]])
    assert got == pytest.approx(expected, abs=1e-6)
    # Through the model at full activation: the same; at half: z is scaled by 1 + 0.5 (Wz - 1).
    full = model.combine(
        B.astype(np.float32), W[None].astype(np.float32), np.ones(1, np.float32), "composite"
    )
    assert full == pytest.approx(expected, abs=1e-6)
    half = model.combine(
        B.astype(np.float32), W[None].astype(np.float32), np.full(1, 0.5, np.float32), "composite"
    )
    assert half == pytest.approx(
        _unit([B[0] + 0.5 * W[0], B[1] + 0.5 * W[1], B[2] * (1 + 0.5 * (W[2] - 1))]), abs=1e-6
    )


def test_composite_keeps_base_detail_stronger_than_averaging():
    # A pore on a flat wrinkle: the composite keeps the pore's tilt, averaging halves it.
    pore = _unit([0.5, 0.0, 1.0]).astype(np.float32)
    flat = np.array([0.0, 0.0, 1.0], np.float32)
    comp = model.composite_detail(pore, flat)
    avg = model.normalize(pore + flat)
    assert comp == pytest.approx(pore, abs=1e-6)
    assert avg[2] > comp[2]


# ---------------------------------------------------------------------------------------------
# policies: hand-computed sums

# Three regions over four texels; two states.
MASKS = np.array(
    [
        [1.0, 0.5, 0.0, 1.0],
        [0.0, 0.5, 1.0, 1.0],
        [0.0, 0.0, 0.5, 1.0],
    ],
    np.float32,
)
WEIGHTS = np.array([[0.8, 0.0], [0.6, 0.5], [-0.4, 1.0]], np.float32)


def test_policy_additive_and_clamp01_by_hand():
    # s_k(t) = sum_r M_r(t) w_rk
    s0 = [0.8, 0.5 * 0.8 + 0.5 * 0.6, 0.6 - 0.5 * 0.4, 0.8 + 0.6 - 0.4]
    s1 = [0.0, 0.25, 0.5 + 0.5, 0.0 + 0.5 + 1.0]
    add = model.activations(MASKS, WEIGHTS, "additive")
    assert add[0] == pytest.approx(s0, abs=1e-6)
    assert add[1] == pytest.approx(s1, abs=1e-6)
    clamp = model.activations(MASKS, WEIGHTS, "clamp01")
    assert clamp[0] == pytest.approx([min(max(v, 0), 1) for v in s0], abs=1e-6)
    assert clamp[1] == pytest.approx([min(max(v, 0), 1) for v in s1], abs=1e-6)


def test_policy_signed_by_hand():
    w = np.array([-0.5, 0.75, 0.5], np.float32)
    s = [-0.5, 0.5 * -0.5 + 0.5 * 0.75, 0.75 + 0.25, -0.5 + 0.75 + 0.5]
    a = model.activations(MASKS, w, "signed")
    assert a[0] == pytest.approx([max(-v, 0) for v in s], abs=1e-6)  # stretch: negative part
    assert a[1] == pytest.approx([min(max(v, 0), 1) for v in s], abs=1e-6)  # compress


def test_policy_renormalize_by_hand():
    # Texel 3: masks sum to 3, so each counts 1/3; texel 2: masks sum 1.5 -> 2/3 and 1/3.
    a = model.activations(MASKS, WEIGHTS, "renormalize")
    assert a[0, 3] == pytest.approx((0.8 + 0.6 - 0.4) / 3, abs=1e-6)
    assert a[1, 2] == pytest.approx((1.0 * 0.5 + 0.5 * 1.0) / 1.5, abs=1e-6)
    assert a[0, 0] == pytest.approx(0.8, abs=1e-6)


def test_policy_lerp_is_convex_by_hand():
    a = model.activations(MASKS, WEIGHTS, "lerp")
    # texel 3: clamp -> (1.0, 1.0), sum 2 -> (0.5, 0.5); texel 1: (0.7, 0.25) unchanged.
    assert a[:, 3] == pytest.approx([0.5, 0.5], abs=1e-6)
    assert a[:, 1] == pytest.approx([0.7, 0.25], abs=1e-6)
    assert np.all(a.sum(axis=0) <= 1.0 + 1e-6)


def test_unknown_policy_and_encoding_are_refused():
    with pytest.raises(ValueError, match="unknown policy"):
        model.activations(MASKS, WEIGHTS, "max")
    with pytest.raises(ValueError, match="unknown encoding"):
        model.combine(np.zeros((4, 3)), np.zeros((2, 4, 3)), np.ones((2, 4)), "hsv")


def test_sixteen_states_and_256_regions():
    rng = np.random.default_rng(1)
    masks = rng.random((256, 8, 8), dtype=np.float32) / 256
    weights = rng.random((256, 16), dtype=np.float32)
    base = model.normalize(
        rng.normal(size=(8, 8, 3)).astype(np.float32) * [0.2, 0.2, 1] + [0, 0, 2]
    )
    states = rng.normal(size=(16, 8, 8, 2)).astype(np.float32) * 0.1
    out = model.blend(base, states, masks, weights, "pd", "additive")
    # Independent: explicit sums in float64
    s = np.einsum("rhw,rk->khw", masks.astype(np.float64), weights.astype(np.float64))
    d = model.normal_to_pd(base).astype(np.float64) + np.einsum("khw,khwc->hwc", s, states)
    truth = _analytic_normal(-d[..., 0], -d[..., 1])
    assert np.max(np.abs(out - truth)) < 1e-5


# ---------------------------------------------------------------------------------------------
# Jimenez et al.: negative weights cancel (Fig. 1.5) on the demo character


def test_surprise_plus_anger_leaves_inner_forehead_smooth():
    from wrinklepipe.demo import demo_asset

    asset = demo_asset(128)
    states_pd = np.stack(
        [model.normal_to_pd(s) - model.normal_to_pd(asset.base) for s in asset.states]
    )
    names = asset.region_names
    inner = (
        asset.masks[names.index("forehead_inner_l")] + asset.masks[names.index("forehead_inner_r")]
    )
    surprise = model.blend(
        asset.base, states_pd, asset.masks, asset.expression_weights({"surprise": 1.0}), "pd"
    )
    both = model.blend(
        asset.base,
        states_pd,
        asset.masks,
        asset.expression_weights({"surprise": 1.0, "anger": 1.0}),
        "pd",
    )
    core = inner > 0.99
    assert core.sum() > 20
    # surprise alone wrinkles the inner forehead; with anger it is the base exactly.
    assert angle_deg(surprise[core], asset.base[core]).max() > 5.0
    assert np.array_equal(both[core], asset.base[core])


# ---------------------------------------------------------------------------------------------
# properties

unit_xy = st.floats(-0.5, 0.5, allow_nan=False, width=32)


@st.composite
def scenes(draw):
    k = draw(st.integers(1, 4))
    r = draw(st.integers(1, 6))
    n = draw(st.integers(1, 5))
    xy = draw(hnp.arrays(np.float32, (n, n, 2), elements=unit_xy))
    base = model.pd_to_normal(xy)
    full_states = model.pd_to_normal(draw(hnp.arrays(np.float32, (k, n, n, 2), elements=unit_xy)))
    masks = draw(hnp.arrays(np.float32, (r, n, n), elements=st.floats(0, 1, width=32)))
    weights = draw(hnp.arrays(np.float32, (r, k), elements=st.floats(-1, 1, width=32)))
    return base, full_states, masks, weights


def _encode(base, full_states, encoding):
    if encoding == "pd":
        return model.normal_to_pd(full_states) - model.normal_to_pd(base)[None]
    if encoding == "diff":
        return model.normal_to_diff(full_states, base[None])
    return full_states


@pytest.mark.parametrize("encoding", model.ENCODINGS)
@pytest.mark.parametrize("policy", ["clamp01", "additive", "renormalize", "lerp"])
@settings(max_examples=25, deadline=None)
@given(scene=scenes())
def test_zero_weights_give_the_base_exactly(encoding, policy, scene):
    base, full_states, masks, weights = scene
    out = model.blend(
        base, _encode(base, full_states, encoding), masks, 0 * weights, encoding, policy
    )
    assert np.array_equal(out, base)


@pytest.mark.parametrize("encoding", model.ENCODINGS)
@pytest.mark.parametrize("policy", model.POLICIES)
@settings(max_examples=25, deadline=None)
@given(scene=scenes())
def test_results_are_unit_length(encoding, policy, scene):
    base, full_states, masks, weights = scene
    if policy == "signed":
        full_states = np.concatenate([full_states, full_states])[:2]
        weights = weights[:, 0]
    out = model.blend(base, _encode(base, full_states, encoding), masks, weights, encoding, policy)
    assert np.allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-5)


@settings(max_examples=50, deadline=None)
@given(scene=scenes(), k_pick=st.integers(0, 3))
def test_one_full_region_reproduces_its_state(scene, k_pick):
    base, full_states, _, _ = scene
    k = k_pick % full_states.shape[0]
    masks = np.ones((1,) + base.shape[:-1], np.float32)
    weights = np.zeros((1, full_states.shape[0]), np.float32)
    weights[0, k] = 1.0
    out = model.blend(base, full_states, masks, weights, "full", "clamp01")
    assert np.allclose(out, full_states[k], atol=2e-6)
