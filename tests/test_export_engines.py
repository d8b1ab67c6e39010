"""`wrinklepipe export`: complete engine folders, their shaders rendered equal to numpy.

For every engine: a flat folder (``textures/``, ``curves/`` only) with the mesh as glTF (0
Khronos validator errors), no texture twice, true notes, wrinkle_setup.json whose files exist and
whose slot table is the shader's, curves named the engine's way, a README with the import steps.
Unreal's BC5 DDS carry full mip chains in DirectX convention (read back by an independent
decoder); its exported Custom-node HLSL, compiled by glslang and rendered on the exported texels
(BC5 level 0 uploaded as is), equals the numpy model with y negated. Unity's exported file
renders the exported strips equal to numpy. Blender's exports are imported, played and rendered
by Blender 5 in tests/test_blender.py.

Whole characters (the generated multi-mesh avatar, RobotExpressive from ../shared/data) export
whole: every mesh, material, texture, skin and animation of the converted document is in each
engine's glTF (pygltflib + struct, :func:`passthrough.compare`), the plain parts unchanged, only
the wrinkle additions gone; the wrinkled material renders equal to numpy from the exported files.
"""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import replace
from pathlib import Path

import gltf_reference as ref
import numpy as np
import pytest
import shader_harness as h
import texture2ddecoder
from engine_imports import check_godot_sidecars, check_unity_sidecars, check_unreal_clipboard
from passthrough import EXTENSION, compare
from wrinkle_setups import ROBOT

from wrinklepipe import codec, model
from wrinklepipe.demo import avatar, demo_asset
from wrinklepipe.errors import InputError
from wrinklepipe.gltf.package_write import write_gltf
from wrinklepipe.io import khronos
from wrinklepipe.io.png import png_pixels
from wrinklepipe.jobs.convert import ConvertOptions, convert
from wrinklepipe.jobs.export import export
from wrinklepipe.metrics import angle_deg
from wrinklepipe.normals.dds import read_dds
from wrinklepipe.paths import ROOT
from wrinklepipe.pipeline.drivers import expression_cycle
from wrinklepipe.pipeline.package import PackOptions, package_from_asset
from wrinklepipe.pipeline.prepare import prepare_mesh
from wrinklepipe.shading import hlsl
from wrinklepipe.sources.validation import load_input
from wrinklepipe.validate.inputs import ChannelEntry, Texture
from wrinklepipe.validate.renderer import shader_setup

ENGINES = ["unreal", "unity", "godot", "blender"]
DATA = ROOT.parent / "shared" / "data"


def _source(
    tmp: Path,
    encoding: str = "pd",
    layout: str = "rgba",
    base=None,
    size: int = 128,
    overlap: bool = False,
) -> Path:
    a = demo_asset(size, encoding=encoding)
    a = replace(a, mesh=prepare_mesh(a.mesh))
    if overlap:  # two regions overlap: every policy gives another result
        masks = a.masks.copy()
        masks[2] = np.maximum(masks[2], masks[6])
        a = replace(a, masks=masks)
    if base is not None:  # the same wrinkles over another base
        relief = model.normal_to_pd(a.states) - model.normal_to_pd(a.base)[None]
        states = model.pd_to_normal(model.normal_to_pd(base)[None] + relief)
        a = replace(a, base=base, states=states.astype(np.float32))
    pkg = package_from_asset(a, PackOptions(mask_layout=layout), [expression_cycle(a)])
    folder = tmp / f"src_{encoding}_{layout}"
    write_gltf(pkg, folder, "demo")
    return folder


def _smooth_base(size: int = 128) -> np.ndarray:
    """A gently curved base normal map (BC5 keeps it well inside the budget)."""
    y, x = np.mgrid[0:size, 0:size] / size
    height = 0.5 * np.sin(2 * np.pi * x) * np.cos(3 * np.pi * y)
    return model.height_to_normal(height, 1.0 / size * 40.0)


@pytest.fixture(scope="module")
def exports(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("export")
    src = _source(tmp, base=_smooth_base())
    out = {}
    for e in ENGINES:
        files, notes = export(src, tmp / e, e)
        out[e] = (tmp / e, files, notes)
    return src, out


def _export_all(src: Path, tmp: Path) -> dict[str, tuple[Path, dict[str, bytes], list[str]]]:
    out = {}
    for e in ENGINES:
        files, notes = export(src, tmp / e, e)
        out[e] = (tmp / e, files, notes)
    return out


@pytest.fixture(scope="module")
def avatar_exports(tmp_path_factory):
    """The generated multi-mesh avatar converted (its Skin material wrinkled) and exported."""
    tmp = tmp_path_factory.mktemp("avatar_export")
    manifest = avatar.avatar_source_dir()
    res = convert(manifest, tmp / "src", ConvertOptions(render=False))
    assert res.exit_code == 0
    return tmp / "src", _export_all(tmp / "src", tmp), manifest.parent / "avatar.glb"


@pytest.fixture(scope="module")
def robot_exports(robot_converted, tmp_path_factory):
    """RobotExpressive (CC0, 14 meshes, 2 skins, 14 animations) converted with the manifest's
    ``material = "Main"`` on ``meshes = ["Head"]`` (cloned as 'Main (wrinkled)'; the shared
    conftest fixture), exported."""
    src = robot_converted[0]
    return src, _export_all(src, tmp_path_factory.mktemp("robot_export")), ROBOT


@pytest.fixture(params=["demo", "avatar"])
def rendered_exports(request, exports, avatar_exports):
    return (exports if request.param == "demo" else avatar_exports)[:2]


#: Each file parsed once per module (pygltflib takes ~1 s on RobotExpressive; read only).
_gltf = functools.lru_cache(maxsize=None)(ref.load)
_input = functools.lru_cache(maxsize=None)(load_input)


def _validates(path: Path) -> None:
    if khronos.available():
        report = khronos.validate_gltf(path)
        assert report["issues"]["numErrors"] == 0, report["issues"]["messages"][:5]


@pytest.mark.parametrize("engine", ENGINES)
def test_export_is_complete_flat_and_true(exports, engine):
    src, out = exports
    folder, files, notes = out[engine]
    _complete_flat_and_true(src, folder, files, notes, engine)
    doc = json.loads(files["demo.gltf"])
    assert len(doc.get("images", [])) == (0 if engine == "unreal" else 1)


#: Import-settings sidecars beside a texture: Unity ``.meta``, Godot ``.import``.
_SIDECARS = (".meta", ".import")


def _complete_flat_and_true(src, folder, files, notes, engine) -> None:
    # flat: the folder itself plus textures/ and curves/ only
    assert {p.split("/")[0] for p in files if "/" in p} <= {"textures", "curves"}
    assert all(p.count("/") <= 1 for p in files)
    on_disk = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file())
    assert on_disk == sorted(files)
    # no texture twice (import-settings sidecars aside: two arrays of as many layers share one)
    images = [
        b for p, b in files.items() if p.startswith("textures/") and not p.endswith(_SIDECARS)
    ]
    digests = [hashlib.sha256(b).hexdigest() for b in images]
    assert len(digests) == len(set(digests))
    setup = json.loads(files["wrinkle_setup.json"])
    # every file the setup names exists
    named = [setup["mesh"], setup["base"]["file"], *setup["curves"]]
    named += [s["file"] for s in setup["states"]]
    named += setup["masks"].get("files", []) + [setup["masks"].get("file")] * (
        "file" in setup["masks"]
    )
    assert all(n in files for n in named), [n for n in named if n not in files]
    # notes are true: nothing "as requested", DirectX only for Unreal
    text = " ".join(notes)
    assert "as requested" not in text
    assert ("DirectX" in text) == (engine == "unreal")
    readme = files["README.md"].decode()
    assert "## Import into" in readme and "wrinkle_setup.json" in readme
    tested = readme.split("## How this export is tested\n\n")[1].split("\n\n")[0]
    if engine == "blender":  # run here (tests/test_blender.py)
        assert "Tested with Blender 5.0" in tested
    else:  # said plainly: the engine itself never ran this export
        assert "does not run where wrinklepipe is tested" in tested and "numpy model" in tested
    assert all(f"`{p}`" in readme for p in files if p != "README.md")
    # curves named the engine's way, values those of the glTF
    curve = json.loads(files[next(c for c in setup["curves"] if c.endswith(".json"))])
    assert curve["regions"] == [r["parameter"] for r in setup["regions"]]
    src_pkg_curve = _input(src).weight_curves
    first = next(iter(src_pkg_curve.values()))
    np.testing.assert_allclose(np.reshape(curve["values"], first.shape), first, atol=1e-6)
    # the mesh: a glTF without the wrinkle extension, valid for the Khronos validator
    doc = json.loads(files[setup["mesh"]])
    assert "WRINKLEPIPE_wrinkle_maps" not in json.dumps(doc)
    assert "KHR_animation_pointer" not in json.dumps(doc)
    _validates(folder / setup["mesh"])


def test_export_is_byte_identical_on_a_rerun(exports, tmp_path):
    src, out = exports
    for e in ("unreal", "godot"):
        files, _ = export(src, tmp_path / e, e)
        assert files == out[e][1]


def test_unreal_dds_have_mip_chains_in_directx(exports):
    src, out = exports
    folder, files, _ = out["unreal"]
    pkg = load_input(src)
    base_png = next(t for t in pkg.textures if t.role == "base")
    dds = read_dds(files["textures/base_normal.dds"])
    assert dds.format == "bc5" and len(dds.levels) == 8  # 128 -> 1: 8 levels
    bgra = np.frombuffer(texture2ddecoder.decode_bc5(dds.levels[0], 128, 128), np.uint8)
    rg = bgra.reshape(128, 128, 4)[..., [2, 1]]
    n_dx = codec.decode("full", rg, "rg", version=1)
    src_px = np.frombuffer(base_png.data, np.uint8).reshape(128, 128, -1)
    n_gl = codec.decode("full", src_px[..., :3], "rgb", version=1)
    err = angle_deg(n_dx * np.array([1, -1, 1], np.float32), n_gl)
    assert err.mean() < 1.0 and np.percentile(err, 99) < 3.0  # BC5 within its budget
    assert angle_deg(n_dx, n_gl).mean() > 5.0  # and really flipped


def _exported_texture(name, role, path, data, state="", mapping=1):
    """An exported base or state map as the render pass uploads it (DDS: level 0 as is)."""
    if path.endswith(".dds"):
        d = read_dds(data)
        return Texture(
            name,
            role,
            d.format,
            d.width,
            d.height,
            bytes(d.levels[0]),
            state=state,
            convention="directx",
            layout="rg",
            mapping=mapping,
        )
    px = png_pixels(data)
    fmt = {2: "rg8", 3: "rgb8", 4: "rgba8"}[px.shape[-1]]
    return Texture(
        name,
        role,
        fmt,
        px.shape[1],
        px.shape[0],
        px.tobytes(),
        state=state,
        convention="directx",
        mapping=mapping,
    )


def _expressions(inp) -> list[str]:
    """Up to three of the asset's expressions (the demo's table, the avatar's two)."""
    return list(inp.asset.expressions)[:3]


@pytest.mark.gpu
def test_unreal_export_renders_the_model(rendered_exports):
    """The exported WP_Wrinkle.hlsl on the exported BC5 texels (glslang -> spirv-cross ->
    moderngl) equals numpy on the same texels (decoded by texture2ddecoder), y negated: for the
    demo and for the avatar's wrinkled material."""
    if h.missing_tools():
        pytest.skip(f"{h.missing_tools()} not installed")
    import test_engine_shaders as ts

    src, out = rendered_exports
    folder, files, _ = out["unreal"]
    setup_doc = json.loads(files["wrinkle_setup.json"])
    ref_in = _input(src)
    mapping = setup_doc["mapping"]
    base = setup_doc["base"]["file"]
    textures = [_exported_texture("base", "base", base, files[base])]
    for s in setup_doc["states"]:
        textures.append(
            _exported_texture(s["name"], "state", s["file"], files[s["file"]], s["name"], mapping)
        )
    assert {t.fmt for t in textures} == {"bc5"}  # the smooth base and its states ship as BC5
    for i, f in enumerate(setup_doc["masks"]["files"]):
        px = png_pixels(files[f])
        textures.append(
            Texture(f"mask{i}", "mask", "rgba8", px.shape[1], px.shape[0], px.tobytes())
        )
    table = [
        ChannelEntry(e["region"], f"mask{e['texture']}", "rgba".index(e["channel"]))
        for e in setup_doc["masks"]["table"]
    ]
    inp = replace(ref_in, textures=textures, channel_table=table, has_source=False)
    setup = replace(shader_setup(inp), output="directx")
    code = files["WP_Wrinkle.hlsl"].decode()
    assert code == hlsl.unreal_nodes(setup).wrinkle.code  # what was exported is what renders
    try:
        gpu = h.UVRenderer(96)
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no OpenGL: {exc}")
    try:
        images = ts._render_unreal(gpu, inp, setup, [None, *_expressions(inp)])
        s = h.samples(inp, gpu.uvs())
        flip = np.array([1.0, -1.0, 1.0], np.float32)
        for expr, img in images.items():
            st = h.compare(img, h.blend(inp, s, expr) * flip)
            assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (expr, st)
        moved = max(h.compare(img, h.blend(inp, s, None) * flip)["p99"] for img in images.values())
        assert moved > 2.0  # the expressions really wrinkle
    finally:
        gpu.release()


@pytest.mark.gpu
@pytest.mark.parametrize("engine", ["unity", "godot"])
def test_unity_and_godot_exports_render_the_model(rendered_exports, engine):
    """The exported shader file on the exported strips (sliced back into array layers) and the
    glTF's base map (read as x, y with z rebuilt, as these engines import normal maps) equals
    numpy on the same texels: for the demo and for the avatar's wrinkled material."""
    if h.missing_tools():
        pytest.skip(f"{h.missing_tools()} not installed")
    import test_engine_shaders as ts

    src, out = rendered_exports
    folder, files, _ = out[engine]
    doc = json.loads(files["wrinkle_setup.json"])
    ref_in = _input(src)

    def texture(name, role, px, **kw):
        fmt = {3: "rgb8", 4: "rgba8"}[px.shape[-1]]
        return Texture(name, role, fmt, px.shape[1], px.shape[0], px.tobytes(), **kw)

    textures = [texture("base", "base", png_pixels(files[doc["base"]["file"]]), layout="rg2")]
    states = png_pixels(files[doc["statesArray"]["file"]])
    n_states = doc["statesArray"]["layers"]
    for k, layer in enumerate(np.split(states, n_states, axis=0)):
        name = doc["states"][k]["name"]
        textures.append(texture(name, "state", layer, state=name, mapping=doc["mapping"]))
    masks = png_pixels(files[doc["masks"]["file"]])
    for i, layer in enumerate(np.split(masks, doc["masks"]["layers"], axis=0)):
        textures.append(texture(f"mask_{i}", "mask", layer))
    inp = replace(ref_in, textures=textures, has_source=False)
    setup = shader_setup(inp)
    assert setup.base_layout == "rg" and doc["shader"]["slots"] == setup.slots()
    try:
        gpu = h.UVRenderer(96)
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no OpenGL: {exc}")
    try:
        samplers_arrays = (
            gpu.upload([textures[0]], array=False),
            gpu.upload(textures[1 : 1 + n_states], array=True),
            gpu.upload(textures[1 + n_states :], array=True),
        )
        if engine == "unity":
            text = files["WrinkleMaps.hlsl"].decode()
            glsl = h.hlsl_to_glsl(ts.UNITY_PRELUDE + text + ts.UNITY_MAIN)
            names = [
                f"SPIRV_Cross_Combined_{n}sampler_BaseMap" for n in ("BaseMap", "States", "Masks")
            ]
        else:
            glsl = ts.godot_core_as_glsl(files["wrinkle.gdshader"].decode(), setup)
            names = ["wp_base", "wp_states", "wp_masks"]
        prog = gpu.program(glsl)
        samplers = {n: (t, i > 0) for i, (n, t) in enumerate(zip(names, samplers_arrays))}
        s = h.samples(inp, gpu.uvs())
        moved = 0.0
        for expr in [None, *_expressions(inp)]:
            wv = setup.weight_vectors(h.region_weights(inp, expr))
            used = setup.used_vectors()
            if engine == "unity":
                block = next(b for b in ("_Globals", "_Global", "type_Globals") if b in glsl)
                data = np.concatenate([wv.ravel(), used.ravel()]).astype(np.float32)
                img = gpu.draw(prog, samplers, blocks={block: data.tobytes()})
            else:
                img = gpu.draw(
                    prog, samplers, uniforms={"wp_w": wv.tobytes(), "wp_used": used.tobytes()}
                )
            st = h.compare(img, h.blend(inp, s, expr))
            assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (engine, expr, st)
            moved = max(moved, h.compare(img, h.blend(inp, s, None))["p99"])
        assert moved > 2.0  # the expressions really wrinkle
    finally:
        gpu.release()


def test_unreal_ships_png_with_a_true_note_when_bc5_is_over_budget(tmp_path):
    rng = np.random.default_rng(3)
    noise = model.normalize(
        np.concatenate([rng.normal(0, 0.6, (128, 128, 2)), np.ones((128, 128, 1))], -1)
    )
    src = _source(tmp_path, base=noise.astype(np.float32))
    files, notes = export(src, tmp_path / "ue", "unreal")
    assert "textures/base_normal.png" in files and "textures/base_normal.dds" not in files
    note = next(n for n in notes if n.startswith("base:"))
    assert "over the error budget" in note and "shipped as PNG" in note


def test_array_masks_become_rgba_for_unreal_and_strips_elsewhere(tmp_path):
    src = _source(tmp_path, layout="array")
    files, notes = export(src, tmp_path / "ue", "unreal")
    setup = json.loads(files["wrinkle_setup.json"])
    assert len(setup["masks"]["files"]) == 2 and setup["masks"]["layout"] == "rgba"
    assert any("repacked" in n for n in notes)
    files, _ = export(src, tmp_path / "godot", "godot")
    setup = json.loads(files["wrinkle_setup.json"])
    strip = png_pixels(files["textures/wrinkle_masks.png"])
    assert strip.shape[:2] == (8 * 128, 128) and setup["masks"]["layers"] == 8
    assert setup["shader"]["gather"] == "layers"


def test_an_export_an_engine_cannot_express_is_refused(tmp_path):
    a = demo_asset(64)
    a = replace(a, mesh=prepare_mesh(a.mesh))
    a = replace(
        a,
        states=np.concatenate([a.states] * 9)[:17],
        state_names=tuple(f"s{k}" for k in range(17)),
        regions=tuple(replace(r, states=()) for r in a.regions),
    )
    folder = tmp_path / "big"
    write_gltf(package_from_asset(a), folder, "big")
    for engine in ENGINES:
        with pytest.raises(InputError) as exc:
            export(folder, tmp_path / engine, engine)
        msg = str(exc.value)
        assert f"cannot export for {engine}" in msg and "17 wrinkle states" in msg
        assert not (tmp_path / engine).exists()


@pytest.fixture(scope="module")
def cesium_exports(tmp_path_factory):
    """CesiumMan (../shared/data, a skinned Khronos sample) with the fidelity fixture's
    wrinkles, written and exported for every engine (None when ../shared/data is absent)."""
    from wrinklepipe.demo import face_fixture as ff

    mesh = DATA / ff.MESH_RELPATH
    if not mesh.is_file():
        return None
    tmp = tmp_path_factory.mktemp("cesium_export")
    a = ff.build_fixture(mesh, 256).asset()
    a = replace(a, mesh=prepare_mesh(a.mesh))
    pkg = package_from_asset(a, PackOptions(), [expression_cycle(a)])
    write_gltf(pkg, tmp / "cesium", "cesium_face")
    return tmp, _export_all(tmp / "cesium", tmp)


@pytest.mark.shared
def test_a_real_skinned_character_exports_for_every_engine(cesium_exports):
    """CesiumMan (../shared/data, a skinned Khronos sample) with the fidelity fixture's
    wrinkles: every engine's folder is complete, the skin survives, the glTF validates
    (tests/test_blender.py runs Blender's script on it)."""
    if cesium_exports is None:
        pytest.skip("../shared/data is absent")
    tmp, out = cesium_exports
    for engine in ENGINES:
        folder, files, notes = out[engine]
        setup = json.loads(files["wrinkle_setup.json"])
        doc = json.loads(files[setup["mesh"]])
        assert doc.get("skins"), engine  # the skeleton survives
        assert len(setup["regions"]) == 8 and setup["shader"]["slots"]
        _validates(folder / setup["mesh"])


def _materials_resolved(path: Path) -> list[dict]:
    """Each material with every texture reference replaced by the SHA-256 of its image's bytes
    (pygltflib reads the file): materials compared whatever the texture numbering."""
    g = _gltf(path)
    j = json.loads(g.to_json())

    def resolve(o):
        if isinstance(o, list):
            return [resolve(v) for v in o]
        if not isinstance(o, dict):
            return o
        out = {}
        for k, v in o.items():
            if k.lower().endswith("texture") and isinstance(v, dict) and "index" in v:
                img = ref.image_bytes(g, path, j["textures"][v["index"]]["source"])
                v = {**v, "index": hashlib.sha256(img).hexdigest()}
            out[k] = resolve(v)
        return out

    return [resolve(m) for m in j.get("materials", [])]


@pytest.mark.parametrize("engine", ENGINES)
@pytest.mark.parametrize("character", ["avatar", "robot"])
def test_a_whole_character_exports_whole(request, character, engine):
    """Every part of the converted character is in the engine's glTF (pygltflib + struct: the
    converted document's meshes, nodes, skins, accessors, animations equal), the plain parts'
    materials with their textures byte for byte, the wrinkled one without the extension (and,
    for Unreal, without its base map: that ships as DDS); the folder is complete, flat and
    true; 0 Khronos errors."""
    src, out, source = request.getfixturevalue(f"{character}_exports")
    folder, files, notes = out[engine]
    _complete_flat_and_true(src, folder, files, notes, engine)
    if engine == "unity":  # the import settings beside the textures, on the real character too
        check_unity_sidecars(folder, files, _input(src))
    elif engine == "godot":
        check_godot_sidecars(files)
    elif engine == "unreal":
        check_unreal_clipboard(files)
    setup = json.loads(files["wrinkle_setup.json"])
    wrinkled_name = {"avatar": "Skin", "robot": "Main (wrinkled)"}[character]
    assert setup["materials"] == [wrinkled_name]
    converted = next(src.glob("*.gltf"))
    mesh = folder / setup["mesh"]
    g0, g1 = _gltf(converted), _gltf(mesh)
    j0, j1 = json.loads(g0.to_json()), json.loads(g1.to_json())
    for key in ("scene", "scenes", "nodes", "skins", "meshes"):
        assert j1.get(key) == j0.get(key), key
    for i in range(len(g0.accessors)):  # every accessor's values, by an independent reader
        np.testing.assert_array_equal(ref.accessor(g0, converted, i), ref.accessor(g1, mesh, i))
    # animations: the converted ones minus the weight channels (KHR_animation_pointer)
    names0 = [a["name"] for a in j0["animations"]]
    assert [a["name"] for a in j1["animations"]] == names0
    for a0, a1 in zip(j0["animations"], j1["animations"], strict=True):
        kept = [c for c in a0["channels"] if c["target"]["path"] != "pointer"]
        assert [c["target"] for c in a1["channels"]] == [c["target"] for c in kept]
    # materials: the plain parts' as converted (textures byte for byte), the wrinkled one bare
    m0, m1 = _materials_resolved(converted), _materials_resolved(mesh)
    assert [m["name"] for m in m1] == [m["name"] for m in m0]
    for a, b in zip(m0, m1, strict=True):
        if EXTENSION not in (a.get("extensions") or {}):
            assert b == a, a["name"]
            continue
        a = {**a, "extensions": {k: v for k, v in a["extensions"].items() if k != EXTENSION}}
        a = {k: v for k, v in a.items() if v != {}}
        if engine == "unreal":
            a.pop("normalTexture")
        assert b == a
    # no wrinkle texture in the glTF: its images are the plain parts' (+ the base off Unreal)
    n_plain = {"avatar": 4, "robot": 0}[character]
    assert len(j1.get("images", [])) == n_plain + (engine != "unreal")
    if character == "avatar" and engine != "unreal":  # the converted document, as converted
        added = compare(source, mesh, base_replaced=False)
        assert added.materials == [] and added.animations == ["blendshapes"]
