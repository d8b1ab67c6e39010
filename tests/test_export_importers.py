"""Engine import settings beside the exported textures, read back by independent readers.

Unity: each texture the wrinkle shader samples has a ``.meta`` (parsed by PyYAML) whose
TextureImporter settings are those Unity documents for the job (the base a NormalMap, the strips
Default 2D arrays with one row per layer, sRGB off, mip maps, uncompressed, clamped, trilinear),
a stable GUID and a max size no smaller than the image (read by OpenImageIO). The Custom Function
reads Unity's NormalMap encodings (x in alpha for DXT5nm-style): rendered from a base stored
that way it equals numpy. Godot 4: each has an ``.import`` (parsed by configparser) naming the
importer and type, with only the keys Godot's class reference documents for that importer.
Unreal: ``WP_CustomNodes.t3d`` holds the two Custom nodes as material-editor clipboard text; read
back by a parser written here (Begin/End blocks, Unreal's string escapes), each node's Code is
byte for byte the exported ``.hlsl``, its inputs those of ``wrinkle_setup.json``, and the code
taken from the text compiles (glslang -> spirv-cross) and renders equal to numpy.
The demo at 64^2, one export per engine per module.
"""

from __future__ import annotations

import configparser
import json
import re
from dataclasses import replace

import numpy as np
import OpenImageIO as oiio
import pytest
import shader_harness as h
import yaml
from test_export_engines import _exported_texture, _expressions, _input, _source

from wrinklepipe.export.job import export
from wrinklepipe.io.package import png_pixels
from wrinklepipe.shading import hlsl
from wrinklepipe.validate.inputs import ChannelEntry, Texture
from wrinklepipe.validate.render import shader_setup

#: ResourceImporterTexture / ResourceImporterLayeredTexture properties (Godot 4 class reference,
#: docs.godotengine.org/en/stable/classes/class_resourceimportertexture.html and
#: class_resourceimporterlayeredtexture.html).
GODOT_TEXTURE_KEYS = {
    "compress/channel_pack",
    "compress/hdr_compression",
    "compress/high_quality",
    "compress/lossy_quality",
    "compress/mode",
    "compress/normal_map",
    "compress/rdo_quality_loss",
    "compress/uastc_level",
    "detect_3d/compress_to",
    "editor/convert_colors_with_editor_theme",
    "editor/scale_with_editor_scale",
    "mipmaps/generate",
    "mipmaps/limit",
    "process/fix_alpha_border",
    "process/hdr_as_srgb",
    "process/hdr_clamp_exposure",
    "process/normal_map_invert_y",
    "process/premult_alpha",
    "process/size_limit",
    "roughness/mode",
    "roughness/src_normal",
    "svg/scale",
}
GODOT_LAYERED_KEYS = {
    "compress/channel_pack",
    "compress/hdr_compression",
    "compress/high_quality",
    "compress/lossy_quality",
    "compress/mode",
    "compress/rdo_quality_loss",
    "compress/uastc_level",
    "mipmaps/generate",
    "mipmaps/limit",
    "slices/arrangement",
    "slices/horizontal",
    "slices/vertical",
}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("importers")
    src = _source(tmp, size=64)
    return src, {e: (tmp / e, *export(src, tmp / e, e)) for e in ("unity", "godot", "unreal")}


def _sampled(files: dict[str, bytes]) -> list[tuple[str, int | None]]:
    """(file, array layers or None) of what the wrinkle shader samples, from the setup."""
    doc = json.loads(files["wrinkle_setup.json"])
    return [
        (doc["base"]["file"], None),
        (doc["statesArray"]["file"], doc["statesArray"]["layers"]),
        (doc["masks"]["file"], doc["masks"]["layers"]),
    ]


def _size(path) -> tuple[int, int]:
    inp = oiio.ImageInput.open(str(path))
    try:
        spec = inp.spec()
        return spec.width, spec.height
    finally:
        inp.close()


def test_unity_textures_carry_their_import_settings(exported, tmp_path):
    src, out = exported
    folder, files, _ = out["unity"]
    pkg_in = _input(src)
    state_h = pkg_in.state_textures()[0].height
    guids = set()
    for rel, layers in _sampled(files):
        meta = yaml.safe_load(files[rel + ".meta"].decode())
        assert meta["fileFormatVersion"] == 2
        assert re.fullmatch(r"[0-9a-f]{32}", meta["guid"]), meta["guid"]
        guids.add(meta["guid"])
        ti = meta["TextureImporter"]
        w, h_ = _size(folder / rel)
        if layers is None:  # the base: Unity's normal-map import
            assert (ti["textureType"], ti["textureShape"]) == (1, 1)
        else:  # a vertical strip: a Texture2DArray of `layers` rows, one column
            assert (ti["textureType"], ti["textureShape"]) == (0, 4)
            assert (ti["flipbookRows"], ti["flipbookColumns"]) == (layers, 1)
            assert h_ % layers == 0 and h_ // layers == state_h
        mip = ti["mipmaps"]
        assert (mip["enableMipMap"], mip["mipMapMode"], mip["sRGBTexture"]) == (1, 0, 0)
        assert ti["bumpmap"]["flipGreenChannel"] == 0  # the maps are already +Y
        assert ti["bumpmap"]["convertToNormalMap"] == 0
        ts = ti["textureSettings"]
        assert (ts["wrapU"], ts["wrapV"], ts["wrapW"], ts["filterMode"]) == (1, 1, 1, 2)
        assert (ti["alphaUsage"], ti["alphaIsTransparency"]) == (1, 0)  # mask alpha is data
        (platform,) = ti["platformSettings"]
        assert platform["buildTarget"] == "DefaultTexturePlatform"
        assert platform["textureCompression"] == 0  # uncompressed: the texels as exported
        for size in (ti["maxTextureSize"], platform["maxTextureSize"]):
            assert size >= max(w, h_) and size & (size - 1) == 0 and 32 <= size <= 16384
    assert len(guids) == 3
    again, _ = export(src, tmp_path / "again", "unity")
    assert all(again[rel + ".meta"] == files[rel + ".meta"] for rel, _ in _sampled(files))


def test_godot_textures_carry_their_import_settings(exported):
    _, out = exported
    _, files, _ = out["godot"]
    for rel, layers in _sampled(files):
        cfg = configparser.ConfigParser(interpolation=None)
        cfg.optionxform = str  # Godot's keys are case-sensitive
        cfg.read_string(files[rel + ".import"].decode())
        params = dict(cfg["params"])
        assert params["compress/mode"] == "0"  # Lossless: the texels as exported
        assert params["mipmaps/generate"] == "true" and params["mipmaps/limit"] == "-1"
        if layers is None:
            assert cfg["remap"]["importer"] == '"texture"'
            assert cfg["remap"]["type"] == '"CompressedTexture2D"'
            assert set(params) <= GODOT_TEXTURE_KEYS, set(params) - GODOT_TEXTURE_KEYS
            assert params["compress/normal_map"] == "1"  # Enable
            assert params["process/normal_map_invert_y"] == "false"  # OpenGL +Y
            assert params["roughness/mode"] == "1"  # Disabled
            assert params["detect_3d/compress_to"] == "0"  # stays lossless when used in 3D
        else:
            assert cfg["remap"]["importer"] == '"2d_array_texture"'
            assert cfg["remap"]["type"] == '"CompressedTexture2DArray"'
            assert set(params) <= GODOT_LAYERED_KEYS, set(params) - GODOT_LAYERED_KEYS
            assert (params["slices/horizontal"], params["slices/vertical"]) == ("1", str(layers))


@pytest.mark.gpu
def test_unity_reads_its_dxt5nm_normal_map_encoding(exported):
    """The exported WrinkleMaps.hlsl with the base stored as Unity stores a NormalMap on
    DXT5nm-style platforms ((1, y, y, x): x in alpha) equals numpy on the exported texels."""
    if h.missing_tools():
        pytest.skip(f"{h.missing_tools()} not installed")
    import test_engine_shaders as ts

    src, out = exported
    _, files, _ = out["unity"]
    doc = json.loads(files["wrinkle_setup.json"])

    def texture(name, role, px, **kw):
        fmt = {3: "rgb8", 4: "rgba8"}[px.shape[-1]]
        return Texture(name, role, fmt, px.shape[1], px.shape[0], px.tobytes(), **kw)

    base = png_pixels(files[doc["base"]["file"]])
    textures = [texture("base", "base", base, layout="rg2")]
    n_states = doc["statesArray"]["layers"]
    states = np.split(png_pixels(files[doc["statesArray"]["file"]]), n_states, axis=0)
    for k, layer in enumerate(states):
        name = doc["states"][k]["name"]
        textures.append(texture(name, "state", layer, state=name, mapping=doc["mapping"]))
    masks = np.split(png_pixels(files[doc["masks"]["file"]]), doc["masks"]["layers"], axis=0)
    textures += [texture(f"mask_{i}", "mask", m) for i, m in enumerate(masks)]
    inp = replace(_input(src), textures=textures, has_source=False)
    setup = shader_setup(inp)
    x, y = base[..., 0], base[..., 1]
    dxt5nm = np.stack([np.full_like(x, 255), y, y, x], axis=-1)
    try:
        gpu = h.UVRenderer(64)
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no OpenGL: {exc}")
    try:
        prefix = "SPIRV_Cross_Combined_"
        samplers = {
            f"{prefix}BaseMapsampler_BaseMap": (
                gpu.upload([texture("base", "base", dxt5nm)], array=False),
                False,
            ),
            f"{prefix}Statessampler_BaseMap": (gpu.upload(textures[1 : 1 + n_states], True), True),
            f"{prefix}Maskssampler_BaseMap": (gpu.upload(textures[1 + n_states :], True), True),
        }
        glsl = h.hlsl_to_glsl(ts.UNITY_PRELUDE + files["WrinkleMaps.hlsl"].decode() + ts.UNITY_MAIN)
        prog = gpu.program(glsl)
        block = next(b for b in ("_Globals", "_Global", "type_Globals") if b in glsl)
        s = h.samples(inp, gpu.uvs())
        for expr in [None, *_expressions(inp)]:
            wv = setup.weight_vectors(h.region_weights(inp, expr))
            data = np.concatenate([wv.ravel(), setup.used_vectors().ravel()]).astype(np.float32)
            img = gpu.draw(prog, samplers, blocks={block: data.tobytes()})
            st = h.compare(img, h.blend(inp, s, expr))
            assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (expr, st)
    finally:
        gpu.release()


# ------------------------------------------------------------------------------------------------
# Unreal clipboard text

_UNESCAPE = {"n": "\n", "r": "\r", "t": "\t"}


def _unquote(value: str) -> str:
    """An Unreal exported string (``"..."`` with backslash escapes) -> its text. The string ends
    at the first quote not escaped (as Unreal's reader ends it): it must be the last character."""
    quoted = re.fullmatch(r'"((?:[^"\\\n]|\\.)*)"', value)
    assert quoted, value[:60]
    return re.sub(r"\\(.)", lambda m: _UNESCAPE.get(m.group(1), m.group(1)), quoted[1])


def _t3d_objects(text: str) -> list[dict]:
    """Top-level ``Begin Object`` blocks: their class, name and the properties of the inner
    object (``key=value`` lines; ``Inputs(i)`` collected in order), nesting checked."""
    objects, depth, current = [], 0, None
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("Begin Object"):
            head = dict(re.findall(r'(\w+)=("[^"]*"|\S+)', stripped))
            if depth == 0:
                current = {"class": head["Class"], "name": head["Name"].strip('"'), "props": {}}
                current["inputs"] = []
            depth += 1
        elif stripped == "End Object":
            depth -= 1
            assert depth >= 0
            if depth == 0:
                objects.append(current)
        elif depth == 2 and "=" in stripped:
            key, value = stripped.split("=", 1)
            if key.startswith("Inputs("):
                assert key == f"Inputs({len(current['inputs'])})"
                current["inputs"].append(_unquote(re.fullmatch(r"\(InputName=(.*)\)", value)[1]))
            else:
                current["props"][key] = value
        elif depth == 1 and "=" in stripped:
            key, value = stripped.split("=", 1)
            current[key] = value
    assert depth == 0
    return objects


def _t3d_nodes(files: dict[str, bytes]) -> list[dict]:
    doc = json.loads(files["wrinkle_setup.json"])
    return _t3d_objects(files[doc["unreal"]["clipboard"]].decode())


def test_unreal_clipboard_text_holds_the_two_custom_nodes(exported):
    _, out = exported
    _, files, _ = out["unreal"]
    doc = json.loads(files["wrinkle_setup.json"])
    assert doc["unreal"]["clipboard"] in files and f"`{doc['unreal']['clipboard']}`" in (
        files["README.md"].decode()
    )
    objects = _t3d_nodes(files)
    assert len(objects) == len(doc["unreal"]["nodes"]) == 2
    for obj, node in zip(objects, doc["unreal"]["nodes"], strict=True):
        assert obj["class"] == "/Script/UnrealEd.MaterialGraphNode"
        props = obj["props"]
        assert _unquote(props["Code"]) == files[node["code"]].decode()  # byte for byte
        assert _unquote(props["Description"]) == node["description"]
        assert props["OutputType"] == node["output"].replace(" ", "_")
        assert props["OutputType"] in ("CMOT_Float1", "CMOT_Float3")
        assert obj["inputs"] == [i["name"] for i in node["inputs"]]
        inner = re.fullmatch(
            r"\"/Script/Engine.MaterialExpressionCustom'(\w+)'\"", obj["MaterialExpression"]
        )
        assert inner, obj["MaterialExpression"]
    assert len({o["name"] for o in objects}) == 2
    assert _unquote(objects[0]["props"]["Description"]) == "WP_Decode"
    assert objects[1]["inputs"][-1] == "Decode"


@pytest.mark.gpu
def test_unreal_clipboard_code_renders_the_model(exported):
    """The Code taken out of the clipboard text, wrapped as Unreal wraps Custom nodes, through
    glslang -> spirv-cross -> moderngl on the exported texels equals numpy with y negated."""
    if h.missing_tools():
        pytest.skip(f"{h.missing_tools()} not installed")
    import test_engine_shaders as ts

    src, out = exported
    _, files, _ = out["unreal"]
    doc = json.loads(files["wrinkle_setup.json"])
    ref_in = _input(src)
    base = doc["base"]["file"]
    textures = [_exported_texture("base", "base", base, files[base])]
    for st in doc["states"]:
        textures.append(
            _exported_texture(
                st["name"], "state", st["file"], files[st["file"]], st["name"], doc["mapping"]
            )
        )
    for i, f in enumerate(doc["masks"]["files"]):
        px = png_pixels(files[f])
        textures.append(
            Texture(f"mask{i}", "mask", "rgba8", px.shape[1], px.shape[0], px.tobytes())
        )
    table = [
        ChannelEntry(e["region"], f"mask{e['texture']}", "rgba".index(e["channel"]))
        for e in doc["masks"]["table"]
    ]
    inp = replace(ref_in, textures=textures, channel_table=table, has_source=False)
    setup = replace(shader_setup(inp), output="directx")
    decode, wrinkle = (_unquote(o["props"]["Code"]) for o in _t3d_nodes(files))
    made = hlsl.unreal_nodes(setup)
    nodes = replace(
        made, decode=replace(made.decode, code=decode), wrinkle=replace(made.wrinkle, code=wrinkle)
    )
    try:
        gpu = h.UVRenderer(64)
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"no OpenGL: {exc}")
    try:
        prog = gpu.program(
            h.hlsl_to_glsl(ts.unreal_material(nodes, setup.n_states, setup.n_layers))
        )
        names = ["Base", *(f"State{k}" for k in range(setup.n_states))]
        names += [f"Mask{k}" for k in range(setup.n_layers)]
        samplers = {
            f"SPIRV_Cross_Combined{n}{n}Sampler": (gpu.upload([t], array=False), False)
            for n, t in zip(
                names, [textures[0], *inp.state_textures(), *h.mask_layers(inp)], strict=True
            )
        }
        s = h.samples(inp, gpu.uvs())
        flip = np.array([1.0, -1.0, 1.0], np.float32)
        for expr in [None, *_expressions(inp)]:
            w = h.region_weights(inp, expr)
            pad = np.zeros(((len(w) + 3) // 4) * 4, np.float32)
            pad[: len(w)] = w
            img = gpu.draw(prog, samplers, blocks={"WPHarness": pad.tobytes()})
            st = h.compare(img, h.blend(inp, s, expr) * flip)
            assert st["mean"] <= 0.5 and st["p99"] <= 2.0, (expr, st)
    finally:
        gpu.release()
