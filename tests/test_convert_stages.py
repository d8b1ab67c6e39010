"""Pipeline stages on hand-made data: driver weights -> curves, expression cycle, mesh prep."""

from __future__ import annotations

import numpy as np
import pytest

from wrinklepipe.asset import Mesh
from wrinklepipe.errors import InputError
from wrinklepipe.pipeline.drivers import curves_from_weights, expression_cycle
from wrinklepipe.pipeline.prepare import prepare_mesh


def test_curves_from_weights_reads_each_regions_first_state():
    # region 0 drives both states, region 1 only state 1 (compress)
    rs = np.array([[1, 1], [0, 1]], np.float32)
    w = np.array([[[0.5, 0.5], [0.0, 0.25]], [[1.0, 1.0], [0.0, -0.5]]], np.float32)
    c, lost = curves_from_weights("x", np.array([0.0, 1.0]), w, rs)
    assert c.values.tolist() == [[0.5, 0.25], [1.0, -0.5]]
    assert lost == 0.0
    w[1, 0, 1] = 0.75  # a driver that weights the two states of region 0 differently
    _, lost = curves_from_weights("x", np.array([0.0, 1.0]), w, rs)
    assert lost == pytest.approx(0.25)


def test_signed_policy_single_weight():
    w = np.array([[[-0.5], [1.0]]], np.float32)
    c, lost = curves_from_weights("s", np.zeros(1), w, np.ones((2, 2), np.float32))
    assert c.values.tolist() == [[-0.5, 1.0]] and lost == 0.0


def test_expression_cycle_jimenez():
    from wrinklepipe.demo import demo_asset
    from wrinklepipe.presets import jimenez

    asset = demo_asset(16)
    c = expression_cycle(asset)
    assert c.times.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
    assert c.values[0].tolist() == [0.0] * 8
    names = list(asset.expressions)
    i = names.index("fear") + 1
    assert c.values[i].tolist() == pytest.approx(list(jimenez.TABLE_1_1["fear"]))


def test_prepare_mesh_adds_tangents_and_ids():
    # a unit quad split in two triangles, UV = (x, 1 - y) as glTF (v down); two duplicated corners
    pos = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    uv = np.array([[0, 1], [1, 1], [1, 0], [0, 0], [1, 0]], np.float32)
    mesh = Mesh(
        positions=pos,
        indices=np.array([[0, 1, 2], [0, 4, 3]], np.uint32),
        uvs=uv,
        normals=np.tile(np.array([0, 0, 1], np.float32), (5, 1)),
    )
    out = prepare_mesh(mesh)
    # tangent follows +u = +x; handedness +1 (bitangent +v_up = +y)
    assert np.allclose(out.tangents[:4, :3], [1, 0, 0], atol=1e-5)
    assert np.all(out.tangents[:, 3] == 1.0)
    assert out.vertex_ids[2] == out.vertex_ids[4] and len(set(out.vertex_ids[:4])) == 4
    with pytest.raises(InputError, match="no UVs"):
        prepare_mesh(Mesh(positions=pos, indices=mesh.indices))


def test_blendshapes_driver_gives_region_and_morph_curves(tmp_path):
    from dataclasses import replace

    from wrinklepipe.demo import demo_asset
    from wrinklepipe.pipeline.drivers import evaluate_drivers

    asset = demo_asset(16)
    spec = {
        "kind": "blendshapes",
        "name": "performance",
        "fps": 4,
        "rows": [["brow_raise", "forehead_outer_l", 0.0, 1.0, 1.0, 0.0]],
        "keys": {"brow_raise": [[0.0, 0.0], [1.0, 1.0], [2.0, 0.25]]},
    }
    curves, _ = evaluate_drivers(replace(asset, drivers=[spec]), tmp_path)
    (c,) = curves
    assert c.name == "performance"
    assert c.times.tolist() == [0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0]
    # brow_raise keys sampled linearly: 0 -> 1 over 1 s, then 1 -> 0.25 over the next second
    expect = [0.0, 0.25, 0.5, 0.75, 1.0, 0.8125, 0.625, 0.4375, 0.25]
    j = asset.mesh.morph_names.index("brow_raise")
    assert c.morph_weights[:, j].tolist() == expect
    assert np.count_nonzero(np.delete(c.morph_weights, j, axis=1)) == 0
    # the row (slope 1, cut 0 on (0, 1]) passes it to forehead_outer_l only
    r = asset.region_names.index("forehead_outer_l")
    assert c.values[:, r].tolist() == expect
    assert np.count_nonzero(np.delete(c.values, r, axis=1)) == 0
