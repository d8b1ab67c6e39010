"""Engine presets: what each engine gets and in which convention."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class EnginePreset:
    """How one engine wants a wrinkle asset.

    ``convention``: green of the normal maps it samples and of the normal its material takes.
    ``textures``: ``dds`` (base and states block-compressed with mip chains, masks as RGBA PNG),
    ``arrays`` (states and masks as vertical strips for the engine's Texture2DArray importer),
    ``images`` (one PNG per state and mask). ``gltf_base``: the glTF keeps the base normal map
    (the engine's material samples it from the imported mesh) or not (it ships as the DDS).
    ``curve_names``: how weight curves and parameters are named.
    """

    name: str
    title: str
    convention: str  # "opengl" (+Y) | "directx" (-Y)
    textures: str  # "dds" | "arrays" | "images"
    gltf_base: bool
    curve_names: str  # "identifier" | "snake" | "region"


ENGINE_PRESETS: dict[str, EnginePreset] = {
    "unreal": EnginePreset("unreal", "Unreal Engine 5", "directx", "dds", False, "identifier"),
    "unity": EnginePreset("unity", "Unity (Shader Graph)", "opengl", "arrays", True, "region"),
    "godot": EnginePreset("godot", "Godot 4", "opengl", "arrays", True, "snake"),
    "blender": EnginePreset("blender", "Blender", "opengl", "images", True, "identifier"),
}
