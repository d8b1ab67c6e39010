"""``dynamic --time`` on a skinned glTF: the rest shape is the skinned rest pose, in the space
of the posed shape (world), not the bind-space positions as stored (which KHR_mesh_quantization
puts in another space altogether)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree
from test_mesh_io_gltf import SAMPLES, _node_tool, needs_data, needs_node_tools, write_gltf

from wrinklepipe.cli import main
from wrinklepipe.geometry.dynamic import skinned_pose, triangle_areas
from wrinklepipe.gltf.meshes import gltf_joint_world_matrices_at
from wrinklepipe.readers.meshes import LoadOptions, load_mesh

CESIUM_MAN = SAMPLES / "CesiumMan" / "glTF-Binary" / "CesiumMan.glb"


def _dynamic(path: Path, time: float, out: Path) -> np.ndarray:
    assert main(["dynamic", str(path), "--time", str(time), "-o", str(out)]) == 0
    return np.load(out)


def _translate(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = [x, y, z]
    return m


# World-space rest triangles (disconnected, so each vertex's weight is its triangle's):
# A in the xy plane, B in the yz plane, C with normal (1, 0, 1) / sqrt(2).
WORLD = np.array(
    [
        [0, 0, 0],
        [1, 0, 0],
        [0, 1, 0],
        [3, 0, 0],
        [3, 1, 0],
        [3, 0, 1],
        [5, 0, 0],
        [5, 1, 0],
        [6, 0, -1],
    ],
    np.float64,
)
# The stored (bind-space) positions are WORLD through the inverse of a non-uniform affine Q:
# the skin's inverse bind matrices carry Q back (what gltfpack does with its quantization).
Q = _translate(-4.0, 0.5, 2.0) @ np.diag([100.0, 50.0, 100.0, 1.0])
PARENT = _translate(1.0, 2.0, 3.0) @ np.diag([3.0, 3.0, 3.0, 1.0])  # the joint's parent node
JOINT_REST = PARENT @ _translate(0.5, 0.0, 0.0)  # the joint's rest world matrix


def _analytic_file(path: Path) -> Path:
    stored = (np.c_[WORLD, np.ones(9)] @ np.linalg.inv(Q).T)[:, :3].astype(np.float32)
    ibm = np.linalg.inv(JOINT_REST) @ Q
    arrays = [
        (stored, {}),
        (np.arange(9, dtype=np.uint16), {}),
        (np.zeros((9, 4), np.uint8), {}),
        (np.tile(np.array([1, 0, 0, 0], np.float32), (9, 1)), {}),
        (ibm.T.reshape(1, 16).astype(np.float32), {}),  # column-major MAT4
        (np.array([0.0, 1.0], np.float32), {}),
        (np.array([[1, 1, 1], [2, 1, 1]], np.float32), {}),  # x scale 1 at rest, 2 at t = 1
    ]
    attrs = {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3}
    doc = {
        "meshes": [{"primitives": [{"attributes": attrs, "indices": 1}]}],
        "nodes": [
            {"mesh": 0, "skin": 0, "scale": [7.0, 7.0, 7.0]},  # ignored: the node is skinned
            {"translation": [1.0, 2.0, 3.0], "scale": [3.0, 3.0, 3.0], "children": [2]},
            {"name": "joint", "translation": [0.5, 0.0, 0.0]},
        ],
        "scenes": [{"nodes": [0, 1]}],
        "skins": [{"joints": [2], "inverseBindMatrices": 4}],
        "animations": [
            {
                "samplers": [{"input": 5, "output": 6, "interpolation": "LINEAR"}],
                "channels": [{"sampler": 0, "target": {"node": 2, "path": "scale"}}],
            }
        ],
    }
    return write_gltf(path, arrays, doc)


@pytest.mark.parametrize("time, s", [(0.0, 1.0), (0.5, 1.5), (1.0, 2.0)])
def test_joint_scaling_x_gives_the_analytic_stretch(tmp_path, time, s):
    # The posed world shape is WORLD scaled by s along x about the joint (the parent's uniform
    # scale and the translations cancel): area ratio = |cof(diag(s,1,1)) n| = |(n_x, s n_y, s n_z)|
    # for a triangle of unit normal n, weight = 1 - ratio.
    f = _analytic_file(tmp_path / "skin.gltf")
    w = _dynamic(f, time, tmp_path / "w.npy")
    expected = np.repeat([1.0 - s, 0.0, 1.0 - np.sqrt(0.5 + 0.5 * s * s)], 3)
    np.testing.assert_allclose(w, expected, rtol=0, atol=1e-5)


@needs_data
def test_cesium_man_bind_space_is_a_rotation_of_its_skinned_rest():
    # Why the unquantized CesiumMan's weights are a valid reference: every joint's rest world
    # matrix times its inverse bind is the same rotation (the Z-up -> Y-up axis cycle), so its
    # stored positions and its skinned rest pose have the same triangle areas.
    m = load_mesh(CESIUM_MAN, LoadOptions(generate_uvs=False))
    rest = gltf_joint_world_matrices_at(CESIUM_MAN, m, [None])[0]
    skin = rest @ m.inverse_bind
    cycle = np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]], np.float64)
    np.testing.assert_allclose(
        skin[:, :3, :3], np.broadcast_to(cycle, (len(skin), 3, 3)), atol=1e-5
    )
    np.testing.assert_allclose(skin[:, :3, 3], 0.0, atol=1e-5)
    a0 = triangle_areas(m.positions, m.indices)
    a1 = triangle_areas(skinned_pose(m, rest), m.indices)
    np.testing.assert_allclose(a1, a0, rtol=1e-4)


@needs_data
@needs_node_tools
def test_quantized_cesium_man_gives_the_original_weights(tmp_path):
    # gltfpack's default quantization: 14-bit positions in mesh space (integers 0..16383), the
    # dequantization folded into the inverse bind matrices. It also welds duplicate vertices
    # (3273 -> 2612), so vertices are matched by skinned rest position (within a step).
    packed = tmp_path / "q.glb"
    _node_tool("gltfpack", "-i", CESIUM_MAN, "-o", packed)
    rest = {}
    for name, f in (("orig", CESIUM_MAN), ("packed", packed)):
        m = load_mesh(f, LoadOptions(generate_uvs=False))
        rest[name] = skinned_pose(m, gltf_joint_world_matrices_at(f, m, [None])[0])
    assert load_mesh(packed, LoadOptions(generate_uvs=False)).positions.max() > 1000  # quantized
    dist, match = cKDTree(rest["packed"]).query(rest["orig"])
    step = np.ptp(rest["orig"], axis=0).max() / 16383  # 9.2e-5 m
    assert dist.max() < step
    for time in (0.5, 1.0, 1.5):
        orig = _dynamic(CESIUM_MAN, time, tmp_path / "o.npy")
        quant = _dynamic(packed, time, tmp_path / "p.npy")[match]
        assert orig.min() < -0.5 and orig.max() > 0.5  # the figure really deforms
        err = np.abs(quant - orig)
        # A vertex moved by at most sqrt(3)/2 step changes a triangle's area by at most
        # 0.5 * that * its perimeter: on CesiumMan's triangles that is a relative area change
        # of 0.016 (median) to 0.048 (max). Measured: max 0.020, mean 1.1e-3 (was 1.0: +1
        # everywhere, the quantized integers taken as the rest shape).
        assert err.max() < 0.048
        assert err.mean() < 2e-3


@pytest.mark.parametrize("time", [0.5, 1.0])
def test_unskinned_morph_under_a_node_scale_is_measured_in_world_space(tmp_path, time):
    # No skin: the node's world transform (z scaled by 3) is baked into the rest positions and
    # the morph deltas alike. The target lifts corner 2 by 0.25 in z (weight = time): in world
    # space the triangle (0,0,0), (1,0,0), (0,1,0.75 t) has area 0.5 |(0, -0.75 t, 1)|, so
    # weight = 1 - sqrt(1 + (0.75 t)^2) (in mesh space it would be 1 - sqrt(1 + (0.25 t)^2)).
    arrays = [
        (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), {}),
        (np.arange(3, dtype=np.uint16), {}),
        (np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0.25]], np.float32), {}),
        (np.array([0.0, 1.0], np.float32), {}),
        (np.array([0.0, 1.0], np.float32), {}),  # the target's weight: 0 at rest, 1 at t = 1
    ]
    prim = {"attributes": {"POSITION": 0}, "indices": 1, "targets": [{"POSITION": 2}]}
    doc = {
        "meshes": [{"primitives": [prim], "weights": [0.0]}],
        "nodes": [{"mesh": 0, "scale": [1.0, 1.0, 3.0]}],
        "scenes": [{"nodes": [0]}],
        "animations": [
            {
                "samplers": [{"input": 3, "output": 4, "interpolation": "LINEAR"}],
                "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
            }
        ],
    }
    f = write_gltf(tmp_path / "morph.gltf", arrays, doc)
    w = _dynamic(f, time, tmp_path / "w.npy")
    np.testing.assert_allclose(w, 1.0 - np.sqrt(1.0 + (0.75 * time) ** 2), rtol=0, atol=1e-5)
