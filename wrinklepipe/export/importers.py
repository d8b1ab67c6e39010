"""Import-settings sidecars an engine reads beside a texture, and Unreal's clipboard text.

Text only (no I/O): :mod:`wrinklepipe.export.files` puts them in the export.

- **Unity** ``.meta`` (:func:`unity_texture_meta`): the TextureImporter block Unity writes itself
  (``fileFormatVersion: 2``, ``serializedVersion: 13`` as Unity 2022.3 / 6 write it; an older
  editor upgrades it on import). The base normal map is ``textureType: 1`` (NormalMap: Unity
  stores it in its own normal-map encoding, which the wrinkle shader reads like Unity's
  ``UnpackNormal``); the state and mask strips are ``textureType: 0`` (Default) with sRGB off,
  ``textureShape: 4`` (Texture2DArray) and ``flipbookRows`` = layers, one column (Unity cuts
  cells left to right, top to bottom: layer 0 is the top of the strip). All: mip maps on with
  the box filter (``mipMapMode: 0``), trilinear filtering, clamped wrap, uncompressed
  (``textureCompression: 0``: the texels the wrinkle tests render), ``maxTextureSize`` no smaller
  than the image. The GUID is derived from the asset name and the file's path
  (:func:`unity_guid`): a rerun writes the same bytes, and a re-export of the asset with new
  texels keeps the GUIDs the project's materials reference.
- **Godot 4** ``.import`` (:func:`godot_normal_map_import`, :func:`godot_array_import`): the
  ``[remap]`` importer, type and a ``uid`` derived from the asset name and the path
  (:func:`godot_uid`; Godot's import keeps the uid it finds there, so a re-export keeps the
  references), and the ``[params]`` Godot's importers read; Godot adds ``path`` and ``[deps]``
  on the first import. Lossless (``compress/mode=0``), mip
  maps generated, ``detect_3d/compress_to=0`` (use in 3D does not switch the texture to VRAM
  compression); the base is ``compress/normal_map=1`` (a normal map: mip maps renormalised,
  x and y read, z rebuilt), ``roughness/mode=1`` (no roughness processing), OpenGL green
  (``process/normal_map_invert_y=false``); the strips are ``2d_array_texture`` with
  ``slices/vertical`` = layers.
- **Unreal** clipboard text (:func:`unreal_t3d`): the two Custom nodes as the material editor
  copies them (``Begin Object Class=/Script/UnrealEd.MaterialGraphNode`` holding a
  ``/Script/Engine.MaterialExpressionCustom`` with ``Code``, ``OutputType``, ``Description`` and
  ``Inputs``); strings escaped as Unreal's ``FString::ReplaceCharWithEscapedChar`` does
  (``\\\\ \\n \\r \\t \\' \\"``). Pasting creates the nodes unconnected.
"""

from __future__ import annotations

import hashlib

from wrinklepipe.shading.hlsl import CustomNode

#: Unity's largest texture import size (TextureImporter.maxTextureSize).
UNITY_MAX_TEXTURE_SIZE = 16384


def unity_guid(asset: str, rel: str) -> str:
    """A Unity asset GUID (32 hex digits) for the file ``rel`` of ``asset``'s export: the same on
    every export of that asset, so materials that reference the textures survive a re-export
    with new texels."""
    return hashlib.md5(f"wrinklepipe:unity:{asset}:{rel}".encode()).hexdigest()


def unity_max_size(width: int, height: int) -> int:
    """The smallest of Unity's import sizes (powers of two 32..16384) holding the image."""
    side = max(width, height, 32)
    return min(1 << (side - 1).bit_length(), UNITY_MAX_TEXTURE_SIZE)


def unity_texture_meta(
    guid: str, max_size: int, layers: int | None = None, srgb: bool = False
) -> str:
    """A texture's ``.meta``: the base normal map (``layers`` None: a 2D NormalMap) or a data
    strip imported as a 2D array of ``layers`` cells stacked vertically (Default, sRGB off;
    ``srgb``: the colour maps' strip, sRGB on)."""
    texture_type, shape, rows = (1, 1, 1) if layers is None else (0, 4, int(layers))
    return f"""\
fileFormatVersion: 2
guid: {guid}
TextureImporter:
  internalIDToNameTable: []
  externalObjects: {{}}
  serializedVersion: 13
  mipmaps:
    mipMapMode: 0
    enableMipMap: 1
    sRGBTexture: {int(srgb)}
    linearTexture: 0
    fadeOut: 0
    borderMipMap: 0
    mipMapsPreserveCoverage: 0
    alphaTestReferenceValue: 0.5
    mipMapFadeDistanceStart: 1
    mipMapFadeDistanceEnd: 3
  bumpmap:
    convertToNormalMap: 0
    externalNormalMap: 0
    heightScale: 0.25
    normalMapFilter: 0
    flipGreenChannel: 0
  isReadable: 0
  streamingMipmaps: 0
  streamingMipmapsPriority: 0
  vTOnly: 0
  ignoreMipmapLimit: 0
  grayScaleToAlpha: 0
  generateCubemap: 6
  cubemapConvolution: 0
  seamlessCubemap: 0
  textureFormat: 1
  maxTextureSize: {max_size}
  textureSettings:
    serializedVersion: 2
    filterMode: 2
    aniso: 1
    mipBias: 0
    wrapU: 1
    wrapV: 1
    wrapW: 1
  nPOTScale: 0
  lightmap: 0
  compressionQuality: 100
  spriteMode: 0
  spriteExtrude: 1
  spriteMeshType: 1
  alignment: 0
  spritePivot: {{x: 0.5, y: 0.5}}
  spritePixelsToUnits: 100
  spriteBorder: {{x: 0, y: 0, z: 0, w: 0}}
  spriteGenerateFallbackPhysicsShape: 1
  alphaUsage: 1
  alphaIsTransparency: 0
  spriteTessellationDetail: -1
  textureType: {texture_type}
  textureShape: {shape}
  singleChannelComponent: 0
  flipbookRows: {rows}
  flipbookColumns: 1
  maxTextureSizeSet: 0
  compressionQualitySet: 0
  textureFormatSet: 0
  ignorePngGamma: 1
  applyGammaDecoding: 0
  swizzle: 50462976
  cookieLightType: 0
  platformSettings:
  - serializedVersion: 4
    buildTarget: DefaultTexturePlatform
    maxTextureSize: {max_size}
    resizeAlgorithm: 0
    textureFormat: -1
    textureCompression: 0
    compressionQuality: 100
    crunchedCompression: 0
    allowsAlphaSplitting: 0
    overridden: 0
    ignorePlatformSupport: 0
    androidETC2FallbackOverride: 0
    forceMaximumCompressionQuality_BC6H_BC7: 0
  spriteSheet:
    serializedVersion: 2
    sprites: []
    outline: []
    physicsShape: []
    bones: []
    spriteID:
    internalID: 0
    vertices: []
    indices:
    edges: []
    weights: []
    secondaryTextures: []
    nameFileIdTable: {{}}
  mipmapLimitGroupName:
  pSDRemoveMatte: 0
  userData: wrinklepipe
  assetBundleName:
  assetBundleVariant:
"""


#: The digits of Godot's resource UID text (``ResourceUID::id_to_text``: 'a'..'y', '0'..'8',
#: base 34, the most significant digit first; Godot keeps this alphabet for compatibility).
_GODOT_UID_DIGITS = "abcdefghijklmnopqrstuvwxy012345678"


def godot_uid(asset: str, rel: str) -> str:
    """A Godot resource UID (``uid://...``, a 63-bit id as ``ResourceUID::id_to_text`` writes it)
    for the file ``rel`` of ``asset``'s export: the same on every export, so scenes and
    materials that reference the texture keep their UID on a re-export."""
    digest = hashlib.md5(f"wrinklepipe:godot:{asset}:{rel}".encode()).digest()
    return godot_uid_text(int.from_bytes(digest[:8], "little") & 0x7FFFFFFFFFFFFFFF)


def godot_uid_text(n: int) -> str:
    """A non-negative 63-bit id as Godot writes it (``uid://`` + base-34 digits)."""
    text = ""
    while True:
        n, c = divmod(n, len(_GODOT_UID_DIGITS))
        text = _GODOT_UID_DIGITS[c] + text
        if n == 0:
            return "uid://" + text


def godot_normal_map_import(uid: str) -> str:
    """The base normal map's ``.import`` (Lossless, a normal map, mip maps)."""
    return f"""\
[remap]

importer="texture"
type="CompressedTexture2D"
uid="{uid}"

[params]

compress/mode=0
compress/high_quality=false
compress/lossy_quality=0.7
compress/hdr_compression=1
compress/normal_map=1
compress/channel_pack=0
mipmaps/generate=true
mipmaps/limit=-1
roughness/mode=1
roughness/src_normal=""
process/fix_alpha_border=false
process/premult_alpha=false
process/normal_map_invert_y=false
process/hdr_as_srgb=false
process/hdr_clamp_exposure=false
process/size_limit=0
detect_3d/compress_to=0
"""


def godot_array_import(layers: int, uid: str) -> str:
    """A vertical strip's ``.import`` as a Texture2DArray of ``layers`` slices (Lossless, mip
    maps)."""
    return f"""\
[remap]

importer="2d_array_texture"
type="CompressedTexture2DArray"
uid="{uid}"

[params]

compress/mode=0
compress/high_quality=false
compress/lossy_quality=0.7
compress/hdr_compression=1
compress/channel_pack=0
mipmaps/generate=true
mipmaps/limit=-1
slices/horizontal=1
slices/vertical={layers}
"""


_ESCAPES = {"\\": "\\\\", "\n": "\\n", "\r": "\\r", "\t": "\\t", "'": "\\'", '"': '\\"'}


def unreal_string(text: str) -> str:
    """``text`` as an Unreal exported string property value (quoted, escaped)."""
    return '"' + "".join(_ESCAPES.get(c, c) for c in text) + '"'


def _node_t3d(node: CustomNode, index: int, x: int) -> str:
    graph = f"MaterialGraphNode_{index}"
    expr = f"MaterialExpressionCustom_{index}"
    lines = [
        f'Begin Object Class=/Script/UnrealEd.MaterialGraphNode Name="{graph}"',
        f'   Begin Object Class=/Script/Engine.MaterialExpressionCustom Name="{expr}"',
        "   End Object",
        f'   Begin Object Name="{expr}"',
        f"      Code={unreal_string(node.code)}",
        f"      OutputType={node.output.replace(' ', '_')}",
        f"      Description={unreal_string(node.description)}",
    ]
    lines += [
        f"      Inputs({i})=(InputName={unreal_string(name)})"
        for i, (name, _) in enumerate(node.inputs)
    ]
    lines += [
        f"      AdditionalOutputs({i})=(OutputName={unreal_string(name)},"
        f"OutputType={kind.replace(' ', '_')})"
        for i, (name, kind) in enumerate(node.additional_outputs)
    ]
    lines += [
        f"      MaterialExpressionEditorX={x}",
        "      MaterialExpressionEditorY=0",
        "   End Object",
        f"   MaterialExpression=\"/Script/Engine.MaterialExpressionCustom'{expr}'\"",
        f"   NodePosX={x}",
        "   NodePosY=0",
        "End Object",
    ]
    return "\n".join(lines) + "\n"


def unreal_t3d(nodes: list[CustomNode]) -> str:
    """The Custom ``nodes`` as material-editor clipboard text, left to right."""
    return "".join(_node_t3d(n, i, -800 + 400 * i) for i, n in enumerate(nodes))
