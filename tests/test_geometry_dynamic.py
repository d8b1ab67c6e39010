"""Dynamic wrinkle weights (Oat): exact area ratios, signs on a squashed/stretched tube, zero jump
at UV seams for the vertex smoothing, a measured jump for the texture-space variant."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.asset import Mesh
from wrinklepipe.demo.character import generate
from wrinklepipe.errors import InputError
from wrinklepipe.geometry.dynamic import (
    DynamicOptions,
    DynamicWeights,
    morph_pose,
    sample_bilinear,
    seam_jump,
    skinned_pose,
    texture_space_weights,
    triangle_weights,
)
from wrinklepipe.geometry.primitives import tube
from wrinklepipe.geometry.vertex_ids import compute_vertex_ids

TRI = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
TRI_IDX = np.array([[0, 1, 2]])


@settings(max_examples=50, deadline=None)
@given(s=st.floats(0.05, 3.0), tx=st.floats(-5, 5), angle=st.floats(0, 6.3))
def test_uniformly_scaled_triangle_gives_exact_ratio(s, tx, angle):
    c, n = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -n, 0], [n, c, 0], [0, 0, 1.0]])
    deformed = (TRI * s) @ rot.T + tx
    expected = np.clip(1.0 - s * s, -1, 1)  # (A - s^2 A) / A
    assert triangle_weights(TRI, deformed, TRI_IDX)[0] == pytest.approx(expected, abs=1e-6)
    op = DynamicWeights.build(TRI, TRI_IDX, options=DynamicOptions(dtype="float64"))
    np.testing.assert_allclose(op.frame(deformed), expected, atol=1e-9)


def test_hand_computed_triangle_and_sign():
    squashed = TRI * np.array([0.5, 1.0, 1.0])  # area 0.25 from 0.5: compressed by half
    assert triangle_weights(TRI, squashed, TRI_IDX)[0] == pytest.approx(0.5)
    stretched = TRI * np.array([1.5, 1.0, 1.0])  # area 0.75: stretched
    assert triangle_weights(TRI, stretched, TRI_IDX)[0] == pytest.approx(-0.5)


def test_angle_weighted_average_by_hand():
    # Vertex 0 is shared by a right-angle triangle (90 deg at 0) and one with 45 deg at 0.
    p = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, -1, 0]], dtype=np.float64)
    idx = np.array([[0, 1, 2], [0, 2, 3]])
    deformed = p.copy()
    deformed[1, 0] = 0.5  # only the first triangle shrinks: area 0.5 -> 0.25, w = 0.5
    op = DynamicWeights.build(p, idx, options=DynamicOptions(dtype="float64"))
    w_t = op.triangle_frame(deformed)
    np.testing.assert_allclose(w_t, [0.5, 0.0], atol=1e-12)
    # Angles at vertex 0: 90 deg and 135 deg (between (0,1) and (-1,-1)).
    expected = (90 * 0.5 + 135 * 0.0) / (90 + 135)
    assert op.frame(deformed)[0] == pytest.approx(expected, abs=1e-12)
    uni = DynamicWeights.build(p, idx, options=DynamicOptions("uniform", dtype="float64"))
    assert uni.frame(deformed)[0] == pytest.approx(0.25, abs=1e-12)


@pytest.mark.parametrize(("scale", "expected"), [(0.8, 0.2), (1.25, -0.25)])
def test_tube_compressed_and_stretched(scale, expected):
    m = tube(24, 6)
    deformed = m.positions.astype(np.float64) * np.array([1.0, scale, 1.0])
    op = DynamicWeights.build(m.positions, m.indices)
    w = op.frame(deformed)
    np.testing.assert_allclose(w, expected, atol=2e-6)
    assert np.sign(w).min() == np.sign(w).max() == np.sign(expected)


def test_partially_squashed_tube_signs():
    m = tube(24, 8, length=2.0)
    p = m.positions.astype(np.float64)
    deformed = p.copy()
    top = p[:, 1] > 1.0
    deformed[top, 1] = 1.0 + (p[top, 1] - 1.0) * 0.5  # squash the top half along the axis
    w = DynamicWeights.build(p, m.indices).frame(deformed)
    assert w[p[:, 1] > 1.3].min() > 0.4
    assert np.abs(w[p[:, 1] < 0.7]).max() < 1e-6


def test_bias_is_added_and_clamped():
    m = tube(16, 4)
    op = DynamicWeights.build(m.positions, m.indices, bias=np.full(len(m.positions), 0.3))
    np.testing.assert_allclose(op.frame(m.positions), 0.3, atol=1e-6)
    squash = m.positions * np.array([1.0, 0.1, 1.0], dtype=np.float32)  # w = 0.9 + 0.3 -> 1
    np.testing.assert_allclose(op.frame(squash), 1.0)


@pytest.fixture(scope="module")
def head_case():
    mesh = generate(64).mesh
    p = mesh.positions.astype(np.float64)
    # A smooth, asymmetric deformation that reaches the seam at the back of the head (x ~ 0,
    # z < 0): depth squashed more on the character's right than on the left.
    deformed = p.copy()
    deformed[:, 2] *= 1.0 - 0.25 * (0.5 + p[:, 0] / 0.16)
    ids = compute_vertex_ids(p)
    return mesh, p, deformed, ids


def test_vertex_smoothing_has_zero_jump_at_seam_twins(head_case):
    mesh, p, deformed, ids = head_case
    op = DynamicWeights.build(p, mesh.indices, vertex_ids=ids)
    w = op.frame(deformed)
    jump = seam_jump(w, ids)
    assert len(jump) > 60  # the seam twins and the pole fans
    assert jump.max() == 0.0
    # Without the vertex IDs (render-vertex indices only) the seam does jump: IDs matter.
    solo = DynamicWeights.build(p, mesh.indices, vertex_ids=np.arange(len(p)))
    assert seam_jump(solo.frame(deformed), ids).max() > 1e-3


def test_texture_space_variant_jumps_at_the_seam(head_case):
    mesh, p, deformed, ids = head_case
    w_t = triangle_weights(p, deformed, mesh.indices)
    img, cov = texture_space_weights(mesh.uvs, mesh.indices, w_t, size=128, blur_px=3.0)
    assert cov.mean() > 0.9
    w_tex = sample_bilinear(img, mesh.uvs)
    jump = seam_jump(w_tex, ids)
    # Measured: the texture-space weights disagree between seam twins (Oat's seam problem).
    assert jump.max() > 0.01
    w_vert = DynamicWeights.build(p, mesh.indices, vertex_ids=ids).frame(deformed)
    assert seam_jump(w_vert, ids).max() == 0.0


def test_morph_and_skinned_poses():
    mesh = generate(64).mesh
    m = Mesh(
        positions=mesh.positions,
        indices=mesh.indices,
        morph_names=mesh.morph_names,
        morph_deltas=mesh.morph_deltas,
    )
    name = mesh.morph_names[0]
    posed = morph_pose(m, {name: 0.5})
    np.testing.assert_allclose(posed, mesh.positions + 0.5 * mesh.morph_deltas[0], atol=1e-7)
    with pytest.raises(InputError, match="unknown morph"):
        morph_pose(m, {"nope": 1.0})
    bad = Mesh(
        positions=mesh.positions,
        indices=mesh.indices,
        morph_names=("a",),
        morph_deltas=np.zeros((1, 5, 3), np.float32),
    )
    with pytest.raises(InputError, match="morph deltas must be"):
        morph_pose(bad, {"a": 1.0})

    # Two joints, vertex 0 fully on joint 0, vertex 1 half/half; joint 1 moves by +2 in x.
    sk = Mesh(
        positions=np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32),
        indices=TRI_IDX.astype(np.uint32),
        joints=np.array([[0, 0, 0, 0], [0, 1, 0, 0], [1, 0, 0, 0]]),
        skin_weights=np.array([[1, 0, 0, 0], [0.5, 0.5, 0, 0], [1, 0, 0, 0]], np.float32),
        joint_names=("a", "b"),
        inverse_bind=np.stack([np.eye(4), np.eye(4)]).astype(np.float32),
    )
    jm = np.stack([np.eye(4), np.eye(4)])
    jm[1, 0, 3] = 2.0
    np.testing.assert_allclose(skinned_pose(sk, jm), [[0, 0, 0], [2, 0, 0], [2, 1, 0]])
    with pytest.raises(InputError, match="joint matrices"):
        skinned_pose(sk, np.eye(4)[None])


def test_bad_inputs_are_clear():
    with pytest.raises(InputError, match="no faces"):
        DynamicWeights.build(TRI, np.zeros((0, 3), int))
    with pytest.raises(InputError, match="out of range"):
        DynamicWeights.build(TRI, np.array([[0, 1, 5]]))
    nan = TRI.copy()
    nan[1, 0] = np.nan
    with pytest.raises(InputError, match="NaN"):
        DynamicWeights.build(nan, TRI_IDX)
    op = DynamicWeights.build(TRI, TRI_IDX)
    with pytest.raises(InputError, match="deformed positions"):
        op.frame(np.zeros((2, 3)))
    # Zero-area triangles are skipped, counted and reported; they do not vote.
    p = np.vstack([TRI, [[2.0, 0, 0], [3.0, 0, 0], [4.0, 0, 0]]])
    idx = np.array([[0, 1, 2], [3, 4, 5]])
    op = DynamicWeights.build(p, idx)
    assert op.skipped_triangles == 1
    assert "skipped 1 zero-area" in op.notes[0]
    w = op.frame(p * 0.5)
    np.testing.assert_allclose(w[:3], 0.75, atol=1e-6)
    np.testing.assert_allclose(w[3:], 0.0)


def test_edge_operator_rows_are_hand_computed_edges():
    # Two triangles; E @ P must give p1 - p0 (rows 0..T-1) and p2 - p0 (rows T..2T-1).
    p = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 0], [1, 1, 4]], dtype=np.float64)
    idx = np.array([[0, 1, 2], [1, 3, 2]])
    op = DynamicWeights.build(p, idx, options=DynamicOptions(dtype="float64"))
    e = op.edges @ p
    np.testing.assert_array_equal(e, [[2, 0, 0], [-1, 1, 4], [0, 3, 0], [-2, 3, 0]])
    # The frame (index form of E) matches the area ratio from these edges, in float32 too.
    q = p * np.array([1.0, 0.5, 1.0])
    area0 = 0.5 * np.linalg.norm(np.cross(e[:2], e[2:]), axis=1)
    eq = op.edges @ q
    area1 = 0.5 * np.linalg.norm(np.cross(eq[:2], eq[2:]), axis=1)
    expected = np.clip((area0 - area1) / area0, -1, 1)
    np.testing.assert_allclose(op.triangle_frame(q), expected, atol=1e-12)
    op32 = DynamicWeights.build(p, idx)
    np.testing.assert_allclose(op32.triangle_frame(q), expected, atol=1e-6)
