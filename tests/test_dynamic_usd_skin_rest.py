"""``dynamic --time`` on a skinned USD prim: the rest shape is the prim skinned with the
skeleton's ``restTransforms`` (no animation), in the space of the posed shape, not the stored
bind-space points (which are the rest only when the rest transforms equal the bind transforms
and geomBindTransform is the identity)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_dynamic_skin_rest import WORLD, _dynamic, _translate
from test_mesh_io_usd import DATA, RAW, needs_data

from wrinklepipe.geometry.dynamic import triangle_areas
from wrinklepipe.pipeline.dynamic import DynamicJobOptions, rest_and_deformed
from wrinklepipe.readers.meshes import load_meshes, merge_meshes

pxr = pytest.importorskip("pxr")
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt  # noqa: E402

# Row-vector USD matrices are the transposes of these column-vector ones.
SKEL_WORLD = _translate(2.0, -1.0, 0.5) @ np.diag([3.0, 3.0, 3.0, 1.0])  # the Skeleton's xform
REST_T = np.array([0.5, 0.25, -1.0])
REST_D = np.array([2.0, 1.0, 3.0])  # the joint's rest scale (non-uniform), its animation x 2
REST = _translate(*REST_T) @ np.diag([*REST_D, 1.0])  # root joint: local = skeleton space
GEOM = _translate(0.0, 1.0, 0.0) @ np.diag([1.0, 2.0, 1.0, 1.0])  # geomBindTransform
BINDS = {
    "uniform": _translate(1.0, 0.0, 0.0) @ np.diag([0.5, 0.5, 0.5, 1.0]),
    "non-uniform": _translate(0.0, 0.0, 2.0) @ np.diag([1.0, 4.0, 0.25, 1.0]),
}


def _m4(m: np.ndarray) -> Gf.Matrix4d:
    return Gf.Matrix4d(np.asarray(m, np.float64).T.tolist())


def _usd_file(path: Path, bind: np.ndarray) -> Path:
    # Points stored so that the rest pose (skeleton world @ rest @ inv(bind) @ geomBind) is WORLD.
    rest_skin = SKEL_WORLD @ REST @ np.linalg.inv(bind) @ GEOM
    stored = (np.c_[WORLD, np.ones(9)] @ np.linalg.inv(rest_skin).T)[:, :3]
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(1)
    UsdSkel.Root.Define(stage, "/Root")
    skel = UsdSkel.Skeleton.Define(stage, "/Root/Skel")
    UsdGeom.Xformable(skel.GetPrim()).AddTransformOp().Set(_m4(SKEL_WORLD))
    skel.CreateJointsAttr(Vt.TokenArray(["j"]))
    skel.CreateBindTransformsAttr(Vt.Matrix4dArray([_m4(bind)]))
    skel.CreateRestTransformsAttr(Vt.Matrix4dArray([_m4(REST)]))
    anim = UsdSkel.Animation.Define(stage, "/Root/Skel/Anim")
    anim.CreateJointsAttr(Vt.TokenArray(["j"]))
    anim.CreateTranslationsAttr(Vt.Vec3fArray([Gf.Vec3f(*REST_T)]))
    anim.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1.0)]))
    scales = anim.CreateScalesAttr()
    scales.Set(Vt.Vec3hArray([Gf.Vec3h(*REST_D)]), 0.0)
    scales.Set(Vt.Vec3hArray([Gf.Vec3h(2.0 * REST_D[0], *REST_D[1:])]), 1.0)
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    mesh = UsdGeom.Mesh.Define(stage, "/Root/Mesh")
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in stored.tolist()]))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3, 3, 3]))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(list(range(9))))
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(True, 1).Set(Vt.IntArray([0]))
    binding.CreateJointWeightsPrimvar(True, 1).Set(Vt.FloatArray([1.0]))
    binding.CreateGeomBindTransformAttr(_m4(GEOM))
    stage.GetRootLayer().Save()
    return path


@pytest.mark.parametrize("bind", sorted(BINDS))
@pytest.mark.parametrize("time, s", [(0.0, 1.0), (0.5, 1.5), (1.0, 2.0)])
def test_joint_scaling_x_gives_the_analytic_stretch(tmp_path, bind, time, s):
    # Posed = SKEL_WORLD @ REST @ diag(s,1,1) @ inv(REST) @ inv(SKEL_WORLD) @ WORLD: the uniform
    # and diagonal scales commute with diag(s,1,1), the translations only shift, so the world
    # shape is WORLD scaled by s along x: weight 1 - |(n_x, s n_y, s n_z)| per unit normal n.
    f = _usd_file(tmp_path / "skin.usda", BINDS[bind])
    w = _dynamic(f, time, tmp_path / "w.npy")
    expected = np.repeat([1.0 - s, 0.0, 1.0 - np.sqrt(0.5 + 0.5 * s * s)], 3)
    np.testing.assert_allclose(w, expected, rtol=0, atol=1e-5)


def test_rest_is_the_world_rest_pose(tmp_path):
    f = _usd_file(tmp_path / "skin.usda", BINDS["non-uniform"])
    parts = load_meshes(f, RAW)
    rest, posed = rest_and_deformed(f, parts[0], parts, DynamicJobOptions(time=1.0))
    np.testing.assert_allclose(rest, WORLD, atol=1e-5)
    # posed: x scaled by 2 about the joint's world origin
    origin = (SKEL_WORLD @ REST)[:3, 3]
    np.testing.assert_allclose(posed, (WORLD - origin) * [2.0, 1.0, 1.0] + origin, atol=1e-5)


def test_skeleton_without_rest_transforms_rests_in_its_bind_pose(tmp_path):
    # UsdSkel gives no rest pose without restTransforms: the bind pose is the rest, i.e. the
    # points as read (geomBindTransform applied) placed by the skeleton's world transform.
    f = _usd_file(tmp_path / "skin.usda", BINDS["uniform"])
    stage = Usd.Stage.Open(str(f))
    UsdSkel.Skeleton(stage.GetPrimAtPath("/Root/Skel")).GetRestTransformsAttr().Clear()
    stage.GetRootLayer().Save()
    parts = load_meshes(f, RAW)
    rest, _ = rest_and_deformed(f, parts[0], parts, DynamicJobOptions(time=1.0))
    stored = np.asarray(UsdGeom.Mesh(stage.GetPrimAtPath("/Root/Mesh")).GetPointsAttr().Get())
    expected = np.c_[stored, np.ones(9)] @ (SKEL_WORLD @ GEOM)[:3].T
    np.testing.assert_allclose(rest, expected, atol=1e-5)


@needs_data
@pytest.mark.parametrize(
    ("rel", "prim"),
    [
        ("openusd/usd/usdSkel/testenv/testUsdSkelBakeSkinning/lbs.usda", "/Root/Mesh"),
        ("openusd/usd/usdSkel/doxygen/skinnedArm.usda", "/Model/Arm"),
        ("usd-wg/test_assets/USDZ/RiggedFigure/RiggedFigure.usdz", None),
    ],
)
def test_usdskel_scene_whose_rest_is_its_bind_is_unchanged(rel, prim):
    # In these scenes the rest transforms compose to the bind transforms and the skeleton's
    # world transform is rigid (identity; RiggedFigure: the Z-up -> Y-up rotation), checked
    # here with UsdSkel itself, so the skinned rest is the points as read (geomBindTransform
    # applied: lbs.usda has one) placed rigidly, with the same triangle areas: the weights are
    # what they were.
    f = DATA / rel
    parts = load_meshes(f, RAW)
    stage = Usd.Stage.Open(str(f))
    p = stage.GetPrimAtPath(prim or parts[0].name)
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(p), Usd.TraverseInstanceProxies())
    skel = UsdSkel.BindingAPI(p).GetInheritedSkeleton()
    kq = cache.GetSkelQuery(skel)
    rest = np.asarray(kq.ComputeJointSkelTransforms(Usd.TimeCode.Default(), True))
    np.testing.assert_allclose(rest, np.asarray(skel.GetBindTransformsAttr().Get()), atol=1e-5)
    t = stage.GetEndTimeCode()
    world = np.asarray(UsdGeom.Xformable(skel.GetPrim()).ComputeLocalToWorldTransform(t)).T
    np.testing.assert_allclose(world[:3, :3] @ world[:3, :3].T, np.eye(3), atol=1e-12)
    mesh = merge_meshes(parts) if len(parts) > 1 else parts[0]
    rest_pos, posed = rest_and_deformed(f, mesh, parts, DynamicJobOptions(time=t / 2))
    stored = mesh.positions.astype(np.float64)
    np.testing.assert_allclose(rest_pos, stored @ world[:3, :3].T + world[:3, 3], atol=1e-5)
    ok = triangle_areas(stored, mesh.indices) > 1e-10
    np.testing.assert_allclose(
        triangle_areas(rest_pos, mesh.indices)[ok],
        triangle_areas(stored, mesh.indices)[ok],
        rtol=1e-4,
    )
    assert np.abs(posed - rest_pos).max() > 0.01  # the pose really moves
