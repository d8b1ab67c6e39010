"""convert writes into the source document: RobotExpressive (14 meshes, 3 materials, 2 skins,
14 animations, CC0) with a wrinkle setup on its head (``material = "Main"`` restricted to
``meshes = ["Head"]``: Main is shared with the body, so it is cloned for the head).

Checked by independent readers: pygltflib + struct (every source element present with equal
data, only the additions differ), the Khronos validator (0 errors), glTF-Transform's inspect
(same meshes, materials, animations plus the additions) and ``inspect --diff``."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import gltf_reference as ref
import numpy as np
import pytest
import usd_checks
from output_hashes import assert_unchanged
from passthrough import EXTENSION, WRINKLE_ATTRIBUTES, compare
from test_document_inspect import GLTF_TRANSFORM, gltf_transform_inspect
from test_document_read import GLTFPACK
from wrinkle_setups import ROBOT, ROBOT_DRIVERS, write_setup

from wrinklepipe.cli import main
from wrinklepipe.io import khronos
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.sources.validation import load_input

needs_robot = pytest.mark.skipif(not ROBOT.is_file(), reason="../shared/data is absent")
HEAD_MAIN = (2, 1)  # meshes[2] "Head", primitive 1 (material Main): the wrinkled primitive


@pytest.fixture(scope="session")
def robot(robot_converted):
    """RobotExpressive converted once (.gltf + .glb; validation without the render pass): the
    shared conftest fixture."""
    return robot_converted


@needs_robot
def test_robot_outputs_are_the_recorded_bytes(robot):
    """Every file of the conversion as recorded on main (``tests/output_hashes.py``)."""
    assert_unchanged("robot", robot[0])


@needs_robot
@pytest.mark.parametrize("name", ["robot.gltf", "robot.glb"])
def test_robot_loses_nothing(robot, name):
    out, _ = robot
    added = compare(ROBOT, out / name)
    # only the head's Main primitive gained attributes: tangents, vertex IDs and (RobotExpressive
    # has no UVs) the front-projection TEXCOORD_0 the masks are laid out on
    assert added.attributes == {HEAD_MAIN: WRINKLE_ATTRIBUTES | {"TEXCOORD_0"}}
    assert added.clones == {3: 1}  # "Main (wrinkled)" appended, the body keeps "Main"
    assert added.materials == [3]
    assert (added.textures, added.images) == (4, 4)  # base, 2 states, 1 RGBA mask texture
    assert added.animations == ["blendshapes"]
    # the source's hands had skin weights summing to up to 1.755: renormalised (4 accessors)
    assert len(added.repaired) == 4
    g = ref.load(out / name)
    assert g.meshes[2].primitives[1].material == 3
    assert [p.material for p in g.meshes[1].primitives] == [0, 1]  # Torso keeps Grey, Main


@needs_robot
def test_robot_extension_and_animation_point_at_the_clone(robot):
    out, _ = robot
    doc = json.loads((out / "robot.gltf").read_text())
    mat = doc["materials"][3]
    ext = mat["extensions"][EXTENSION]
    assert [r["name"] for r in ext["regions"]] == ["brow_L", "brow_R", "mouth"]
    assert doc["textures"][mat["normalTexture"]["index"]]["name"] == "base_normal"
    anim = doc["animations"][ext["weightCurves"][0]["animation"]]
    pointers = [
        c["target"]["extensions"]["KHR_animation_pointer"]["pointer"]
        for c in anim["channels"]
        if c["target"]["path"] == "pointer"
    ]
    assert pointers == [f"/materials/3/extensions/{EXTENSION}/weights"]
    # the blendshapes driver's inputs play on the Head node (13), in its target order
    morph = [c for c in anim["channels"] if c["target"]["path"] == "weights"]
    assert [c["target"]["node"] for c in morph] == [13]
    g = ref.load(out / "robot.gltf")
    sampler = anim["samplers"][morph[0]["sampler"]]
    t = ref.accessor(g, out / "robot.gltf", sampler["input"])[:, 0]
    w = ref.accessor(g, out / "robot.gltf", sampler["output"]).reshape(len(t), 3)
    angry = np.interp(t, [0, 1, 2, 3], [0, 1, 0, 0])  # keys of the manifest
    np.testing.assert_allclose(w[:, 0], angry, atol=1e-6)
    np.testing.assert_allclose(w[:, 2], 0, atol=0)  # Sad is not driven


@needs_robot
@pytest.mark.skipif(not khronos.available(), reason="Khronos validator not installed")
@pytest.mark.parametrize("name", ["robot.gltf", "robot.glb"])
def test_robot_output_passes_the_khronos_validator(robot, name):
    out, _ = robot
    report = khronos.validate_gltf(out / name)
    assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]


@needs_robot
@pytest.mark.skipif(not GLTF_TRANSFORM.exists(), reason="npm @gltf-transform/cli absent")
def test_robot_gltf_transform_sees_the_same_character_plus_the_additions(robot):
    out, _ = robot
    before = gltf_transform_inspect(ROBOT)
    after = gltf_transform_inspect(out / "robot.glb")
    assert [(r["name"], r["vertices"]) for r in after["MESHES"]] == [
        (r["name"], r["vertices"]) for r in before["MESHES"]
    ]
    mats0 = [(r["name"], r["instances"]) for r in before["MATERIALS"]]
    mats1 = [(r["name"], r["instances"]) for r in after["MATERIALS"]]
    assert mats0 == [("Grey", "6"), ("Main", "12"), ("Black", "1")]
    assert mats1 == [("Grey", "6"), ("Main", "11"), ("Black", "1"), ("Main (wrinkled)", "1")]
    keys = ("name", "channels", "duration", "keyframes")
    anims0 = [tuple(r[k] for k in keys) for r in before["ANIMATIONS"]]
    anims1 = [tuple(r[k] for k in keys) for r in after["ANIMATIONS"]]
    assert anims1[:14] == anims0 and len(anims1) == 15 and anims1[14][0] == "blendshapes"
    assert "TEXTURES" not in before
    assert sorted(r["name"] for r in after["TEXTURES"]) == [
        "base_normal",
        "mask_0",
        "wrinkle_compress",
        "wrinkle_stretch",
    ]


@needs_robot
def test_robot_inspect_diff_lists_only_the_additions(robot, capsys):
    out, _ = robot
    assert main(["inspect", "--diff", str(ROBOT), str(out / "robot.glb")]) == 1
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines == [
        "+ animations[14]: 'blendshapes'",
        "~ extensionsUsed: [] -> ['KHR_animation_pointer', 'WRINKLEPIPE_wrinkle_maps']",
        "~ materials[1].instances: 12 -> 11",
        "+ materials[3]: 'Main (wrinkled)'",
        "+ meshes[2].primitives[1].attributes.TANGENT: 'VEC4:f32'",
        "+ meshes[2].primitives[1].attributes.TEXCOORD_0: 'VEC2:f32'",
        "+ meshes[2].primitives[1].attributes._WRINKLE_VERTEX_ID: 'SCALAR:f32'",
        "~ meshes[2].primitives[1].material: 'Main' -> 'Main (wrinkled)'",
        "+ textures[0]: 'base_normal'",
        "+ textures[1]: 'wrinkle_stretch'",
        "+ textures[2]: 'wrinkle_compress'",
        "+ textures[3]: 'mask_0'",
    ]


@needs_robot
def test_robot_masks_touch_only_the_wrinkled_primitive_and_sides_hold(robot):
    out, report = robot
    # the validator works on the wrinkled primitive alone: Head/1's 876 vertices of 7214
    inp = load_input(out)
    mesh = inp.asset.mesh
    assert mesh.vertex_count == 876 and [p.pointer for p in mesh.parts] == [
        "/meshes/2/primitives/1"
    ]
    g = ref.load(ROBOT)
    head = ref.accessor(g, ROBOT, g.meshes[2].primitives[1].attributes.POSITION)
    assert mesh.vertex_count == len(head)
    # no side-rule problem (the masks' weight falls on their side of the head), no error
    assert report["validation"]["counts"]["error"] == 0
    assert not [i for i in report["validation"]["issues"] if "side" in i["message"].lower()]


def _convert_cli(tmp_path, manifest) -> tuple[int, Path]:
    out = tmp_path / "out"
    code = main(["convert", str(manifest), "-o", str(out), "--allow-root", str(ROBOT.parent)])
    return code, out


@needs_robot
@pytest.mark.parametrize(
    "material, meshes, message",
    [
        ("Skin", None, "no material 'Skin' in RobotExpressive.glb (materials: 'Grey' ("),
        (None, None, "RobotExpressive.glb has 3 materials; name the wrinkled one with"),
        ("Main", ["Hat"], "no mesh or node 'Hat' in RobotExpressive.glb has a primitive using"),
    ],
)
def test_robot_bad_selection_one_message_exit_2_nothing_written(
    tmp_path, capsys, material, meshes, message
):
    manifest = write_setup(tmp_path / "src", ROBOT, "robot", material, meshes)
    code, out = _convert_cli(tmp_path, manifest)
    err = capsys.readouterr().err
    assert code == 2 and not out.exists()
    assert message in " ".join(err.split())


@needs_robot
def test_robot_masks_on_no_wrinkled_primitive_are_refused(tmp_path, capsys):
    # a mask painted outside the head's UV layout (the corner the front projection leaves empty)
    regions = {
        "brow_L": ((0.55, 0.05, 0.95, 0.45), "left"),
        "ghost": ((0.0, 0.0, 0.05, 0.05), "center"),
    }
    manifest = write_setup(tmp_path / "src", ROBOT, "robot", "Main", ["Head"], regions=regions)
    code, out = _convert_cli(tmp_path, manifest)
    err = " ".join(capsys.readouterr().err.split())
    assert code == 2 and not out.exists()
    assert "the mask of region 'ghost' falls on no wrinkled primitive" in err and "Head/1" in err


@needs_robot
def test_robot_unused_and_ambiguous_materials_are_refused(tmp_path, capsys):
    # a copy of the robot with an unused material and two materials named alike
    g = ref.load(ROBOT)
    doc = json.loads(g.to_json())
    doc["materials"].append({"name": "Unused"})
    doc["materials"].append({"name": "Black"})
    src = tmp_path / "src"
    src.mkdir()
    g2 = ref.load(ROBOT)
    g2.materials = type(g2).from_dict(doc).materials
    g2.save(str(src / "robot2.glb"))
    for material, message in (
        ("Unused", "material 'Unused' is used by no primitive of robot2.glb"),
        ("Black", "material name 'Black' is ambiguous in robot2.glb: materials 2, 4 share it"),
    ):
        manifest = write_setup(src, src / "robot2.glb", "robot", material)
        code, out = _convert_cli(tmp_path, manifest)
        err = " ".join(capsys.readouterr().err.split())
        assert code == 2 and not out.exists(), err
        assert message in err


@needs_robot
def test_robot_engine_export_keeps_every_part(robot, tmp_path):
    out, _ = robot
    assert main(["export", str(out), "--engine", "unreal", "-o", str(tmp_path / "ue")]) == 0
    gltf = tmp_path / "ue" / "robot.gltf"
    added = compare(ROBOT, gltf)  # every source element with equal data (pygltflib + struct)
    assert added.attributes == {HEAD_MAIN: WRINKLE_ATTRIBUTES | {"TEXCOORD_0"}}
    assert added.clones == {3: 1} and added.materials == []  # the clone, without the extension
    assert (added.textures, added.images) == (0, 0)  # Unreal's base ships as a DirectX DDS
    assert added.animations == ["blendshapes"]  # the Head's morph weights, no pointer channel
    g = ref.load(gltf)
    assert (len(g.meshes), len(g.materials), len(g.skins), len(g.animations)) == (14, 4, 2, 15)
    assert not (g.extensionsUsed or []) and g.materials[3].normalTexture is None
    if khronos.available():
        report = khronos.validate_gltf(gltf)
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]


def _gltf_worlds(g) -> dict[int, np.ndarray]:
    """Node world matrices from pygltflib's TRS / matrix (column vectors)."""
    parents = {c: i for i, n in enumerate(g.nodes) for c in n.children or []}

    def local(n) -> np.ndarray:
        if n.matrix is not None:
            return np.asarray(n.matrix, np.float64).reshape(4, 4).T
        x, y, z, w = n.rotation or [0, 0, 0, 1]
        r = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        m = np.eye(4)
        m[:3, :3] = r * np.asarray(n.scale or [1, 1, 1])
        m[:3, 3] = n.translation or [0, 0, 0]
        return m

    def world(i: int) -> np.ndarray:
        return local(g.nodes[i]) if i not in parents else world(parents[i]) @ local(g.nodes[i])

    return {i: world(i) for i in range(len(g.nodes))}


@needs_robot
def test_robot_usd_carries_every_part_at_its_place(robot):
    from pxr import Usd, UsdGeom, UsdSkel

    out, _ = robot
    g = ref.load(ROBOT)
    stage = Usd.Stage.Open(str(out / "robot.usda"))
    errors = [e.GetMessage() for e in usd_checks.validation_errors(stage)]
    assert errors == []
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    instanced = sum(len(g.meshes[n.mesh].primitives) for n in g.nodes if n.mesh is not None)
    assert len(meshes) == instanced  # every primitive below Scene, the wrinkled head too
    # rigid parts sit where the glTF puts them at rest: USD's composed transform of the points
    # equals pygltflib's node world matrix applied to the accessor (struct) positions
    worlds = _gltf_worlds(g)
    cache = UsdGeom.XformCache()
    checked = 0
    for i, n in enumerate(g.nodes):
        if n.mesh is None or n.skin is not None:
            continue
        for k, p in enumerate(g.meshes[n.mesh].primitives):
            if (n.mesh, k) == HEAD_MAIN:
                continue
            name = g.meshes[n.mesh].name + (f"_{k}" if len(g.meshes[n.mesh].primitives) > 1 else "")
            prim = next(
                m
                for m in meshes
                if (m.GetDisplayName() or m.GetName()) == name
                and (m.GetParent().GetDisplayName() or m.GetParent().GetName()) == n.name
            )
            m = np.asarray(cache.GetLocalToWorldTransform(prim)).T
            pts = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(), np.float64)
            src = ref.accessor(g, ROBOT, p.attributes.POSITION).astype(np.float64)
            want = src @ worlds[i][:3, :3].T + worlds[i][:3, 3]
            np.testing.assert_allclose(pts @ m[:3, :3].T + m[:3, 3], want, atol=1e-4)
            checked += 1
    assert checked == 14  # the parts parented to bones; the hands are skinned
    skels = [UsdSkel.Skeleton(p) for p in stage.Traverse() if p.IsA(UsdSkel.Skeleton)]
    scene = [s for s in skels if "/Scene/" in str(s.GetPath())]
    assert [len(s.GetJointsAttr().Get()) for s in scene] == [len(s.joints) for s in g.skins]
    head = next(m for m in meshes if m.GetName() == "Head_0")
    assert list(UsdSkel.BindingAPI(head).GetBlendShapesAttr().Get()) == [
        "Angry",
        "Surprised",
        "Sad",
    ]


@needs_robot
@pytest.mark.skipif(not GLTFPACK.exists(), reason="npm gltfpack absent")
def test_gltfpack_compressed_robot_converts_whole(tmp_path, capsys):
    """RobotExpressive through the real encoder (meshopt + quantization) converts, its face
    plate ("Black") wrinkled: decoded, written uncompressed (the report says so), the
    quantized accessors kept, every part there; inspect --diff lists only the additions."""
    packed = tmp_path / "src" / "packed.glb"
    packed.parent.mkdir()
    cmd = [str(GLTFPACK), "-i", str(ROBOT), "-o", str(packed), "-kn", "-km", "-cc", "-ke"]
    subprocess.run(cmd, check=True, capture_output=True, timeout=120)
    manifest = write_setup(tmp_path / "src", packed, "robot", "Black", drivers=ROBOT_DRIVERS)
    res = convert(manifest, tmp_path / "out", ConvertOptions(render=False))
    assert res.exit_code == 0 and res.report["validation"]["counts"]["error"] == 0
    assert "EXT_meshopt_compression: decoded; written uncompressed" in res.report["notes"]
    out = tmp_path / "out" / "robot.gltf"
    g = ref.load(out)
    assert g.extensionsRequired == ["KHR_mesh_quantization"]  # quantized accessors kept
    assert (len(g.meshes), len(g.skins), len(g.animations)) == (14, 2, 15)
    if khronos.available():
        report = khronos.validate_gltf(out)
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]
    assert main(["inspect", "--diff", str(packed), str(out), "--json"]) == 1
    lines = json.loads(capsys.readouterr().out)["differences"]
    changed = [ln for ln in lines if not ln.startswith("+ textures[")]
    assert [ln for ln in changed if "WRINKLEPIPE_wrinkle_maps." not in ln] == [
        "+ animations[14]: 'blendshapes'",
        "~ decoded: ['EXT_meshopt_compression'] -> []",
        "~ extensionsUsed: ['KHR_mesh_quantization'] -> ['KHR_animation_pointer', "
        "'KHR_mesh_quantization', 'WRINKLEPIPE_wrinkle_maps']",
        "~ materials[2].extensions: [] -> ['WRINKLEPIPE_wrinkle_maps']",
        "+ materials[2].textures.normalTexture: 0",
        "+ meshes[2].primitives[2].attributes.TANGENT: 'VEC4:f32'",
        "+ meshes[2].primitives[2].attributes.TEXCOORD_0: 'VEC2:f32'",
        "+ meshes[2].primitives[2].attributes._WRINKLE_VERTEX_ID: 'SCALAR:f32'",
    ]
