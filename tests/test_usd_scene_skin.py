"""The USD of a glTF source keeps the character rigged: its wrinkled primitives sit in the scene,
bound to the scene's UsdSkel Skeleton, and pose with it as the glTF skin poses them.

Three characters: the generated avatar (its Head skinned to 20 joints whose rest pose is not
the bind pose), RobotExpressive (its head a rigid part under the ``Head`` bone, CC0) and
CesiumMan (skinned, 19 joints, textured). Checked by pxr.UsdSkel's own queries (skinning query,
skeleton query, topology) against a numpy linear-blend skinning of the glTF's accessors read by
pygltflib + struct (the test's reader), by pxr.UsdValidation, and by validate-asset on the USD
giving the glTF's issues and metrics."""

from __future__ import annotations

import json
from pathlib import Path

import gltf_reference as ref
import numpy as np
import pytest
import usd_checks
from wrinkle_setups import ROBOT, avatar_variant, write_setup

from wrinklepipe.cli import main
from wrinklepipe.demo import avatar
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.io.confine import allowed_roots
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.usd.inspect import usd_summary
from wrinklepipe.usd.package_read import read_usd

CESIUM = ROBOT.parents[1] / "CesiumMan" / "glTF-Binary" / "CesiumMan.glb"


def _convert(root: Path, manifest: Path) -> Path:
    with allowed_roots([ROBOT.parents[1]]):
        res = convert(manifest, root / "out", ConvertOptions(render=False))
    assert res.exit_code == 0, res.report["validation"]
    return root / "out"


@pytest.fixture(scope="module")
def characters(tmp_path_factory, robot_converted) -> dict[str, tuple[Path, Path, str]]:
    """name -> (source glTF, output folder, asset name)."""
    out = {}
    root = tmp_path_factory.mktemp("skin")
    src = avatar.avatar_source_dir()
    out["avatar"] = (
        src.parent / "avatar.glb",
        _convert(root / "a", src),
        "avatar",
    )
    out["robot"] = (ROBOT, robot_converted[0], "robot")
    if CESIUM.is_file():
        # one centre region over the whole layout (CesiumMan's UVs are no face layout)
        whole = {"skin": ((0.0, 0.0, 1.0, 1.0), "center")}
        manifest = write_setup(root / "c" / "src", CESIUM, "cesium", regions=whole)
        out["cesium"] = (CESIUM, _convert(root / "c", manifest), "cesium")
    return out


def _local(n) -> np.ndarray:
    if n.matrix is not None:
        return np.asarray(n.matrix, np.float64).reshape(4, 4).T
    x, y, z, w = n.rotation or [0, 0, 0, 1]
    m = np.eye(4)
    m[:3, :3] = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    ) * np.asarray(n.scale or [1, 1, 1])
    m[:3, 3] = n.translation or [0, 0, 0]
    return m


def _worlds(g, pose: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """Node world matrices with ``pose`` (node -> rotation) applied after each node's local."""
    parents = {c: i for i, n in enumerate(g.nodes) for c in n.children or []}
    out: dict[int, np.ndarray] = {}

    def world(i: int) -> np.ndarray:
        if i not in out:
            local = _local(g.nodes[i]) @ pose.get(i, np.eye(4))
            out[i] = local if i not in parents else world(parents[i]) @ local
        return out[i]

    for i in range(len(g.nodes)):
        world(i)
    return out


def _rot_x(deg: float) -> np.ndarray:
    a = np.radians(deg)
    m = np.eye(4)
    m[1:3, 1:3] = [[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]
    return m


def _wrinkled_prims(stage):
    from pxr import UsdShade

    mat = next(
        p for p in stage.Traverse() if p.IsA(UsdShade.Material) and p.HasAttribute("wrinkle:meshes")
    )
    return [stage.GetPrimAtPath(p) for p in mat.GetAttribute("wrinkle:meshes").Get()]


def _wrinkled_node(g, src: Path) -> tuple[int, int, int]:
    """(node, mesh, primitive) of the first wrinkled primitive: the one using the output's
    wrinkled material, found by its vertex ID attribute."""
    for i, n in enumerate(g.nodes):
        if n.mesh is None:
            continue
        for k, p in enumerate(g.meshes[n.mesh].primitives):
            if getattr(p.attributes, "_WRINKLE_VERTEX_ID", None) is not None:
                return i, n.mesh, k
    raise AssertionError("no wrinkled primitive")


def _usd_posed(stage, prim_path: str, joint: str | None, rot: np.ndarray) -> np.ndarray:
    """World points of a prim skinned by UsdSkel (SkinningQuery.ComputeSkinnedPoints), the
    joint ``joint`` of its Skeleton turned by ``rot`` after its rest transform (in the
    stage's session layer, from the file's rest transforms)."""
    from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

    stage.SetEditTarget(stage.GetSessionLayer())
    prim = stage.GetPrimAtPath(prim_path)
    skel = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
    if joint is not None:
        names = list(skel.GetPrim().GetAttribute("wrinkle:jointNames").Get())
        k = names.index(joint)
        spec = stage.GetRootLayer().GetAttributeAtPath(skel.GetRestTransformsAttr().GetPath())
        rest = [np.asarray(m, np.float64) for m in spec.default]
        rest[k] = rot.T @ rest[k]  # row vectors: local' = local @ rot
        skel.GetRestTransformsAttr().Set(Vt.Matrix4dArray([Gf.Matrix4d(m.tolist()) for m in rest]))
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(prim), Usd.TraverseInstanceProxies())
    sq = cache.GetSkinningQuery(prim)
    xf = cache.GetSkelQuery(skel).ComputeSkinningTransforms(Usd.TimeCode.Default())
    pts = Vt.Vec3fArray(UsdGeom.Mesh(prim).GetPointsAttr().Get())
    assert sq.ComputeSkinnedPoints(xf, pts, Usd.TimeCode.Default())
    skel_world = np.asarray(
        UsdGeom.Xformable(skel.GetPrim()).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    ).T
    p = np.asarray(pts, np.float64)
    return p @ skel_world[:3, :3].T + skel_world[:3, 3]


def _gltf_posed(g, src: Path, node: int, mesh: int, prim: int, pose: dict) -> np.ndarray:
    """numpy linear-blend skinning of the glTF accessors (a rigid node: its world matrix)."""
    p = g.meshes[mesh].primitives[prim]
    pos = ref.accessor(g, src, p.attributes.POSITION).astype(np.float64)
    worlds = _worlds(g, pose)
    skin = g.nodes[node].skin
    if skin is None:
        m = worlds[node]
        return pos @ m[:3, :3].T + m[:3, 3]
    s = g.skins[skin]
    ibm = ref.accessor(g, src, s.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    joints = ref.accessor(g, src, p.attributes.JOINTS_0).astype(np.int64)
    weights = ref.accessor(g, src, p.attributes.WEIGHTS_0).astype(np.float64)
    mats = np.stack([worlds[j] for j in s.joints]) @ ibm  # [J, 4, 4]
    h = np.concatenate([pos, np.ones((len(pos), 1))], 1)
    per = np.einsum("vkab,vb->vka", mats[joints], h)[..., :3]
    return np.einsum("vk,vka->va", weights, per)


def _pose_joint(g, src: Path, node: int, mesh: int, prim: int) -> int:
    """The joint to turn: the parent of the joint that moves the wrinkled primitive (rigid: its
    nearest joint ancestor; skinned: its most-weighted joint), so the hierarchy carries the
    motion down."""
    parents = {c: i for i, n in enumerate(g.nodes) for c in n.children or []}
    joints = {j for s in g.skins for j in s.joints}
    skin = g.nodes[node].skin
    if skin is None:
        n = node
        while n not in joints:
            n = parents[n]
    else:
        p = g.meshes[mesh].primitives[prim]
        j = ref.accessor(g, src, p.attributes.JOINTS_0).astype(np.int64)
        w = ref.accessor(g, src, p.attributes.WEIGHTS_0)
        total = np.bincount(j.reshape(-1), w.reshape(-1), len(g.skins[skin].joints))
        n = g.skins[skin].joints[int(np.argmax(total))]
    return parents[n] if parents.get(n) in joints else n


@pytest.mark.parametrize("name", ["avatar", "robot", "cesium"])
def test_wrinkled_prims_pose_with_the_skeleton_as_the_gltf_skin(characters, name):
    from pxr import Usd, UsdSkel

    if name not in characters:
        pytest.skip("../shared/data is absent")
    src, out, asset = characters[name]
    g = ref.load(src)
    usda = out / f"{asset}.usda"
    stage = Usd.Stage.Open(str(usda))
    prims = _wrinkled_prims(stage)
    assert len(prims) == 1
    prim = prims[0]
    node, mesh, k = _wrinkled_node(ref.load(out / f"{asset}.gltf"), out / f"{asset}.gltf")
    binding = UsdSkel.BindingAPI(prim)
    skel = binding.GetInheritedSkeleton()
    assert "/Scene/Skeletons/" in str(skel.GetPath())  # the scene's, not a flat one
    # the Skeleton is the glTF skin: joint names, hierarchy (parents) and bind = inv(IBM)
    gskin = g.nodes[node].skin
    joint = _pose_joint(g, src, node, mesh, k)
    sidx = (
        gskin if gskin is not None else next(i for i, s in enumerate(g.skins) if joint in s.joints)
    )
    joints = list(g.skins[sidx].joints)
    names = list(skel.GetPrim().GetAttribute("wrinkle:jointNames").Get())
    assert names == [g.nodes[j].name or f"node{j}" for j in joints]
    parents = {c: i for i, n in enumerate(g.nodes) for c in n.children or []}
    topo = UsdSkel.Topology(skel.GetJointsAttr().Get())
    assert [joints[p] if p >= 0 else None for p in topo.GetParentIndices()] == [
        parents.get(j) if parents.get(j) in joints else None for j in joints
    ]
    ibm = ref.accessor(g, src, g.skins[sidx].inverseBindMatrices).reshape(-1, 4, 4)
    np.testing.assert_allclose(
        np.asarray(skel.GetBindTransformsAttr().Get()), np.linalg.inv(ibm), atol=1e-5
    )
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(prim), Usd.TraverseInstanceProxies())
    sq = cache.GetSkinningQuery(prim)
    assert sq.HasJointInfluences()
    ji, jw = sq.ComputeJointInfluences()
    p = g.meshes[mesh].primitives[k]
    if gskin is not None:  # the glTF's JOINTS_0 / WEIGHTS_0, per point
        w = ref.accessor(g, src, p.attributes.WEIGHTS_0)
        j = ref.accessor(g, src, p.attributes.JOINTS_0).astype(np.int64)
        n = sq.GetNumInfluencesPerComponent()
        np.testing.assert_allclose(np.asarray(jw).reshape(-1, n), w, atol=1e-6)
        np.testing.assert_array_equal(np.asarray(ji).reshape(-1, n), np.where(w > 0, j, 0))
        np.testing.assert_allclose(np.asarray(sq.GetGeomBindTransform()), np.eye(4))
    else:  # rigid: bound to its joint whole
        assert sq.IsRigidlyDeformed() and list(jw) == [1.0]
        assert names[int(ji[0])] == g.nodes[parents[node]].name
    # at rest and with a joint turned 30 degrees: UsdSkel's points = the glTF skin's
    scale = float(np.ptp(ref.accessor(g, src, p.attributes.POSITION), axis=0).max())
    for deg in (0.0, 30.0):
        pose = {joint: _rot_x(deg)}
        want = _gltf_posed(g, src, node, mesh, k, pose)
        got = _usd_posed(stage, str(prim.GetPath()), g.nodes[joint].name, _rot_x(deg))
        np.testing.assert_allclose(got, want, atol=2e-5 * max(scale, 1.0))
        if deg:  # the pose moves the wrinkled vertices (the check can fail)
            rest = _gltf_posed(g, src, node, mesh, k, {})
            assert np.abs(want - rest).max() > 0.05 * scale


@pytest.mark.parametrize("name", ["avatar", "robot", "cesium"])
def test_usd_reads_the_wrinkled_mesh_the_gltf_path_measures(characters, name):
    if name not in characters:
        pytest.skip("../shared/data is absent")
    _, out, asset = characters[name]
    u = read_usd(out / f"{asset}.usda").mesh
    g = read_wrinkled(out / f"{asset}.gltf").mesh
    np.testing.assert_array_equal(u.indices, g.indices)
    np.testing.assert_array_equal(u.vertex_ids, g.vertex_ids)
    np.testing.assert_allclose(u.positions, g.positions, atol=1e-5)
    np.testing.assert_allclose(u.tangents, g.tangents, atol=1e-5)
    np.testing.assert_allclose(u.normals, g.normals, atol=1e-5)
    np.testing.assert_allclose(u.uvs, g.uvs, atol=1e-6)
    assert u.joint_names == g.joint_names and u.morph_names == g.morph_names
    assert u.name == g.name  # the package mesh's name, not a prim path
    for f in ("joints", "skin_weights", "inverse_bind", "morph_deltas"):
        a, b = getattr(u, f), getattr(g, f)
        assert (a is None) == (b is None), f
        if a is not None:
            np.testing.assert_allclose(a, b, atol=1e-6)


def _usd_errors(path: Path) -> list[str]:
    from pxr import Usd

    return [e.GetMessage() for e in usd_checks.validation_errors(Usd.Stage.Open(str(path)))]


@pytest.mark.parametrize("name", ["avatar", "robot", "cesium"])
def test_usd_validation_and_validate_asset_are_clean(characters, name, capsys):
    if name not in characters:
        pytest.skip("../shared/data is absent")
    _, out, asset = characters[name]
    assert _usd_errors(out / f"{asset}.usda") == []
    reports = {}
    for suffix in ("usda", "gltf"):
        args = [str(out / f"{asset}.{suffix}"), "--no-render", "--json"]
        code = main(["validate-asset", *args, "--allow-root", str(ROBOT.parents[1])])
        text = capsys.readouterr().out
        reports[suffix] = json.loads(text[: text.rindex("}") + 1])
        assert code == 0 and reports[suffix]["counts"]["error"] == 0
    u, g = reports["usda"], reports["gltf"]
    assert [i["code"] for i in u["issues"]] == [i["code"] for i in g["issues"]]
    assert [i["message"] for i in u["issues"]] == [i["message"] for i in g["issues"]]
    assert u["metrics"] == g["metrics"]


def test_wrinkled_mesh_outside_the_scene_is_written_unplaced(tmp_path):
    from pxr import Usd, UsdSkel

    def change(doc, data, folder):  # the Head node (20) taken out of the scene
        doc["scenes"][0]["nodes"] = [n for n in doc["scenes"][0]["nodes"] if n != 20]

    res = convert(avatar_variant(tmp_path, change), tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0
    assert any(
        "is in no scene: written below /avatar/Scene/Unplaced" in n for n in res.report["notes"]
    )
    usda = tmp_path / "out" / "avatar.usda"
    stage = Usd.Stage.Open(str(usda))
    (prim,) = _wrinkled_prims(stage)
    assert str(prim.GetPath()) == "/avatar/Scene/Unplaced/Head"
    assert "/Scene/Skeletons/" in str(UsdSkel.BindingAPI(prim).GetInheritedSkeleton().GetPath())
    u, g = read_usd(usda).mesh, read_wrinkled(tmp_path / "out" / "avatar.gltf").mesh
    np.testing.assert_allclose(u.positions, g.positions, atol=1e-6)
    np.testing.assert_array_equal(u.vertex_ids, g.vertex_ids)
    assert _usd_errors(usda) == []


def test_rigid_morph_head_under_no_joint_plays_its_blend_shapes(tmp_path):
    """The Head made rigid (no skin) at the scene root: bound to the one-joint Morphs skeleton
    (geomBindTransform = its world matrix), whose SkelAnimation plays the glTF output's morph
    weight animation; UsdSkel's blend-shape query applies them to the points as glTF does."""
    from pxr import Usd, UsdGeom, UsdSkel

    def change(doc, data, folder):
        del doc["nodes"][20]["skin"]
        doc["nodes"][20]["translation"] = [0.0, 0.25, 0.0]
        for p in doc["meshes"][0]["primitives"]:
            p["attributes"].pop("JOINTS_0"), p["attributes"].pop("WEIGHTS_0")

    res = convert(avatar_variant(tmp_path, change), tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0
    out = tmp_path / "out"
    stage = Usd.Stage.Open(str(out / "avatar.usda"))
    (prim,) = _wrinkled_prims(stage)
    skel = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
    assert skel.GetPath().name == "Morphs"
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(prim), Usd.TraverseInstanceProxies())
    sq = cache.GetSkinningQuery(prim)
    assert sq.IsRigidlyDeformed()
    np.testing.assert_allclose(
        np.asarray(sq.GetGeomBindTransform())[3, :3], [0.0, 0.25, 0.0], atol=1e-7
    )
    # the glTF output's morph-weight channel on the Head node = the SkelAnimation's samples
    g = ref.load(out / "avatar.gltf")
    names = g.meshes[0].extras["targetNames"]
    channel = [  # the last: convert's curve animation (after the source's own)
        (a, c)
        for a in g.animations
        for c in a.channels
        if c.target.node == 20 and c.target.path == "weights"
    ][-1]
    sampler = channel[0].samplers[channel[1].sampler]
    t = ref.accessor(g, out / "avatar.gltf", sampler.input).reshape(-1)
    w = ref.accessor(g, out / "avatar.gltf", sampler.output).reshape(len(t), len(names))
    anim = UsdSkel.Animation(UsdSkel.BindingAPI(skel.GetPrim()).GetAnimationSource())
    assert list(anim.GetBlendShapesAttr().Get()) == names
    attr = anim.GetBlendShapeWeightsAttr()
    fps = stage.GetTimeCodesPerSecond()
    np.testing.assert_allclose(np.asarray(attr.GetTimeSamples()) / fps, t, atol=1e-6)
    got = np.stack([np.asarray(attr.Get(c)) for c in attr.GetTimeSamples()])
    np.testing.assert_allclose(got, w, atol=1e-6)
    # UsdSkel applies them: points at the busiest frame = positions + sum w deltas (glTF)
    f = int(np.argmax(w.sum(1)))
    code = attr.GetTimeSamples()[f]
    skel_q = cache.GetSkelQuery(skel)
    bsq = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim))
    weights = sq.GetBlendShapeMapper().Remap(skel_q.GetAnimQuery().ComputeBlendShapeWeights(code))
    sub = bsq.ComputeSubShapeWeights(weights)
    pts = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(), np.float32)
    from pxr import Vt

    posed = Vt.Vec3fArray.FromNumpy(pts.copy())
    assert bsq.ComputeDeformedPoints(
        sub[0],
        sub[1],
        sub[2],
        bsq.ComputeBlendShapePointIndices(),
        bsq.ComputeSubShapePointOffsets(),
        posed,
    )
    p = g.meshes[0].primitives[0]
    want = ref.accessor(g, out / "avatar.gltf", p.attributes.POSITION).astype(np.float64)
    for i, target in enumerate(p.targets):
        want = want + w[f, i] * ref.accessor(g, out / "avatar.gltf", target["POSITION"])
    np.testing.assert_allclose(np.asarray(posed), want, atol=1e-5)
    assert np.abs(want - pts).max() > 1e-3  # the frame moves the face
    assert _usd_errors(out / "avatar.usda") == []


def test_texture_transform_becomes_a_usd_transform2d(tmp_path):
    """KHR_texture_transform on the Body's base colour (offset, rotation, scale, texCoord): a
    UsdTransform2d between its primvar reader and the texture whose transform of USD's st,
    applied as the UsdPreviewSurface spec says (scale, then rotate counter-clockwise by
    degrees, then translate), is the glTF transform of uv (the spec's T * R * S, written out
    here as three.js's GLTFLoader builds its matrix) with v flipped."""
    from pxr import Usd, UsdShade

    xf = {"offset": [0.25, -0.5], "rotation": 0.4, "scale": [0.5, 2.0], "texCoord": 0}

    def change(doc, data, folder):
        doc["materials"][3]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {
            "KHR_texture_transform": xf
        }
        doc["extensionsUsed"].append("KHR_texture_transform")

    res = convert(avatar_variant(tmp_path, change), tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0
    assert not any("KHR_texture_transform" in n for n in res.report["notes"])
    usda = tmp_path / "out" / "avatar.usda"
    stage = Usd.Stage.Open(str(usda))
    body = next(p for p in stage.Traverse() if p.IsA(UsdShade.Material) and p.GetName() == "Body")
    tex = UsdShade.Shader(body.GetChild("baseColorTexture"))
    src, _, _ = tex.GetInput("st").GetConnectedSource()
    t2d = UsdShade.Shader(src.GetPrim())
    assert t2d.GetIdAttr().Get() == "UsdTransform2d"
    reader, _, _ = t2d.GetInput("in").GetConnectedSource()
    assert reader.GetPrim().GetAttribute("inputs:varname").Get() == "st"
    scale = np.asarray(t2d.GetInput("scale").Get(), np.float64)
    deg = float(t2d.GetInput("rotation").Get())
    move = np.asarray(t2d.GetInput("translation").Get(), np.float64)
    # glTF: uv' = M (u, v, 1), M as three.js sets it (row-major) for T * R * S
    (ox, oy), r, (sx, sy) = xf["offset"], xf["rotation"], xf["scale"]
    c, s = np.cos(r), np.sin(r)
    m = np.array([[sx * c, sy * s, ox], [-sx * s, sy * c, oy], [0, 0, 1]])
    uv = np.stack(np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 5)), -1).reshape(-1, 2)
    want = (np.concatenate([uv, np.ones((len(uv), 1))], 1) @ m.T)[:, :2]
    # USD: st = (u, 1 - v); st' = translation + rotate(deg) (scale * st); back to uv
    st = np.stack([uv[:, 0], 1 - uv[:, 1]], -1) * scale
    a = np.radians(deg)
    rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    st2 = st @ rot.T + move
    got = np.stack([st2[:, 0], 1 - st2[:, 1]], -1)
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert _usd_errors(usda) == []


def _image(doc: dict, data: bytes, i: int) -> bytes:
    view = doc["bufferViews"][doc["images"][i]["bufferView"]]
    return data[view.get("byteOffset", 0) :][: view["byteLength"]]


def _append_image(doc: dict, data: bytes, blob: bytes, mime: str, name: str) -> tuple[int, bytes]:
    pad = b"\0" * ((-len(data)) % 4)
    doc["bufferViews"].append(
        {"buffer": 0, "byteOffset": len(data) + len(pad), "byteLength": len(blob)}
    )
    doc["images"].append(
        {"name": name, "mimeType": mime, "bufferView": len(doc["bufferViews"]) - 1}
    )
    new = data + pad + blob
    new += b"\0" * ((-len(new)) % 4)
    doc["buffers"][0]["byteLength"] = len(new)
    return len(doc["images"]) - 1, new


def test_ktx2_and_webp_images_are_transcoded_to_png_for_usd(tmp_path):
    """The Body's base colour only as a UASTC KTX2 image (KHR_texture_basisu, no fallback
    source) and the Teeth's only as a lossless WebP (EXT_texture_webp): the USD's textures are
    PNGs of their pixels (PIL reads them: the WebP's exactly, the KTX2's as alktx2 decodes it,
    close to the source PNG), noted; the glTF keeps both images byte for byte."""
    import io

    alktx2 = pytest.importorskip("alktx2")
    from PIL import Image
    from pxr import Usd, UsdShade

    blobs: dict[str, bytes] = {}

    def change(doc, data, folder):
        body = doc["materials"][3]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
        teeth = doc["materials"][2]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
        png = folder / "body.png"
        blobs["body_png"] = _image(doc, data, doc["textures"][body]["source"])
        png.write_bytes(blobs["body_png"])
        ktx = folder / "body.ktx2"
        alktx2.encode_image_to_ktx2(
            str(png), str(ktx), codec="uastc", srgb=True, quality=255, effort=5
        )
        blobs["ktx2"] = ktx.read_bytes()
        png.unlink(), ktx.unlink()
        blobs["teeth_png"] = _image(doc, data, doc["textures"][teeth]["source"])
        webp = io.BytesIO()
        Image.open(io.BytesIO(blobs["teeth_png"])).save(webp, "WEBP", lossless=True)
        blobs["webp"] = webp.getvalue()
        k, data = _append_image(doc, data, blobs["ktx2"], "image/ktx2", "body_ktx2")
        doc["textures"][body] = {"extensions": {"KHR_texture_basisu": {"source": k}}}
        w, data = _append_image(doc, data, blobs["webp"], "image/webp", "teeth_webp")
        doc["textures"][teeth] = {"extensions": {"EXT_texture_webp": {"source": w}}}
        doc["extensionsUsed"] += ["KHR_texture_basisu", "EXT_texture_webp"]
        doc.setdefault("extensionsRequired", []).extend(["KHR_texture_basisu", "EXT_texture_webp"])
        return data

    res = convert(avatar_variant(tmp_path, change), tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0
    notes = [n for n in res.report["notes"] if "transcoded to PNG for the USD" in n]
    assert (
        len(notes) == 2 and "image/ktx2" in notes[0] + notes[1] and "image/webp" in "".join(notes)
    )
    out = tmp_path / "out"
    stage = Usd.Stage.Open(str(out / "avatar.usda"))

    def usd_pixels(material: str) -> np.ndarray:
        mat = next(
            p for p in stage.Traverse() if p.IsA(UsdShade.Material) and p.GetName() == material
        )
        f = UsdShade.Shader(mat.GetChild("baseColorTexture")).GetInput("file").Get().path
        assert f.endswith(".png")
        return np.asarray(Image.open(out / f).convert("RGBA"), np.int64)

    teeth = np.asarray(Image.open(io.BytesIO(blobs["teeth_png"])).convert("RGBA"), np.int64)
    np.testing.assert_array_equal(usd_pixels("Teeth"), teeth)  # lossless WebP: exact
    decoded, _ = alktx2.decode_ktx2_to_bytes(blobs["ktx2"], format="png")
    ktx_px = np.asarray(Image.open(io.BytesIO(bytes(decoded))).convert("RGBA"), np.int64)
    np.testing.assert_array_equal(usd_pixels("Body"), ktx_px)
    body = np.asarray(Image.open(io.BytesIO(blobs["body_png"])).convert("RGBA"), np.int64)
    assert np.abs(ktx_px - body).mean() < 4  # UASTC: close to the source
    # the glTF output keeps both images as they were
    g = ref.load(out / "avatar.gltf")
    got = {ref.image_bytes(g, out / "avatar.gltf", i) for i in range(len(g.images))}
    assert {blobs["ktx2"], blobs["webp"]} <= got
    assert _usd_errors(out / "avatar.usda") == []


def _clip_pose(g, src: Path, a: int) -> tuple[float, dict[int, np.ndarray]]:
    """A time that is a key of every TRS channel of animation ``a`` (the middle key of the
    first) and each animated node's local matrix there, read from the accessors."""
    anim = g.animations[a]
    chans = [c for c in anim.channels if c.target.path in ("translation", "rotation", "scale")]
    times = [ref.accessor(g, src, anim.samplers[c.sampler].input).reshape(-1) for c in chans]
    t = float(times[0][len(times[0]) // 2])
    trs: dict[int, dict[str, np.ndarray]] = {}
    for c, keys in zip(chans, times):
        (k,) = np.flatnonzero(np.isclose(keys, t, atol=1e-6))  # a key of every channel
        values = ref.accessor(g, src, anim.samplers[c.sampler].output)
        trs.setdefault(c.target.node, {})[c.target.path] = values[k]
    locals_ = {}
    for n, got in trs.items():
        node = g.nodes[n]
        tr = got.get("translation", node.translation or [0, 0, 0])
        x, y, z, w = got.get("rotation", node.rotation or [0, 0, 0, 1])
        sc = got.get("scale", node.scale or [1, 1, 1])
        m = np.eye(4)
        m[:3, :3] = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        ) * np.asarray(sc)
        m[:3, 3] = tr
        locals_[n] = m
    return t, locals_


@pytest.mark.parametrize(("name", "clip"), [("robot", "Wave"), ("cesium", None)])
def test_gltf_clips_play_as_skel_animations(characters, name, clip):
    """Each glTF animation is a SkelAnimation variant of Scene's 'animation' set: with the clip
    selected, UsdSkel's skinned points of the wrinkled primitive at a key time equal the glTF
    skin (numpy LBS of the accessors, the keyed TRS put on the nodes) at that time."""
    from pxr import Usd, UsdGeom, UsdSkel, Vt

    if name not in characters:
        pytest.skip("../shared/data is absent")
    src, out, asset = characters[name]
    g = ref.load(src)
    a = next(i for i, x in enumerate(g.animations) if x.name == clip) if clip else 0
    t, locals_ = _clip_pose(g, src, a)
    stage = Usd.Stage.Open(str(out / f"{asset}.usda"))
    vset = stage.GetDefaultPrim().GetChild("Scene").GetVariantSets().GetVariantSet("animation")
    variant = clip or "animation_0"
    assert variant in vset.GetVariantNames()
    # inspect lists the set: a variant per clip, and wrinkle (selected) where the curve drives
    # morphs (the robot's face; CesiumMan has none: its clip is selected)
    row = usd_summary(out / f"{asset}.usda")["prims"][f"/{asset}/Scene"]["variantSets"]
    morphs = name == "robot"
    assert row["animation"]["selected"] == ("wrinkle" if morphs else "animation_0")
    assert len(row["animation"]["variants"]) == len(g.animations) + morphs
    last = max(float(ref.accessor(g, src, s.input).max()) for x in g.animations for s in x.samplers)
    fps = stage.GetTimeCodesPerSecond()
    assert stage.GetEndTimeCode() == pytest.approx(max(last * fps, 0.0), abs=1e-4)  # whole clips
    stage.SetEditTarget(stage.GetSessionLayer())
    vset.SetVariantSelection(variant)
    (prim,) = _wrinkled_prims(stage)
    node, mesh, k = _wrinkled_node(ref.load(out / f"{asset}.gltf"), out / f"{asset}.gltf")
    skel = UsdSkel.BindingAPI(prim).GetInheritedSkeleton()
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(prim), Usd.TraverseInstanceProxies())
    code = Usd.TimeCode(t * stage.GetTimeCodesPerSecond())
    xf = cache.GetSkelQuery(skel).ComputeSkinningTransforms(code)
    pts = Vt.Vec3fArray(UsdGeom.Mesh(prim).GetPointsAttr().Get())
    assert cache.GetSkinningQuery(prim).ComputeSkinnedPoints(xf, pts, code)
    got = np.asarray(pts, np.float64)

    parents = {c: i for i, n in enumerate(g.nodes) for c in n.children or []}
    worlds: dict[int, np.ndarray] = {}

    def world(i: int) -> np.ndarray:
        if i not in worlds:
            local = locals_.get(i, _local(g.nodes[i]))
            worlds[i] = local if i not in parents else world(parents[i]) @ local
        return worlds[i]

    p = g.meshes[mesh].primitives[k]
    pos = ref.accessor(g, src, p.attributes.POSITION).astype(np.float64)
    if g.nodes[node].skin is None:
        m = world(node)
        want = pos @ m[:3, :3].T + m[:3, 3]
    else:
        s = g.skins[g.nodes[node].skin]
        ibm = ref.accessor(g, src, s.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
        j = ref.accessor(g, src, p.attributes.JOINTS_0).astype(np.int64)
        w = ref.accessor(g, src, p.attributes.WEIGHTS_0).astype(np.float64)
        mats = np.stack([world(x) for x in s.joints]) @ ibm
        h = np.concatenate([pos, np.ones((len(pos), 1))], 1)
        want = np.einsum("vk,vka->va", w, np.einsum("vkab,vb->vka", mats[j], h)[..., :3])
    size = float(np.ptp(pos, axis=0).max())
    np.testing.assert_allclose(got, want, atol=1e-4 * max(size, 1.0))
    rest = _gltf_posed(g, src, node, mesh, k, {})
    assert np.abs(want - rest).max() > 0.01 * size  # the clip moves it at that time


def test_two_wrinkled_materials_read_back_in_the_package_order(tmp_path):
    """material = ["Skin", "Teeth"]: both skinned meshes in the scene, listed in the package's
    order in wrinkle:meshes; read_usd's merged mesh = read_wrinkled's, vertex for vertex."""
    from wrinklepipe.io.images import write_image

    manifest = avatar_variant(tmp_path, lambda doc, data, folder: None)
    flat = np.zeros((64, 64, 3))  # the states' size
    flat[...] = (0.5, 0.5, 1.0)
    write_image(manifest.parent / "flat.png", flat, 8)  # Teeth has no normalTexture
    text = manifest.read_text().replace(
        'material = "Skin"', 'material = ["Skin", "Teeth"]\nbase = "flat.png"'
    )
    manifest.write_text(text)
    res = convert(manifest, tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0
    u = read_usd(tmp_path / "out" / "avatar.usda").mesh
    g = read_wrinkled(tmp_path / "out" / "avatar.gltf").mesh
    assert [p.name for p in u.parts] == [
        "/avatar/Scene/Skinned/Head",
        "/avatar/Scene/Skinned/Teeth",
    ]
    assert [p.name for p in g.parts] == ["Head", "Teeth"]
    assert [p.count for p in u.parts] == [p.count for p in g.parts]
    np.testing.assert_array_equal(u.indices, g.indices)
    np.testing.assert_array_equal(u.vertex_ids, g.vertex_ids)
    np.testing.assert_array_equal(u.positions, g.positions)
    np.testing.assert_array_equal(u.joints, g.joints)
    assert u.morph_names == g.morph_names and u.joint_names == g.joint_names


def _append_accessor(doc: dict, data: bytes, values: np.ndarray, kind: str) -> tuple[int, bytes]:
    blob = np.ascontiguousarray(values, np.float32).tobytes()
    pad = b"\0" * ((-len(data)) % 4)
    doc["bufferViews"].append(
        {"buffer": 0, "byteOffset": len(data) + len(pad), "byteLength": len(blob)}
    )
    acc = {"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5126}
    acc.update(count=len(values), type=kind)
    if kind == "SCALAR":
        acc.update(min=[float(values.min())], max=[float(values.max())])
    doc["accessors"].append(acc)
    new = data + pad + blob
    doc["buffers"][0]["byteLength"] = len(new)
    return len(doc["accessors"]) - 1, new


def test_non_joint_nodes_animate_their_xforms_and_carry_the_skeleton(tmp_path):
    """A clip moving two nodes that are no joints: the Avatar root (the skeleton's parent:
    translated) and the Eyes made rigid (rotated about Y): with its variant selected, at the
    key time 1 s the Eyes' Xform (UsdGeom.XformCache) places its points where glTF does, and
    UsdSkel's skinned Head follows the moved root as the glTF skin; at the default time the
    rest pose (what validate reads)."""
    from pxr import Usd, UsdGeom, UsdSkel, Vt

    half = np.sin(0.3), np.cos(0.3)

    def change(doc, data, folder):
        del doc["nodes"][21]["skin"]  # the Eyes: a rigid part under the scene root
        for p in doc["meshes"][1]["primitives"]:
            p["attributes"].pop("JOINTS_0"), p["attributes"].pop("WEIGHTS_0")
        t, data = _append_accessor(doc, data, np.array([0.0, 1.0]), "SCALAR")
        move, data = _append_accessor(doc, data, np.array([[0, 0, 0], [0.5, 0.1, 0]]), "VEC3")
        turn, data = _append_accessor(
            doc, data, np.array([[0, 0, 0, 1], [0, half[0], 0, half[1]]]), "VEC4"
        )
        doc["animations"].append(
            {
                "name": "Props",
                "samplers": [{"input": t, "output": move}, {"input": t, "output": turn}],
                "channels": [
                    {"sampler": 0, "target": {"node": 24, "path": "translation"}},
                    {"sampler": 1, "target": {"node": 21, "path": "rotation"}},
                ],
            }
        )
        return data

    manifest = avatar_variant(tmp_path, change)
    res = convert(manifest, tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0
    src = manifest.parent / "avatar.glb"
    g = ref.load(src)
    out = tmp_path / "out"
    stage = Usd.Stage.Open(str(out / "avatar.usda"))
    stage.SetEditTarget(stage.GetSessionLayer())
    vset = stage.GetDefaultPrim().GetChild("Scene").GetVariantSets().GetVariantSet("animation")
    vset.SetVariantSelection("Props")
    code = Usd.TimeCode(1.0 * stage.GetTimeCodesPerSecond())
    pose = {24: np.eye(4), 21: np.eye(4)}
    pose[24][:3, 3] = [0.5, 0.1, 0]
    pose[21][:3, :3] = [[half[1] ** 2 - half[0] ** 2, 0, 2 * half[0] * half[1]], [0, 1, 0],
                        [-2 * half[0] * half[1], 0, half[1] ** 2 - half[0] ** 2]]  # fmt: skip
    worlds = _worlds(g, pose)  # rest: no rotation/scale, the root at 0: keyed TRS = rest @ pose
    eyes = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and p.GetName() == "Eyes")
    pos = ref.accessor(g, src, g.meshes[1].primitives[0].attributes.POSITION).astype(np.float64)
    for time, w in ((code, worlds[21]), (Usd.TimeCode.Default(), _worlds(g, {})[21])):
        m = np.asarray(UsdGeom.XformCache(time).GetLocalToWorldTransform(eyes)).T
        got = np.asarray(UsdGeom.Mesh(eyes).GetPointsAttr().Get(), np.float64)
        np.testing.assert_allclose(
            got @ m[:3, :3].T + m[:3, 3], pos @ w[:3, :3].T + w[:3, 3], atol=1e-5
        )
    (head,) = _wrinkled_prims(stage)
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root.Find(head), Usd.TraverseInstanceProxies())
    skel = UsdSkel.BindingAPI(head).GetInheritedSkeleton()
    xf = cache.GetSkelQuery(skel).ComputeSkinningTransforms(code)
    pts = Vt.Vec3fArray(UsdGeom.Mesh(head).GetPointsAttr().Get())
    assert cache.GetSkinningQuery(head).ComputeSkinnedPoints(xf, pts, code)
    want = _gltf_posed(g, src, 20, 0, 0, pose)
    np.testing.assert_allclose(np.asarray(pts), want, atol=1e-5)
    assert np.abs(want - _gltf_posed(g, src, 20, 0, 0, {})).max() > 0.4  # moved by the root
    assert read_usd(out / "avatar.usda").mesh.positions.shape[0] > 0
    assert _usd_errors(out / "avatar.usda") == []


def test_clearcoat_and_ior_reach_the_preview_surface_and_others_are_named(tmp_path):
    """KHR_materials_clearcoat (factor 0.6 with a clearcoatTexture, roughness factor 0.3) and
    KHR_materials_ior (1.4) on the Body; KHR_materials_sheen on the Teeth: the Body's
    UsdPreviewSurface has clearcoat <- the texture's r scaled by 0.6, clearcoatRoughness 0.3 and
    ior 1.4; the sheen is named in the report."""
    from pxr import Usd, UsdShade

    def change(doc, data, folder):
        body = doc["materials"][3]
        tex = body["pbrMetallicRoughness"]["baseColorTexture"]["index"]
        body["extensions"] = {
            "KHR_materials_clearcoat": {
                "clearcoatFactor": 0.6,
                "clearcoatTexture": {"index": tex},
                "clearcoatRoughnessFactor": 0.3,
            },
            "KHR_materials_ior": {"ior": 1.4},
        }
        doc["materials"][2]["extensions"] = {"KHR_materials_sheen": {"sheenRoughnessFactor": 0.5}}
        doc["extensionsUsed"] += [
            "KHR_materials_clearcoat",
            "KHR_materials_ior",
            "KHR_materials_sheen",
        ]

    res = convert(avatar_variant(tmp_path, change), tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0
    assert any(
        "material 'Teeth' has KHR_materials_sheen, which UsdPreviewSurface cannot hold" in n
        for n in res.report["notes"]
    )
    assert not any("'Body' has" in n for n in res.report["notes"])
    stage = Usd.Stage.Open(str(tmp_path / "out" / "avatar.usda"))
    body = next(p for p in stage.Traverse() if p.IsA(UsdShade.Material) and p.GetName() == "Body")
    surf = UsdShade.Shader(body.GetChild("Surface"))
    src, out, _ = surf.GetInput("clearcoat").GetConnectedSource()
    assert out == "r" and src.GetPrim().GetName() == "clearcoatTexture"
    scale = UsdShade.Shader(src.GetPrim()).GetInput("scale").Get()
    np.testing.assert_allclose(list(scale), [0.6] * 4, atol=1e-7)
    assert surf.GetInput("clearcoatRoughness").Get() == pytest.approx(0.3)
    assert surf.GetInput("ior").Get() == pytest.approx(1.4)
    assert _usd_errors(tmp_path / "out" / "avatar.usda") == []


def test_gltf_cameras_become_usd_cameras(tmp_path):
    """A perspective camera (yfov 0.6, aspect 1.5, 0.05 .. 100) on a node translated to
    (0, 1.6, 2) and an orthographic one (xmag 2, ymag 1, 0.1 .. 50): pxr's Gf.Frustum of each
    UsdGeom.Camera has the glTF projection window (tan(yfov / 2) x aspect; +-xmag, +-ymag), the
    clipping range and the node's place; a KHR_lights_punctual light is named in the report."""
    from pxr import Gf, Usd, UsdGeom

    def change(doc, data, folder):
        doc["cameras"] = [
            {
                "type": "perspective",
                "perspective": {"yfov": 0.6, "aspectRatio": 1.5, "znear": 0.05, "zfar": 100},
            },
            {
                "type": "orthographic",
                "orthographic": {"xmag": 2, "ymag": 1, "znear": 0.1, "zfar": 50},
            },
        ]
        doc["nodes"] += [
            {"name": "Shot", "camera": 0, "translation": [0, 1.6, 2]},
            {"name": "Plan", "camera": 1},
            {"name": "Key", "extensions": {"KHR_lights_punctual": {"light": 0}}},
        ]
        doc["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "point"}]}}
        doc["extensionsUsed"].append("KHR_lights_punctual")
        doc["scenes"][0]["nodes"] += [
            len(doc["nodes"]) - 3,
            len(doc["nodes"]) - 2,
            len(doc["nodes"]) - 1,
        ]

    res = convert(avatar_variant(tmp_path, change), tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0
    assert any("node 'Key' holds a KHR_lights_punctual light" in n for n in res.report["notes"])
    stage = Usd.Stage.Open(str(tmp_path / "out" / "avatar.usda"))
    cams = {
        p.GetParent().GetName(): UsdGeom.Camera(p)
        for p in stage.Traverse()
        if p.IsA(UsdGeom.Camera)
    }
    assert sorted(cams) == ["Plan", "Shot"]
    shot = cams["Shot"].GetCamera(Usd.TimeCode.Default())
    assert shot.projection == Gf.Camera.Perspective
    win = shot.frustum.GetWindow()
    half = np.tan(0.3)
    np.testing.assert_allclose([win.GetMin()[1], win.GetMax()[1]], [-half, half], rtol=1e-6)
    np.testing.assert_allclose(
        [win.GetMin()[0], win.GetMax()[0]], [-1.5 * half, 1.5 * half], rtol=1e-6
    )
    rng = shot.frustum.GetNearFar()
    np.testing.assert_allclose([rng.GetMin(), rng.GetMax()], [0.05, 100], rtol=1e-6)
    np.testing.assert_allclose(list(shot.frustum.GetPosition()), [0, 1.6, 2], atol=1e-6)
    plan = cams["Plan"].GetCamera(Usd.TimeCode.Default())
    assert plan.projection == Gf.Camera.Orthographic
    win = plan.frustum.GetWindow()
    np.testing.assert_allclose([*win.GetMin(), *win.GetMax()], [-2, -1, 2, 1], rtol=1e-6)
    assert _usd_errors(tmp_path / "out" / "avatar.usda") == []
