"""wrinklepipe.gltf: read a glTF whole, write it back losing nothing.

Accessor decoding against hand-computed values; real files (RobotExpressive, DamagedHelmet,
LittlestTokyo) read back by an independent reader (pygltflib + tests/gltf_reference.py); meshopt
and quantized files made with the real encoder (npm gltfpack) compared with the uncompressed
original within the quantization step; the Khronos validator on every output.
"""

from __future__ import annotations

import base64
import json
import shutil
import subprocess
from pathlib import Path

import gltf_reference as ref
import numpy as np
import pytest
from output_hashes import assert_unchanged
from scipy.spatial import cKDTree
from wrinkle_setups import write_tokyo_setup

from wrinklepipe.errors import InputError
from wrinklepipe.gltf.document import read_document
from wrinklepipe.gltf.repair import repair
from wrinklepipe.gltf.scene import node_world_matrices, primitive_triangles, rest_positions
from wrinklepipe.gltf.write import write_document
from wrinklepipe.io import khronos
from wrinklepipe.io.confine import allowed_roots
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.paths import ROOT

SAMPLES = Path(__file__).resolve().parents[2] / "shared" / "data" / "gltf-samples"
ROBOT = SAMPLES / "RobotExpressive" / "RobotExpressive.glb"
HELMET = SAMPLES / "DamagedHelmet" / "glTF-Binary" / "DamagedHelmet.glb"
TOKYO = SAMPLES / "LittlestTokyo" / "LittlestTokyo.glb"
needs_data = pytest.mark.skipif(not SAMPLES.is_dir(), reason="../shared/data is absent")
GLTFPACK = ROOT / "tools" / "node" / "node_modules" / ".bin" / "gltfpack"
needs_gltfpack = pytest.mark.skipif(
    not GLTFPACK.exists() or shutil.which("node") is None, reason="npm gltfpack not installed"
)
needs_validator = pytest.mark.skipif(not khronos.available(), reason="gltf-validator missing")


def gltf_file(tmp_path: Path, blob: bytes, tree: dict, name: str = "t.gltf") -> Path:
    uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    full = {"asset": {"version": "2.0"}, "buffers": [{"byteLength": len(blob), "uri": uri}]}
    full.update(tree)
    p = tmp_path / name
    p.write_text(json.dumps(full))
    return p


# -- accessors on tiny literal buffers --------------------------------------------------------


def test_strided_normalized_and_signed_accessors(tmp_path):
    # two interleaved vertices: int8 normalized VEC3 (padded to 4) + uint16 normalized VEC2
    blob = bytes([127, 0x81, 0, 0, 0xFF, 0xFF, 0x00, 0x80])  # v0: (1, -127/127, 0), (1, 0.5)
    blob += bytes([0x80, 64, 1, 0, 0, 0, 0xFF, 0x7F])  # v1: (-128 -> -1, 64/127, 1/127), (0, ..)
    tree = {
        "bufferViews": [{"buffer": 0, "byteLength": 16, "byteStride": 8}],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5120,
                "count": 2,
                "type": "VEC3",
                "normalized": True,
            },
            {
                "bufferView": 0,
                "byteOffset": 4,
                "componentType": 5123,
                "count": 2,
                "type": "VEC2",
                "normalized": True,
            },
        ],
    }
    doc = read_document(gltf_file(tmp_path, blob, tree))
    np.testing.assert_array_equal(
        doc.accessor(0), np.float32([[1, -1, 0], [-1, 64 / 127, 1 / 127]])
    )
    np.testing.assert_allclose(doc.accessor(1), [[1, 0x8000 / 65535], [0, 0x7FFF / 65535]])
    raw = doc.accessor(0, normalize=False)
    assert raw.dtype == np.int8 and raw.tolist() == [[127, -127, 0], [-128, 64, 1]]


def test_mat2_of_bytes_pads_columns_and_sparse_substitutes(tmp_path):
    # MAT2 of uint8: each 2-byte column padded to 4 bytes (spec 3.6.2.4)
    mat = bytes([1, 2, 0, 0, 3, 4, 0, 0])
    # sparse: base accessor without bufferView (zeros), indices uint8 [1, 3], values float
    idx = bytes([1, 3, 0, 0])
    vals = np.float32([[5, 6], [7, 8]]).tobytes()
    blob = mat + idx + vals
    tree = {
        "bufferViews": [
            {"buffer": 0, "byteLength": 8},
            {"buffer": 0, "byteOffset": 8, "byteLength": 2},
            {"buffer": 0, "byteOffset": 12, "byteLength": 16},
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5121, "count": 1, "type": "MAT2"},
            {
                "componentType": 5126,
                "count": 4,
                "type": "VEC2",
                "sparse": {
                    "count": 2,
                    "indices": {"bufferView": 1, "componentType": 5121},
                    "values": {"bufferView": 2},
                },
            },
        ],
    }
    doc = read_document(gltf_file(tmp_path, blob, tree))
    assert doc.accessor(0).tolist() == [[1, 2, 3, 4]]
    assert doc.accessor(1).tolist() == [[0, 0], [5, 6], [0, 0], [7, 8]]


@pytest.mark.parametrize(
    "accessor, message",
    [
        ({"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}, "needs 36 bytes"),
        ({"bufferView": 0, "componentType": 5126, "count": 1, "type": "VEC9"}, "bad componentType"),
        ({"bufferView": 7, "componentType": 5126, "count": 1, "type": "VEC3"}, "bufferView 7"),
    ],
)
def test_bad_accessors_name_the_file_and_pointer(tmp_path, accessor, message):
    tree = {"bufferViews": [{"buffer": 0, "byteLength": 12}], "accessors": [accessor]}
    doc = read_document(gltf_file(tmp_path, bytes(12), tree))
    with pytest.raises(InputError) as exc:
        doc.accessor(0)
    assert message in str(exc.value) and "t.gltf" in str(exc.value)


def test_uri_outside_the_folder_is_refused(tmp_path):
    tree = {"images": [{"uri": "../secret.png"}]}
    p = gltf_file(tmp_path, bytes(4), tree)
    with pytest.raises(InputError, match="leaves the asset folder"):
        read_document(p)


def test_truncated_glb_is_refused(tmp_path):
    p = tmp_path / "bad.glb"
    p.write_bytes(b"glTF" + (2).to_bytes(4, "little") + (99).to_bytes(4, "little") + bytes(8))
    with pytest.raises(InputError, match="length field"):
        read_document(p)


def test_external_images_are_copied_byte_for_byte(tmp_path):
    src = tmp_path / "src"
    (src / "maps").mkdir(parents=True)
    png = b"\x89PNG\r\n\x1a\n" + bytes(range(40))  # bytes are copied, never decoded
    (src / "maps" / "a b.png").write_bytes(png)
    p = gltf_file(src, bytes(4), {"images": [{"uri": "maps/a%20b.png"}]}, "x.gltf")
    doc = read_document(p)
    out = tmp_path / "out"
    write_document(doc, out / "x.gltf")
    assert (out / "maps" / "a b.png").read_bytes() == png
    write_document(doc, out / "x.glb")
    g = ref.load(out / "x.glb")
    assert ref.image_bytes(g, out / "x.glb", 0) == png
    assert g.images[0].mimeType == "image/png" and g.images[0].uri is None


# -- real files --------------------------------------------------------------------------------


def _tree_without_buffers(g) -> dict:
    d = json.loads(g.to_json())
    for k in ("buffers", "bufferViews"):
        d.pop(k, None)
    for a in d.get("accessors", []):
        a.pop("bufferView", None)
    for img in d.get("images", []):
        img.pop("bufferView", None)
    return d


@needs_data
def test_robot_round_trip_keeps_every_element_and_every_value(tmp_path):
    out = tmp_path / "robot.glb"
    write_document(read_document(ROBOT), out)
    a, b = ref.load(ROBOT), ref.load(out)
    assert _tree_without_buffers(a) == _tree_without_buffers(b)
    assert len(a.accessors) == len(b.accessors) == 283
    for i, acc in enumerate(a.accessors):
        va, vb = ref.accessor(a, ROBOT, i), ref.accessor(b, out, i)
        assert va.dtype == vb.dtype and np.array_equal(va, vb), i
        assert acc.componentType == b.accessors[i].componentType


@needs_data
@needs_validator
def test_robot_repairs_leave_no_validator_error(tmp_path):
    src = khronos.validate_gltf(ROBOT)
    assert src["issues"]["numErrors"] > 0  # the sample's hand weights sum to up to 1.755
    doc = read_document(ROBOT)
    notes = repair(doc)
    assert len(notes) == 4 and all("did not sum to 1" in n for n in notes)
    out = tmp_path / "robot.glb"
    write_document(doc, out)
    assert khronos.validate_gltf(out)["issues"]["numErrors"] == 0
    g = ref.load(out)
    for mesh in (12, 13):  # the hands: new weight accessors, rows sum to 1
        for prim in g.meshes[mesh].primitives:
            w = ref.accessor(g, out, prim.attributes.WEIGHTS_0)
            np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-6)


def _soup(path: Path, float_bits: int = 14) -> tuple[np.ndarray, np.ndarray]:
    """Rest-pose world positions of every triangle corner, and each corner's quantization
    bound as a 3-D length: half a grid step of the node's scale for integer positions, one
    step of a ``float_bits`` mantissa for float positions (gltfpack -vpf rounds the mantissa)."""
    doc = read_document(path)
    worlds = node_world_matrices(doc)
    pts, bounds = [], []
    for ni, node in enumerate(doc.array("nodes")):
        if "mesh" not in node:
            continue
        for r in (r for r in doc.primitives() if r.mesh == node["mesh"]):
            tri = primitive_triangles(doc, r)
            p = rest_positions(doc, r, ni, worlds)[tri].reshape(-1, 3)
            pts.append(p)
            pa = doc.primitive(r)["attributes"]["POSITION"]
            scale = np.linalg.norm(worlds[ni][:3, :3], 2)
            if doc.array("accessors")[pa]["componentType"] == 5126:
                local = np.abs(doc.accessor(pa)).max(axis=1)[tri].reshape(-1)
                bounds.append(np.sqrt(3) * scale * local * 2.0**-float_bits)
            else:
                bounds.append(np.full(len(p), 0.5 * np.sqrt(3) * scale))
    return np.concatenate(pts), np.concatenate(bounds)


def _pack(tmp_path: Path, src: Path, name: str, *flags: str) -> Path:
    out = tmp_path / name
    subprocess.run(
        [str(GLTFPACK), "-i", str(src), "-o", str(out), "-kn", "-km", *flags],
        check=True,
        capture_output=True,
        timeout=120,
    )
    return out


@needs_data
@needs_gltfpack
@needs_validator
@pytest.mark.parametrize(
    "flags",
    [("-c", "-vpf", "-vtf", "-vnf"), ("-c",), ("-cc",), ()],
    ids=["meshopt-float", "meshopt-quantized", "meshopt-filters", "quantized-only"],
)
def test_gltfpack_helmet_decodes_to_the_original_geometry(tmp_path, flags):
    packed = _pack(tmp_path, HELMET, "h.glb", *flags)
    doc = read_document(packed)
    assert ("EXT_meshopt_compression" in doc.decoded_extensions) == bool(flags)
    a, _ = _soup(HELMET)
    b, bound = _soup(packed)
    assert len(a) == len(b) == 46356  # every triangle corner is there
    dist, _ = cKDTree(a).query(b)
    assert np.all(dist <= bound * (1 + 1e-3) + 1e-7)
    assert 0 < dist.max()  # the quantization is real, and the bound is not loose by much
    assert dist.max() > 0.1 * bound.max()
    back, _ = cKDTree(b).query(a)
    assert back.max() <= bound.max() * (1 + 1e-3)
    out = tmp_path / "out.glb"
    write_document(doc, out)
    g = json.loads(ref.load(out).to_json())
    assert "EXT_meshopt_compression" not in g.get("extensionsUsed", [])
    was = json.loads(ref.load(packed).to_json()).get("extensionsRequired", [])
    # quantized accessors are kept as they are, so the extension stays required
    assert ("KHR_mesh_quantization" in g.get("extensionsRequired", [])) == (
        "KHR_mesh_quantization" in was
    )
    assert khronos.validate_gltf(out)["issues"]["numErrors"] == 0
    src = ref.load(packed)
    for i in range(len(src.images)):  # textures pass through byte for byte
        assert ref.image_bytes(src, packed, i) == ref.image_bytes(ref.load(out), out, i)


@needs_data
@needs_gltfpack
def test_gltfpack_robot_keeps_its_parts(tmp_path):
    doc = read_document(_pack(tmp_path, ROBOT, "r.glb", "-cc", "-ke"))
    assert doc.decoded_extensions == ["EXT_meshopt_compression"]
    assert len(doc.array("animations")) == 14 and len(doc.array("skins")) == 2
    names = {doc.material_name(i) for i in range(len(doc.array("materials")))}
    assert names == {"Grey", "Main", "Black"}
    # gltfpack drops mesh names and moves meshes under child nodes; the morph names stay
    morphed = [i for i in range(len(doc.array("meshes"))) if doc.target_names(i)]
    assert [doc.target_names(i) for i in morphed] == [["Angry", "Surprised", "Sad"]]


@needs_data
@needs_validator
def test_littlest_tokyo_draco_decodes_inside_the_encoder_bounds(tmp_path):
    doc = read_document(TOKYO)
    assert doc.decoded_extensions == ["KHR_draco_mesh_compression"]
    g = ref.load(TOKYO)
    n_prims = 0
    for r in doc.primitives():
        prim = doc.primitive(r)
        for sem, ai in prim["attributes"].items():
            acc = g.accessors[ai]
            v = doc.accessor(ai)
            assert v.shape == (acc.count, {"VEC2": 2, "VEC3": 3, "VEC4": 4}[acc.type])
            if acc.min is not None and sem in ("POSITION", "TEXCOORD_0"):
                # min/max were written by the encoder from the original data: the decoded
                # values lie inside them to within Draco's quantization step (Draco quantizes
                # every axis with the step of the largest one)
                span = np.float64(acc.max) - np.float64(acc.min)
                step = span.max() / (2**11 - 1) + 1e-6  # one step of the largest axis
                assert np.all(v >= np.float64(acc.min) - step), (r, sem)
                assert np.all(v <= np.float64(acc.max) + step), (r, sem)
        tris = primitive_triangles(doc, r)
        assert len(tris) * 3 == g.accessors[prim["indices"]].count
        n_prims += 1
    assert n_prims == 71
    out = tmp_path / "tokyo.glb"
    repair(doc)
    write_document(doc, out)
    issues = khronos.validate_gltf(out)["issues"]
    codes = {m["code"] for m in issues["messages"] if m["severity"] == 0}
    # the only errors left are the source's own animation keys (times that repeat), which a
    # repair would have to change: nothing that decoding or packing introduced
    assert codes == {"ACCESSOR_ANIMATION_INPUT_NON_INCREASING"}
    assert "KHR_draco_mesh_compression" not in json.loads(ref.load(out).to_json()).get(
        "extensionsUsed", []
    )


@needs_data
def test_littlest_tokyo_converts_to_the_recorded_bytes(tmp_path):
    """LittlestTokyo's skinned body wrinkled (``wrinkle_setups.write_tokyo_setup``): every file
    of the conversion as recorded on main (``tests/output_hashes.py``). Exit 1: the validator
    finds the body's tangents off MikkTSpace (WP-MESH-002); the files are written all the same."""
    with allowed_roots([TOKYO.parent]):
        res = convert(
            write_tokyo_setup(tmp_path / "src"),
            tmp_path / "out",
            ConvertOptions(glb=True, render=False),
        )
    assert res.exit_code == 1
    assert [i["code"] for i in res.report["validation"]["issues"] if i["severity"] == "error"] == [
        "WP-MESH-002"
    ]
    assert_unchanged("tokyo", tmp_path / "out")
