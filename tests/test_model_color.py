"""The colour model and the sRGB transfer functions, against hand-computed texels, the
IEC 61966-2-1 values and colour-science (an independent implementation)."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from wrinklepipe import model
from wrinklepipe.codec import srgb

os.environ.setdefault("COLOUR_SCIENCE__FILTER_USAGE_WARNINGS", "True")
colour = pytest.importorskip("colour")

_SRGB = colour.RGB_COLOURSPACES["sRGB"]


def _delta_e(lin_a, lin_b):
    """CIEDE2000 between linear sRGB colours, by colour-science (D65 white)."""

    def lab(x):
        xyz = colour.RGB_to_XYZ(np.asarray(x, np.float64), _SRGB, apply_cctf_decoding=False)
        return colour.XYZ_to_Lab(xyz, _SRGB.whitepoint)

    return colour.delta_E(lab(lin_a), lab(lin_b), method="CIE 2000")


# ---------------------------------------------------------------------------------------------
# sRGB transfer


def test_published_values_of_the_transfer_functions():
    # IEC 61966-2-1: the two segments meet at (0.04045, 0.0031308); mid grey 0.5 -> 0.2140411
    assert srgb.srgb_to_linear(np.float64(0.04045)) == pytest.approx(0.04045 / 12.92, abs=1e-9)
    assert srgb.srgb_to_linear(np.float64(0.5)) == pytest.approx(0.21404114, abs=1e-7)
    assert srgb.srgb_to_linear(np.float64(1.0)) == pytest.approx(1.0, abs=1e-7)
    assert srgb.linear_to_srgb(np.float64(0.0031308)) == pytest.approx(0.0404500, abs=1e-6)
    assert srgb.linear_to_srgb(np.float64(0.21404114)) == pytest.approx(0.5, abs=1e-7)


def test_transfer_functions_agree_with_colour_science():
    v = np.linspace(0.0, 1.0, 10001)
    np.testing.assert_allclose(srgb.srgb_to_linear(v), colour.models.eotf_sRGB(v), atol=2e-7)
    np.testing.assert_allclose(
        srgb.linear_to_srgb(v), colour.models.eotf_inverse_sRGB(v), atol=2e-7
    )


@pytest.mark.parametrize("bits", [8, 16])
def test_every_code_decodes_and_encodes_back_exactly(bits):
    dtype = np.uint8 if bits == 8 else np.uint16
    codes = np.arange(1 << bits, dtype=dtype)
    lin = srgb.decode_texels(codes)
    assert lin.dtype == np.float32
    assert np.all(np.diff(lin) > 0)  # strictly increasing: every code its own linear value
    np.testing.assert_array_equal(srgb.encode_texels(lin, bits), codes)


def test_decoded_table_matches_colour_science_per_code():
    codes = np.arange(256, dtype=np.uint8)
    expect = colour.models.eotf_sRGB(codes / 255.0)
    np.testing.assert_allclose(srgb.decode_texels(codes), expect, atol=6e-8)


def test_texels_of_other_types_are_refused():
    with pytest.raises(ValueError, match="uint8 or uint16"):
        srgb.decode_texels(np.zeros(3, np.float32))
    with pytest.raises(ValueError, match="8 or 16"):
        srgb.encode_texels(np.zeros(3, np.float32), 10)


# ---------------------------------------------------------------------------------------------
# the colour model

# a skin texel (sRGB 200, 150, 130) and the deep flush of a compressed pose (150, 40, 40), in
# linear light by IEC 61966-2-1 (checked against colour-science above)
SKIN = np.array([0.57758044, 0.30498731, 0.22322796], np.float32)
FLUSH = np.array([0.30498731, 0.02121901, 0.02121901], np.float32)
PALE = np.array([0.79129794, 0.57758044, 0.48514994], np.float32)  # sRGB 230, 200, 185


def test_texels_decode_to_the_hand_computed_linear_values():
    got = srgb.decode_texels(np.array([[200, 150, 130], [150, 40, 40], [230, 200, 185]], np.uint8))
    np.testing.assert_allclose(got, np.stack([SKIN, FLUSH, PALE]), atol=1e-7)


def test_half_flush_is_the_linear_midpoint():
    got = model.combine_color(SKIN, FLUSH[None], np.array([0.5], np.float32))
    # by hand: 0.57758044 + 0.5 (0.30498731 - 0.57758044) = 0.44128388, and so on
    np.testing.assert_allclose(got, [0.44128388, 0.16310316, 0.12222348], atol=1e-7)


def test_blending_in_srgb_instead_of_linear_light_fails_by_a_measured_delta_e():
    """The same half-flush blended on the sRGB-encoded values (the common mistake) lands
    5.7 CIEDE2000 units away: more than two just-noticeable differences. The model's result
    is within 1e-3 of the linear-light blend."""
    a = np.array([0.5], np.float32)
    got = model.combine_color(SKIN, FLUSH[None], a)
    linear = SKIN.astype(np.float64) + 0.5 * (FLUSH.astype(np.float64) - SKIN)
    skin_s = srgb.linear_to_srgb(SKIN).astype(np.float64)
    flush_s = srgb.linear_to_srgb(FLUSH).astype(np.float64)
    in_srgb = colour.models.eotf_sRGB(skin_s + 0.5 * (flush_s - skin_s))
    assert float(_delta_e(got, linear)) < 1e-3
    wrong = float(_delta_e(linear, in_srgb))
    assert wrong == pytest.approx(5.68, abs=0.01)
    assert float(_delta_e(got, in_srgb)) > 5.0


def test_two_states_add_their_deltas_and_clip():
    # stretch (pale) at 1 and compress (flush) at 1 on the same texel: C_B + dP + dF, clipped
    act = np.array([1.0, 1.0], np.float32)
    got = model.combine_color(SKIN, np.stack([PALE, FLUSH]), act)
    expect = np.clip(SKIN + (PALE - SKIN) + (FLUSH - SKIN), 0.0, 1.0)
    np.testing.assert_allclose(got, expect, atol=1e-7)
    assert got[2] == pytest.approx(0.48514994 + 0.02121901 - 0.22322796, abs=1e-7)
    # additive weights beyond 1 push past white: clipped to 1
    big = model.combine_color(SKIN, PALE[None], np.array([4.0], np.float32))
    np.testing.assert_array_equal(big, [1.0, 1.0, 1.0])
    # and below black: clipped to 0
    neg = model.combine_color(SKIN, PALE[None], np.array([-4.0], np.float32))
    np.testing.assert_array_equal(neg, [0.0, 0.0, 0.0])


def test_blend_color_uses_the_normals_activations_and_only_the_colour_states():
    # 2 regions over a 1 x 3 strip; 3 states, of which states 0 and 2 carry colour
    masks = np.array([[[1.0, 0.5, 0.0]], [[0.0, 0.5, 1.0]]], np.float32)
    weights = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.8]], np.float32)
    base = np.broadcast_to(SKIN, (1, 3, 3)).copy()
    states = np.stack([np.broadcast_to(PALE, (1, 3, 3)), np.broadcast_to(FLUSH, (1, 3, 3))])
    got = model.blend_color(base, states, masks, weights, "clamp01", color_states=(0, 2))
    # texel 0: pale at 1; texel 1: pale at 0.5 and flush at 0.4; texel 2: flush at 0.8
    np.testing.assert_allclose(got[0, 0], PALE, atol=1e-7)
    np.testing.assert_allclose(
        got[0, 1], SKIN + 0.5 * (PALE - SKIN) + 0.4 * (FLUSH - SKIN), atol=1e-7
    )
    np.testing.assert_allclose(got[0, 2], SKIN + 0.8 * (FLUSH - SKIN), atol=1e-7)


def test_blend_color_under_the_signed_policy():
    masks = np.ones((1, 1, 2), np.float32)
    base = np.broadcast_to(SKIN, (1, 2, 3)).copy()
    states = np.stack([np.broadcast_to(PALE, (1, 2, 3)), np.broadcast_to(FLUSH, (1, 2, 3))])
    got = model.blend_color(base, states, masks, np.array([-0.25], np.float32), "signed")
    np.testing.assert_allclose(got[0, 0], SKIN + 0.25 * (PALE - SKIN), atol=1e-7)
    got = model.blend_color(base, states, masks, np.array([0.75], np.float32), "signed")
    np.testing.assert_allclose(got[0, 1], SKIN + 0.75 * (FLUSH - SKIN), atol=1e-7)


def test_shape_mismatches_are_refused():
    with pytest.raises(ValueError, match="activations"):
        model.combine_color(SKIN, FLUSH[None], np.zeros(2, np.float32))
    with pytest.raises(ValueError, match="differ"):
        model.combine_color(SKIN, np.zeros((1, 2, 3), np.float32), np.zeros((1, 2), np.float32))


@settings(max_examples=40, deadline=None)
@given(
    hnp.arrays(np.uint8, (5, 7, 3)),
    hnp.arrays(np.uint8, (2, 5, 7, 3)),
    st.floats(-2.0, 2.0, width=32),
)
def test_where_no_state_is_active_the_base_comes_back_byte_for_byte(base_q, states_q, w):
    base = srgb.decode_texels(base_q)
    states = srgb.decode_texels(states_q)
    act = np.zeros((2, 5, 7), np.float32)
    act[0, 1:3, 2:4] = w  # some texels active (w may be 0), the rest idle
    got = model.combine_color(base, states, act)
    idle = np.ones((5, 7), bool)
    idle[1:3, 2:4] = w == 0
    assert np.array_equal(got[idle].view(np.uint32), base[idle].view(np.uint32))
    np.testing.assert_array_equal(srgb.encode_texels(got)[idle], base_q[idle])


@settings(max_examples=40, deadline=None)
@given(hnp.arrays(np.uint8, (4, 3)), hnp.arrays(np.uint8, (4, 3)), st.floats(0.0, 1.0, width=32))
def test_one_state_is_a_lerp_in_linear_light(bq, sq, a):
    """A law: under one state at activation a in [0, 1], C = (1 - a) C_B + a C_k, inside the
    segment between the two colours (so never clipped)."""
    b, s = srgb.decode_texels(bq), srgb.decode_texels(sq)
    got = model.combine_color(b, s[None], np.full((1, 4), a, np.float32))
    expect = (1.0 - np.float64(a)) * b + np.float64(a) * s
    np.testing.assert_allclose(got, expect, atol=2e-7)
