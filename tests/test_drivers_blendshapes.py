"""Blend-shape driver: RigLogic conditional-table rows, and the ARKit-52 preset on a real glTF."""

from __future__ import annotations

import numpy as np
import pygltflib
import pytest

from wrinklepipe import drivers as wd
from wrinklepipe.drivers.blendshapes import Row, evaluate_rows
from wrinklepipe.gltf.animation import read_morph_tracks
from wrinklepipe.presets import arkit, jimenez


def make_morph_gltf(path, names, times, weights, interpolation="LINEAR"):
    """A one-triangle GLB with named morph targets and an animation of their weights.

    ``weights`` is ``[len(times), len(names)]`` (or ``[len(times), 3, len(names)]`` for
    CUBICSPLINE: in-tangent, value, out-tangent)."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    delta = np.zeros((3, 3), np.float32)
    idx = np.array([0, 1, 2], np.uint16)
    t = np.asarray(times, np.float32)
    w = np.asarray(weights, np.float32).reshape(-1)
    chunks = [pos.tobytes(), delta.tobytes(), idx.tobytes() + b"\0\0", t.tobytes(), w.tobytes()]
    targets = [pygltflib.ARRAY_BUFFER, pygltflib.ARRAY_BUFFER, pygltflib.ELEMENT_ARRAY_BUFFER]
    views, off = [], 0
    for i, c in enumerate(chunks):
        tgt = targets[i] if i < 3 else None
        views.append(pygltflib.BufferView(buffer=0, byteOffset=off, byteLength=len(c), target=tgt))
        off += len(c)
    acc = [
        pygltflib.Accessor(
            bufferView=0,
            componentType=pygltflib.FLOAT,
            count=3,
            type="VEC3",
            min=[0, 0, 0],
            max=[1, 1, 0],
        ),
        pygltflib.Accessor(
            bufferView=1,
            componentType=pygltflib.FLOAT,
            count=3,
            type="VEC3",
            min=[0, 0, 0],
            max=[0, 0, 0],
        ),
        pygltflib.Accessor(
            bufferView=2, componentType=pygltflib.UNSIGNED_SHORT, count=3, type="SCALAR"
        ),
        pygltflib.Accessor(
            bufferView=3,
            componentType=pygltflib.FLOAT,
            count=len(t),
            type="SCALAR",
            min=[float(t.min())],
            max=[float(t.max())],
        ),
        pygltflib.Accessor(
            bufferView=4, componentType=pygltflib.FLOAT, count=w.size, type="SCALAR"
        ),
    ]
    prim = pygltflib.Primitive(
        attributes=pygltflib.Attributes(POSITION=0),
        indices=2,
        targets=[{"POSITION": 1} for _ in names],
    )
    g = pygltflib.GLTF2(
        scene=0,
        scenes=[pygltflib.Scene(nodes=[0])],
        nodes=[pygltflib.Node(mesh=0)],
        meshes=[
            pygltflib.Mesh(
                primitives=[prim],
                weights=[0.0] * len(names),
                extras={"targetNames": list(names)},
            )
        ],
        accessors=acc,
        bufferViews=views,
        buffers=[pygltflib.Buffer(byteLength=off)],
        animations=[
            pygltflib.Animation(
                samplers=[
                    pygltflib.AnimationSampler(input=3, output=4, interpolation=interpolation)
                ],
                channels=[
                    pygltflib.AnimationChannel(
                        sampler=0, target=pygltflib.AnimationChannelTarget(node=0, path="weights")
                    )
                ],
            )
        ],
    )
    g.set_binary_blob(b"".join(chunks))
    g.save_binary(str(path))
    return path


def _assert_valid_gltf(path):
    from wrinklepipe.io import khronos

    if not khronos.available():
        return
    report = khronos.validate_gltf(path)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"]
    assert report["issues"]["numWarnings"] == 0, report["issues"]["messages"]


def test_rows_follow_riglogic_intervals_and_clamp():
    rows = [
        Row("smile", "fold", 0.0, 0.5, 0.5, 0.0),
        Row("smile", "fold", 0.5, 1.0, 1.5, -0.5),
        Row("a", "sum", 0.0, 1.0, 0.6, 0.0),
        Row("b", "sum", 0.0, 1.0, 0.6, 0.0),
        Row("b", "neg", 0.0, 1.0, -1.0, 0.0),
    ]
    x = np.array(
        [
            [0.0, 0.0, 0.0],
            [0.25, 1.0, 1.0],
            [0.5, 0.5, 0.5],
            [0.75, 1.0, 0.0],
            [1.0, 0.0, 1.0],
        ]
    )
    out = evaluate_rows(x, ["smile", "a", "b"], rows, ["fold", "sum", "neg"])
    expected = np.array(
        [
            [0.0, 0.0, 0.0],  # from < x fails at x = 0: nothing fires
            [0.125, 1.0, 0.0],  # 0.6 + 0.6 = 1.2 clamped; -1 clamped to 0
            [0.25, 0.6, 0.0],  # x = 0.5 belongs to (0, 0.5]: 0.25, continuous with 1.5*0.5-0.5
            [0.625, 0.6, 0.0],
            [1.0, 0.6, 0.0],
        ]
    )
    np.testing.assert_allclose(out, expected, atol=1e-6)
    raw = evaluate_rows(x, ["smile", "a", "b"], rows, ["fold", "sum", "neg"], clamp=False)
    assert raw[1, 1] == pytest.approx(1.2) and raw[1, 2] == pytest.approx(-1.0)


EXTRA = ("crowsfeet_l", "crowsfeet_r", "nasolabial_l", "nasolabial_r", "ears", "neck")


def _arkit_pose(browinner, browdown, default):
    w = np.full(len(arkit.NAMES), default)
    w[arkit.NAMES.index("browInnerUp")] = browinner
    w[arkit.NAMES.index("browDownLeft")] = browdown
    w[arkit.NAMES.index("browDownRight")] = browdown
    return w


def test_arkit_preset_on_a_gltf_drives_only_the_mapped_regions(tmp_path):
    assert len(arkit.NAMES) == 52 and len(set(arkit.NAMES)) == 52
    k0 = _arkit_pose(0.9, 0.2, 0.5)
    k1 = _arkit_pose(1.0, 0.1, 0.3)
    glb = make_morph_gltf(tmp_path / "arkit.glb", arkit.NAMES, [0.0, 1.0], np.stack([k0, k1]))
    _assert_valid_gltf(glb)
    regions = (*jimenez.REGION_NAMES, *EXTRA)
    ctx = wd.DriverContext(
        regions, ("stretch", "compress"), root=tmp_path, read_morph_tracks=read_morph_tracks
    )
    res = wd.evaluate(
        "blendshapes", ctx, {"preset": "arkit52", "file": "arkit.glb"}, times=[0.0, 0.5, 1.0]
    )
    w = res.weights[..., 0]  # [F, R]
    mapped = set(arkit.REGIONS)
    for i, r in enumerate(regions):
        if r in mapped:
            assert np.all(w[:, i] > 0), r
        else:
            assert np.all(w[:, i] == 0), r
    # hand-computed from the rows at t = 0 (all other shapes 0.5) and t = 0.5 (the average)
    at = {r: w[0, i] for i, r in enumerate(regions)}
    assert at["forehead_inner_l"] == pytest.approx(0.9 - 0.8 * 0.2, abs=1e-6)
    assert at["forehead_outer_r"] == pytest.approx(0.5, abs=1e-6)
    assert at["glabella"] == pytest.approx(0.6 * 0.2 * 2, abs=1e-6)
    assert at["crowsfeet_l"] == pytest.approx(0.5 + 0.5 * 0.5, abs=1e-6)
    assert at["nasolabial_r"] == pytest.approx(0.25, abs=1e-6)
    assert at["chin"] == pytest.approx(0.5, abs=1e-6)
    mid = {r: w[1, i] for i, r in enumerate(regions)}
    smile = 0.4  # (0.5 + 0.3) / 2, in the first row's interval
    assert mid["nasolabial_l"] == pytest.approx(0.5 * smile, abs=1e-6)
    assert mid["forehead_inner_r"] == pytest.approx(0.95 - 0.8 * 0.15, abs=1e-6)


def test_arkit_preset_skips_regions_the_asset_lacks():
    ctx = wd.DriverContext(jimenez.REGION_NAMES, ("compress",))
    res = wd.evaluate("blendshapes", ctx, {"preset": "arkit52", "morphs": {"mouthSmileLeft": 1}})
    assert "nasolabial_l" in res.notes[0]
    assert np.all(res.weights == 0)


def test_blendshape_keys_with_explicit_rows_and_state():
    ctx = wd.DriverContext(["brow", "chin"], ("stretch", "compress"))
    spec = {
        "rows": [["raise", "brow:stretch", 0, 1, 2, 0], ["shrug", "chin", 0, 1, 1, -0.5]],
        "keys": {"raise": [[0, 0], [1, 1]], "shrug": [[0, 1], [1, 1]]},
        "fps": 4,
    }
    res = wd.evaluate("blendshapes", ctx, spec)
    np.testing.assert_allclose(res.weights[:, 0, 0], np.minimum(2 * res.times, 1), atol=1e-6)
    assert np.all(res.weights[:, 0, 1] == 0)
    np.testing.assert_allclose(res.weights[:, 1, :], 0.5, atol=1e-6)


def test_row_naming_an_unknown_blend_shape_is_refused():
    from wrinklepipe.errors import InputError

    ctx = wd.DriverContext(["brow"], ("compress",))
    spec = {"rows": [["browInnerUpp", "brow", 0, 1, 1, 0]], "morphs": {"browInnerUp": 1}}
    with pytest.raises(InputError, match="unknown blend shape 'browInnerUpp'"):
        wd.evaluate("blendshapes", ctx, spec)
