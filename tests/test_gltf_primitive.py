"""The one per-primitive glTF reader (wrinklepipe.gltf.primitive) over its two sources: a
file opened for mesh ingest (GltfFile) and the pass-through Document. Hand-built files with
expectations from the glTF 2.0 spec (and scipy for the node transform), and the two readers
held against each other on the Khronos samples (skipped when ../shared/data is absent)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from test_mesh_io_gltf import QUAD_I, QUAD_P, QUAD_UV, SAMPLES, needs_data, quad_doc, write_gltf

from wrinklepipe.errors import InputError
from wrinklepipe.gltf.animation import read_channels, read_morph_tracks
from wrinklepipe.gltf.document import read_document
from wrinklepipe.gltf.meshes import read_gltf_meshes
from wrinklepipe.gltf.primitive import (
    PrimitiveOptions,
    read_instance,
    read_primitive,
    world_matrices,
)
from wrinklepipe.gltf.read import GltfFile, GltfReadOptions
from wrinklepipe.gltf.render_mesh import OPTIONS, primitive_mesh

JOINTS = np.array([[1, 0, 0, 0]] * 4, np.uint8)
WEIGHTS = np.array([[1, 0, 0, 0]] * 4, np.float32)
DELTA = np.array([[0, 0, 1]] * 4, np.float32)


def skinned_quad(path: Path, normalized_ints: bool = False) -> Path:
    """A quad skinned to the second of two unnamed joints (no inverseBindMatrices), with one
    morph target; ``normalized_ints`` marks its indices and JOINTS_0 ``normalized`` (which the
    spec forbids for both: a reader must still read them as integers)."""
    flag = {"normalized": True} if normalized_ints else {}
    idx = QUAD_I.astype(np.uint8)
    doc = quad_doc({"attributes": {"POSITION": 0, "TEXCOORD_0": 2, "JOINTS_0": 3, "WEIGHTS_0": 4}})
    doc["meshes"][0]["primitives"][0]["targets"] = [{"POSITION": 5}]
    doc["meshes"][0]["extras"] = {"targetNames": ["smile"]}
    doc["nodes"] = [{"mesh": 0, "skin": 0}, {"children": [2]}, {"translation": [0, 1, 0]}]
    doc["scenes"] = [{"nodes": [0, 1]}]
    doc["skins"] = [{"joints": [1, 2]}]
    arrays = [(QUAD_P, {}), (idx, flag), (QUAD_UV, {}), (JOINTS, flag), (WEIGHTS, {})]
    return write_gltf(path, [*arrays, (DELTA, {})], doc)


def _sources(f: Path) -> list:
    return [GltfFile(f, GltfReadOptions()), read_document(f)]


def test_ints_the_spec_never_normalizes_stay_ints_from_both_sources(tmp_path):
    f = skinned_quad(tmp_path / "s.gltf", normalized_ints=True)
    for src in _sources(f):
        m = read_primitive(src, 0, 0, skin=None)
        np.testing.assert_array_equal(m.indices, [[0, 1, 2], [0, 2, 3]])
        m, placed = read_instance(src, 0, 0, 0, np.eye(4))
        assert placed == "skinned"
        np.testing.assert_array_equal(m.joints, JOINTS.astype(np.int64))


def test_skin_names_unnamed_joints_by_node_and_defaults_to_identity_binds(tmp_path):
    f = skinned_quad(tmp_path / "s.gltf")
    for src in _sources(f):
        m, _ = read_instance(src, 0, 0, 0, np.eye(4))
        assert m.joint_names == ("node1", "node2")
        np.testing.assert_array_equal(m.inverse_bind, np.tile(np.eye(4), (2, 1, 1)))
        assert m.morph_names == ("smile",)
        np.testing.assert_array_equal(m.morph_deltas[0], DELTA)
    (ingested,) = read_gltf_meshes(f)
    assert ingested.joint_names == ("node1", "node2")
    assert any("skin 0: 2 joints" in n for n in ingested.notes)


@settings(max_examples=25, deadline=None)
@given(
    t=st.lists(st.floats(-5, 5), min_size=3, max_size=3),
    q=st.lists(st.floats(-1, 1), min_size=4, max_size=4).filter(lambda v: np.linalg.norm(v) > 0.1),
    s=st.lists(st.sampled_from([-2.0, -0.5, 0.5, 1.0, 3.0]), min_size=3, max_size=3),
)
def test_a_rigid_instance_is_baked_like_scipy_says(tmp_path_factory, t, q, s):
    q = (np.asarray(q) / np.linalg.norm(q)).tolist()
    d = tmp_path_factory.mktemp("bake")
    doc = quad_doc({"attributes": {"POSITION": 0, "TEXCOORD_0": 2, "NORMAL": 3}})
    doc["nodes"][0].update(translation=t, rotation=q, scale=s)
    nrm = np.array([[0, 0, 1]] * 4, np.float32)
    f = write_gltf(d / "b.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (nrm, {})], doc)
    rot = Rotation.from_quat(q).as_matrix()  # scipy's quaternions are (x, y, z, w) as glTF's
    lin = rot @ np.diag(s)
    want = QUAD_P @ lin.T + t
    n_want = nrm @ np.linalg.inv(lin)  # normals by the inverse transpose
    n_want /= np.linalg.norm(n_want, axis=1, keepdims=True)
    flip = np.linalg.det(lin) < 0
    for src in _sources(f):
        m, placed = read_instance(src, 0, 0, 0, world_matrices(src.gltf)[0])
        assert placed == "baked"
        np.testing.assert_allclose(m.positions, want, atol=1e-5)
        np.testing.assert_allclose(m.normals, n_want, atol=1e-5)
        want_tris = QUAD_I.reshape(-1, 3)[:, [0, 2, 1]] if flip else QUAD_I.reshape(-1, 3)
        np.testing.assert_array_equal(m.indices, want_tris)


def test_an_all_degenerate_primitive_is_read_empty_and_ingest_skips_it(tmp_path):
    doc = quad_doc()
    doc["meshes"][0]["primitives"].append({"attributes": {"POSITION": 0}, "indices": 3})
    flat = np.array([0, 0, 1, 2, 2, 3], np.uint16)  # repeated indices only
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (flat, {})]
    f = write_gltf(tmp_path / "d.gltf", arrays, doc)
    for src in _sources(f):
        m = read_primitive(src, 0, 1)
        assert m.triangle_count == 0 and any("skipped 2 degenerate" in n for n in m.notes)
    meshes = read_gltf_meshes(f)
    assert [m.triangle_count for m in meshes] == [2]
    assert any(
        "skipped 1 primitive whose triangles are all degenerate" in n for n in meshes[0].notes
    )


def test_strict_refuses_what_ingest_leaves_out(tmp_path):
    doc = quad_doc({"targets": [{"POSITION": 3}]})
    doc["meshes"][0]["primitives"][0]["attributes"]["_WRINKLE_VERTEX_ID"] = 4
    short = np.zeros((3, 3), np.float32)
    ids = np.array([0, 1, 2.5, 3], np.float32)  # not integers
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (short, {}), (ids, {})]
    f = write_gltf(tmp_path / "m.gltf", arrays, doc)
    lenient = read_primitive(GltfFile(f, GltfReadOptions()), 0, 0, PrimitiveOptions())
    assert lenient.morph_names == () and lenient.vertex_ids is None
    assert any("skipped morph target 'target_0'" in n for n in lenient.notes)
    assert any("ignored _WRINKLE_VERTEX_ID" in n for n in lenient.notes)
    with pytest.raises(InputError, match="vertex IDs") as exc:
        primitive_mesh(read_document(f), read_document(f).primitives()[0])
    assert exc.value.problems[0].key == "/meshes/0/primitives/0/attributes/_WRINKLE_VERTEX_ID"
    d = json.loads(f.read_text())
    del d["meshes"][0]["primitives"][0]["attributes"]["_WRINKLE_VERTEX_ID"]
    f.write_text(json.dumps(d))
    doc_ = read_document(f)
    with pytest.raises(InputError, match="morph target has 3 x 3 deltas for 4") as exc:
        primitive_mesh(doc_, doc_.primitives()[0])
    assert exc.value.problems[0].key == "/meshes/0/primitives/0/targets/0/POSITION"


def test_colors_come_from_the_attribute_the_options_name(tmp_path):
    doc = quad_doc()
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    attrs.update(COLOR_0=3, _WRINKLE_BIAS=4)
    rgb = np.array([[1, 0, 0]] * 4, np.float32)
    bias = np.full((4, 4), 0.25, np.float32)
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (rgb, {}), (bias, {})]
    f = write_gltf(tmp_path / "c.gltf", arrays, doc)
    for src in _sources(f):
        # COLOR_0 VEC3 gets alpha 1 (spec: RGB colours are opaque)
        np.testing.assert_array_equal(read_primitive(src, 0, 0).colors, [[1, 0, 0, 1]] * 4)
        np.testing.assert_array_equal(read_primitive(src, 0, 0, OPTIONS).colors, bias)


def test_the_bias_reads_from_its_four_channel_attributes(tmp_path):
    """The bias as wrinklepipe writes it (one SCALAR FLOAT attribute per channel), and a
    partial set of channels as one clear error naming the missing ones."""
    doc = quad_doc()
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    attrs.update(_WRINKLE_BIAS_R=3, _WRINKLE_BIAS_G=4, _WRINKLE_BIAS_B=5, _WRINKLE_BIAS_A=6)
    bias = np.arange(16, dtype=np.float32).reshape(4, 4) / 16
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {})] + [(bias[:, c], {}) for c in range(4)]
    f = write_gltf(tmp_path / "c.gltf", arrays, doc)
    for src in _sources(f):
        np.testing.assert_array_equal(read_primitive(src, 0, 0, OPTIONS).colors, bias)
        assert read_primitive(src, 0, 0).colors is None  # COLOR_0 is not the bias
    del attrs["_WRINKLE_BIAS_B"]
    f = write_gltf(tmp_path / "d.gltf", arrays, doc)
    with pytest.raises(InputError, match="the bias lacks _WRINKLE_BIAS_B") as exc:
        read_primitive(next(iter(_sources(f))), 0, 0, OPTIONS)
    assert exc.value.problems[0].key == "/meshes/0/primitives/0/attributes"


FIELDS = ("positions", "indices", "uvs", "normals", "tangents", "morph_deltas", "joints")
FIELDS += ("skin_weights", "inverse_bind", "vertex_ids")


@needs_data
@pytest.mark.parametrize(
    "rel",
    [
        "CesiumMan/glTF-Binary/CesiumMan.glb",
        "Fox/glTF-Binary/Fox.glb",
        "MorphPrimitivesTest/glTF/MorphPrimitivesTest.gltf",
        "RiggedFigure/glTF-Binary/RiggedFigure.glb",
        "RobotExpressive/RobotExpressive.glb",
        "SimpleSkin/glTF/SimpleSkin.gltf",
        "SimpleSparseAccessor/glTF-Embedded/SimpleSparseAccessor.gltf",
        "TextureCoordinateTest/glTF-Binary/TextureCoordinateTest.glb",
    ],
)
def test_mesh_ingest_and_the_document_read_every_primitive_alike(rel):
    """Each of these files instances every mesh once: ingest's meshes (in node order) are the
    document's render meshes of the same primitives."""
    f = SAMPLES / rel
    ingested = read_gltf_meshes(f)
    doc = read_document(f)
    by_name = {}
    for ref in doc.primitives():
        if int(doc.primitive(ref).get("mode", 4)) in (4, 5, 6):
            m = primitive_mesh(doc, ref)
            by_name[m.name] = m
    assert sorted(by_name) == sorted(m.name for m in ingested)
    for a in ingested:
        b = by_name[a.name]
        for field in FIELDS:
            x, y = getattr(a, field), getattr(b, field)
            assert (x is None) == (y is None), (a.name, field)
            if x is not None:
                np.testing.assert_array_equal(x, y, err_msg=f"{a.name}.{field}")
        assert a.morph_names == b.morph_names and a.joint_names == b.joint_names


def test_morph_tracks_name_targets_as_the_mesh_does(tmp_path):
    """A weights animation on a mesh whose targetNames lists fewer names than targets: the
    tracks' target names are the mesh's morph names (the driver matches them)."""
    doc = quad_doc({"targets": [{"POSITION": 3}, {"POSITION": 3}]})
    doc["meshes"][0]["extras"] = {"targetNames": ["smile"]}
    doc["animations"] = [
        {
            "samplers": [{"input": 4, "output": 5}],
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
        }
    ]
    times = np.array([0.0, 1.0], np.float32)
    weights = np.array([0.0, 0.0, 1.0, 0.5], np.float32)
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (DELTA, {}), (times, {}), (weights, {})]
    f = write_gltf(tmp_path / "a.gltf", arrays, doc)
    (track,) = read_morph_tracks(f)
    (mesh,) = read_gltf_meshes(f)
    assert track.names == mesh.morph_names == ("smile", "target_1")
    np.testing.assert_array_equal(track.values[1], [1.0, 0.5])


def test_channels_are_read_once_strictly_or_leniently(tmp_path):
    """One channel reader for every glTF animation user: a rotation channel comes back
    ``[N, 4]`` from both sources; keys that do not increase are refused when strict (the drivers'
    and the skeleton's readers) and kept when lenient (the USD writer of a source)."""
    doc = quad_doc()
    doc["animations"] = [
        {
            "samplers": [{"input": 3, "output": 4}],
            "channels": [
                {"sampler": 0, "target": {"node": 0, "path": "rotation"}},
                {"sampler": 0, "target": {"path": "rotation"}},  # no node: not a node channel
            ],
        }
    ]
    times = np.array([0.0, 1.0], np.float32)
    quats = np.array([[0, 0, 0, 1], [0, 0, 1, 0]], np.float32)
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (times, {}), (quats, {})]
    f = write_gltf(tmp_path / "r.gltf", arrays, doc)
    for src in _sources(f):
        (c,) = read_channels(src)
        assert (c.node, c.path, c.interpolation) == (0, "rotation", "LINEAR")
        np.testing.assert_array_equal(c.values, quats)
    same_times = [*arrays[:3], (np.zeros(2, np.float32), {}), arrays[4]]
    flat = write_gltf(tmp_path / "s.gltf", same_times, doc)
    with pytest.raises(InputError, match="increase strictly"):
        read_channels(GltfFile(flat, GltfReadOptions()))
    assert len(read_channels(read_document(flat), strict=False)) == 1
