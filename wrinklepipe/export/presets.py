"""Engine presets: green convention, normal-map container, extra files per engine."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class EnginePreset:
    """How one engine wants the data: green convention, normal-map container, extra files."""

    name: str
    convention: str  # "opengl" (+Y) | "directx" (-Y)
    normal_format: str  # "png" | "bc5" (DDS, PNG if the compression stage is missing)
    gltf: bool  # also ship the glTF (mesh + +Y maps) for the engine's glTF importer
    shader: str  # "hlsl" | "glsl" | ""


ENGINE_PRESETS: dict[str, EnginePreset] = {
    "unreal": EnginePreset("unreal", "directx", "bc5", False, "hlsl"),
    "unity": EnginePreset("unity", "opengl", "png", True, "hlsl"),
    "godot": EnginePreset("godot", "opengl", "png", True, "glsl"),
    "blender": EnginePreset("blender", "opengl", "png", True, ""),
}
