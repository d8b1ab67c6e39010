"""convert over a USD source writes a layer over it: the source file is untouched (hash), the
composed stage has every source prim with equal values (read independently through pxr) plus
the wrinkle data, UsdValidation finds no error the source does not have, and the flattened usdz
holds it all.

Sources: a generated avatar (a skinned quad-grid head whose UV layout has a mirrored island, so
its tangents differ per corner on the seam; a skinned body sharing the head's material; a rigid
eye under a rotated Xform; a textured material; a 3-joint skeleton with an animation), and from
``../shared/data`` Khronos' RiggedFigure (UsdSkel, 19 joints, no UVs) and CesiumMan (UsdSkel,
textured) as Apple's Reality Converter wrote them."""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import usd_checks
from hypothesis import given, settings
from hypothesis import strategies as hs
from wrinkle_setups import write_setup

from wrinklepipe.cli import main
from wrinklepipe.io.confine import allowed_roots
from wrinklepipe.io.images import write_image
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.usd.layer import topology_values
from wrinklepipe.usd.meshes import read_usd_meshes
from wrinklepipe.usd.package_read import read_usd

pxr = pytest.importorskip("pxr")
from pxr import Sdf, Usd, UsdGeom, UsdShade, UsdSkel  # noqa: E402

USDZ = Path(__file__).resolve().parents[2] / "shared" / "data" / "usd" / "usd-wg" / "test_assets"
RIGGED = USDZ / "USDZ" / "RiggedFigure" / "RiggedFigure.usdz"
CESIUM = USDZ / "USDZ" / "CesiumMan" / "CesiumMan.usdz"
IDENTITY = "( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 0, 1) )"
TILT = "(0.9238795, 0.3826834, 0, 0)"  # 45 degrees about X
CENTRE = {  # real characters: regions in the middle of their layout (sides are not judged)
    "brow": ((0.2, 0.2, 0.8, 0.5), "center"),
    "mouth": ((0.2, 0.5, 0.8, 0.8), "center"),
}


def _grid() -> tuple[str, np.ndarray]:
    """A 3 x 3 quad head in the XY plane facing +Z; columns 0-1 map u = 0.6 x, column 2 is a
    mirrored island u = 1 - 0.6 (x - 2/3) (x, y in [0, 1]): the corners on x = 2/3 have two UVs
    and, since u runs the other way there, the opposite tangent."""
    xs = np.linspace(0, 1, 4)
    pts = np.array([(x, 1.3 + 0.6 * y, 0.1) for y in xs for x in xs])
    faces, st = [], []
    for r in range(3):
        for c in range(3):
            quad = [r * 4 + c, r * 4 + c + 1, (r + 1) * 4 + c + 1, (r + 1) * 4 + c]
            faces += quad
            for q in quad:
                x, y = xs[q % 4], xs[q // 4]
                st.append((0.6 * x if c < 2 else 1 - 0.6 * (x - 2 / 3), y))
    fmt = ", ".join
    text = (
        f"point3f[] points = [{fmt(f'({a:g}, {b:g}, {z:g})' for a, b, z in pts)}]\n"
        f"int[] faceVertexCounts = [{fmt(['4'] * 9)}]\n"
        f"int[] faceVertexIndices = [{fmt(map(str, faces))}]\n"
        f"texCoord2f[] primvars:st = [{fmt(f'({u:g}, {v:g})' for u, v in st)}] "
        '(interpolation = "faceVarying")\n'
        f'normal3f[] normals = [{fmt(["(0, 0, 1)"] * 16)}] (interpolation = "vertex")\n'
    )
    return text, np.array(st)


def _quad(z: float, y0: float, uv: str = "st") -> str:
    return (
        f"point3f[] points = [(0, {y0}, {z}), (1, {y0}, {z}), (1, {y0 + 1}, {z}), "
        f"(0, {y0 + 1}, {z})]\n"
        "int[] faceVertexCounts = [4]\nint[] faceVertexIndices = [0, 1, 2, 3]\n"
        f"texCoord2f[] primvars:{uv} = [(0, 0), (1, 0), (1, 1), (0, 1)] "
        '(interpolation = "vertex")\n'
        f"normal3f[] normals = [{', '.join(['(0, 0, 1)'] * 4)}] "
        '(interpolation = "vertex")\n'
    )


def _material(name: str, texture: bool) -> str:
    p = f"/Avatar/Looks/{name}"
    tex = (
        f"""
            color3f inputs:diffuseColor.connect = <{p}/Albedo.outputs:rgb>"""
        if texture
        else ""
    )
    shaders = (
        f"""
        def Shader "Albedo" {{
            uniform token info:id = "UsdUVTexture"
            asset inputs:file = @textures/skin.png@
            float2 inputs:st.connect = <{p}/St.outputs:result>
            float3 outputs:rgb
        }}
        def Shader "St" {{
            uniform token info:id = "UsdPrimvarReader_float2"
            string inputs:varname = "st"
            float2 outputs:result
        }}"""
        if texture
        else ""
    )
    return f"""
    def Material "{name}" {{
        token outputs:surface.connect = <{p}/Surface.outputs:surface>
        def Shader "Surface" {{
            uniform token info:id = "UsdPreviewSurface"{tex}
            float inputs:roughness = 0.6
            token outputs:surface
        }}{shaders}
    }}"""


def _skinned(name: str, geometry: str, joint: int, n: int, material: str) -> str:
    return f"""
    def Mesh "{name}" (prepend apiSchemas = ["SkelBindingAPI", "MaterialBindingAPI"]) {{
        {geometry}
        uniform token subdivisionScheme = "none"
        int[] primvars:skel:jointIndices = [{", ".join([str(joint)] * n)}] (
            interpolation = "vertex"
            elementSize = 1
        )
        float[] primvars:skel:jointWeights = [{", ".join(["1"] * n)}] (
            interpolation = "vertex"
            elementSize = 1
        )
        matrix4d primvars:skel:geomBindTransform = {IDENTITY}
        rel skel:skeleton = </Avatar/Skel>
        rel material:binding = </Avatar/Looks/{material}>
    }}"""


def write_avatar(folder: Path) -> Path:
    """The generated avatar (see the module doc) as ``avatar.usda`` + ``textures/skin.png``."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "textures").mkdir(exist_ok=True)
    albedo = np.zeros((4, 4, 3))
    albedo[..., 0] = np.linspace(0, 1, 4)
    write_image(folder / "textures" / "skin.png", albedo, 8)
    head, _ = _grid()
    ident = IDENTITY

    def up(y: float) -> str:
        return f"( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, {y}, 0, 1) )"

    text = f"""#usda 1.0
(
    defaultPrim = "Avatar"
    metersPerUnit = 1
    upAxis = "Y"
    startTimeCode = 0
    endTimeCode = 48
    timeCodesPerSecond = 24
)

def SkelRoot "Avatar" (kind = "component") {{
    def Skeleton "Skel" (prepend apiSchemas = ["SkelBindingAPI"]) {{
        uniform token[] joints = ["root", "root/neck", "root/neck/head"]
        uniform matrix4d[] bindTransforms = [{ident}, {up(1)}, {up(1.5)}]
        uniform matrix4d[] restTransforms = [{ident}, {up(1)}, {up(0.4)}]
        rel skel:animationSource = </Avatar/Skel/Anim>
        def SkelAnimation "Anim" {{
            uniform token[] joints = ["root/neck/head"]
            quatf[] rotations.timeSamples = {{0: [(1, 0, 0, 0)], 48: [{TILT}]}}
            half3[] scales = [(1, 1, 1)]
            float3[] translations = [(0, 0.5, 0)]
        }}
    }}{_skinned("Head", head, 2, 16, "Skin")}{_skinned("Body", _quad(0, -0.5), 0, 4, "Skin")}
    def Xform "EyeRig" {{
        double3 xformOp:translate = (0, 1.6, 0.2)
        float xformOp:rotateY = 90
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateY"]
        def Mesh "Eye" (prepend apiSchemas = ["MaterialBindingAPI"]) {{
            {_quad(0, 0, "UVMap")}
            uniform token subdivisionScheme = "none"
            rel material:binding = </Avatar/Looks/Eye>
        }}
    }}
    def Scope "Looks" {{{_material("Skin", True)}{_material("Eye", False)}
        def Material "Spare" {{
        }}
    }}
    def Scope "Props" {{
        def Material "Eye" {{
        }}
    }}
}}
"""
    path = folder / "avatar.usda"
    path.write_text(text, encoding="utf-8")
    return path


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _convert(root: Path, source: Path, name: str, **setup) -> tuple[Path, dict, str]:
    digest = _sha(source)
    manifest = write_setup(root / "src", source, name, **setup)
    with allowed_roots([source.parent]):
        res = convert(manifest, root / "out", ConvertOptions(render=False))
    assert _sha(source) == digest  # the source's bytes are untouched
    return root / "out", res.report, digest


@pytest.fixture(scope="module")
def avatar(tmp_path_factory):
    """The avatar's head wrinkled (material Skin, restricted to Head: Skin is cloned)."""
    root = tmp_path_factory.mktemp("usd_avatar")
    source = write_avatar(root / "assets")
    out, report, _ = _convert(root, source, "hero", material="Skin", meshes=["Head"])
    return source, out, report


def _errors(stage) -> list[str]:
    return sorted(e.GetMessage() for e in usd_checks.validation_errors(stage))


def _resolved(asset) -> str:
    """An asset path's resolved file, symbolic links followed (a package member kept)."""
    r = asset.resolvedPath
    inner = r[r.index("[") :] if r.endswith("]") else ""
    return os.path.realpath(r[: len(r) - len(inner)]) + inner


def _same(a, b) -> bool:
    if isinstance(a, Sdf.AssetPath):
        return a.path == b.path and _resolved(a) == _resolved(b)
    try:
        return bool(np.array_equal(np.asarray(a), np.asarray(b)))
    except (TypeError, ValueError):
        return a == b


def assert_composes_to_source(source: Path, layer: Path, changed_rels: set[str] = frozenset()):
    """Every prim of the source (an independent pxr read of the source file alone) is in the
    composed layer with its type and every attribute's value and time samples equal;
    relationships equal except ``changed_rels`` (``PATH.NAME``)."""
    src = Usd.Stage.Open(str(source))
    out = Usd.Stage.Open(str(layer))
    n = 0
    for p in src.Traverse():
        q = out.GetPrimAtPath(p.GetPath())
        assert q and q.GetTypeName() == p.GetTypeName(), p.GetPath()
        for a in p.GetAttributes():
            b = q.GetAttribute(a.GetName())
            assert b.GetTypeName() == a.GetTypeName(), a.GetPath()
            assert b.GetTimeSamples() == a.GetTimeSamples(), a.GetPath()
            for t in [Usd.TimeCode.Default(), *map(Usd.TimeCode, a.GetTimeSamples())]:
                assert _same(b.Get(t), a.Get(t)), (a.GetPath(), t)
            n += 1
        for r in p.GetRelationships():
            if str(r.GetPath()) not in changed_rels:
                assert q.GetRelationship(r.GetName()).GetTargets() == r.GetTargets(), r.GetPath()
    assert n > 0
    return src, out


def test_avatar_layer_sublayers_the_source_by_a_relative_path(avatar):
    source, out, _ = avatar
    layer = Sdf.Layer.FindOrOpen(str(out / "hero.usda"))
    assert list(layer.subLayerPaths) == [Path(os.path.relpath(source, out)).as_posix()]
    assert layer.defaultPrim == "Avatar" and layer.pseudoRoot.GetInfo("upAxis") == "Y"
    assert Path(layer.ComputeAbsolutePath(layer.subLayerPaths[0])) == source.resolve()


def test_avatar_composes_to_the_source_plus_the_wrinkle_data(avatar):
    source, out, _ = avatar
    src, stage = assert_composes_to_source(
        source, out / "hero.usda", {"/Avatar/Head.material:binding"}
    )
    # the additions: over the source's prims only wrinkle data; new prims only the clone's
    layer = stage.GetRootLayer()
    for spec_path in [
        p for p in _spec_paths(layer) if src.GetPrimAtPath(p) and layer.GetPrimAtPath(p)
    ]:
        spec = layer.GetPrimAtPath(spec_path)
        assert spec.specifier == Sdf.SpecifierOver, spec_path
    head = stage.GetPrimAtPath("/Avatar/Head")
    added = {p.name for p in layer.GetPrimAtPath("/Avatar/Head").properties}
    assert {"primvars:wrinkle:vertexId", "primvars:wrinkle:tangent", "material:binding"} <= added
    assert added <= {
        "primvars:wrinkle:vertexId",
        "primvars:wrinkle:tangent",
        "primvars:wrinkle:bias",
        "material:binding",
    }
    assert not layer.GetPrimAtPath("/Avatar/Body")  # not wrinkled: no opinion at all
    # the head is bound to the clone; the body keeps the source material, without wrinkles
    mat, _ = UsdShade.MaterialBindingAPI(head).ComputeBoundMaterial()
    assert str(mat.GetPath()) == "/Avatar/Looks/Skin_wrinkled"
    assert "WrinkleMapsAPI" in mat.GetPrim().GetMetadata("apiSchemas").ApplyOperations([])
    body, _ = UsdShade.MaterialBindingAPI(
        stage.GetPrimAtPath("/Avatar/Body")
    ).ComputeBoundMaterial()
    assert str(body.GetPath()) == "/Avatar/Looks/Skin"
    assert not body.GetPrim().HasAttribute("wrinkle:encoding")
    # the clone keeps the source look (its albedo texture) and reads the base normal map
    surface = stage.GetPrimAtPath("/Avatar/Looks/Skin_wrinkled/Surface")
    albedo = UsdShade.Shader(surface).GetInput("diffuseColor").GetConnectedSources()[0][0]
    assert albedo.source.GetPath() == Sdf.Path("/Avatar/Looks/Skin_wrinkled/Albedo")
    normal = UsdShade.Shader(surface).GetInput("normal").GetConnectedSources()[0][0]
    assert normal.source.GetPath() == Sdf.Path("/Avatar/Looks/Skin_wrinkled/base_normal")
    assert mat.GetPrim().GetAttribute("wrinkle:weights").GetTimeSamples()


def _spec_paths(layer) -> list[Sdf.Path]:
    paths: list[Sdf.Path] = []
    layer.Traverse(Sdf.Path.absoluteRootPath, lambda p: paths.append(p) if p.IsPrimPath() else None)
    return paths


def test_avatar_tangents_line_up_with_the_source_topology(avatar):
    """The head's tangents are +X on the plain island and -X on the mirrored one (u runs along
    -x there), with opposite handedness: per corner (faceVarying), since the seam's points
    have both; vertex IDs agree per point (vertex)."""
    source, out, _ = avatar
    stage = Usd.Stage.Open(str(out / "hero.usda"))
    pv = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/Avatar/Head"))
    tangent = pv.GetPrimvar("wrinkle:tangent")
    assert tangent.GetInterpolation() == "faceVarying"
    t = np.asarray(tangent.Get(), np.float64)
    _, st = _grid()
    mirrored = np.repeat(np.arange(9) % 3 == 2, 4)  # the corners of column-2 faces
    assert t.shape == (36, 4) and len(st) == 36
    np.testing.assert_allclose(t[~mirrored, :3], [[1, 0, 0]] * 24, atol=1e-5)
    np.testing.assert_allclose(t[mirrored, :3], [[-1, 0, 0]] * 12, atol=1e-5)
    w = t[:, 3]
    assert set(np.abs(w)) == {1.0} and len(set(w[~mirrored])) == 1
    assert set(w[mirrored]) == {-w[0]}
    ids = pv.GetPrimvar("wrinkle:vertexId")
    assert ids.GetInterpolation() == "vertex" and len(ids.Get()) == 16
    assert len(set(ids.Get())) == 16  # 16 distinct positions


def test_avatar_skin_binding_is_the_source_skeleton(avatar):
    source, out, _ = avatar
    stage = Usd.Stage.Open(str(out / "hero.usda"))
    src = Usd.Stage.Open(str(source))
    for path in ("/Avatar/Head", "/Avatar/Body"):
        b, a = (
            UsdSkel.BindingAPI(stage.GetPrimAtPath(path)),
            UsdSkel.BindingAPI(src.GetPrimAtPath(path)),
        )
        assert b.GetSkeletonRel().GetTargets() == [Sdf.Path("/Avatar/Skel")]
        assert list(b.GetJointIndicesPrimvar().Get()) == list(a.GetJointIndicesPrimvar().Get())
        assert list(b.GetJointWeightsPrimvar().Get()) == list(a.GetJointWeightsPrimvar().Get())
    skel = UsdSkel.Skeleton(stage.GetPrimAtPath("/Avatar/Skel"))
    assert list(skel.GetJointsAttr().Get()) == ["root", "root/neck", "root/neck/head"]
    # UsdSkel poses the composed head with the source's animation: at frame 48 the head
    # joint's world transform is the source's (computed on the source alone)
    cache_a, cache_b = UsdSkel.Cache(), UsdSkel.Cache()
    qa = cache_a.GetSkelQuery(UsdSkel.Skeleton(src.GetPrimAtPath("/Avatar/Skel")))
    qb = cache_b.GetSkelQuery(skel)
    for t in (0, 24, 48):
        np.testing.assert_allclose(
            np.asarray(qb.ComputeJointSkelTransforms(Usd.TimeCode(t))),
            np.asarray(qa.ComputeJointSkelTransforms(Usd.TimeCode(t))),
        )


def test_avatar_read_back_and_validated(avatar, capsys):
    source, out, _ = avatar
    layer = str(out / "hero.usda")
    code = main(["validate-asset", layer, "--no-render", "--allow-root", str(source.parent)])
    said = "".join(capsys.readouterr())
    assert code == 0 and "(usd: " in said and "0 errors" in said, said
    with allowed_roots([source.parent]):
        pkg = read_usd(out / "hero.usda")
    assert pkg.mesh.vertex_count == 20  # 16 points, the 4 seam points split
    assert pkg.mesh.joint_names == ("root", "root/neck", "root/neck/head")
    np.testing.assert_allclose(np.abs(pkg.mesh.tangents[:, 0]), 1, atol=1e-5)
    assert [t.name for t in pkg.textures][:1] == ["base_normal"]
    assert pkg.curves and pkg.meta.regions[0].name == "brow_L"
    with pytest.raises(Exception, match="outside"):  # without --allow-root: confined
        read_usd(out / "hero.usda")
    assert _errors(Usd.Stage.Open(str(out / "hero.usda"))) == []
    usdz = Usd.Stage.Open(str(out / "hero.usdz"))
    assert _errors(usdz) == []
    # the usdz: self-contained, every source prim, the source texture byte for byte
    src = Usd.Stage.Open(str(source))
    assert {p.GetPath() for p in src.Traverse()} <= {p.GetPath() for p in usdz.Traverse()}
    import zipfile

    z = zipfile.ZipFile(out / "hero.usdz")
    assert z.read("textures/source/skin.png") == (source.parent / "textures/skin.png").read_bytes()
    assert read_usd(out / "hero.usdz").mesh.vertex_count == 20


def test_rigid_mesh_tangents_are_written_in_the_prim_space(tmp_path):
    """The eye sits under translate + rotateY(90): the pipeline works in world space (its
    tangent -Z), the layer writes the prim's own +X back; reading the layer bakes it again.
    Its UVs are ``primvars:UVMap``."""
    source = write_avatar(tmp_path / "assets")
    out, report, _ = _convert(tmp_path, source, "eye", material="/Avatar/Looks/Eye")
    stage = Usd.Stage.Open(str(out / "eye.usda"))
    pv = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/Avatar/EyeRig/Eye"))
    t = np.asarray(pv.GetPrimvar("wrinkle:tangent").Get(), np.float64)
    assert pv.GetPrimvar("wrinkle:tangent").GetInterpolation() == "vertex"
    np.testing.assert_allclose(t[:, :3], [[1, 0, 0]] * 4, atol=1e-6)
    eye = stage.GetPrimAtPath("/Avatar/EyeRig/Eye")
    mat, _ = UsdShade.MaterialBindingAPI(eye).ComputeBoundMaterial()
    assert str(mat.GetPath()) == "/Avatar/Looks/Eye"  # not shared: the wrinkle data over it
    # the eye's UVs are primvars:UVMap (as Blender names them): the wrinkle textures read it
    reader = stage.GetPrimAtPath("/Avatar/Looks/Eye/StReader")
    assert reader.GetAttribute("inputs:varname").Get() == "UVMap"
    assert not UsdGeom.PrimvarsAPI(eye).GetPrimvar("st")
    with allowed_roots([source.parent]):
        pkg = read_usd(out / "eye.usda")
    np.testing.assert_allclose(pkg.mesh.tangents[:, :3], [[0, 0, -1]] * 4, atol=1e-6)
    assert _errors(stage) == []
    # a rerun writes the same bytes
    again = tmp_path / "again"
    with allowed_roots([source.parent]):
        convert(tmp_path / "src" / "manifest.toml", again, ConvertOptions(render=False))
    for name in ("eye.usda", "eye.usdz", "eye.gltf"):
        assert (again / name).read_bytes() == (out / name).read_bytes(), name


GAP = {"gap": ((0.45, 0.1, 0.75, 0.9), "center")}  # between the head's two UV islands


@pytest.mark.parametrize(
    ("setup", "said"),
    [
        ({"material": "Cloth"}, "no material 'Cloth' in avatar.usda; its materials: 'Eye' ("),
        ({"material": "Eye"}, "material name 'Eye' is ambiguous in avatar.usda (name it by path)"),
        ({}, "avatar.usda has 2 materials bound to meshes: name the wrinkled one"),
        ({"material": "Spare"}, "material /Avatar/Looks/Spare is bound to no mesh in avatar.usda"),
        ({"material": "Skin", "meshes": ["Eye"]}, "no Mesh prim 'Eye' bound to /Avatar/Looks/Skin"),
        (
            {"material": "Skin", "meshes": ["Head"], "regions": GAP},
            "the mask of region 'gap' falls on no wrinkled primitive",
        ),
    ],
)
def test_bad_usd_selection_one_message_exit_2_nothing_written(tmp_path, capsys, setup, said):
    source = write_avatar(tmp_path / "assets")
    manifest = write_setup(tmp_path / "src", source, "hero", **setup)
    out = tmp_path / "out"
    code = main(["convert", str(manifest), "-o", str(out), "--allow-root", str(source.parent)])
    err = capsys.readouterr().err
    assert code == 2 and said in err, err
    if "materials:" in said:  # the message lists every material and the meshes bound to it
        assert "'Skin' (/Avatar/Looks/Skin: /Avatar/Head, /Avatar/Body)" in err
        assert "'Spare' (/Avatar/Looks/Spare: no mesh)" in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["assets", "src"]


needs_rigged = pytest.mark.skipif(not RIGGED.is_file(), reason="../shared/data is absent")


@needs_rigged
def test_rigged_figure_layer_keeps_the_figure_and_adds_uvs(tmp_path):
    """RiggedFigure (UsdSkel: 19 joints, an animation, no UVs): the layer adds front-projected
    st (vertex: no vertex split) and the wrinkle primvars over the skinned mesh; the figure,
    its skeleton and its animation compose exactly as the source file alone reads."""
    out, report, _ = _convert(tmp_path, RIGGED, "figure", regions=CENTRE)
    src, stage = assert_composes_to_source(RIGGED, out / "figure.usda")
    mesh = "/RiggedFigure/Geom/Z_UP/Armature/torso_joint_1_2/Proxy_1"
    pv = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(mesh))
    st = pv.GetPrimvar("st")
    assert st.GetInterpolation() == "vertex" and len(st.Get()) == 370
    assert not UsdGeom.PrimvarsAPI(src.GetPrimAtPath(mesh)).GetPrimvar("st")
    assert len(pv.GetPrimvar("wrinkle:tangent").Get()) == 370
    skel = UsdSkel.BindingAPI(stage.GetPrimAtPath(mesh)).GetInheritedSkeleton()
    assert len(skel.GetJointsAttr().Get()) == 19
    assert any("front-projected UVs" in n for n in report["notes"])
    assert _errors(stage) == []
    assert _errors(Usd.Stage.Open(str(out / "figure.usdz"))) == []


@pytest.mark.skipif(not CESIUM.is_file(), reason="../shared/data is absent")
def test_cesium_man_layer_over_a_usdz_source(tmp_path):
    """CesiumMan.usdz (UsdSkel, a JPEG albedo inside the package): the layer sublayers the usdz;
    UsdValidation finds on it only the source's own error (usdzconvert wrote its primvar
    reader's varname as a token; no layer can retype an attribute), none added; the flattened
    usdz, whose specs are ours, has it as a string: 0 errors; it carries the JPEG byte for
    byte."""
    out, report, _ = _convert(tmp_path, CESIUM, "cesium", regions=CENTRE)
    assert_composes_to_source(CESIUM, out / "cesium.usda")
    source_errors = _errors(Usd.Stage.Open(str(CESIUM)))
    assert len(source_errors) == 1 and "varname" in source_errors[0]
    assert _errors(Usd.Stage.Open(str(out / "cesium.usda"))) == source_errors
    flat = Usd.Stage.Open(str(out / "cesium.usdz"))
    assert _errors(flat) == []
    reader = flat.GetPrimAtPath("/CesiumMan/Materials/Cesium_Man_effect/uvReader_st")
    assert reader.GetAttribute("inputs:varname").Get() == "st"
    assert any("written as a string" in n for n in report["notes"])
    import zipfile

    inner = zipfile.ZipFile(CESIUM).read("0/CesiumMan_img0.jpg")
    assert zipfile.ZipFile(out / "cesium.usdz").read("textures/source/CesiumMan_img0.jpg") == inner


def test_a_list_of_materials_wrinkles_each(tmp_path):
    """``material = ["Skin", "/Avatar/Looks/Eye"]`` with ``meshes = ["Head", "Eye"]``: Skin is
    cloned (the body keeps it), the eye's material gets the data itself; read back, the head and
    the eye are one wrinkled mesh whose vertex IDs are shared (computed over both)."""
    source = write_avatar(tmp_path / "assets")
    out, report, _ = _convert(
        tmp_path, source, "pair", material=["Skin", "/Avatar/Looks/Eye"], meshes=["Head", "Eye"]
    )
    stage = Usd.Stage.Open(str(out / "pair.usda"))
    for mesh, mat in (("/Avatar/Head", "Skin_wrinkled"), ("/Avatar/EyeRig/Eye", "Eye")):
        bound, _ = UsdShade.MaterialBindingAPI(stage.GetPrimAtPath(mesh)).ComputeBoundMaterial()
        assert str(bound.GetPath()) == f"/Avatar/Looks/{mat}"
        assert bound.GetPrim().HasAttribute("wrinkle:encoding")
    assert not stage.GetPrimAtPath("/Avatar/Looks/Skin").HasAttribute("wrinkle:encoding")
    with allowed_roots([source.parent]):
        pkg = read_usd(out / "pair.usda")
    assert pkg.mesh.vertex_count == 24 and [p.name for p in pkg.mesh.parts] == [
        "/Avatar/Head",
        "/Avatar/EyeRig/Eye",
    ]
    assert len(set(pkg.mesh.vertex_ids.tolist())) == 20  # 16 head + 4 eye positions
    assert _errors(stage) == []


@hs.composite
def polygon_meshes(draw):
    """Random polygons (3-5 distinct corners) over up to 8 points, faceVarying st drawn from a
    few values (so corners of a point sometimes agree, sometimes split), per-point normals."""
    n = draw(hs.integers(4, 8))
    faces = draw(
        hs.lists(
            hs.lists(hs.integers(0, n - 1), min_size=3, max_size=5, unique=True),
            min_size=1,
            max_size=6,
        )
    )
    fvi = [i for f in faces for i in f]
    st = draw(
        hs.lists(
            hs.sampled_from([(0, 0), (0.25, 1), (1, 0.5)]), min_size=len(fvi), max_size=len(fvi)
        )
    )
    seed = draw(hs.integers(0, 2**16))
    return n, faces, fvi, st, seed


@settings(max_examples=25, deadline=None)
@given(polygon_meshes())
def test_corner_map_law(mesh):
    """For any polygon mesh with faceVarying UVs: the reader's render vertex of each corner
    carries that corner's point and UV (v flipped), and per-vertex values written back through
    :func:`topology_values` (vertex where the points agree, else faceVarying) read per corner
    exactly as the render vertices hold them."""
    n, faces, fvi, st, seed = mesh
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, 3))
    fmt = ", ".join
    points = fmt("({!r}, {!r}, {!r})".format(*map(float, q)) for q in pts.astype(np.float32))
    text = f"""#usda 1.0
def Mesh "m" {{
    point3f[] points = [{points}]
    int[] faceVertexCounts = [{fmt(str(len(f)) for f in faces)}]
    int[] faceVertexIndices = [{fmt(map(str, fvi))}]
    texCoord2f[] primvars:st = [{fmt(f"({u}, {v})" for u, v in st)}] (interpolation = "faceVarying")
}}
"""
    with tempfile.TemporaryDirectory() as work:
        path = Path(work) / "m.usda"
        path.write_text(text, encoding="utf-8")
        (m,) = read_usd_meshes(path)
    corners = m.parts[0].corners
    fvi_a = np.asarray(fvi)
    np.testing.assert_array_equal(m.positions[corners], pts.astype(np.float32)[fvi_a])
    st_a = np.asarray(st, np.float32)
    np.testing.assert_array_equal(m.uvs[corners], np.stack([st_a[:, 0], 1 - st_a[:, 1]], 1))
    values = rng.integers(0, 3, size=(m.vertex_count, 2)).astype(np.float32)
    interp, data = topology_values(values, corners, fvi_a, n)
    per_corner = data[fvi_a] if interp == "vertex" else data
    np.testing.assert_array_equal(per_corner, values[corners])
    same_per_point = all(
        len({tuple(values[corners[c]]) for c in np.flatnonzero(fvi_a == q)}) <= 1 for q in range(n)
    )
    assert (interp == "vertex") == same_per_point


ARM = USDZ.parents[1] / "openusd" / "usd" / "usdSkel" / "doxygen" / "skinnedArm.usda"


@pytest.mark.skipif(not ARM.is_file(), reason="../shared/data is absent")
def test_skinned_arm_quads_without_uvs_or_normals(tmp_path):
    """OpenUSD's skinned arm (quads, 3 joints, an animation, no UVs, no normals, no material):
    the layer adds st, the wrinkle primvars and a material bound to the arm; it composes to the
    source; read back, the tangents are the pipeline's (the glTF output's) to float rounding."""
    import gltf_reference as ref

    out, report, _ = _convert(tmp_path, ARM, "arm", regions=CENTRE)
    _, stage = assert_composes_to_source(ARM, out / "arm.usda")
    arm = stage.GetPrimAtPath("/Model/Arm")
    mat, _ = UsdShade.MaterialBindingAPI(arm).ComputeBoundMaterial()
    assert str(mat.GetPath()) == "/Model/WrinkleLooks/arm"
    assert UsdGeom.PrimvarsAPI(arm).GetPrimvar("st").GetInterpolation() == "vertex"
    assert any("no normals on /Model/Arm" in n for n in report["notes"])
    assert _errors(stage) == [] and _errors(Usd.Stage.Open(str(out / "arm.usdz"))) == []
    with allowed_roots([ARM.parent]):
        pkg = read_usd(out / "arm.usda")
    g = ref.load(out / "arm.gltf")
    prim = g.meshes[0].primitives[0]
    tangents = ref.accessor(g, out / "arm.gltf", prim.attributes.TANGENT)
    positions = ref.accessor(g, out / "arm.gltf", prim.attributes.POSITION)
    assert len(positions) == pkg.mesh.vertex_count == 12
    order = [
        int(np.flatnonzero((np.abs(positions - p) < 1e-6).all(1))[0]) for p in pkg.mesh.positions
    ]
    np.testing.assert_allclose(pkg.mesh.tangents, tangents[order], atol=1e-5)


def test_material_bound_only_to_faces_is_refused(tmp_path, capsys):
    """A material bound through a GeomSubset (some faces of a mesh) cannot be wrinkled alone."""
    (tmp_path / "assets").mkdir()
    source = tmp_path / "assets" / "faces.usda"
    source.write_text(
        f"""#usda 1.0
(
    defaultPrim = "Root"
    upAxis = "Y"
)
def Xform "Root" {{
    def Mesh "Face" (prepend apiSchemas = ["MaterialBindingAPI"]) {{
        {_quad(0, 0)}
        rel material:binding = </Root/Skin>
        def GeomSubset "lips" (prepend apiSchemas = ["MaterialBindingAPI"]) {{
            uniform token elementType = "face"
            uniform token familyName = "materialBind"
            int[] indices = [0]
            rel material:binding = </Root/Lips>
        }}
    }}
    def Material "Skin" {{
    }}
    def Material "Lips" {{
    }}
}}
""",
        encoding="utf-8",
    )
    manifest = write_setup(tmp_path / "src", source, "face", "Lips")
    out = tmp_path / "out"
    code = main(["convert", str(manifest), "-o", str(out), "--allow-root", str(source.parent)])
    err = capsys.readouterr().err
    assert code == 2 and "material /Root/Lips is bound only to GeomSubset faces" in err, err
    assert not (tmp_path / "out").exists()


TEAPOT = USDZ.parents[0] / "full_assets" / "Teapot" / "Teapot.usd"


@pytest.mark.skipif(not TEAPOT.is_file(), reason="../shared/data is absent")
def test_teapot_payload_and_variants_compose_through_the_layer(tmp_path):
    """usd-wg's Teapot (a payload, a model variant set, references, textured materials): the
    layer over it composes to the source (the selected variant, the payload's prims, every
    value); UsdValidation 0 errors on the layer and the usdz, which packs the selected
    variant's textures byte for byte and names its own layer, not the source's, as the
    asset's identifier."""
    import zipfile

    out, report, _ = _convert(tmp_path, TEAPOT, "teapot", regions=CENTRE)
    _, stage = assert_composes_to_source(TEAPOT, out / "teapot.usda")
    mat, _ = UsdShade.MaterialBindingAPI(
        stage.GetPrimAtPath("/Teapot/Geometry")
    ).ComputeBoundMaterial()
    assert str(mat.GetPath()) == "/Teapot/Materials/Ceramic"
    assert _errors(stage) == []
    assert _errors(Usd.Stage.Open(str(out / "teapot.usdz"))) == []
    names = zipfile.ZipFile(out / "teapot.usdz").namelist()
    assert names[0] == "teapot.usdc" and not any(n.endswith(".usd") for n in names)
    cards = TEAPOT.parent / "cards" / "Utah"
    z = zipfile.ZipFile(out / "teapot.usdz")
    assert z.read("textures/source/XNeg.png") == (cards / "XNeg.png").read_bytes()
    flat = Usd.Stage.Open(str(out / "teapot.usdz"))
    info = flat.GetPrimAtPath("/Teapot").GetAssetInfo()
    assert info["identifier"].path == "teapot.usdc"


def test_instanced_head_is_made_overridable(tmp_path):
    """A head referenced twice as an instanceable asset: its meshes and material are instance
    proxies, which no layer can override. The layer turns the wrinkled instance into ordinary
    prims (instanceable = false, noted), the other instance stays instanced, and the stage
    composes to the source's values."""
    assets = tmp_path / "assets"
    assets.mkdir()
    (assets / "head.usda").write_text(
        f"""#usda 1.0
(
    defaultPrim = "Head"
)
def Xform "Head" {{
    def Mesh "Face" (prepend apiSchemas = ["MaterialBindingAPI"]) {{
        {_quad(0, 0)}
        rel material:binding = </Head/Skin>
    }}{_material("Skin", False).replace("/Avatar/Looks/Skin", "/Head/Skin")}
}}
""",
        encoding="utf-8",
    )
    source = assets / "crowd.usda"
    source.write_text(
        """#usda 1.0
(
    defaultPrim = "Crowd"
    metersPerUnit = 1
    upAxis = "Y"
)
def Xform "Crowd" {
    def "Ada" (instanceable = true
        prepend references = @./head.usda@) {
    }
    def "Bo" (instanceable = true
        prepend references = @./head.usda@) {
        double3 xformOp:translate = (3, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
}
""",
        encoding="utf-8",
    )
    out, report, _ = _convert(
        tmp_path, source, "ada", material="/Crowd/Ada/Skin", meshes=["/Crowd/Ada/Face"]
    )
    stage = Usd.Stage.Open(str(out / "ada.usda"))
    assert not stage.GetPrimAtPath("/Crowd/Ada").IsInstance()
    assert stage.GetPrimAtPath("/Crowd/Bo").IsInstance()
    face = stage.GetPrimAtPath("/Crowd/Ada/Face")
    assert UsdGeom.PrimvarsAPI(face).GetPrimvar("wrinkle:tangent").Get() is not None
    mat, _ = UsdShade.MaterialBindingAPI(face).ComputeBoundMaterial()
    assert mat.GetPrim().HasAttribute("wrinkle:encoding")
    assert any("made not instanceable" in n for n in report["notes"])
    src = Usd.Stage.Open(str(source))
    for path in ("/Crowd/Ada/Face", "/Crowd/Bo/Face"):
        a = UsdGeom.Mesh(src.GetPrimAtPath(path))
        b = UsdGeom.Mesh(stage.GetPrimAtPath(path))
        assert list(b.GetPointsAttr().Get()) == list(a.GetPointsAttr().Get())
    assert _errors(stage) == []


def test_wrinkling_a_wrinkled_material_again_is_refused(avatar, tmp_path, capsys):
    """The avatar's layer as a source, its wrinkled clone named again: one message (the
    material already holds the wrinkle shaders), exit 2, nothing written."""
    source, out, _ = avatar
    manifest = write_setup(tmp_path / "src", out / "hero.usda", "again", "Skin_wrinkled")
    code = main(
        ["convert", str(manifest), "-o", str(tmp_path / "out2")]
        + ["--allow-root", str(out), "--allow-root", str(source.parent)]
    )
    err = capsys.readouterr().err
    assert code == 2 and "already has" in err and "is it already wrinkled?" in err, err
    assert not (tmp_path / "out2").exists()


def test_batch_cache_key_holds_the_layer_path_of_a_usd_source(tmp_path):
    """The layer names its source relative to the output folder, so a cached convert folder
    restored elsewhere would point nowhere: for a USD source the batch cache key holds that
    path (same key where it is the same, another where it differs); for a glTF source the
    output place is not part of the key."""
    from wrinklepipe.batch.fingerprint import asset_key
    from wrinklepipe.batch.options import AssetOptions

    source = write_avatar(tmp_path / "assets")
    manifest = write_setup(tmp_path / "src", source, "hero", material="Skin")
    opt = AssetOptions()
    with allowed_roots([source.parent]):
        a = asset_key(manifest, opt, tmp_path / "build" / "hero")[0]
        b = asset_key(manifest, opt, tmp_path / "build" / "hero2")[0]  # ../../assets as well
        c = asset_key(manifest, opt, tmp_path / "deep" / "build" / "hero")[0]
    assert a == b != c
    gltf = write_setup(tmp_path / "g", tmp_path / "g" / "head.glb", "hero")
    (tmp_path / "g" / "head.glb").write_bytes(b"glTF")
    assert asset_key(gltf, opt, tmp_path / "x")[0] == asset_key(gltf, opt, tmp_path / "y" / "z")[0]


def test_meshes_without_material_take_their_own_materials(tmp_path):
    """``meshes = ["Head", "Eye"]`` and no ``material``: the named meshes with the materials
    they are bound to (Skin, cloned since the body keeps it; Eye)."""
    source = write_avatar(tmp_path / "assets")
    out, report, _ = _convert(tmp_path, source, "named", meshes=["Head", "Eye"])
    stage = Usd.Stage.Open(str(out / "named.usda"))
    for mesh, mat in (("/Avatar/Head", "Skin_wrinkled"), ("/Avatar/EyeRig/Eye", "Eye")):
        bound, _ = UsdShade.MaterialBindingAPI(stage.GetPrimAtPath(mesh)).ComputeBoundMaterial()
        assert str(bound.GetPath()) == f"/Avatar/Looks/{mat}"
    body, _ = UsdShade.MaterialBindingAPI(
        stage.GetPrimAtPath("/Avatar/Body")
    ).ComputeBoundMaterial()
    assert str(body.GetPath()) == "/Avatar/Looks/Skin"
    # each material's wrinkle textures read its own meshes' UVs (the head's st, the eye's UVMap)
    for mat, uv in (("Skin_wrinkled", "st"), ("Eye", "UVMap")):
        reader = stage.GetPrimAtPath(f"/Avatar/Looks/{mat}/StReader")
        assert reader.GetAttribute("inputs:varname").Get() == uv


def test_inspect_diff_of_source_and_layer_lists_only_the_additions(avatar, capsys):
    """``inspect --diff SOURCE LAYER``: nothing removed; changed only the sublayer list, the
    material count and the head's material binding (to the clone); added only the head's
    wrinkle primvars and the clone with its shaders."""
    import json

    source, out, _ = avatar
    code = main(
        ["inspect", "--diff", str(source), str(out / "hero.usda"), "--json"]
        + ["--allow-root", str(source.parent)]
    )
    lines = json.loads(capsys.readouterr().out)["differences"]
    assert code == 1 and lines
    assert not [x for x in lines if x.startswith("-")]
    changed = sorted(x.split(":")[0] for x in lines if x.startswith("~"))
    assert changed == [
        "~ counts.materials",  # the clone
        "~ layers",
        "~ prims./Avatar/Head.material",
        "~ prims./Avatar/Head.relationships.material",  # material:binding
        "~ used_layers",
    ]
    added = [x[2:].split(": ")[0] for x in lines if x.startswith("+")]
    assert added and all(
        a.startswith("prims./Avatar/Head.attributes.primvars:wrinkle:")
        or a.startswith("prims./Avatar/Looks/Skin_wrinkled")
        for a in added
    ), added
    assert "prims./Avatar/Head.attributes.primvars:wrinkle:tangent" in added
    # one file: the table names the layer's sublayer and the wrinkled material
    assert main(["inspect", str(out / "hero.usda"), "--allow-root", str(source.parent)]) == 0
    said = capsys.readouterr().out
    assert "WrinkleMapsAPI" in said and "../assets/avatar.usda" in said


def test_engine_export_from_the_flattened_usdz(avatar, tmp_path):
    """The self-contained usdz is an input like any written asset: the Godot export reads it
    (the layered mesh through the source topology) and writes its files."""
    _, out, _ = avatar
    dest = tmp_path / "godot"
    assert main(["export", str(out / "hero.usdz"), "--engine", "godot", "-o", str(dest)]) == 0
    assert (dest / "wrinkle.gdshader").is_file() and list(dest.glob("*.gltf"))


LBS = ARM.parents[1] / "testenv" / "testUsdSkelBakeSkinning" / "lbs.usda"


@pytest.mark.skipif(not LBS.is_file(), reason="../shared/data is absent")
def test_lbs_source_without_units_or_default_prim(tmp_path):
    """OpenUSD's lbs.usda (skinned, animated extentsHint, no metersPerUnit, no defaultPrim:
    UsdValidation errors of its own): the layer states USD's fallbacks (metersPerUnit 0.01, the
    only root prim as defaultPrim), composes to the source, and validates with 0 errors."""
    assert len(_errors(Usd.Stage.Open(str(LBS)))) == 2
    out, report, _ = _convert(tmp_path, LBS, "lbs", regions=CENTRE)
    _, stage = assert_composes_to_source(LBS, out / "lbs.usda")
    assert UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/Root")
    assert any("to USD's fallbacks" in n for n in report["notes"])
    assert _errors(stage) == [] and _errors(Usd.Stage.Open(str(out / "lbs.usdz"))) == []


def test_eye_with_only_time_sampled_points_is_wrinkled_at_the_start_time_code(tmp_path):
    """The eye's points only as time samples (0 and 24; the stage's startTimeCode = 0): the
    selection and the layer read it at time code 0 (said in the report); its wrinkle primvars
    are one per point; reading the layer back gives the t = 0 points, baked to world."""
    source = write_avatar(tmp_path / "assets")
    text = source.read_text()
    rest = "point3f[] points = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]"
    assert text.count(rest) == 1  # the eye's quad (z = 0, y0 = 0)
    moved = "[(0, 0, 0.5), (1, 0, 0.5), (1, 1, 0.5), (0, 1, 0.5)]"
    sampled = f"point3f[] points.timeSamples = {{0: {rest.split(' = ')[1]}, 24: {moved}}}"
    source.write_text(text.replace(rest, sampled))
    out, report, _ = _convert(tmp_path, source, "eye", material="/Avatar/Looks/Eye")
    assert any(
        "only 2 time samples: read at time code 0 (the stage's startTimeCode)" in n
        for n in report["notes"]
    ), report["notes"]
    stage = Usd.Stage.Open(str(out / "eye.usda"))
    eye = stage.GetPrimAtPath("/Avatar/EyeRig/Eye")
    ids = UsdGeom.PrimvarsAPI(eye).GetPrimvar("wrinkle:vertexId")
    assert ids.GetInterpolation() == "vertex" and len(ids.Get()) == 4
    with allowed_roots([source.parent]):
        pkg = read_usd(out / "eye.usda")
    # world = translate (0, 1.6, 0.2) rotateY(90): local (x, y, 0) -> (0, 1.6 + y, 0.2 - x)
    want = [[0, 1.6, 0.2], [0, 1.6, -0.8], [0, 2.6, -0.8], [0, 2.6, 0.2]]
    np.testing.assert_allclose(np.sort(pkg.mesh.positions, 0), np.sort(want, 0), atol=1e-6)
    assert _errors(stage) == []
