"""The generated multi-mesh avatar (wrinklepipe.demo.avatar) through convert: its head material
wrinkled, the base its own normalTexture, nothing else of the character lost.

The fixture's claims are checked by pygltflib (4 meshes, 4 textured materials, 20 joints whose
rest pose is not the bind pose, morphs on two meshes); the conversion by pygltflib + struct, the
Khronos validator, glTF-Transform's inspect and ``inspect --diff``."""

from __future__ import annotations

import io
import json
import re
import shutil
from pathlib import Path

import gltf_reference as ref
import numpy as np
import pytest
import usd_checks
from output_hashes import assert_unchanged
from passthrough import EXTENSION, WRINKLE_ATTRIBUTES, compare
from PIL import Image
from test_document_inspect import GLTF_TRANSFORM, gltf_transform_inspect
from wrinkle_setups import avatar_variant

from wrinklepipe.cli import main
from wrinklepipe.demo import avatar
from wrinklepipe.errors import InputError
from wrinklepipe.gltf.document import read_document
from wrinklepipe.gltf.images import image_pixels
from wrinklepipe.gltf.limits import GltfReadOptions
from wrinklepipe.io import khronos
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.sources.validation import load_input


@pytest.fixture(scope="session")
def source() -> Path:
    return avatar.avatar_source_dir()


@pytest.fixture(scope="session")
def converted(source, tmp_path_factory):
    out = tmp_path_factory.mktemp("avatar") / "out"
    res = convert(source, out, ConvertOptions(glb=True, render=False))
    assert res.exit_code == 0, res.report["validation"]
    return out, res.report


def test_outputs_are_the_recorded_bytes(converted):
    """Every file of the conversion as recorded on main (``tests/output_hashes.py``)."""
    assert_unchanged("avatar", converted[0])


def _world(nodes, i, parents) -> np.ndarray:
    n = nodes[i]
    t = np.eye(4)
    t[:3, 3] = n.translation or [0, 0, 0]
    x, y, z, w = n.rotation or [0, 0, 0, 1]
    r = np.eye(4)
    r[:3, :3] = [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]
    local = t @ r
    return local if parents[i] is None else _world(nodes, parents[i], parents) @ local


def test_fixture_is_the_character_the_issue_describes(source):
    path = source.parent / "avatar.glb"
    g = ref.load(path)
    assert [m.name for m in g.meshes] == ["Head", "Eyes", "Teeth", "Body"]
    assert [m.name for m in g.materials] == ["Skin", "Eye", "Teeth", "Body"]
    assert all(m.pbrMetallicRoughness.baseColorTexture is not None for m in g.materials)
    assert g.materials[0].normalTexture.index == 1 and len(g.images) == 5
    assert [len(p.targets or []) for m in g.meshes for p in m.primitives] == [3, 0, 1, 0]
    skin = g.skins[0]
    assert len(skin.joints) == 20
    parents = {i: None for i in range(len(g.nodes))}
    for i, n in enumerate(g.nodes):
        for c in n.children or []:
            parents[c] = i

    def depth(j: int | None) -> int:
        return 0 if j is None else 1 + depth(parents[j])

    assert max(depth(j) for j in skin.joints) == 9  # Avatar > Hips > 3 spines > arm chain
    ibm = ref.accessor(g, path, skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    rest = np.stack([_world(g.nodes, j, parents) for j in skin.joints])
    bind = np.linalg.inv(ibm)
    moved = np.abs(rest - bind).max(axis=(1, 2)) > 1e-3
    names = [g.nodes[j].name for j in np.array(skin.joints)[moved]]
    assert "LeftHand" in names and "HeadTop" in names  # arms lowered, head turned at rest
    assert avatar.avatar_glb_bytes() == path.read_bytes()  # deterministic


@pytest.mark.parametrize("name", ["avatar.gltf", "avatar.glb"])
def test_avatar_loses_nothing(source, converted, name):
    out, _ = converted
    src = source.parent / "avatar.glb"
    added = compare(src, out / name, base_replaced=False)
    assert added.attributes == {(0, 0): WRINKLE_ATTRIBUTES}  # the head only; it had UVs
    assert added.materials == [0] and added.clones == {}
    assert (added.textures, added.images) == (3, 3)  # 2 states + 1 mask; the base is Skin's
    assert added.animations == ["blendshapes"] and not added.repaired
    doc = json.loads((out / "avatar.gltf").read_text())
    assert doc["materials"][0]["normalTexture"] == {"index": 1}  # the material's own base
    assert doc["materials"][0]["extensions"][EXTENSION]["regions"][0]["name"] == "brow_L"


@pytest.mark.skipif(not khronos.available(), reason="Khronos validator not installed")
@pytest.mark.parametrize("name", ["avatar.gltf", "avatar.glb"])
def test_avatar_output_passes_the_khronos_validator(converted, name):
    out, _ = converted
    report = khronos.validate_gltf(out / name)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]


@pytest.mark.skipif(not GLTF_TRANSFORM.exists(), reason="npm @gltf-transform/cli absent")
def test_avatar_gltf_transform_sees_the_same_character_plus_the_additions(source, converted):
    out, _ = converted
    before = gltf_transform_inspect(source.parent / "avatar.glb")
    after = gltf_transform_inspect(out / "avatar.glb")
    for section, keys in (
        ("MESHES", ("name", "vertices")),
        ("MATERIALS", ("name", "instances")),
    ):
        rows0 = [tuple(r[k] for k in keys) for r in before[section]]
        assert [tuple(r[k] for k in keys) for r in after[section]] == rows0
    keys = ("name", "mimeType", "resolution", "size")
    tex0 = [tuple(r[k] for k in keys) for r in before["TEXTURES"]]
    tex1 = [tuple(r[k] for k in keys) for r in after["TEXTURES"]]
    assert tex1[:5] == tex0  # the source's images, same bytes
    assert sorted(t[0] for t in tex1[5:]) == ["mask_0", "wrinkle_compress", "wrinkle_stretch"]
    anim = [r["name"] for r in after["ANIMATIONS"]]
    assert (
        anim
        == [r["name"] for r in before["ANIMATIONS"]] + ["blendshapes"]
        == [
            "Idle",
            "blendshapes",
        ]
    )


def test_avatar_inspect_diff_lists_only_the_additions(source, converted, capsys):
    out, _ = converted
    assert main(["inspect", "--diff", str(source.parent / "avatar.glb"), str(out / "avatar.glb")])
    text = " ".join(capsys.readouterr().out.split())  # the table may wrap long lines
    # the block-compressed copies' texture references (one per shipped copy) aside
    copies = re.findall(r"\+ \S*WRINKLEPIPE_wrinkle_maps\.compressed\[\d+\]\.texture: \d+ ", text)
    text = re.sub(r"\+ \S*WRINKLEPIPE_wrinkle_maps\.compressed\[\d+\]\.texture: \d+ ", "", text)
    assert len(copies) == len(json.loads((out / "avatar.gltf").read_text())["materials"][0][
        "extensions"][EXTENSION].get("compressed", []))  # fmt: skip
    ext = "materials[0].textures.extensions.WRINKLEPIPE_wrinkle_maps"
    expected = [
        "+ animations[1]: 'blendshapes'",
        "~ extensionsUsed: ['KHR_materials_emissive_strength'] -> ['KHR_animation_pointer', "
        "'KHR_materials_emissive_strength', 'WRINKLEPIPE_wrinkle_maps']",
        "~ materials[0].extensions: [] -> ['WRINKLEPIPE_wrinkle_maps']",
        f"+ {ext}.masks.textures[0]: 7",
        f"+ {ext}.states[0].texture: 5",
        f"+ {ext}.states[1].texture: 6",
        "+ meshes[0].primitives[0].attributes.TANGENT: 'VEC4:f32'",
        "+ meshes[0].primitives[0].attributes._WRINKLE_VERTEX_ID: 'SCALAR:f32'",
        "+ textures[5]: 'wrinkle_stretch'",
        "+ textures[6]: 'wrinkle_compress'",
        "+ textures[7]: 'mask_0'",
    ]
    assert text == " ".join(expected)


def test_avatar_masks_touch_only_the_head_and_sides_hold(source, converted):
    out, report = converted
    inp = load_input(out)
    mesh = inp.asset.mesh
    assert [(p.pointer, p.count) for p in mesh.parts] == [("/meshes/0/primitives/0", 825)]
    # each side's mask weight falls on its side of the face (character's left = +X): the
    # independent check, from the masks as shipped and the head's own positions
    g = ref.load(source.parent / "avatar.glb")
    pos = ref.accessor(
        g, source.parent / "avatar.glb", g.meshes[0].primitives[0].attributes.POSITION
    )
    uv = ref.accessor(
        g, source.parent / "avatar.glb", g.meshes[0].primitives[0].attributes.TEXCOORD_0
    )
    masks = inp.asset.masks
    h, w = masks.shape[1:]
    px = np.clip((uv * [w, h]).astype(int), 0, [w - 1, h - 1])
    for r, region in enumerate(inp.asset.regions):
        weight = masks[r][px[:, 1], px[:, 0]]
        assert weight.sum() > 0
        x = float((weight * pos[:, 0]).sum() / weight.sum())
        assert {"left": x > 0.01, "right": x < -0.01, "center": abs(x) < 0.01}[region.side]
    assert report["validation"]["counts"]["error"] == 0
    assert not [i for i in report["validation"]["issues"] if "side" in i["message"].lower()]


def test_avatar_base_is_the_materials_own_normal_texture(converted):
    out, _ = converted
    inp = load_input(out)  # read back from the output: the base texture is Skin's normalTexture
    truth = avatar.skin_normals()
    got = inp.asset.base
    err = np.degrees(np.arccos(np.clip((got * truth).sum(-1), -1, 1)))
    assert got.shape == truth.shape and float(err.max()) < 0.5  # 8-bit quantisation


def test_texture_transform_on_the_base_is_refused(tmp_path, capsys):
    def change(doc, data, folder):
        doc["materials"][0]["normalTexture"]["extensions"] = {
            "KHR_texture_transform": {"scale": [2, 2]}
        }
        doc["extensionsUsed"].append("KHR_texture_transform")

    manifest = avatar_variant(tmp_path, change)
    out = tmp_path / "out"
    assert main(["convert", str(manifest), "-o", str(out)]) == 2 and not out.exists()
    err = " ".join(capsys.readouterr().err.split())
    assert "/materials/0/normalTexture (the base) has KHR_texture_transform" in err


@pytest.mark.skipif(shutil.which("node") is None, reason="needs the shared toolchain")
def test_basisu_base_is_decoded_with_alktx2_and_passed_through(tmp_path):
    alktx2 = pytest.importorskip("alktx2")

    def change(doc, data, folder):
        # the Skin normal map as a UASTC KTX2 image behind KHR_texture_basisu
        png = folder / "skin_normal.png"
        img = doc["images"][1]
        view = doc["bufferViews"][img["bufferView"]]
        start = view.get("byteOffset", 0)
        png.write_bytes(data[start : start + view["byteLength"]])
        alktx2.encode_image_to_ktx2(
            str(png),
            str(folder / "skin_normal.ktx2"),
            codec="uastc",
            srgb=False,
            linear=True,
            quality=255,
            effort=5,
        )
        ktx = (folder / "skin_normal.ktx2").read_bytes()
        png.unlink()
        (folder / "skin_normal.ktx2").unlink()
        pad = b"\0" * ((-len(data)) % 4)
        doc["bufferViews"].append(
            {"buffer": 0, "byteOffset": len(data) + len(pad), "byteLength": len(ktx)}
        )
        doc["images"].append(
            {
                "name": "skin_normal_ktx2",
                "mimeType": "image/ktx2",
                "bufferView": len(doc["bufferViews"]) - 1,
            }
        )
        doc["textures"][1]["extensions"] = {
            "KHR_texture_basisu": {"source": len(doc["images"]) - 1}
        }
        doc["extensionsUsed"].append("KHR_texture_basisu")
        new = data + pad + ktx
        new += b"\0" * ((-len(new)) % 4)
        doc["buffers"][0]["byteLength"] = len(new)
        return new

    manifest = avatar_variant(tmp_path, change)
    # the KTX2 is held to the reader's pixel cap by its header, before alktx2 transcodes it
    capped = read_document(manifest.parent / "avatar.glb", GltfReadOptions(max_pixels=1))
    with pytest.raises(InputError, match=r"/images/\d+.*over the cap of 1 pixels"):
        image_pixels(capped, len(capped.array("images")) - 1)
    res = convert(manifest, tmp_path / "out", ConvertOptions(validate=False, compressed=False))
    assert res.exit_code == 0
    assert any("base normal map" in n and "png" in n for n in res.report["notes"])
    added = compare(manifest.parent / "avatar.glb", tmp_path / "out" / "avatar.gltf", False)
    assert added.materials == [0]  # the KTX2 image went through byte for byte (compare)
    inp = load_input(tmp_path / "out")
    err = np.degrees(np.arccos(np.clip((inp.asset.base * avatar.skin_normals()).sum(-1), -1, 1)))
    assert float(np.percentile(err, 99)) < 3.0  # UASTC is lossy, close to the source


@pytest.mark.gpu
def test_blendshapes_driver_renders_its_wrinkled_poses_and_frames_the_face(converted):
    from wrinklepipe.validate import ValidateOptions, validate
    from wrinklepipe.validate import gl as glw

    try:
        glw.create_context().release()
    except glw.GLUnavailable as exc:
        pytest.skip(f"no OpenGL: {exc}")
    out, _ = converted
    rep = validate(load_input(out), ValidateOptions(render=True))
    poses = rep.render["poses"]
    # the driver's keys: browInnerUp peaks at 1 s (both brows), jawOpen at 3 s (the mouth)
    assert list(poses) == ["neutral", "browInnerUp @ 1.0 s", "jawOpen @ 3.0 s"]
    src = rep.render["pose_sources"]
    assert src["browInnerUp @ 1.0 s"]["regions"] == ["brow_L", "brow_R"]
    assert src["jawOpen @ 3.0 s"] == {
        "curve": "blendshapes",
        "time": 3.0,
        "regions": ["mouth"],
        "morphs": {"jawOpen": 1.0},
    }
    covered = rep.render["covered_pixels"]
    for name in ("browInnerUp @ 1.0 s", "jawOpen @ 3.0 s"):
        # 8-12 % of the head changes (the render's size follows the 64^2 maps: 160^2)
        assert poses[name]["changed_pixels"] > 0.05 * covered and poses[name]["leak_pixels"] == 0
        assert poses[name]["gpu_vs_reference_deg"]["p99"] < 1.0
    # the view is the wrinkled head alone: it fills half the square frame (the ellipsoid's
    # area over its bounding square is pi / 4, less the framing margin)
    assert rep.render["covered_pixels"] / rep.render["size"] ** 2 > 0.5
    assert rep.counts.get("error", 0) == 0


@pytest.fixture(scope="module")
def exported(converted, tmp_path_factory):
    """The converted avatar exported for Godot (base kept in the glTF) and Unreal (base dropped:
    it ships as a DirectX DDS of its own)."""
    out, _ = converted
    root = tmp_path_factory.mktemp("avatar-export")
    for engine in ("godot", "unreal"):
        assert main(["export", str(out), "--engine", engine, "-o", str(root / engine)]) == 0
    return root


def test_engine_export_is_the_whole_avatar_less_the_extension(source, exported):
    src = source.parent / "avatar.glb"
    gltf = exported / "godot" / "avatar.gltf"
    added = compare(src, gltf, base_replaced=False)  # every source element, equal data
    assert added.attributes == {(0, 0): WRINKLE_ATTRIBUTES}
    assert added.materials == [] and (added.textures, added.images) == (0, 0)
    assert added.animations == ["blendshapes"]  # the morph weights stay; the pointer went
    doc = json.loads(gltf.read_text())
    assert EXTENSION not in json.dumps(doc)
    assert doc["extensionsUsed"] == (ref.load(src).extensionsUsed or [])  # no pointer left
    assert [c["target"]["path"] for c in doc["animations"][1]["channels"]] == ["weights"]
    setup = json.loads((exported / "godot" / "wrinkle_setup.json").read_text())
    # Skin's normal map is embedded in the buffer: the shader's base is it, as a PNG beside
    assert setup["base"]["file"] == "textures/base_normal.png"
    g = ref.load(src)
    skin_normal = ref.image_bytes(g, src, g.textures[g.materials[0].normalTexture.index].source)
    with (
        Image.open(io.BytesIO(skin_normal)) as a,
        Image.open(exported / "godot" / setup["base"]["file"]) as b,
    ):
        np.testing.assert_array_equal(np.asarray(a.convert("RGB")), np.asarray(b.convert("RGB")))
    # Unreal: the same character without Skin's normalTexture (its base is the DirectX DDS)
    g0 = ref.load(src)
    g1 = ref.load(exported / "unreal" / "avatar.gltf")
    assert [m.name for m in g1.meshes] == [m.name for m in g0.meshes]
    assert g1.materials[0].normalTexture is None and len(g1.images) == len(g0.images) - 1
    for m0, m1 in zip(g0.materials[1:], g1.materials[1:]):
        assert m1.name == m0.name and m1.doubleSided == m0.doubleSided
        i0, i1 = m0.pbrMetallicRoughness.baseColorTexture, m1.pbrMetallicRoughness.baseColorTexture
        b0 = ref.image_bytes(g0, src, g0.textures[i0.index].source)
        assert (
            ref.image_bytes(g1, exported / "unreal" / "avatar.gltf", g1.textures[i1.index].source)
            == b0
        )


@pytest.mark.skipif(not khronos.available(), reason="Khronos validator not installed")
@pytest.mark.parametrize("engine", ["godot", "unreal"])
def test_engine_export_of_the_avatar_passes_the_khronos_validator(exported, engine):
    report = khronos.validate_gltf(exported / engine / "avatar.gltf")
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]


def _usd_errors(stage) -> list[str]:

    return [e.GetMessage() for e in usd_checks.validation_errors(stage)]


def test_usd_output_carries_the_whole_avatar(source, converted):
    from pxr import Usd, UsdGeom, UsdShade, UsdSkel

    out, report = converted
    src = source.parent / "avatar.glb"
    g = ref.load(src)
    stage = Usd.Stage.Open(str(out / "avatar.usda"))
    assert _usd_errors(stage) == []
    meshes = {p.GetName(): p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)}
    assert sorted(meshes) == sorted(m.name for m in g.meshes)  # Head too, in the scene
    # every part: its points, triangles, UVs (v flipped), material (double-sided flag kept)
    for m in g.meshes[1:]:
        prim = meshes[m.name]
        gm = UsdGeom.Mesh(prim)
        p = m.primitives[0]
        np.testing.assert_array_equal(
            np.asarray(gm.GetPointsAttr().Get()), ref.accessor(g, src, p.attributes.POSITION)
        )
        idx = ref.accessor(g, src, p.indices).reshape(-1)
        np.testing.assert_array_equal(np.asarray(gm.GetFaceVertexIndicesAttr().Get()), idx)
        uv = ref.accessor(g, src, p.attributes.TEXCOORD_0)
        st = np.asarray(UsdGeom.PrimvarsAPI(gm).GetPrimvar("st").Get())
        np.testing.assert_allclose(st, np.stack([uv[:, 0], 1 - uv[:, 1]], -1), atol=1e-7)
        mat = g.materials[p.material]
        bound, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        assert bound.GetPrim().GetName() == mat.name
        assert gm.GetDoubleSidedAttr().Get() == bool(mat.doubleSided)
        # the base colour texture: the source image, byte for byte
        tex = UsdShade.Shader(bound.GetPrim().GetChild("baseColorTexture"))
        file = tex.GetInput("file").Get().path
        image = g.textures[mat.pbrMetallicRoughness.baseColorTexture.index].source
        assert (out / file).read_bytes() == ref.image_bytes(g, src, image)
    # the skeleton: the 20 joints, their hierarchy, rest pose (node TRS) and bind pose (IBM)
    skel = UsdSkel.Skeleton(next(p for p in stage.Traverse() if p.GetName() == "AvatarSkin"))
    topo = UsdSkel.Topology(skel.GetJointsAttr().Get())
    joints = list(g.skins[0].joints)
    parents = {c: i for i, n in enumerate(g.nodes) for c in n.children or []}
    assert [joints[k] if k >= 0 else None for k in topo.GetParentIndices()] == [
        parents.get(j) if parents.get(j) in joints else None for j in joints
    ]
    rest = np.asarray(skel.GetRestTransformsAttr().Get()).transpose(0, 2, 1)
    world_parents = {i: parents.get(i) for i in range(len(g.nodes))}
    for k, j in enumerate(joints):
        local = _world(g.nodes, j, {**world_parents, j: None})
        want = local if parents.get(j) in joints else _world(g.nodes, j, world_parents)
        np.testing.assert_allclose(rest[k], want, atol=1e-6)
    ibm = ref.accessor(g, src, g.skins[0].inverseBindMatrices).reshape(-1, 4, 4)
    bind = np.asarray(skel.GetBindTransformsAttr().Get())
    np.testing.assert_allclose(bind, np.linalg.inv(ibm), atol=1e-5)  # both row-major here
    # Teeth's morph target: its name and deltas
    teeth = UsdSkel.BindingAPI(meshes["Teeth"])
    assert list(teeth.GetBlendShapesAttr().Get()) == ["jawOpen"]
    shape = UsdSkel.BlendShape(stage.GetPrimAtPath(teeth.GetBlendShapeTargetsRel().GetTargets()[0]))
    delta = ref.accessor(g, src, g.meshes[2].primitives[0].targets[0]["POSITION"])
    np.testing.assert_array_equal(np.asarray(shape.GetOffsetsAttr().Get()), delta)
    # the source's animation: a SkelAnimation variant (tests/test_usd_scene_skin.py plays them)
    assert any("the 1 glTF animation is a SkelAnimation" in n for n in report["notes"])


def test_states_with_the_base_detail_everywhere_are_of_one_face(converted, capsys):
    """The avatar's states are its skin's normal map plus ridges over the whole face (PD
    addition, ``avatar._ridged``): they differ from the base everywhere and keep all of its
    detail (the ridges, 4 and 8 cycles along v, are orthogonal to the skin's 11 x 7 bumps: the
    regression slope of the states' slopes on the base's is 1). WP-FID-006/007 stay silent."""
    out, report = converted
    codes = [i["code"] for i in report["validation"]["issues"]]
    assert "WP-FID-006" not in codes and "WP-FID-007" not in codes
    capsys.readouterr()
    assert main(["validate-asset", str(out), "--json", "--no-render"]) == 0
    metrics = json.loads(capsys.readouterr().out)["metrics"]
    assert metrics["base_state_spread"] > 0.9
    assert metrics["base_detail_kept"] == pytest.approx([1.0, 1.0], abs=0.02)
