"""``wrinklepipe bake``: weight curves (JSON, CSV), pre-blended maps only when weights change."""

from __future__ import annotations

import json

import numpy as np
import pytest

from wrinklepipe.cli import main
from wrinklepipe.demo.character import generate
from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.drivers.bake import changed_frames
from wrinklepipe.io.images import read_image
from wrinklepipe.masks import read_mask, resample_masks
from wrinklepipe.metrics import angle_deg

SIZE = 64

CURVES = """
[[drivers]]
kind = "curves"
interpolation = "linear"
fps = 2
[drivers.keys]
glabella = [[0.0, 0.0], [1.0, 1.0], [2.0, 1.0]]
chin = [[0.0, 0.0], [2.0, 0.0]]
"""


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    folder = tmp_path_factory.mktemp("demo")
    manifest = write_demo_source(folder, size=SIZE)
    return manifest


def _with_driver(demo, tmp_path, text):
    src = demo.read_text()
    # keep only the header, states and regions; replace the demo's drivers
    head = src.split("[[drivers]]")[0]
    p = demo.parent / f"m_{abs(hash(text)) % 10**8}.toml"
    p.write_text(head + text)
    return p


def test_changed_frames_skips_repeats():
    w = np.array([0, 0.5, 1, 1, 1, 0.5, 0.5], float)[:, None, None]
    np.testing.assert_array_equal(changed_frames(w), [0, 1, 2, 2, 2, 5, 5])
    w2 = np.array([0, 0.001, 0.002, 0.5], float)[:, None, None]
    np.testing.assert_array_equal(changed_frames(w2, tolerance=0.0015), [0, 0, 2, 3])


def test_bake_curves_with_maps(demo, tmp_path, capsys):
    m = _with_driver(demo, tmp_path, CURVES)
    out = tmp_path / "out"
    assert main(["bake", str(m), "--maps", "-o", str(out)]) == 0
    err = " ".join(capsys.readouterr().err.split())
    assert "rendered 3 maps; skipped 2 frames" in err
    doc = json.loads((out / "weights.json").read_text())
    assert doc["times"] == [0.0, 0.5, 1.0, 1.5, 2.0]
    g = doc["regions"].index("glabella")
    assert [f[g][0] for f in doc["weights"]] == [0.0, 0.5, 1.0, 1.0, 1.0]
    assert doc["maps"]["files"][3] == "maps/frame_00002.png"
    assert sorted(p.name for p in (out / "maps").iterdir()) == [
        "frame_00000.png",
        "frame_00001.png",
        "frame_00002.png",
    ]
    csv = (out / "weights.csv").read_text().splitlines()
    assert csv[0].startswith("time,forehead_outer_l:stretch,forehead_outer_l:compress")
    assert csv[3].split(",")[1 + 2 * g] == "1.000000"
    # The map at full glabella weight is the analytic normal of base + a * (both wrinkle
    # heights) in slope space, a = the glabella mask (PD blending is exact in slopes).
    c = generate(SIZE)
    a = resample_masks(read_mask(demo.parent / "masks" / "glabella.png")[0][None], SIZE)[0]
    slopes = _slopes(c.base_height) + a[..., None] * _slopes(c.wrinkle_heights.sum(axis=0))
    expected = slopes_to_normal(slopes)
    got = read_image(out / "maps" / "frame_00002.png")[0] * 2 - 1
    assert float(a.max()) > 0.2
    err_deg = angle_deg(got, expected)
    assert float(err_deg.max()) < 0.01  # 16-bit quantisation only (measured 0.002 deg)
    # at zero weight, the base
    base = read_image(out / "maps" / "frame_00000.png")[0] * 2 - 1
    assert float(angle_deg(base, c.base_normal).max()) < 0.2
    # byte-identical rerun
    out2 = tmp_path / "out2"
    assert main(["bake", str(m), "--maps", "-o", str(out2)]) == 0
    for f in ["weights.json", "weights.csv", "maps/frame_00001.png"]:
        assert (out / f).read_bytes() == (out2 / f).read_bytes()


def _slopes(h):
    """(-dh/dx, -dh/dy) with x along columns and y up (rows run down): independent of the code."""
    d_row, d_col = np.gradient(np.asarray(h, np.float64))
    return np.stack([-d_col, d_row], axis=-1)


def slopes_to_normal(s):
    n = np.concatenate([s, np.ones(s.shape[:-1] + (1,))], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def test_bake_expressions_driver_of_the_demo(demo, tmp_path):
    out = tmp_path / "e"
    assert main(["bake", str(demo), "-o", str(out), "--json"]) == 0
    doc = json.loads((out / "weights.json").read_text())
    assert doc["kind"] == "expressions" and doc["policy"] == "clamp01"
    t = doc["times"].index(1.0)  # joy fully on at t = 1
    assert doc["weights"][t][0] == [1.0, 1.0]  # forehead_outer_l, Table 1.1


def _one_error(capsys, argv):
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err
    assert len([ln for ln in err.splitlines() if ln.startswith("error:")]) == 1, err
    return " ".join(err.split())


def test_bake_row_naming_an_unknown_blend_shape(demo, tmp_path, capsys):
    text = """
[[drivers]]
kind = "blendshapes"
rows = [["brow_raise", "glabella", 0, 1, 1, 0], ["brow_raize", "chin", 0, 1, 1, 0]]
[drivers.keys]
brow_raise = [[0.0, 0.0], [1.0, 1.0]]
"""
    m = _with_driver(demo, tmp_path, text)
    msg = _one_error(capsys, ["bake", str(m), "-o", str(tmp_path / "o")])
    assert "unknown blend shape 'brow_raize'" in msg and "rows[1]" in msg
    assert "brow_raise" in msg  # lists what the mesh has
    assert not (tmp_path / "o").exists()


def test_bake_blendshapes_with_the_demo_morphs(demo, tmp_path):
    text = """
[[drivers]]
kind = "blendshapes"
rows = [["brow_furrow", "glabella", 0, 1, 1, 0], ["chin_raise", "chin", 0, 1, 2, 0]]
fps = 2
[drivers.keys]
brow_furrow = [[0.0, 0.0], [1.0, 1.0]]
chin_raise = [[0.0, 0.0], [1.0, 0.25]]
"""
    m = _with_driver(demo, tmp_path, text)
    out = tmp_path / "b"
    assert main(["bake", str(m), "-o", str(out)]) == 0
    doc = json.loads((out / "weights.json").read_text())
    g, c = doc["regions"].index("glabella"), doc["regions"].index("chin")
    assert [f[g][1] for f in doc["weights"]] == [0.0, 0.5, 1.0]
    assert [f[c][0] for f in doc["weights"]] == [0.0, 0.25, 0.5]


def test_bake_missing_driver_kind(demo, tmp_path, capsys):
    msg = _one_error(capsys, ["bake", str(demo), "--driver", "bones", "-o", str(tmp_path / "o")])
    assert "no [[drivers]] of kind = 'bones'" in msg


def test_bake_bones_per_vertex_from_the_manifest(demo, tmp_path, capsys):
    bones = {
        "times": [0.0, 1.0],
        "bones": {"brow": [[0, 0, 0], [0, 0.5, 0]], "jaw": [[0, 0, 0], [0, 0, 0]]},
        "skin": {"joints": ["brow", "jaw"], "weights": [[1, 0], [0, 1], [0.5, 0.5]]},
    }
    (demo.parent / "bones.json").write_text(json.dumps(bones))
    text = """
[[drivers]]
kind = "bones"
file = "bones.json"
poses = [
  {name = "neutral", bones = {brow = [0, 0, 0], jaw = [0, 0, 0]}},
  {name = "compress", bones = {brow = [0, 1, 0], jaw = [0, -1, 0]}},
]
"""
    m = _with_driver(demo, tmp_path, text)
    out = tmp_path / "bones"
    assert main(["bake", str(m), "-o", str(out)]) == 0
    doc = json.loads((out / "weights.json").read_text())
    assert doc["per_vertex"] and doc["states"] == ["compress"]
    # t = 1: brow alpha 0.5 -> theta 0.5; jaw does not move -> 0
    assert doc["weights"][1] == [[0.5], [0.0], [0.5]]
    msg = _one_error(capsys, ["bake", str(m), "--maps", "-o", str(tmp_path / "m")])
    assert "per-vertex weights" in msg


@pytest.mark.parametrize("encoding", ["full", "diff"])
def test_bake_maps_other_encodings(demo, tmp_path, encoding):
    """``full``/``diff``: N = normalize(B + sum_k a (W_k - B)), from the analytic demo normals."""
    m = _with_driver(demo, tmp_path, CURVES)
    m.write_text(m.read_text().replace('encoding = "pd"', f'encoding = "{encoding}"'))
    out = tmp_path / encoding
    assert main(["bake", str(m), "--maps", "--start", "1", "--end", "1", "-o", str(out)]) == 0
    c = generate(SIZE)
    a = resample_masks(read_mask(demo.parent / "masks" / "glabella.png")[0][None], SIZE)[0]
    b = c.base_normal.astype(np.float64)
    n = b + a[..., None] * sum(c.wrinkled_normal(k) - b for k in range(2))
    expected = n / np.linalg.norm(n, axis=-1, keepdims=True)
    got = read_image(out / "maps" / "frame_00000.png")[0] * 2 - 1
    assert float(angle_deg(got, expected).max()) < 0.01
