"""USD mesh ingest: UsdSkel blend shapes with inbetweens against OpenUSD's own baked baseline,
UsdSkel skinning against UsdSkel's skinning, faceVarying/indexed st, bad inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wrinklepipe.errors import InputError
from wrinklepipe.geometry.dynamic import DynamicWeights, morph_pose, skinned_pose
from wrinklepipe.readers.meshes import LoadOptions, load_mesh, load_meshes
from wrinklepipe.usd.poses import usd_blend_shape_weights, usd_joint_world_matrices

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom, UsdSkel, Vt  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "usd"
SKEL = DATA / "openusd/usd/usdSkel/testenv/testUsdSkelBakeSkinning"
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="shared/data absent")
RAW = LoadOptions(generate_uvs=False)


def nearest(points: np.ndarray, queries: np.ndarray) -> np.ndarray:
    from scipy.spatial import cKDTree

    d, i = cKDTree(points).query(queries)
    assert d.max() < 1e-5
    return i


@needs_data
def test_blend_shapes_with_inbetweens_match_openusd_baseline():
    f = SKEL / "blendshapes.usda"
    m = next(x for x in load_meshes(f, RAW) if x.name == "/TestPlane/Mesh")
    assert m.morph_names[:5] == ("targetA", "targetB", "targetC", "targetC@0.5", "targetC@1.5")
    assert sum("@" in n for n in m.morph_names) == 5
    baked = Usd.Stage.Open(str(SKEL / "baseline/blendshapes.baked.usda"))
    pts = UsdGeom.Mesh(baked.GetPrimAtPath("/TestPlane/Mesh")).GetPointsAttr()
    rest = np.asarray(pts.Get(1.0), dtype=np.float64)
    idx = nearest(rest, m.positions)
    worst = 0.0
    for t in pts.GetTimeSamples():
        posed = morph_pose(m, usd_blend_shape_weights(f, m, t))
        worst = max(worst, float(np.abs(posed - np.asarray(pts.Get(t))[idx]).max()))
    # Measured: 3.9e-6 over all 131 frames (weights -1..2, inbetweens at -0.499, 0.5, 1.5).
    assert worst < 1e-4


@needs_data
@pytest.mark.parametrize(
    ("rel", "prim"),
    [
        ("openusd/usd/usdSkel/testenv/testUsdSkelBakeSkinning/lbs.usda", "/Root/Mesh"),
        ("openusd/usd/usdSkel/doxygen/skinnedArm.usda", "/Model/Arm"),
        ("usd-wg/test_assets/USDZ/RiggedFigure/RiggedFigure.usdz", None),
    ],
)
def test_skinning_matches_usdskel(rel, prim):
    f = DATA / rel
    parts = load_meshes(f, RAW)
    m = parts[0] if prim is None else next(x for x in parts if x.name == prim)
    stage = Usd.Stage.Open(str(f))
    p = stage.GetPrimAtPath(m.name)
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(p), Usd.TraverseInstanceProxies())
    sq = cache.GetSkinningQuery(p)
    skel = UsdSkel.BindingAPI(p).GetInheritedSkeleton()
    kq = cache.GetSkelQuery(skel)
    geom = np.asarray(sq.GetGeomBindTransform()).T
    raw = np.asarray(UsdGeom.Mesh(p).GetPointsAttr().Get(), dtype=np.float64)
    idx = nearest(raw @ geom[:3, :3].T + geom[:3, 3], m.positions)
    t0, t1 = stage.GetStartTimeCode(), stage.GetEndTimeCode()
    for t in (t0, 0.5 * (t0 + t1), t1):
        tc = Usd.TimeCode(t)
        pts = Vt.Vec3fArray(UsdGeom.Mesh(p).GetPointsAttr().Get(tc))
        sq.ComputeSkinnedPoints(kq.ComputeSkinningTransforms(tc), pts, tc)
        w = np.asarray(UsdGeom.Xformable(skel.GetPrim()).ComputeLocalToWorldTransform(tc)).T
        ref = np.asarray(pts, dtype=np.float64) @ w[:3, :3].T + w[:3, 3]
        ours = skinned_pose(m, usd_joint_world_matrices(f, m, t))
        np.testing.assert_allclose(ours, ref[idx], atol=1e-5)


@needs_data
@pytest.mark.parametrize(
    ("rel", "n_shapes"),
    [
        ("openusd/usd/usdSkel/testenv/testUsdSkelBakeSkinning/blendshapes.usda", 6),
        ("openusd/usd/usdSkel/testenv/testUsdSkelBakeSkinning/blendshapesWithNormals.usda", 4),
        (
            "openusd/usdImaging/usdImagingGL/testenv/testUsdImagingGLSkelBlendShapes/blendshapes.usda",
            6,
        ),
    ],
)
def test_usdskel_blend_shape_scenes_ingest(rel, n_shapes):
    m = next(x for x in load_meshes(DATA / rel) if x.morph_names)
    assert sum("@" not in n for n in m.morph_names) == n_shapes
    assert m.morph_deltas.shape == (len(m.morph_names), m.vertex_count, 3)
    assert m.uvs is not None and m.triangle_count > 0


@needs_data
def test_dynamic_weights_on_usd_blend_shapes():
    f = SKEL / "blendshapes.usda"
    m = next(x for x in load_meshes(f, RAW) if x.name == "/TestPlane/Mesh")
    op = DynamicWeights.build(m.positions, m.indices)
    # targetC at 1 lifts and shears part of the plane: that skin stretches (w < 0), the rest
    # of the plane is untouched (w = 0).
    w = op.frame(morph_pose(m, {"targetC": 1.0}))
    assert w.min() < -0.1 and np.isfinite(w).all()
    assert (np.abs(w) < 1e-6).sum() > 10
    np.testing.assert_allclose(op.frame(m.positions), 0.0, atol=1e-6)


def write_usda(path: Path, body: str) -> Path:
    path.write_text('#usda 1.0\n(\n    upAxis = "Y"\n)\n' + body)
    return path


QUAD = """
def Mesh "quad"
{
    int[] faceVertexCounts = [4, 4]
    int[] faceVertexIndices = [0, 1, 2, 3, 1, 4, 5, 2]
    point3f[] points = [(0,0,0), (1,0,0), (1,1,0), (0,1,0), (2,0,0), (2,1,0)]
    %s
}
"""


def test_face_varying_indexed_st_splits_seam(tmp_path):
    # Two quads sharing the edge 1-2; faceVarying st makes that edge a UV seam.
    st = (
        "texCoord2f[] primvars:st = [(0,0), (0.5,0), (0.5,1), (0,1), (0.6,0), (1,0), (1,1),"
        ' (0.6,1)] (interpolation = "faceVarying")\n'
        "    int[] primvars:st:indices = [0, 1, 2, 3, 4, 5, 6, 7]"
    )
    m = load_mesh(write_usda(tmp_path / "q.usda", QUAD % st))
    assert m.vertex_count == 8  # points 1 and 2 are split by the seam
    assert m.triangle_count == 4
    # V flipped to the glTF convention: st (0, 1) -> uv (0, 0).
    i = int(np.flatnonzero((m.positions == [0, 1, 0]).all(1))[0])
    np.testing.assert_allclose(m.uvs[i], [0, 0])
    # Indexed vertex st: shared, no split.
    st2 = (
        'texCoord2f[] primvars:st = [(0,0), (1,1)] (interpolation = "vertex")\n'
        "    int[] primvars:st:indices = [0, 0, 1, 1, 0, 1]"
    )
    m2 = load_mesh(write_usda(tmp_path / "v.usda", QUAD % st2))
    assert m2.vertex_count == 6
    np.testing.assert_allclose(m2.uvs[2], [1, 0])


def test_usd_bad_inputs(tmp_path):
    bad = QUAD.replace("[0, 1, 2, 3, 1, 4, 5, 2]", "[0, 1, 2, 3, 1, 4, 5, 9]") % ""
    with pytest.raises(InputError, match="out of range"):
        load_mesh(write_usda(tmp_path / "b.usda", bad))
    empty = 'def Mesh "m"\n{\n    point3f[] points = [(0,0,0)]\n}\n'
    with pytest.raises(InputError, match="no UsdGeom.Mesh with faces"):
        load_mesh(write_usda(tmp_path / "e.usda", empty))
    (tmp_path / "junk.usda").write_text("this is not usd")
    with pytest.raises(InputError, match="cannot open"):
        load_mesh(tmp_path / "junk.usda")


@needs_data
def test_points_only_time_sampled_are_read_at_the_start_time_code():
    """OpenUSD's baked blend-shape baseline: /GroundTruth/Mesh has points (and topology) only
    as time samples (113 frames), the stage startTimeCode = 1: read at time code 1 (pxr's own
    points there), the choice in the notes; /TestPlane/Mesh (a default value) as before."""
    f = SKEL / "baseline/blendshapes.baked.usda"
    meshes = {m.name: m for m in load_meshes(f, RAW)}
    assert set(meshes) == {"/GroundTruth/Mesh", "/TestPlane/Mesh"}  # before: GroundTruth skipped
    m = meshes["/GroundTruth/Mesh"]
    stage = Usd.Stage.Open(str(f))
    attr = UsdGeom.Mesh(stage.GetPrimAtPath("/GroundTruth/Mesh")).GetPointsAttr()
    assert attr.Get(Usd.TimeCode.Default()) is None and len(attr.GetTimeSamples()) == 113
    at_start = np.asarray(attr.Get(1.0), np.float32)
    moves = max(np.abs(np.asarray(attr.Get(t)) - at_start).max() for t in attr.GetTimeSamples())
    assert moves > 0.1  # so which sample is read matters
    np.testing.assert_array_equal(m.positions, at_start[nearest(at_start, m.positions)])
    assert len(np.unique(nearest(at_start, m.positions))) == len(at_start)  # every point
    assert any(
        "only 113 time samples: read at time code 1 (the stage's startTimeCode)" in n
        for n in m.notes
    )
    assert not any("time sample" in n for n in meshes["/TestPlane/Mesh"].notes)


def test_points_only_time_sampled_without_a_range_use_the_earliest_sample(tmp_path):
    """A generated stage (no time-code range): points sampled at 5 and 10 only, the transform
    animated too: read whole at 5 (the earliest sample); an explicit time still wins."""
    path = tmp_path / "sampled.usda"
    stage = Usd.Stage.CreateNew(str(path))
    xf = UsdGeom.Xform.Define(stage, "/W")
    op = xf.AddTranslateOp()
    op.Set((0.0, 1.0, 0.0), 5.0)
    op.Set((0.0, 3.0, 0.0), 10.0)
    mesh = UsdGeom.Mesh.Define(stage, "/W/M")
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2])
    pts = mesh.CreatePointsAttr()
    pts.Set(Vt.Vec3fArray([(0, 0, 0), (1, 0, 0), (0, 1, 0)]), 5.0)
    pts.Set(Vt.Vec3fArray([(0, 0, 0), (2, 0, 0), (0, 2, 0)]), 10.0)
    stage.GetRootLayer().Save()
    (m,) = load_meshes(path, RAW)
    np.testing.assert_array_equal(m.positions, [[0, 1, 0], [1, 1, 0], [0, 2, 0]])  # t = 5
    assert any("read at time code 5 (the earliest of 2 samples)" in n for n in m.notes)
    (late,) = load_meshes(path, LoadOptions(generate_uvs=False, usd_time=10.0))
    np.testing.assert_array_equal(late.positions, [[0, 3, 0], [2, 3, 0], [0, 5, 0]])
    assert not any("time sample" in n for n in late.notes)


@needs_data
def test_paths_option_reads_only_those_meshes():
    from wrinklepipe.usd.meshes import UsdMeshOptions, read_usd_meshes

    f = SKEL / "baseline/blendshapes.baked.usda"
    (only,) = read_usd_meshes(f, UsdMeshOptions(paths=("/TestPlane/Mesh",)))
    assert only.name == "/TestPlane/Mesh"
    with pytest.raises(InputError, match="no UsdGeom.Mesh with faces"):
        read_usd_meshes(f, UsdMeshOptions(paths=("/Nowhere",)))
