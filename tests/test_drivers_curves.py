"""Curves driver: linear / step / cubic keys from the manifest, CSV, JSON and glTF animations."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_drivers_blendshapes import make_morph_gltf

from wrinklepipe import drivers as wd
from wrinklepipe.drivers.curves import sample
from wrinklepipe.errors import InputError
from wrinklepipe.gltf.animation import read_morph_tracks

REGIONS = ("brow", "chin")
STATES = ("stretch", "compress")


def test_linear_step_and_hold():
    kt, kv = np.array([0.0, 1.0, 3.0]), np.array([0.0, 1.0, -1.0])
    t = np.array([-1.0, 0.5, 2.0, 5.0])
    np.testing.assert_allclose(sample(kt, kv, t, "linear"), [0.0, 0.5, 0.0, -1.0])
    np.testing.assert_allclose(sample(kt, kv, t, "step"), [0.0, 0.0, 1.0, -1.0])


def test_cubic_is_exact_on_a_cubic_polynomial():
    def f(x):
        return 0.3 * x**3 - 0.5 * x**2 + 0.1 * x + 0.2

    kt = np.array([0.0, 0.4, 1.0, 1.7, 2.0])
    t = np.array([0.13, 0.77, 1.5, 1.99])
    np.testing.assert_allclose(sample(kt, f(kt), t, "cubic"), f(t), atol=1e-12)


def test_manifest_keys_region_and_region_state():
    ctx = wd.DriverContext(REGIONS, STATES)
    spec = {"keys": {"brow": [[0, 0], [1, 1]], "chin:compress": [[0, 0.5]]}, "fps": 2}
    res = wd.evaluate("curves", ctx, spec)
    np.testing.assert_allclose(res.times, [0, 0.5, 1.0])
    np.testing.assert_allclose(res.weights[:, 0, :], [[0, 0], [0.5, 0.5], [1, 1]])
    np.testing.assert_allclose(res.weights[:, 1, :], [[0, 0.5]] * 3)


def test_csv_and_json_files(tmp_path):
    (tmp_path / "c.csv").write_text("time,brow,chin:stretch\n0,0,\n2,1,0.25\n")
    (tmp_path / "c.json").write_text(
        json.dumps({"interpolation": "step", "keys": {"brow": [[0, 0], [2, 1]]}})
    )
    ctx = wd.DriverContext(REGIONS, STATES, root=tmp_path)
    a = wd.evaluate("curves", ctx, {"file": "c.csv"}, times=[1.0])
    np.testing.assert_allclose(a.weights[0], [[0.5, 0.5], [0.25, 0.0]])
    b = wd.evaluate("curves", ctx, {"file": "c.json"}, times=[1.0, 2.0])
    np.testing.assert_allclose(b.weights[:, 0, 0], [0.0, 1.0])


def test_gltf_animation_linear_and_cubicspline(tmp_path):
    glb = make_morph_gltf(tmp_path / "a.glb", ["brow", "other"], [0, 1], [[0, 0], [1, 1]])
    ctx = wd.DriverContext(REGIONS, STATES, root=tmp_path, read_morph_tracks=read_morph_tracks)
    res = wd.evaluate("curves", ctx, {"file": glb.name}, times=[0.25])
    assert res.weights[0, 0, 0] == pytest.approx(0.25)
    assert "other" in res.notes[0]
    # CUBICSPLINE with zero tangents: smoothstep 3s^2 - 2s^3
    w = np.zeros((2, 3, 2))
    w[1, 1, :] = 1.0
    make_morph_gltf(tmp_path / "c.glb", ["brow", "chin"], [0, 2], w, "CUBICSPLINE")
    res = wd.evaluate("curves", ctx, {"file": "c.glb"}, times=[0.5])
    s = 0.25
    assert res.weights[0, 0, 0] == pytest.approx(3 * s * s - 2 * s**3, abs=1e-6)


def test_unknown_region_and_bad_keys_are_named():
    ctx = wd.DriverContext(REGIONS, STATES, source="m.toml")
    with pytest.raises(InputError, match="unknown region 'nose'"):
        wd.evaluate("curves", ctx, {"keys": {"nose": [[0, 1]]}})
    with pytest.raises(InputError, match="two keys at the same time") as e:
        wd.evaluate("curves", ctx, {"keys": {"brow": [[0, 1], [0, 2]]}})
    assert "keys.brow" in str(e.value) and "m.toml" in str(e.value)


def test_policy_weights():
    w = np.array([[1.5, -0.5], [0.7, 0.6]], np.float32)
    np.testing.assert_allclose(wd.policy_weights(w, "clamp01"), [[1, 0], [0.7, 0.6]])
    np.testing.assert_allclose(wd.policy_weights(w, "additive"), w)
    np.testing.assert_allclose(wd.policy_weights(w, "lerp"), [[1, 0], [0.7 / 1.3, 0.6 / 1.3]])


def test_dynamic_is_registered():
    assert set(wd.KINDS) <= set(wd.DRIVERS)


def test_dynamic_driver_plugs_in_the_geometry_module():
    """A grid shrunk uniformly by s has every triangle's area times s^2: weight 1 - s^2."""
    from wrinklepipe.asset import Mesh

    n = 4
    y, x = np.mgrid[0:n, 0:n].astype(np.float32)
    pos = np.stack([x.ravel(), y.ravel(), np.zeros(n * n, np.float32)], axis=1)
    quads = np.array(
        [[r * n + c, r * n + c + 1, (r + 1) * n + c] for r in range(n - 1) for c in range(n - 1)]
    )
    quads2 = np.array(
        [
            [r * n + c + 1, (r + 1) * n + c + 1, (r + 1) * n + c]
            for r in range(n - 1)
            for c in range(n - 1)
        ]
    )
    idx = np.concatenate([quads, quads2]).astype(np.uint32)
    mesh = Mesh(pos, idx, morph_names=("shrink",), morph_deltas=(-0.1 * pos)[None])
    ctx = wd.DriverContext(("face",), ("stretch", "compress"), mesh=mesh, policy="signed")
    res = wd.evaluate("dynamic", ctx, {"keys": {"shrink": [[0, 0], [1, 1]]}}, times=[0, 0.5, 1])
    assert res.per_vertex and res.weights.shape == (3, n * n, 1)
    np.testing.assert_allclose(
        res.weights[:, :, 0].mean(axis=1), [0, 1 - 0.95**2, 1 - 0.9**2], atol=1e-5
    )
    np.testing.assert_allclose(res.weights[2, :, 0], 0.19, atol=1e-5)


def test_gltf_with_external_buffer_and_broken_files(tmp_path):
    import pygltflib

    glb = make_morph_gltf(tmp_path / "a.glb", ["brow"], [0, 1], [[0], [1]])
    g = pygltflib.GLTF2().load(str(glb))
    g.convert_buffers(pygltflib.BufferFormat.BINFILE)
    g.save(str(tmp_path / "ext.gltf"))
    assert any(p.suffix == ".bin" for p in tmp_path.iterdir())
    ctx = wd.DriverContext(REGIONS, STATES, root=tmp_path, read_morph_tracks=read_morph_tracks)
    res = wd.evaluate("curves", ctx, {"file": "ext.gltf"}, times=[0.5])
    assert res.weights[0, 0, 0] == pytest.approx(0.5)
    # a truncated GLB and a buffer URI escaping the folder: clear messages, no traceback
    (tmp_path / "cut.glb").write_bytes(glb.read_bytes()[:-40])
    with pytest.raises(InputError):
        wd.evaluate("curves", ctx, {"file": "cut.glb"})
    g.buffers[0].uri = "../../etc/passwd"
    g.save(str(tmp_path / "evil.gltf"))
    with pytest.raises(InputError, match="leaves the asset folder"):
        wd.evaluate("curves", ctx, {"file": "evil.gltf"})
