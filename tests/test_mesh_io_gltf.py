"""glTF/GLB mesh ingest: hand-built files (quantization, sparse, strips, refusals, bad inputs) and
the Khronos sample assets (skipped when ../shared/data is absent)."""

from __future__ import annotations

import base64
import json
import shutil
import subprocess
from pathlib import Path

import meshoptimizer
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.cli import main
from wrinklepipe.errors import InputError
from wrinklepipe.geometry.dynamic import skinned_pose, triangle_weights
from wrinklepipe.geometry.tangents import ensure_tangents, mikktspace_tangents_report
from wrinklepipe.gltf.decompress import compressed
from wrinklepipe.gltf.meshes import gltf_joint_world_matrices, read_gltf_meshes
from wrinklepipe.gltf.read import GltfFile, GltfReadOptions
from wrinklepipe.paths import ROOT
from wrinklepipe.readers.meshes import LoadOptions, load_mesh, load_meshes

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
SAMPLES = DATA / "gltf-samples"
needs_data = pytest.mark.skipif(not SAMPLES.is_dir(), reason="shared/data absent")


def write_gltf(path: Path, arrays: list[tuple[np.ndarray, dict]], doc: dict) -> Path:
    """Pack arrays into one data-URI buffer; arrays[i] becomes accessors[i] (extra keys merged)."""
    blob = b""
    views, accs = [], []
    types = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}
    comp = {np.float32: 5126, np.uint8: 5121, np.int8: 5120, np.int16: 5122, np.uint16: 5123}
    comp[np.uint32] = 5125
    for arr, extra in arrays:
        a = np.ascontiguousarray(arr)
        width = 1 if a.ndim == 1 else a.shape[1]
        while len(blob) % 4:
            blob += b"\0"
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": a.nbytes})
        blob += a.tobytes()
        acc = {
            "bufferView": len(views) - 1,
            "componentType": comp[a.dtype.type],
            "count": len(a),
            "type": types[width],
        }
        acc.update(extra)
        accs.append(acc)
    uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    full = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(blob), "uri": uri}],
        "bufferViews": views,
        "accessors": accs,
        **doc,
    }
    path.write_text(json.dumps(full))
    return path


QUAD_P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
QUAD_I = np.array([0, 1, 2, 0, 2, 3], np.uint16)
QUAD_UV = np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32)


def quad_doc(extra_prim: dict | None = None, extra: dict | None = None) -> dict:
    prim = {"attributes": {"POSITION": 0, "TEXCOORD_0": 2}, "indices": 1}
    prim.update(extra_prim or {})
    doc = {"meshes": [{"primitives": [prim]}], "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]}
    doc.update(extra or {})
    return doc


def test_quad_reads_and_triangulates(tmp_path):
    f = write_gltf(tmp_path / "q.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {})], quad_doc())
    m = load_mesh(f)
    np.testing.assert_array_equal(m.positions, QUAD_P)
    np.testing.assert_array_equal(m.indices, QUAD_I.reshape(-1, 3))
    np.testing.assert_array_equal(m.uvs, QUAD_UV)


def test_strip_and_fan_are_triangulated(tmp_path):
    strip = np.array([0, 1, 3, 2], np.uint16)  # two triangles, second flipped back to CCW
    f = write_gltf(
        tmp_path / "s.gltf", [(QUAD_P, {}), (strip, {}), (QUAD_UV, {})], quad_doc({"mode": 5})
    )
    m = load_mesh(f)
    np.testing.assert_array_equal(m.indices, [[0, 1, 3], [3, 1, 2]])
    assert any("strip" in n for n in m.notes)
    fan = np.array([0, 1, 2, 3], np.uint16)
    f = write_gltf(
        tmp_path / "f.gltf", [(QUAD_P, {}), (fan, {}), (QUAD_UV, {})], quad_doc({"mode": 6})
    )
    np.testing.assert_array_equal(load_mesh(f).indices, [[0, 1, 2], [0, 2, 3]])


def test_khr_mesh_quantization_decodes(tmp_path):
    # int16 positions with a node scale of 1/1000; normalized int8 normals; normalized uint16 UVs.
    qpos = np.array([[0, 0, 0], [1000, 0, 0], [1000, 1000, 0], [0, 1000, 0]], np.int16)
    qnrm = np.array([[0, 0, 127]] * 4, np.int8)
    qnrm[0] = [0, 0, -128]  # -128/127 clamps to -1 (spec)
    quv = (QUAD_UV * 65535).astype(np.uint16)
    doc = quad_doc(extra={"extensionsUsed": ["KHR_mesh_quantization"]})
    doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = 3
    doc["nodes"][0]["scale"] = [0.001, 0.001, 0.001]
    f = write_gltf(
        tmp_path / "q.gltf",
        [(qpos, {}), (QUAD_I, {}), (quv, {"normalized": True}), (qnrm, {"normalized": True})],
        doc,
    )
    m = load_mesh(f)
    np.testing.assert_allclose(m.positions, QUAD_P, atol=1e-6)
    np.testing.assert_allclose(m.uvs, QUAD_UV, atol=1e-6)
    np.testing.assert_allclose(m.normals[0], [0, 0, -1], atol=1e-6)
    np.testing.assert_allclose(m.normals[1], [0, 0, 1], atol=1e-6)
    assert any("KHR_mesh_quantization" in n for n in m.notes)


def test_sparse_accessor_applies(tmp_path):
    sp_idx = np.array([2], np.uint16)
    sp_val = np.array([[5, 5, 0]], np.float32)
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (sp_idx, {}), (sp_val, {})]
    f = write_gltf(tmp_path / "sp.gltf", arrays, quad_doc())
    doc = json.loads(f.read_text())
    doc["accessors"][0]["sparse"] = {
        "count": 1,
        "indices": {"bufferView": 3, "componentType": 5123},
        "values": {"bufferView": 4},
    }
    f.write_text(json.dumps(doc))
    np.testing.assert_array_equal(load_mesh(f).positions[2], [5, 5, 0])


def test_unknown_required_extension_refused_by_name(tmp_path):
    doc = quad_doc(extra={"extensionsUsed": ["EXT_made_up"], "extensionsRequired": ["EXT_made_up"]})
    f = write_gltf(tmp_path / "e.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {})], doc)
    with pytest.raises(InputError, match="EXT_made_up") as exc:
        load_mesh(f)
    assert str(f) in str(exc.value)


@pytest.mark.parametrize("ext", ["EXT_meshopt_compression", "KHR_draco_mesh_compression"])
def test_required_compression_with_nothing_compressed_reads_the_plain_data(tmp_path, ext):
    doc = quad_doc(extra={"extensionsUsed": [ext], "extensionsRequired": [ext]})
    f = write_gltf(tmp_path / "e.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {})], doc)
    m = load_mesh(f)
    np.testing.assert_array_equal(m.positions, QUAD_P)
    np.testing.assert_array_equal(m.indices, QUAD_I.reshape(-1, 3))
    assert not any(ext in n for n in m.notes)  # nothing was decoded


def test_corrupt_draco_stream_is_one_line_naming_file_and_extension(tmp_path):
    # the primitive's attributes live in a Draco bitstream (bufferView 3) of garbage bytes
    garbage = np.frombuffer(b"DRACO\x02\x02" + bytes(range(57)), np.uint8)
    ext = {"bufferView": 3, "attributes": {"POSITION": 0, "TEXCOORD_0": 1}}
    doc = quad_doc(
        extra_prim={"extensions": {"KHR_draco_mesh_compression": ext}},
        extra={
            "extensionsUsed": ["KHR_draco_mesh_compression"],
            "extensionsRequired": ["KHR_draco_mesh_compression"],
        },
    )
    f = write_gltf(
        tmp_path / "d.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (garbage, {})], doc
    )
    with pytest.raises(InputError) as exc:
        load_mesh(f)
    text = str(exc.value)
    assert str(f) in text and "KHR_draco_mesh_compression" in text and "\n" not in text
    key = exc.value.problems[0].key
    assert key == "/meshes/0/primitives/0/extensions/KHR_draco_mesh_compression"


@pytest.mark.parametrize(
    ("ext", "message"),
    [
        ({"bufferView": 99, "attributes": {"POSITION": 0}}, "Draco bufferView 99 does not exist"),
        ({"attributes": {"POSITION": 0}}, "Draco bufferView None does not exist"),
        ({"bufferView": 3, "attributes": [0]}, "attributes must be an object"),
        ({"bufferView": 3, "attributes": {"POSITION": "0"}}, "'0' of POSITION is not an integer"),
    ],
)
def test_malformed_draco_extension_is_one_line_naming_it(tmp_path, ext, message):
    garbage = np.zeros(8, np.uint8)
    doc = quad_doc(
        extra_prim={"extensions": {"KHR_draco_mesh_compression": ext}},
        extra={"extensionsUsed": ["KHR_draco_mesh_compression"]},
    )
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (garbage, {})]
    f = write_gltf(tmp_path / "d.gltf", arrays, doc)
    with pytest.raises(InputError, match=message) as exc:
        load_mesh(f)
    assert exc.value.problems[0].key.endswith("/extensions/KHR_draco_mesh_compression")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"mode": "SPIRAL"}, "unknown meshopt mode 'SPIRAL'"),
        ({"filter": "FUZZY"}, "unknown meshopt filter 'FUZZY'"),
        ({"byteStride": 6}, "byteStride 6 is not a multiple of 4"),
        ({"count": "many"}, "lacks count, byteStride or mode"),
    ],
)
def test_malformed_meshopt_view_is_one_line_naming_it(tmp_path, change, message):
    ext = {"buffer": 0, "byteLength": 8, "count": 4, "byteStride": 12, "mode": "ATTRIBUTES"}
    ext.update(change)
    f = write_gltf(tmp_path / "m.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {})], quad_doc())
    tree = json.loads(f.read_text())
    tree["bufferViews"][0]["extensions"] = {"EXT_meshopt_compression": ext}
    tree["extensionsUsed"] = tree["extensionsRequired"] = ["EXT_meshopt_compression"]
    f.write_text(json.dumps(tree))
    with pytest.raises(InputError, match=message) as exc:
        load_mesh(f)
    assert exc.value.problems[0].key == "/bufferViews/0/extensions/EXT_meshopt_compression"
    assert str(f) in str(exc.value)


def test_texture_extension_ignored_with_note(tmp_path):
    doc = quad_doc(
        extra={
            "extensionsUsed": ["KHR_texture_basisu"],
            "extensionsRequired": ["KHR_texture_basisu"],
        }
    )
    f = write_gltf(tmp_path / "b.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {})], doc)
    assert any("KHR_texture_basisu" in n for n in load_mesh(f).notes)


def test_bad_inputs_are_clear(tmp_path):
    bad_i = np.array([0, 1, 9], np.uint16)
    f = write_gltf(tmp_path / "i.gltf", [(QUAD_P, {}), (bad_i, {}), (QUAD_UV, {})], quad_doc())
    with pytest.raises(InputError, match="out of range") as exc:
        load_mesh(f)
    assert exc.value.problems[0].key == "/meshes/0/primitives/0/indices"

    nan_p = QUAD_P.copy()
    nan_p[3, 1] = np.nan
    f = write_gltf(tmp_path / "n.gltf", [(nan_p, {}), (QUAD_I, {}), (QUAD_UV, {})], quad_doc())
    with pytest.raises(InputError, match="NaN"):
        load_mesh(f)

    f = write_gltf(
        tmp_path / "p.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {})], quad_doc({"mode": 0})
    )
    with pytest.raises(InputError, match="no triangle primitives"):
        load_mesh(f)

    # Zero-area triangle: skipped and counted.
    degen = np.array([0, 1, 2, 0, 2, 3, 0, 0, 1], np.uint16)
    f = write_gltf(tmp_path / "d.gltf", [(QUAD_P, {}), (degen, {}), (QUAD_UV, {})], quad_doc())
    m = load_mesh(f)
    assert m.triangle_count == 2
    assert any("skipped 1 degenerate" in n for n in m.notes)

    # A morph target of the wrong length: skipped and reported, the rest loads.
    short = np.zeros((3, 3), np.float32)
    ok = np.zeros((4, 3), np.float32)
    doc = quad_doc({"targets": [{"POSITION": 3}, {"POSITION": 4}]})
    doc["meshes"][0]["extras"] = {"targetNames": ["short", "fine"]}
    arrays = [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {}), (short, {}), (ok, {})]
    m = load_mesh(write_gltf(tmp_path / "m.gltf", arrays, doc))
    assert m.morph_names == ("fine",)
    assert any("skipped morph target 'short'" in n for n in m.notes)

    with pytest.raises(InputError, match="not found"):
        load_mesh(tmp_path / "missing.glb")
    (tmp_path / "junk.glb").write_bytes(b"glTF\x02\x00\x00\x00")
    with pytest.raises(InputError):
        load_mesh(tmp_path / "junk.glb")


@needs_data
def test_normal_tangent_mirror_tangents_agree():
    m = load_mesh(SAMPLES / "NormalTangentMirrorTest/glTF-Binary/NormalTangentMirrorTest.glb")
    assert m.tangents is not None
    assert ensure_tangents(m).tangents is m.tangents  # supplied tangents are kept
    t, rep = mikktspace_tangents_report(m.positions, m.normals, m.uvs, m.indices)
    s = m.tangents
    cos = np.sum(t[:, :3] * s[:, :3], 1) / np.linalg.norm(s[:, :3], axis=1)
    ang = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    # Measured: mean 0.002 deg, max 0.028 deg over 2770 vertices; 80 mirrored (w = -1).
    assert ang.mean() < 0.01 and ang.max() < 0.1
    np.testing.assert_array_equal(np.sign(t[:, 3]), np.sign(s[:, 3]))
    assert (s[:, 3] < 0).sum() == 80
    assert rep.fallback_vertices == 0


@needs_data
def test_morph_stress_test_names_and_primitives():
    f = SAMPLES / "MorphStressTest/glTF-Binary/MorphStressTest.glb"
    parts = load_meshes(f)
    assert len(parts) == 2
    m = load_mesh(f)
    assert m.morph_names == tuple(f"Key {i}" for i in range(1, 9))
    assert m.morph_deltas.shape == (8, m.vertex_count, 3)
    assert m.vertex_count == sum(p.vertex_count for p in parts)
    assert np.abs(m.morph_deltas).max() > 0


@needs_data
def test_simple_skin_poses():
    f = SAMPLES / "SimpleSkin/glTF/SimpleSkin.gltf"
    m = load_mesh(f, LoadOptions(generate_uvs=False))
    assert m.joint_names and m.joints.shape == (10, 4) and m.inverse_bind.shape == (2, 4, 4)
    rest = skinned_pose(m, gltf_joint_world_matrices(f, m))
    np.testing.assert_allclose(rest, m.positions, atol=1e-6)
    # The animation bends the upper half; the bottom row (weights on joint 0 only) stays put.
    posed = skinned_pose(m, gltf_joint_world_matrices(f, m, time=1.0))
    bottom = m.positions[:, 1] == m.positions[:, 1].min()
    np.testing.assert_allclose(posed[bottom], m.positions[bottom], atol=1e-6)
    assert np.abs(posed - m.positions).max() > 0.5


@needs_data
def test_rigged_figure_ingests_and_deforms():
    f = SAMPLES / "RiggedFigure/glTF-Binary/RiggedFigure.glb"
    m = load_mesh(f)
    assert len(m.joint_names) == 19
    assert any("xatlas" in n for n in m.notes) and m.uvs is not None
    rest = skinned_pose(m, gltf_joint_world_matrices(f, m))
    # The rest pose is the bind pose up to a rigid transform: areas kept.
    assert np.abs(triangle_weights(m.positions, rest, m.indices)).max() < 1e-4
    posed = skinned_pose(m, gltf_joint_world_matrices(f, m, time=0.5))
    w = triangle_weights(rest, posed, m.indices)
    assert w.min() < -0.1 and w.max() > 0.1  # some skin stretches, some compresses


@needs_data
@pytest.mark.parametrize(
    "rel",
    [
        "AnimatedMorphCube/glTF-Binary/AnimatedMorphCube.glb",
        "CesiumMan/glTF-Binary/CesiumMan.glb",
        "DamagedHelmet/glTF-Binary/DamagedHelmet.glb",
        "Fox/glTF-Binary/Fox.glb",
        "MorphPrimitivesTest/glTF/MorphPrimitivesTest.gltf",
        "NegativeScaleTest/glTF-Binary/NegativeScaleTest.glb",
        "SimpleSparseAccessor/glTF-Embedded/SimpleSparseAccessor.gltf",
        "TextureCoordinateTest/glTF-Binary/TextureCoordinateTest.glb",
    ],
)
def test_samples_ingest(rel):
    m = load_mesh(SAMPLES / rel)
    assert m.triangle_count > 0 and m.uvs is not None
    assert np.isfinite(m.positions).all()
    assert int(m.indices.max()) < m.vertex_count


@needs_data
def test_sparse_sample_values():
    m = load_mesh(SAMPLES / "SimpleSparseAccessor/glTF-Embedded/SimpleSparseAccessor.gltf")
    # The sparse accessor lifts three vertices of the flat base (y 0 / 1) to y = 2, 3 and 4.
    assert sorted(np.unique(m.positions[:, 1]).tolist()) == [0.0, 1.0, 2.0, 3.0, 4.0]


MUTATIONS = [
    ("accessors", 0, "count", [0, 1, 5, 10**9, -1, "x", None]),
    ("accessors", 0, "componentType", [5120, 5121, 5125, 1, "f", None]),
    ("accessors", 0, "type", ["VEC2", "SCALAR", "MAT4", "BAD", 3]),
    ("accessors", 0, "bufferView", [1, 2, 99, -1, "0"]),
    ("accessors", 0, "byteOffset", [4, 1, 10**6, -8]),
    ("accessors", 1, "count", [0, 2, 7, 10**6]),
    ("accessors", 1, "componentType", [5126, 5121, 5125]),
    ("accessors", 2, "type", ["VEC3", "SCALAR"]),
    ("bufferViews", 0, "byteLength", [0, 3, 10**7, -1]),
    ("bufferViews", 0, "byteStride", [4, 0, 1000]),
    ("bufferViews", 1, "buffer", [1, -1, "a"]),
    ("buffers", 0, "uri", ["data:application/octet-stream;base64,AAA", "../x.bin", "/etc/x", 5]),
    ("meshes", 0, "primitives", [[], [{}], [{"attributes": {}}], "x", [{"attributes": 5}]]),
    ("nodes", 0, "mesh", [5, -1, "0"]),
    ("nodes", 0, "matrix", [[1, 2], [0] * 16, "x"]),
    ("nodes", 0, "children", [[0], [9], "x"]),
]


@settings(max_examples=60, deadline=None)
@given(picks=st.lists(st.tuples(st.integers(0, len(MUTATIONS) - 1), st.integers(0, 9)), max_size=3))
def test_mutated_gltf_never_tracebacks(tmp_path_factory, picks):
    d = tmp_path_factory.mktemp("mut")
    f = write_gltf(d / "m.gltf", [(QUAD_P, {}), (QUAD_I, {}), (QUAD_UV, {})], quad_doc())
    doc = json.loads(f.read_text())
    for mi, vi in picks:
        section, i, key, values = MUTATIONS[mi]
        doc[section][i][key] = values[vi % len(values)]
    f.write_text(json.dumps(doc))
    try:
        m = load_mesh(f, LoadOptions(generate_uvs=False))
    except InputError:
        return
    assert m.triangle_count > 0 and int(m.indices.max()) < m.vertex_count


@needs_data
def test_morph_weight_animation_sampled_like_pygltflib():
    from pygltflib import GLTF2

    from wrinklepipe.gltf.meshes import gltf_morph_weights

    f = SAMPLES / "AnimatedMorphCube/glTF-Binary/AnimatedMorphCube.glb"
    g = GLTF2().load(str(f))
    blob = g.binary_blob()
    smp = g.animations[0].samplers[0]

    def acc(i: int) -> np.ndarray:
        a = g.accessors[i]
        bv = g.bufferViews[a.bufferView]
        off = (bv.byteOffset or 0) + (a.byteOffset or 0)
        return np.frombuffer(blob, np.float32, count=a.count, offset=off)

    t_in = acc(smp.input)
    w_out = acc(smp.output).reshape(len(t_in), 2)  # two targets per key
    m = load_mesh(f)
    for k in (0, 30, 64, 126):
        w = gltf_morph_weights(f, m, float(t_in[k]))
        np.testing.assert_allclose([w["target_0"], w["target_1"]], w_out[k], atol=1e-6)
    mid = 0.5 * (t_in[40] + t_in[41])
    w = gltf_morph_weights(f, m, float(mid))
    np.testing.assert_allclose(w["target_0"], 0.5 * (w_out[40, 0] + w_out[41, 0]), atol=1e-6)


# --- animation sampling (glTF 2.0 Appendix C), against hand-computed values ------------------


def test_linear_rotation_is_slerp():
    from wrinklepipe.geometry.keyframes import sample_channel

    t = np.array([0.0, 1.0])
    # identity to 90 degrees about Z: at a quarter of the way, 22.5 degrees (nlerp gives ~18.4)
    q = np.array([[0.0, 0.0, 0.0, 1.0], [0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)]])
    got = sample_channel(t, q, 0.25, "LINEAR", "rotation")
    half = np.radians(22.5) / 2
    assert got == pytest.approx([0.0, 0.0, np.sin(half), np.cos(half)], abs=1e-12)


def test_cubic_spline_hermite_by_hand():
    from wrinklepipe.geometry.keyframes import sample_channel

    t = np.array([0.0, 2.0])
    # [in-tangent, value, out-tangent] per key, one component
    v = np.array([[[0.0], [1.0], [3.0]], [[-1.0], [4.0], [0.0]]])
    s = 0.5  # time 1.0 of 2.0
    h00, h10, h01, h11 = (
        2 * s**3 - 3 * s**2 + 1,
        s**3 - 2 * s**2 + s,
        -2 * s**3 + 3 * s**2,
        s**3 - s**2,
    )
    expected = h00 * 1.0 + 2.0 * h10 * 3.0 + h01 * 4.0 + 2.0 * h11 * -1.0
    assert sample_channel(t, v, 1.0, "CUBICSPLINE", "translation")[0] == pytest.approx(expected)
    assert sample_channel(t, v, -1.0, "CUBICSPLINE", "translation")[0] == 1.0  # clamped
    assert sample_channel(t, v, 9.0, "CUBICSPLINE", "translation")[0] == 4.0
    assert sample_channel(t, v[:, 1], 1.5, "STEP", "translation")[0] == 1.0


# -- compressed geometry against an independent decoder ---------------------------------------
# `gltf-transform copy` (npm glTF Transform CLI) decodes Draco and meshopt on read and writes
# plain accessors; wrinklepipe reads that copy on its plain path (nothing to decode) and the
# compressed original through the document model's decoder. The two must be the same geometry.

NODE_BIN = ROOT / "tools" / "node" / "node_modules" / ".bin"
needs_node_tools = pytest.mark.skipif(
    not (NODE_BIN / "gltf-transform").exists()
    or not (NODE_BIN / "gltfpack").exists()
    or shutil.which("node") is None,
    reason="npm gltf-transform / gltfpack not installed (ci/bootstrap.sh setup)",
)
TOKYO = SAMPLES / "LittlestTokyo" / "LittlestTokyo.glb"
MIRROR = SAMPLES / "NormalTangentMirrorTest" / "glTF-Binary" / "NormalTangentMirrorTest.glb"


def _node_tool(*argv: str | Path) -> None:
    subprocess.run(
        [str(NODE_BIN / str(argv[0])), *map(str, argv[1:])],
        check=True,
        capture_output=True,
        timeout=300,
    )


def _plain_copy(src: Path, out: Path) -> Path:
    _node_tool("gltf-transform", "copy", src, out)
    r = GltfFile(out, GltfReadOptions())
    assert r.decoded == [] and not compressed(r.gltf)  # really plain: the plain path reads it
    return out


def _soup(mesh) -> tuple[np.ndarray, np.ndarray | None]:
    """Triangles as corner positions [F, 9] and corner UVs [F, 6] (None without UVs), each
    triangle rotated to start at its lexicographically smallest corner (winding kept), rows
    sorted: the triangle set whatever the vertex and triangle order."""
    p = mesh.positions.astype(np.float64)[mesh.indices]  # [F, 3, 3]
    rank = np.argsort(np.lexsort(p.reshape(-1, 3).T[::-1])).reshape(-1, 3)
    start = np.argmin(rank, axis=1)
    rot = (start[:, None] + np.arange(3)) % 3
    p = np.take_along_axis(p, rot[:, :, None], axis=1).reshape(-1, 9)
    order = np.lexsort(p.T[::-1])
    if mesh.uvs is None:
        return p[order], None
    uv = mesh.uvs.astype(np.float64)[mesh.indices]
    uv = np.take_along_axis(uv, rot[:, :, None], axis=1).reshape(-1, 6)
    return p[order], uv[order]


def _same_geometry(compressed_file: Path, plain_file: Path, step: float) -> tuple[int, int]:
    """Compare every mesh part; return the numbers of triangles and of parts with UVs."""
    opts = LoadOptions(generate_uvs=False)
    got, want = load_meshes(compressed_file, opts), load_meshes(plain_file, opts)
    assert [m.name for m in got] == [m.name for m in want]
    n = with_uvs = 0
    for a, b in zip(got, want):
        assert a.vertex_count == b.vertex_count and a.triangle_count == b.triangle_count
        np.testing.assert_array_equal(a.indices.max(), b.indices.max())
        pa, ua = _soup(a)
        pb, ub = _soup(b)
        span = float(np.ptp(b.positions, axis=0).max())
        # the same quantized data through two decoders: far inside one quantization step
        np.testing.assert_allclose(pa, pb, rtol=0, atol=1e-3 * step * span)
        assert (ua is None) == (ub is None)
        if ua is not None:
            np.testing.assert_allclose(ua, ub, rtol=0, atol=1e-3 * step)
            with_uvs += 1
        n += a.triangle_count
    return n, with_uvs


@needs_data
@needs_node_tools
def test_draco_littlest_tokyo_matches_gltf_transform(tmp_path):
    plain = _plain_copy(TOKYO, tmp_path / "plain.glb")
    assert GltfFile(TOKYO, GltfReadOptions()).decoded == ["KHR_draco_mesh_compression"]
    assert "decoded KHR_draco_mesh_compression" in load_meshes(TOKYO)[0].notes
    # step: one of 10-bit quantization (Draco encoders default to 11 bits for positions, 10 for
    # texture coordinates)
    n, with_uvs = _same_geometry(TOKYO, plain, 1 / (2**10 - 1))
    # every triangle: the 71 indices accessors' counts / 3 = 141802, less the 3 degenerate
    # ones ingest skips (and notes); 68 of the 71 parts have texture coordinates
    assert (n, with_uvs) == (141_802 - 3, 68)


@needs_data
@needs_node_tools
def test_meshopt_gltfpack_file_matches_gltf_transform(tmp_path):
    packed = tmp_path / "packed.glb"
    _node_tool("gltfpack", "-i", MIRROR, "-o", packed, "-cc")
    r = GltfFile(packed, GltfReadOptions())
    assert r.decoded == ["EXT_meshopt_compression"]
    plain = _plain_copy(packed, tmp_path / "plain.glb")
    # gltfpack's default quantization: 14-bit positions, 12-bit texture coordinates
    n, with_uvs = _same_geometry(packed, plain, 1 / (2**12 - 1))
    assert n > 0 and with_uvs == 1
    # and the geometry is the sample's, to within that quantization (gltfpack reorders and
    # welds vertices, so compare the triangle sets' bounds and areas)
    src, got = load_mesh(MIRROR), load_mesh(packed)
    assert got.triangle_count == src.triangle_count
    np.testing.assert_allclose(
        got.positions.min(axis=0), src.positions.min(axis=0), atol=1e-3 * np.ptp(src.positions)
    )


@needs_data
@needs_node_tools
def test_vertex_ids_on_compressed_files_match_the_plain_copy(tmp_path, capsys):
    plain = _plain_copy(TOKYO, tmp_path / "plain.glb")
    summaries = []
    for f in (TOKYO, plain):
        capsys.readouterr()
        assert main(["vertex-ids", str(f), "--json"]) == 0
        summaries.append(json.loads(capsys.readouterr().out))
    keys = ("vertices", "ids", "shared_ids", "vertices_sharing")
    assert [summaries[0][k] for k in keys] == [summaries[1][k] for k in keys]
    assert summaries[0]["vertices"] == 193_125


@needs_data
@needs_node_tools
def test_dynamic_time_on_a_meshopt_file_matches_the_plain_copy(tmp_path):
    # the morph targets and the weights animation are meshopt-compressed (gltfpack -cc)
    src = SAMPLES / "AnimatedMorphCube" / "glTF-Binary" / "AnimatedMorphCube.glb"
    packed = tmp_path / "packed.glb"
    _node_tool("gltfpack", "-i", src, "-o", packed, "-cc")
    assert GltfFile(packed, GltfReadOptions()).decoded == ["EXT_meshopt_compression"]
    plain = _plain_copy(packed, tmp_path / "plain.glb")
    out = {}
    for name, f in (("packed", packed), ("plain", plain), ("source", src)):
        assert main(["dynamic", str(f), "--time", "1.0", "-o", str(tmp_path / f"{name}.npy")]) == 0
        out[name] = np.load(tmp_path / f"{name}.npy")
    np.testing.assert_allclose(out["packed"], out["plain"], rtol=0, atol=1e-6)
    # and the source's, to within gltfpack's quantization of the morph deltas
    np.testing.assert_allclose(out["packed"], out["source"], rtol=0, atol=2e-3)
    assert out["source"].min() > 0.4  # the cube really deforms at t = 1 s


def _meshopt_gltf(path: Path, pos: np.ndarray, uv: np.ndarray, idx: np.ndarray, mode: str) -> Path:
    """A glTF whose three bufferViews are meshopt-compressed by PyPI meshoptimizer's encoder
    (the fallback buffer 1 holds no data, as gltfpack writes it)."""
    streams = [
        (meshoptimizer.encode_vertex_buffer(pos, len(pos), 12), 12, len(pos), "ATTRIBUTES"),
        (meshoptimizer.encode_vertex_buffer(uv, len(uv), 8), 8, len(uv), "ATTRIBUTES"),
    ]
    encode = (
        meshoptimizer.encode_index_buffer
        if mode == "TRIANGLES"
        else meshoptimizer.encode_index_sequence
    )
    streams.append(
        (encode(idx.astype(np.uint32), len(idx), len(pos)), idx.itemsize, len(idx), mode)
    )
    blob, views = b"", []
    for data, stride, count, m in streams:
        blob += b"\0" * (-len(blob) % 4)
        ext = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        ext.update(byteStride=stride, count=count, mode=m)
        view = {"buffer": 1, "byteLength": stride * count}
        if m == "ATTRIBUTES":  # index views have no byteStride (the extension has it)
            view["byteStride"] = stride
        view["extensions"] = {"EXT_meshopt_compression": ext}
        views.append(view)
        blob += data
    comp = {2: 5123, 4: 5125}[idx.itemsize]
    tree = {
        "asset": {"version": "2.0"},
        "buffers": [
            {
                "byteLength": len(blob),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode(),
            },
            {
                "byteLength": sum(v["byteLength"] for v in views),
                "extensions": {"EXT_meshopt_compression": {"fallback": True}},
            },
        ],
        "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": len(pos), "type": "VEC3"},
            {"bufferView": 1, "componentType": 5126, "count": len(uv), "type": "VEC2"},
            {"bufferView": 2, "componentType": comp, "count": len(idx), "type": "SCALAR"},
        ],
        "meshes": [
            {"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2}]}
        ],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "extensionsUsed": ["EXT_meshopt_compression"],
        "extensionsRequired": ["EXT_meshopt_compression"],
    }
    path.write_text(json.dumps(tree))
    return path


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_vertices=st.integers(3, 300),
    n_triangles=st.integers(1, 200),
    index_bytes=st.sampled_from([2, 4]),
    mode=st.sampled_from(["TRIANGLES", "INDICES"]),
)
def test_meshopt_is_lossless_through_ingest(
    tmp_path_factory, seed, n_vertices, n_triangles, index_bytes, mode
):
    # law: meshopt is lossless, so ingest returns the encoded arrays (the TRIANGLES codec may
    # rotate a triangle's corners, winding kept); 2-byte indices exercise the decoder's
    # uint32-array trap
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-1, 1, (n_vertices, 3)).astype(np.float32)
    uv = rng.uniform(0, 1, (n_vertices, 2)).astype(np.float32)
    # three distinct corners per triangle: the first 3 of a random permutation of the vertices
    tris = np.argsort(rng.random((n_triangles, n_vertices)), axis=1)[:, :3]
    idx = tris.reshape(-1).astype(np.uint16 if index_bytes == 2 else np.uint32)
    f = _meshopt_gltf(tmp_path_factory.mktemp("mo") / "m.gltf", pos, uv, idx, mode)
    (m,) = read_gltf_meshes(f)
    assert m.notes[0] == "decoded EXT_meshopt_compression"
    np.testing.assert_array_equal(m.positions, pos)
    np.testing.assert_array_equal(m.uvs, uv)
    got = m.indices.astype(np.int64)
    if mode == "INDICES":
        np.testing.assert_array_equal(got, tris)
    else:  # each triangle rotated to start at its smallest index
        rot = (np.argmin(got, 1)[:, None] + np.arange(3)) % 3
        want = (np.argmin(tris, 1)[:, None] + np.arange(3)) % 3
        np.testing.assert_array_equal(
            np.take_along_axis(got, rot, 1), np.take_along_axis(tris, want, 1)
        )
