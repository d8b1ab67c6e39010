"""Bones driver (Dutreve et al.): alpha, beta and theta on a hand-computed 3-bone toy rig."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from wrinklepipe import drivers as wd
from wrinklepipe.drivers.bones import dense_skin, pose_influence, theta, vertex_influence

# Three bones in a row (head-root space); two reference poses.
NEUTRAL = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
COMPRESS = np.array([[0, 1, 0], [1, 0, 2], [2, 0, 0]], float)  # bone 2 does not move
STRETCH = np.array([[0, 0, 0], [1, 0, 0], [2, -1, 0]], float)  # only bone 2 moves
FRAMES = np.array(
    [
        [[0, 0.5, 0.5], [1, 3, 3], [2, 0, 0]],
        [[0, -1, 0], [1, 0, 0.5], [2, -0.75, 0.3]],
    ],
    float,
)
# Skin weights [V, J]
SKIN = np.array([[1, 0, 0], [0.5, 0.5, 0], [0, 0, 1], [0, 0.3, 0.7]], float)

S = math.sqrt(2) / 2
THETA_025 = (1 - S) / 2  # (cos(1.25 pi) + 1) / 2
THETA_075 = (1 + S) / 2  # (cos(1.75 pi) + 1) / 2


def test_theta_endpoints_midpoint_and_monotone():
    assert theta(0.0) == pytest.approx(0.0, abs=1e-15)
    assert theta(1.0) == pytest.approx(1.0)
    assert theta(0.5) == pytest.approx(0.5)
    assert theta(0.25) == pytest.approx(THETA_025)
    x = np.linspace(0, 1, 1001)
    assert np.all(np.diff(theta(x)) > 0)


@given(st.floats(0, 1), st.floats(0, 1))
def test_theta_is_monotone_and_symmetric(a, b):
    lo, hi = min(a, b), max(a, b)
    assert theta(lo) <= theta(hi) + 1e-15
    assert theta(a) + theta(1 - a) == pytest.approx(1.0)


def test_alpha_hand_computed():
    alpha = pose_influence(NEUTRAL, np.stack([COMPRESS, STRETCH]), FRAMES)
    assert alpha.shape == (2, 2, 3)  # [F, P, J]
    # frame 0, compress: bone0 AB.AC = 0.5 / |AC|^2 = 1 -> 0.5; bone1 (0,3,3).(0,0,2) = 6 / 4
    # -> 1.5 clamped to 1; bone2 does not move in the pose -> 0
    np.testing.assert_allclose(alpha[0, 0], [0.5, 1.0, 0.0])
    # frame 1, compress: bone0 -1 -> clamped 0; bone1 (0,0,0.5).(0,0,2) / 4 = 0.25
    np.testing.assert_allclose(alpha[1, 0], [0.0, 0.25, 0.0])
    # stretch: only bone 2; frame 1 (0,-0.75,0.3).(0,-1,0) / 1 = 0.75
    np.testing.assert_allclose(alpha[:, 1], [[0, 0, 0], [0, 0, 0.75]])


def test_beta_hand_computed():
    alpha = pose_influence(NEUTRAL, np.stack([COMPRESS, STRETCH]), FRAMES)
    beta = vertex_influence(alpha, SKIN)  # [F, V, P], clamped
    expected = np.zeros((2, 4, 2))
    # frame 0, compress: theta(alpha) = [0.5, 1, 0]
    expected[0, :, 0] = [0.5, 1.0, 0.0, 1.0]  # v1 = 0.5 + 1 = 1.5 -> clamped to 1
    # frame 1, compress: theta = [0, THETA_025, 0]; stretch: theta = [0, 0, THETA_075]
    expected[1, :, 0] = [0.0, THETA_025, 0.0, THETA_025]
    expected[1, :, 1] = [0.0, 0.0, THETA_075, THETA_075]
    np.testing.assert_allclose(beta, expected, atol=1e-12)
    raw = vertex_influence(alpha, SKIN, combine="sum")
    assert raw[0, 1, 0] == pytest.approx(1.5)  # eq. 5 literally: lambda = 1 for both bones


def test_lambda_ignores_weight_size():
    alpha = np.array([[[0.5, 0.5]]])
    a = vertex_influence(alpha, np.array([[0.01, 0.0]]))
    b = vertex_influence(alpha, np.array([[1.0, 0.0]]))
    assert a[0, 0, 0] == b[0, 0, 0] == pytest.approx(0.5)


def test_dense_skin_from_gltf_joints():
    d = dense_skin(np.array([[0, 2, 0, 0]]), np.array([[0.25, 0.75, 0, 0]]), 3)
    np.testing.assert_allclose(d, [[0.25, 0, 0.75]])


def test_bones_driver_from_file(tmp_path):
    names = ["b0", "b1", "b2"]
    doc = {
        "times": [0.0, 0.5],
        "bones": {n: FRAMES[:, j].tolist() for j, n in enumerate(names)},
        "skin": {"joints": names, "weights": SKIN.tolist()},
    }
    (tmp_path / "bones.json").write_text(json.dumps(doc))
    spec = {
        "file": "bones.json",
        "poses": [
            {"name": "neutral", "bones": {n: NEUTRAL[j].tolist() for j, n in enumerate(names)}},
            {"name": "compress", "bones": {n: COMPRESS[j].tolist() for j, n in enumerate(names)}},
            {"name": "stretch", "bones": {n: STRETCH[j].tolist() for j, n in enumerate(names)}},
        ],
    }
    ctx = wd.DriverContext(["face"], ("compress", "stretch"), root=tmp_path)
    res = wd.evaluate("bones", ctx, spec)
    assert res.per_vertex and res.states == ("compress", "stretch")
    assert res.weights.shape == (2, 4, 2)
    assert res.weights[1, 3, 1] == pytest.approx(THETA_075, abs=1e-6)
    assert res.weights[0, 1, 0] == pytest.approx(1.0)
    # resampled at t = 0.25: positions interpolate linearly between the two frames
    mid = wd.evaluate("bones", ctx, spec, times=[0.25])
    alpha = pose_influence(NEUTRAL, COMPRESS[None], FRAMES.mean(axis=0)[None])
    assert mid.weights[0, 0, 0] == pytest.approx(theta(alpha[0, 0, 0]), abs=1e-6)


def test_bones_driver_takes_skin_from_the_mesh(tmp_path):
    from wrinklepipe.asset import Mesh

    names = ["b0", "b1", "b2"]
    doc = {"times": [0.0], "bones": {n: FRAMES[:1, j].tolist() for j, n in enumerate(names)}}
    (tmp_path / "bones.json").write_text(json.dumps(doc))
    # glTF-style JOINTS_0 / WEIGHTS_0 (joint order differs from the sorted bone names)
    mesh = Mesh(
        np.zeros((2, 3), np.float32),
        np.zeros((0, 3), np.uint32),
        joints=np.array([[0, 1, 0, 0], [2, 0, 0, 0]]),
        skin_weights=np.array([[0.5, 0.5, 0, 0], [1, 0, 0, 0]], np.float32),
        joint_names=("b1", "b0", "b2"),
    )
    spec = {
        "file": "bones.json",
        "poses": [
            {"name": "neutral", "bones": {n: NEUTRAL[j].tolist() for j, n in enumerate(names)}},
            {"name": "compress", "bones": {n: COMPRESS[j].tolist() for j, n in enumerate(names)}},
        ],
    }
    ctx = wd.DriverContext(["face"], ("compress",), root=tmp_path, mesh=mesh)
    res = wd.evaluate("bones", ctx, spec)
    # vertex 0: b1 (theta 1) + b0 (theta 0.5) -> 1.5 clamped to 1; vertex 1: b2 only -> 0
    np.testing.assert_allclose(res.weights[0, :, 0], [1.0, 0.0])


# --- bones from a skinned glTF's own animation (Khronos RiggedSimple) --------------------------

_RIGGED = (
    Path(__file__).resolve().parents[2]
    / "shared"
    / "data"
    / "gltf-samples"
    / "RiggedSimple"
    / "glTF-Binary"
    / "RiggedSimple.glb"
)


@pytest.mark.skipif(not _RIGGED.is_file(), reason="../shared/data is absent")
def test_bones_from_gltf_animation_reach_the_reference_frame():
    from wrinklepipe.drivers import DriverContext, evaluate
    from wrinklepipe.gltf.meshes import gltf_animation_times
    from wrinklepipe.readers.meshes import load_mesh
    from wrinklepipe.readers.rig import GltfRig

    keys = gltf_animation_times(_RIGGED)
    t_ref = float(keys[len(keys) // 2])
    mesh = load_mesh(_RIGGED)
    ctx = DriverContext(("r",), ("bent",), mesh=mesh, root=_RIGGED.parent, fps=24, read_rig=GltfRig)
    spec = {
        "kind": "bones",
        "file": _RIGGED.name,
        "root": "Bone",
        "reference_times": {"bent": t_ref},
    }
    res = evaluate("bones", ctx, spec, np.array([float(keys[0]), t_ref]))
    beta = np.asarray(res.weights)  # [frames, vertices, poses]
    assert beta.shape == (2, mesh.vertex_count, 1)
    # At the reference frame every moving bone sits at C: alpha = theta = 1 on its vertices.
    skinned_by_moving = dense_skin(mesh.joints, mesh.skin_weights, 2)[:, 1] > 0  # Bone.001
    assert np.allclose(beta[1, skinned_by_moving, 0], 1.0)
    # In the root joint's own space the root never moves: its vertices alone stay at 0.
    only_root = ~skinned_by_moving
    assert np.allclose(beta[:, only_root, 0], 0.0)
    assert 0.0 <= beta.min() and beta.max() <= 1.0
