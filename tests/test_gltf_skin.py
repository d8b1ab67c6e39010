"""Skins: JOINTS_0/WEIGHTS_0 + joint nodes in glTF, UsdSkel skinning in USD, exact round trip."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import usd_checks

from wrinklepipe.demo.package import demo_package
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.gltf.package_write import skin_weights_normalized, write_gltf
from wrinklepipe.io import khronos
from wrinklepipe.usd.meshes import UsdMeshOptions, read_usd_meshes
from wrinklepipe.usd.package_read import read_usd
from wrinklepipe.usd.package_write import write_usd


@pytest.fixture(scope="module")
def skinned():
    pkg = demo_package(64)
    m = pkg.mesh
    x = m.positions[:, 0]
    # three joints: left cheek, right cheek, head; weights blend by x, rows sum to 1
    left = np.clip(x / 0.08, 0, 1).astype(np.float32)
    right = np.clip(-x / 0.08, 0, 1).astype(np.float32)
    head = (1.0 - left - right).astype(np.float32)
    weights = np.stack([head, left, right, np.zeros_like(x)], -1)
    joints = np.tile(np.array([0, 1, 2, 0], np.int64), (m.vertex_count, 1))
    ibm = np.tile(np.eye(4, dtype=np.float32), (3, 1, 1))
    ibm[1, :3, 3] = [-0.05, -0.01, -0.08]  # joint 1 sits at (0.05, 0.01, 0.08)
    ibm[2, :3, 3] = [0.05, -0.01, -0.08]
    mesh = replace(
        m,
        joints=joints,
        skin_weights=weights,
        joint_names=("head", "cheek.L", "cheek.R"),
        inverse_bind=ibm,
    )
    return replace(pkg, mesh=mesh)


def test_gltf_skin_structure(skinned, tmp_path):
    write_gltf(skinned, tmp_path, "s")
    doc = json.loads((tmp_path / "s.gltf").read_text())
    skin = doc["skins"][0]
    assert [doc["nodes"][j]["name"] for j in skin["joints"]] == ["head", "cheek.L", "cheek.R"]
    # joint 1's node is at its bind pose: the inverse of its IBM (column-major matrix)
    assert doc["nodes"][skin["joints"][1]]["matrix"][12:15] == pytest.approx([0.05, 0.01, 0.08])
    assert "matrix" not in doc["nodes"][skin["joints"][0]]  # identity omitted
    assert doc["nodes"][0]["skin"] == 0 and set(doc["scenes"][0]["nodes"]) == {0, 1, 2, 3}
    if khronos.available():
        issues = khronos.validate_gltf(tmp_path / "s.gltf")["issues"]
        assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]


def test_skin_round_trip_gltf_usd_gltf(skinned, tmp_path):
    skinned = replace(skinned, name="s")  # a package is named by its file's stem, as convert writes
    write_gltf(skinned, tmp_path / "a", "s")
    g = read_wrinkled(tmp_path / "a" / "s.gltf")
    assert g.mesh.joint_names == ("head", "cheek.L", "cheek.R")
    assert np.array_equal(g.mesh.inverse_bind, skinned.mesh.inverse_bind)
    assert np.array_equal(g.mesh.skin_weights, skinned.mesh.skin_weights)
    write_usd(g, tmp_path / "s.usda")
    u = read_usd(tmp_path / "s.usda")
    for f in ("joints", "skin_weights", "inverse_bind"):
        assert np.array_equal(getattr(u.mesh, f), getattr(g.mesh, f)), f
    assert u.mesh.joint_names == g.mesh.joint_names
    write_gltf(u, tmp_path / "b", "s")
    for rel in ("s.gltf", "s.bin"):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()


def test_usd_skinning_at_rest_gives_the_rest_points(skinned, tmp_path):
    from pxr import Usd, UsdSkel

    from wrinklepipe.usd.package_write import register_schema

    write_usd(skinned, tmp_path / "s.usda")
    register_schema()
    stage = Usd.Stage.Open(str(tmp_path / "s.usda"))
    errors = usd_checks.validation_errors(stage)
    assert errors == [], [(e.GetName(), e.GetMessage()) for e in errors]
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetPrimAtPath("/demo"))
    cache.Populate(root, Usd.TraverseInstanceProxies())
    skel_query = cache.GetSkelQuery(UsdSkel.Skeleton(stage.GetPrimAtPath("/demo/Skel")))
    xforms = skel_query.ComputeSkinningTransforms(Usd.TimeCode.Default())
    mesh = stage.GetPrimAtPath("/demo/demo_head")
    sq = cache.GetSkinningQuery(mesh)
    points = mesh.GetAttribute("points").Get()
    assert sq.ComputeSkinnedPoints(xforms, points, Usd.TimeCode.Default())
    assert np.allclose(np.asarray(points), skinned.mesh.positions, atol=1e-6)


def test_weights_normalized_only_where_needed():
    w = np.array([[0.5, 0.5, 0, 0], [2, 2, 0, 0], [0, 0, 0, 0]], np.float32)
    out = skin_weights_normalized(w)
    assert out[0].tolist() == [0.5, 0.5, 0, 0]  # untouched (bits kept)
    assert out[1].tolist() == [0.5, 0.5, 0, 0]
    assert out[2].tolist() == [1, 0, 0, 0]


def test_usd_mesh_reader_reads_the_gltf_joint_names_and_exact_inverse_binds(skinned, tmp_path):
    """The one USD mesh reader (which the package reader reads through) names the joints as in
    the glTF ('cheek.L', not the USD token 'cheek_L') and takes the exact inverse binds the
    Skeleton carries, for a rotated joint too; UsdSkel's bindTransforms agree with them."""
    from pxr import Usd, UsdSkel

    a = 0.3
    ibm = skinned.mesh.inverse_bind.copy()
    ibm[1, :3, :3] = np.array(
        [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]], np.float32
    )
    pkg = replace(skinned, mesh=replace(skinned.mesh, inverse_bind=ibm))
    write_usd(pkg, tmp_path / "r.usda")
    m = read_usd_meshes(tmp_path / "r.usda", UsdMeshOptions(exact=True))[0]
    assert m.joint_names == ("head", "cheek.L", "cheek.R")
    assert np.array_equal(m.inverse_bind, ibm)
    assert np.array_equal(m.skin_weights, skin_weights_normalized(pkg.mesh.skin_weights))
    assert np.array_equal(read_usd(tmp_path / "r.usda").mesh.inverse_bind, ibm)
    stage = Usd.Stage.Open(str(tmp_path / "r.usda"))
    skel = next(UsdSkel.Skeleton(p) for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton))
    assert [str(t) for t in skel.GetJointsAttr().Get()] == ["head", "cheek_L", "cheek_R"]
    bind = np.asarray(skel.GetBindTransformsAttr().Get(), np.float64).transpose(0, 2, 1)
    assert np.allclose(np.linalg.inv(bind), ibm, atol=1e-6)
