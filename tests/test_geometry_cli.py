"""``wrinklepipe vertex-ids`` and ``wrinklepipe dynamic``: outputs, rerun identity, exit codes."""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np

from wrinklepipe.cli import main
from wrinklepipe.geometry.primitives import tube


def tube_gltf(path: Path) -> Path:
    """A tube with a UV seam and one morph target "squash" (top half squashed along the axis)."""
    m = tube(16, 4, length=2.0)
    p = m.positions
    d = np.zeros_like(p)
    top = p[:, 1] > 1.0
    d[top, 1] = -(p[top, 1] - 1.0) * 0.5
    arrays = [p, m.indices.reshape(-1).astype(np.uint32), m.uvs, d]
    blob = b""
    views = []
    for a in arrays:
        views.append({"buffer": 0, "byteOffset": len(blob), "byteLength": a.nbytes})
        blob += np.ascontiguousarray(a).tobytes()
    acc = [
        {"bufferView": 0, "componentType": 5126, "count": len(p), "type": "VEC3"},
        {"bufferView": 1, "componentType": 5125, "count": m.indices.size, "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5126, "count": len(p), "type": "VEC2"},
        {"bufferView": 3, "componentType": 5126, "count": len(p), "type": "VEC3"},
    ]
    acc[0]["min"] = p.min(0).tolist()
    acc[0]["max"] = p.max(0).tolist()
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [
            {
                "byteLength": len(blob),
                "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode(),
            }
        ],
        "bufferViews": views,
        "accessors": acc,
        "meshes": [
            {
                "primitives": [
                    {
                        "attributes": {"POSITION": 0, "TEXCOORD_0": 2},
                        "indices": 1,
                        "targets": [{"POSITION": 3}],
                    }
                ],
                "extras": {"targetNames": ["squash"]},
            }
        ],
        "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
    }
    path.write_text(json.dumps(doc))
    return path


def test_vertex_ids_command(tmp_path, capsys):
    f = tube_gltf(tmp_path / "tube.gltf")
    out = tmp_path / "ids.npy"
    assert main(["vertex-ids", str(f), "-o", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    # 17 columns x 5 rings with the seam column duplicated: 16 x 5 distinct positions.
    assert summary["vertices"] == 85 and summary["ids"] == 80
    assert summary["shared_ids"] == 5 and summary["vertices_sharing"] == 10
    ids = np.load(out)
    np.testing.assert_array_equal(ids.reshape(5, 17)[:, 0], ids.reshape(5, 17)[:, -1])
    first = out.read_bytes()
    assert main(["vertex-ids", str(f), "-o", str(out)]) == 0
    assert out.read_bytes() == first  # byte-identical rerun
    js = tmp_path / "ids.json"
    assert main(["vertex-ids", str(f), "-o", str(js)]) == 0
    assert json.loads(js.read_text())["values"] == ids.tolist()


def test_vertex_ids_bad_arguments_exit_2(tmp_path, capsys):
    f = tube_gltf(tmp_path / "tube.gltf")
    assert main(["vertex-ids", str(f), "--tolerance", "-1"]) == 2
    assert main(["vertex-ids", str(tmp_path / "nope.glb")]) == 2
    assert main(["vertex-ids", str(f), "-o", str(tmp_path / "ids.xyz")]) == 2
    assert main(["vertex-ids", str(f), "-o", str(f)]) == 2  # never overwrite the input
    err = capsys.readouterr().err
    assert "Traceback" not in err and "error:" in err


def test_dynamic_command_morph_and_pose(tmp_path, capsys):
    f = tube_gltf(tmp_path / "tube.gltf")
    out = tmp_path / "w.npy"
    args = ["dynamic", str(f), "--morph", "squash=1", "-o", str(out)]
    assert main([*args, "--texture-space", "64", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    w = np.load(out)
    m = tube(16, 4, length=2.0)
    y = m.positions[:, 1]
    # The top ring pair is squashed to half its height: w = 0.5 there; the bottom is untouched.
    np.testing.assert_allclose(w[y > 1.6], 0.5, atol=1e-5)
    np.testing.assert_allclose(w[y < 0.6], 0.0, atol=1e-6)
    assert s["seam_jump_max"] == 0.0 and s["compressed_vertices"] > 0
    assert s["texture_space"]["seam_jump_max"] >= 0.0
    # The same pose given as positions.
    pose = tmp_path / "pose.npy"
    p = m.positions.astype(np.float64)
    p[y > 1.0, 1] = 1.0 + (p[y > 1.0, 1] - 1.0) * 0.5
    np.save(pose, p)
    out2 = tmp_path / "w2.npy"
    assert main(["dynamic", str(f), "--pose", str(pose), "-o", str(out2)]) == 0
    np.testing.assert_allclose(np.load(out2), w, atol=1e-6)


def test_dynamic_bad_inputs_exit_2(tmp_path, capsys):
    f = tube_gltf(tmp_path / "tube.gltf")
    o = str(tmp_path / "w.npy")
    assert main(["dynamic", str(f), "--morph", "nope=1", "-o", o]) == 2
    assert main(["dynamic", str(f), "--morph", "squash", "-o", o]) == 2
    bad = tmp_path / "bad.npy"
    np.save(bad, np.zeros((3, 3)))
    assert main(["dynamic", str(f), "--pose", str(bad), "-o", o]) == 2
    assert main(["dynamic", str(f), "--time", "1", "-o", o]) == 2  # no animation
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert "unknown morph" in err and "NAME=WEIGHT" in err and "pose has shape" in err
