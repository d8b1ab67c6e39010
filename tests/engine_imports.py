"""Checks of an engine export's import settings and clipboard text, by independent readers.

Unity ``.meta`` read by PyYAML (image sizes by OpenImageIO), Godot ``.import`` by configparser
(keys checked against Godot's documented importer properties), Unreal's clipboard text by the
parser here (Begin/End nesting, Unreal's string escapes). Used by ``test_export_importers`` (the
demo) and ``test_export_engines`` (the whole characters, RobotExpressive from ../shared/data).
"""

from __future__ import annotations

import configparser
import json
import re
from pathlib import Path

import OpenImageIO as oiio
import yaml

from wrinklepipe.validate.inputs import ValidationInput

#: ResourceImporterTexture / ResourceImporterLayeredTexture properties (Godot 4 class reference,
#: docs.godotengine.org/en/stable/classes/class_resourceimportertexture.html and
#: class_resourceimporterlayeredtexture.html; the 2D-array slice counts ``slices/horizontal`` and
#: ``slices/vertical`` from ResourceImporterLayeredTexture::get_import_options, which the
#: reference's page lists only for its cubemap mode as ``slices/arrangement``).
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


def sampled(files: dict[str, bytes]) -> list[tuple[str, int | None]]:
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


def check_unity_sidecars(folder: Path, files: dict[str, bytes], source: ValidationInput) -> None:
    """Every texture the wrinkle shader samples has a ``.meta`` with the settings it needs; the
    strips' rows are as tall as the ``source``'s state and mask maps."""
    guids = set()
    row_h = [None, source.state_textures()[0].height, source.by_role("mask")[0].height]
    for (rel, layers), layer_h in zip(sampled(files), row_h, strict=True):
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
            assert h_ % layers == 0 and h_ // layers == layer_h
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


def godot_uid_id(text: str) -> int:
    """A Godot ``uid://`` text -> its id, as ``ResourceUID::text_to_id`` reads it: base 34,
    'a'..'z' -> 0.., '0'..'9' -> 25.. (Godot's alphabet stops at 'y' and '8')."""
    assert text.startswith("uid://") and len(text) > 6, text
    n = 0
    for ch in text[6:]:
        if "a" <= ch <= "z":
            digit = ord(ch) - ord("a")
        else:
            assert "0" <= ch <= "9", text
            digit = ord(ch) - ord("0") + 25
        assert digit < 34, text  # 'z' and '9' are not digits of Godot's UIDs
        n = n * 34 + digit
    return n


def check_godot_sidecars(files: dict[str, bytes]) -> list[str]:
    """Every texture the wrinkle shader samples has an ``.import`` with the settings it needs;
    returns their UIDs."""
    uids = []
    for rel, layers in sampled(files):
        cfg = configparser.ConfigParser(interpolation=None)
        cfg.optionxform = str  # Godot's keys are case-sensitive
        cfg.read_string(files[rel + ".import"].decode())
        params = dict(cfg["params"])
        uid = cfg["remap"]["uid"].strip('"')
        assert 0 <= godot_uid_id(uid) < 2**63  # a valid ResourceUID id
        uids.append(uid)
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
    assert len(set(uids)) == len(uids)
    return uids


# ------------------------------------------------------------------------------------------------
# Unreal clipboard text

_UNESCAPE = {"n": "\n", "r": "\r", "t": "\t"}


def unquote(value: str) -> str:
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
                current["inputs"].append(unquote(re.fullmatch(r"\(InputName=(.*)\)", value)[1]))
            else:
                current["props"][key] = value
        elif depth == 1 and "=" in stripped:
            key, value = stripped.split("=", 1)
            current[key] = value
    assert depth == 0
    return objects


def t3d_nodes(files: dict[str, bytes]) -> list[dict]:
    doc = json.loads(files["wrinkle_setup.json"])
    return _t3d_objects(files[doc["unreal"]["clipboard"]].decode())


def check_unreal_clipboard(files: dict[str, bytes]) -> list[dict]:
    """The clipboard text holds the two Custom nodes of ``wrinkle_setup.json``, Code byte for
    byte the exported ``.hlsl``; returns the parsed nodes."""
    doc = json.loads(files["wrinkle_setup.json"])
    assert doc["unreal"]["clipboard"] in files and f"`{doc['unreal']['clipboard']}`" in (
        files["README.md"].decode()
    )
    objects = t3d_nodes(files)
    assert len(objects) == len(doc["unreal"]["nodes"]) == 2
    for obj, node in zip(objects, doc["unreal"]["nodes"], strict=True):
        assert obj["class"] == "/Script/UnrealEd.MaterialGraphNode"
        props = obj["props"]
        assert unquote(props["Code"]) == files[node["code"]].decode()  # byte for byte
        assert unquote(props["Description"]) == node["description"]
        assert props["OutputType"] == node["output"].replace(" ", "_")
        assert props["OutputType"] in ("CMOT_Float1", "CMOT_Float3")
        assert obj["inputs"] == [i["name"] for i in node["inputs"]]
        inner = re.fullmatch(
            r"\"/Script/Engine.MaterialExpressionCustom'(\w+)'\"", obj["MaterialExpression"]
        )
        assert inner, obj["MaterialExpression"]
    assert len({o["name"] for o in objects}) == 2
    assert unquote(objects[0]["props"]["Description"]) == "WP_Decode"
    assert objects[1]["inputs"][-1] == "Decode"
    return objects
