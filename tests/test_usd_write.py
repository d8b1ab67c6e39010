"""USD writer/reader: UsdValidation, codeless WrinkleMapsAPI, V flip, time samples, round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest
import usd_checks
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.demo.package import demo_package
from wrinklepipe.errors import InputError
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.gltf.package_write import write_gltf
from wrinklepipe.usd.package_read import read_usd
from wrinklepipe.usd.package_write import API_NAME, register_schema, write_usd

pxr = pytest.importorskip("pxr")
from pxr import Sdf, Usd, UsdShade, UsdValidation  # noqa: E402


@pytest.fixture(scope="module")
def pkg():
    return demo_package(256)


@pytest.fixture(scope="module")
def usda(pkg, tmp_path_factory):
    folder = tmp_path_factory.mktemp("usd")
    write_usd(pkg, folder / "demo.usda")
    return folder / "demo.usda"


def _validate(path):
    register_schema()
    stage = Usd.Stage.Open(str(path))
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    assert len(validators) > 20
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    return usd_checks.validation_errors(stage), errors


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usdz"])
def test_usd_validation_clean(pkg, tmp_path, suffix):
    path = tmp_path / f"demo{suffix}"
    write_usd(pkg, path)
    errors, _ = _validate(path)
    assert errors == [], [(e.GetName(), e.GetMessage()) for e in errors]


def test_usd_validation_detects_problems(tmp_path):
    # the same validators do report a stage without upAxis / metersPerUnit / defaultPrim
    stage = Usd.Stage.CreateNew(str(tmp_path / "bad.usda"))
    stage.DefinePrim("/a", "Xform")
    stage.Save()
    errors, _ = _validate(tmp_path / "bad.usda")
    names = {e.GetName() for e in errors}
    assert {"MissingDefaultPrim", "MissingUpAxisMetadata"} <= names


_HAS_API_SCRIPT = """
import sys
from wrinklepipe.usd.package_write import API_ATTRIBUTES, API_NAME  # registers the plugin on import
from pxr import Usd
stage = Usd.Stage.Open(sys.argv[1])
mat = stage.GetPrimAtPath("/demo/Looks/skin")
api = Usd.SchemaRegistry.GetTypeFromSchemaTypeName(API_NAME)
definition = Usd.SchemaRegistry().FindAppliedAPIPrimDefinition(API_NAME)
assert api and mat.HasAPI(api), "HasAPI"
for name, type_name in API_ATTRIBUTES.items():
    assert str(definition.GetAttributeDefinition(name).GetTypeName()) == type_name, name
    assert str(mat.GetAttribute(name).GetTypeName()) == type_name, name
print("ok")
"""


def test_wrinkle_maps_api_is_applied_and_typed(usda):
    # A fresh process, as a user's: the plugin is registered before USD builds its registry
    # (this test process may have opened stages before the plugin was registered).
    import subprocess
    import sys

    proc = subprocess.run(
        [sys.executable, "-c", _HAS_API_SCRIPT, str(usda)], capture_output=True, text=True
    )
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr


def test_api_attributes_match_generated_schema():
    from wrinklepipe.usd.package_write import (
        API_ATTRIBUTES,
        COLOR_ATTRIBUTES,
        TILE_ATTRIBUTES,
        USD_SCHEMA_DIR,
    )

    layer = Sdf.Layer.FindOrOpen(str(USD_SCHEMA_DIR / "generatedSchema.usda"))
    spec = layer.GetPrimAtPath("/WrinkleMapsAPI")
    declared = {a.name: str(a.typeName) for a in spec.attributes}
    assert declared == {**API_ATTRIBUTES, **COLOR_ATTRIBUTES, **TILE_ATTRIBUTES}


def test_typed_values_without_the_plugin(usda):
    # whatever the registration state of this process, the authored values carry their types
    stage = Usd.Stage.Open(str(usda))
    mat = stage.GetPrimAtPath("/demo/Looks/skin")
    assert API_NAME in mat.GetMetadata("apiSchemas").ApplyOperations([])
    assert str(mat.GetAttribute("wrinkle:expressionWeights").GetTypeName()) == "double[]"
    assert mat.GetAttribute("wrinkle:encoding").Get() == "pd"
    assert list(mat.GetAttribute("wrinkle:regionNames").Get())[6] == "glabella"
    # Jimenez Table 1.1 anger row, regions in order (Red..Gray)
    names = list(mat.GetAttribute("wrinkle:expressionNames").Get())
    table = np.asarray(mat.GetAttribute("wrinkle:expressionWeights").Get()).reshape(len(names), 8)
    assert table[names.index("anger")].tolist() == [-0.6, -0.6, -0.8, -0.8, 0.8, 0.8, 1.0, 0.0]


_LATE_SCRIPT = """
import sys
from pxr import Usd
Usd.Stage.Open(sys.argv[1]).Traverse()  # USD builds its schema registry before the plugin
assert not Usd.SchemaRegistry().FindAppliedAPIPrimDefinition("WrinkleMapsAPI")
from wrinklepipe.usd.package_read import read_usd
from wrinklepipe.usd.package_write import write_usd
pkg = read_usd(sys.argv[1])
write_usd(pkg, sys.argv[2], write_textures=False)
print("ok")
"""


def test_late_plugin_registration_changes_nothing(usda, tmp_path):
    import subprocess
    import sys

    out = tmp_path / "late.usda"
    proc = subprocess.run(
        [sys.executable, "-c", _LATE_SCRIPT, str(usda), str(out)], capture_output=True, text=True
    )
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr
    assert out.read_bytes() == usda.read_bytes()


def test_material_network(usda):
    stage = Usd.Stage.Open(str(usda))
    mat = UsdShade.Material(stage.GetPrimAtPath("/demo/Looks/skin"))
    base = UsdShade.Shader(stage.GetPrimAtPath("/demo/Looks/skin/base_normal"))
    assert base.GetIdAttr().Get() == "UsdUVTexture"
    assert base.GetInput("sourceColorSpace").Get() == "raw"
    assert tuple(base.GetInput("scale").Get()) == (2, 2, 2, 1)
    assert tuple(base.GetInput("bias").Get()) == (-1, -1, -1, 0)
    surf = UsdShade.Shader(stage.GetPrimAtPath("/demo/Looks/skin/Surface"))
    src = surf.GetInput("normal").GetConnectedSources()[0][0]
    assert src.source.GetPath() == base.GetPath() and src.sourceName == "rgb"
    # wrinkle states and masks: UsdUVTexture whose file comes from the material's wrinkle inputs
    stretch = UsdShade.Shader(stage.GetPrimAtPath("/demo/Looks/skin/wrinkle_stretch"))
    src = stretch.GetInput("file").GetConnectedSources()[0][0]
    assert src.source.GetPath() == mat.GetPath()
    assert src.sourceName == "wrinkle:state:stretch"
    assert mat.GetInput("wrinkle:state:stretch").Get().path == "./textures/wrinkle_stretch.png"
    assert mat.GetInput("wrinkle:mask:mask_1").Get().path == "./textures/mask_1.png"
    # pd scale 1, mapping v2 at 8 bits: slope = s (255 v - 128) / 127 = v 255/127 - 128/127
    assert tuple(stretch.GetInput("scale").Get())[:2] == pytest.approx((255 / 127,) * 2)
    assert tuple(stretch.GetInput("bias").Get())[:2] == pytest.approx((-128 / 127,) * 2)
    assert mat.GetPrim().GetAttribute("wrinkle:mapping").Get() == 2


def test_v_flip_and_vertex_ids(usda, pkg):
    stage = Usd.Stage.Open(str(usda))
    mesh = stage.GetPrimAtPath("/demo/demo_head")
    st_ = np.asarray(mesh.GetAttribute("primvars:st").Get())
    uv = pkg.mesh.uvs
    assert np.array_equal(st_[:, 0], uv[:, 0])
    assert np.array_equal(st_[:, 1], (np.float32(1.0) - uv[:, 1]).astype(np.float32))
    # the top row of the image (glTF v near 0) is the top in USD too (t near 1)
    top = np.argmin(uv[:, 1])
    assert uv[top, 1] == 0.0 and st_[top, 1] == 1.0
    vid = mesh.GetAttribute("primvars:wrinkle:vertexId")
    assert str(vid.GetTypeName()) == "int[]"
    assert np.array_equal(np.asarray(vid.Get()), pkg.mesh.vertex_ids)


@settings(max_examples=300, deadline=None)
@given(st.floats(0.0, 1.0, width=32))
def test_v_flip_round_trip_within_one_ulp_of_one(v):
    # USD t = 1 - v in float32, read back v' = 1 - t: exact for v >= 0.5, else within 2^-24
    v32 = np.float32(v)
    t = np.float32(1.0) - v32
    back = np.float32(1.0) - t
    assert abs(float(back) - float(v32)) <= 2.0**-24


def test_weights_are_time_samples(usda, pkg):
    stage = Usd.Stage.Open(str(usda))
    attr = stage.GetPrimAtPath("/demo/Looks/skin").GetAttribute("wrinkle:weights")
    fps = stage.GetTimeCodesPerSecond()
    curve = pkg.curves[0]
    assert attr.GetTimeSamples() == [float(t) * fps for t in curve.times]
    # at t = 1 s the expression cycle shows the table's first expression fully on
    row = np.asarray(attr.Get(Usd.TimeCode(1.0 * fps)))
    assert np.array_equal(row, curve.values[1])
    # halfway between keys USD interpolates linearly, like the glTF LINEAR sampler
    mid = np.asarray(attr.Get(Usd.TimeCode(1.5 * fps)))
    assert np.allclose(mid, 0.5 * (curve.values[1] + curve.values[2]))


def test_blend_shapes(usda, pkg):
    from pxr import UsdSkel

    stage = Usd.Stage.Open(str(usda))
    binding = UsdSkel.BindingAPI(stage.GetPrimAtPath("/demo/demo_head"))
    assert list(binding.GetBlendShapesAttr().Get()) == list(pkg.mesh.morph_names)
    target = binding.GetBlendShapeTargetsRel().GetTargets()[2]
    offsets = np.asarray(UsdSkel.BlendShape(stage.GetPrimAtPath(target)).GetOffsetsAttr().Get())
    assert np.array_equal(offsets, pkg.mesh.morph_deltas[2])


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usdz"])
def test_gltf_usd_gltf_round_trip(pkg, tmp_path, suffix):
    write_gltf(pkg, tmp_path / "a", "demo")
    first = read_wrinkled(tmp_path / "a" / "demo.gltf")
    write_usd(first, tmp_path / "u" / f"demo{suffix}")
    via_usd = read_usd(tmp_path / "u" / f"demo{suffix}")
    assert via_usd.meta == first.meta  # channel tables, expressions, drivers, weights, encoding
    for t in first.textures:
        assert np.array_equal(via_usd.texture(t.name).pixels, t.pixels), t.name
    for f in ("positions", "indices", "uvs", "normals", "tangents", "vertex_ids", "morph_deltas"):
        assert np.array_equal(getattr(via_usd.mesh, f), getattr(first.mesh, f)), f
    assert np.array_equal(via_usd.curves[0].times, first.curves[0].times)
    assert np.array_equal(via_usd.curves[0].values, first.curves[0].values)
    write_gltf(via_usd, tmp_path / "b", "demo")
    for rel in ("demo.gltf", "demo.bin", "textures/wrinkle_compress.png", "textures/mask_0.png"):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes(), rel


def test_usda_is_deterministic(pkg, tmp_path):
    write_usd(pkg, tmp_path / "a" / "x.usda")
    write_usd(pkg, tmp_path / "b" / "x.usda")
    assert (tmp_path / "a/x.usda").read_bytes() == (tmp_path / "b/x.usda").read_bytes()


def test_reader_refuses_escaping_texture_paths(usda, tmp_path):
    layer = Sdf.Layer.FindOrOpen(str(usda))
    text = layer.ExportToString().replace("@./textures/mask_0.png@", "@../../etc/mask_0.png@")
    bad = usda.parent / "bad.usda"
    bad.write_text(text)
    with pytest.raises(InputError, match="is outside"):  # refused before the stage opens
        read_usd(bad)


def test_reader_refuses_non_wrinkle_stage(tmp_path):
    stage = Usd.Stage.CreateNew(str(tmp_path / "plain.usda"))
    stage.DefinePrim("/a", "Xform")
    stage.Save()
    with pytest.raises(InputError, match="not a wrinklepipe asset"):
        read_usd(tmp_path / "plain.usda")


def test_bias_and_metadata_round_trip(pkg, tmp_path):
    from dataclasses import replace

    rng = np.random.default_rng(3)
    colors = rng.random((pkg.mesh.vertex_count, 4)).astype(np.float32)
    meta = replace(
        pkg.meta, drivers=({"kind": "curves", "keys": {"glabella": [[0.0, 0.0], [1.0, 0.5]]}},)
    )
    p2 = replace(pkg, mesh=replace(pkg.mesh, colors=colors), meta=meta)
    write_gltf(p2, tmp_path / "g", "x")
    # every custom attribute SCALAR FLOAT (Blender 5's importer needs one shape): the bias
    # as four channels beside the vertex IDs
    doc = json.loads((tmp_path / "g" / "x.gltf").read_text())
    attrs = doc["meshes"][0]["primitives"][0]["attributes"]
    custom = {k: doc["accessors"][i] for k, i in attrs.items() if k.startswith("_")}
    assert sorted(custom) == ["_WRINKLE_BIAS_A", "_WRINKLE_BIAS_B", "_WRINKLE_BIAS_G"] + [
        "_WRINKLE_BIAS_R",
        "_WRINKLE_VERTEX_ID",
    ]
    assert {(a["type"], a["componentType"]) for a in custom.values()} == {("SCALAR", 5126)}
    g = read_wrinkled(tmp_path / "g" / "x.gltf")
    write_usd(g, tmp_path / "u.usda")
    u = read_usd(tmp_path / "u.usda")
    assert np.array_equal(g.mesh.colors, colors) and np.array_equal(u.mesh.colors, colors)
    assert u.meta.drivers == g.meta.drivers == meta.drivers


def test_several_weight_curves_keep_names_and_order(pkg, tmp_path):
    from dataclasses import replace

    from wrinklepipe.package import WeightCurves

    c0 = pkg.curves[0]
    c1 = WeightCurves("z blink/test", np.array([0.0, 0.5], np.float32), c0.values[:2][::-1])
    c2 = WeightCurves("a_second", np.array([0.25], np.float32), c0.values[3:4])
    p2 = replace(pkg, curves=[c0, c1, c2])
    write_gltf(p2, tmp_path / "g", "x")
    g = read_wrinkled(tmp_path / "g" / "x.gltf")
    write_usd(g, tmp_path / "u.usda")
    u = read_usd(tmp_path / "u.usda")
    assert [c.name for c in u.curves] == [c.name for c in g.curves] == [c0.name, c1.name, c2.name]
    for a, b in zip(u.curves, p2.curves):
        assert np.array_equal(a.times, b.times) and np.array_equal(a.values, b.values)


def test_morph_weight_animation_round_trip(pkg, tmp_path):
    from dataclasses import replace

    from pxr import UsdSkel

    from wrinklepipe.io import khronos

    c0 = pkg.curves[0]
    rng = np.random.default_rng(11)
    mw = rng.random((len(c0.times), len(pkg.mesh.morph_names))).astype(np.float32)
    # named "x" and written as x.gltf: the glTF package reader names a package by the file stem
    p2 = replace(pkg, name="x", curves=[replace(c0, morph_weights=mw)])
    write_gltf(p2, tmp_path / "a", "x")
    doc = json.loads((tmp_path / "a" / "x.gltf").read_text())
    channels = doc["animations"][0]["channels"]
    assert {"node": 0, "path": "weights"} in [ch["target"] for ch in channels]
    if khronos.available():
        issues = khronos.validate_gltf(tmp_path / "a" / "x.gltf")["issues"]
        assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]
    g = read_wrinkled(tmp_path / "a" / "x.gltf")
    assert np.array_equal(g.curves[0].morph_weights, mw)
    write_usd(g, tmp_path / "x.usda")
    stage = Usd.Stage.Open(str(tmp_path / "x.usda"))
    anim = UsdSkel.Animation(stage.GetPrimAtPath("/x/Skel/Anim"))
    fps = stage.GetTimeCodesPerSecond()
    t2 = float(c0.times[2]) * fps
    assert np.array_equal(np.asarray(anim.GetBlendShapeWeightsAttr().Get(t2)), mw[2])
    u = read_usd(tmp_path / "x.usda")
    assert np.array_equal(u.curves[0].morph_weights, mw)
    write_gltf(u, tmp_path / "b", "x")
    for rel in ("x.gltf", "x.bin"):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()


@pytest.mark.parametrize(
    "name, data", [("x.usda", b"#usda 1.0\ndef Xform (((\n"), ("x.usdz", b"PK\x03\x04junk")]
)
def test_reader_refuses_broken_files(tmp_path, name, data):
    (tmp_path / name).write_bytes(data)
    with pytest.raises(InputError) as exc:
        read_usd(tmp_path / name)
    assert name in str(exc.value)
