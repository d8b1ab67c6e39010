"""A packed asset -> the files of one engine's export (``{relative path: bytes}``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wrinklepipe.atomic import dumps_json
from wrinklepipe.export.presets import ENGINE_PRESETS
from wrinklepipe.export.shaders import GLSL, HLSL
from wrinklepipe.io.gltf_write import gltf_document
from wrinklepipe.io.package import WrinklePackage, png_bytes
from wrinklepipe.outputs.compression import compressed_files
from wrinklepipe.outputs.curves import curve_files, format_float32


def flip_green(pkg: WrinklePackage) -> WrinklePackage:
    """OpenGL <-> DirectX: stored green ``q -> top - q`` on the base and state maps.

    For every encoding this negates the tangent-space y: ``0.5 + 0.5 (-y) = 1 - (0.5 + 0.5 y)``
    (base, ``full``, ``composite``), likewise the PD slope ``d.y`` and the ``diff`` delta's y.
    Exact on integers, and its own inverse. Masks are unchanged.
    """
    out = []
    for t in pkg.textures:
        if t.role in ("base_normal", "state"):
            px = t.pixels.copy()
            top = np.iinfo(px.dtype).max
            px[..., 1] = top - px[..., 1]
            t = replace(t, pixels=px)
        out.append(t)
    return replace(pkg, textures=out)


def export_files(pkg: WrinklePackage, engine: str) -> tuple[dict[str, bytes], list[str]]:
    """The files of an engine export as ``{relative path: bytes}`` and notes."""
    preset = ENGINE_PRESETS[engine]
    notes: list[str] = []
    files: dict[str, bytes] = {}
    if preset.gltf:
        doc, data, images = gltf_document(pkg)
        doc["buffers"][0]["uri"] = f"{pkg.name}.bin"
        files[f"{pkg.name}.gltf"] = dumps_json(doc).encode("utf-8")
        files[f"{pkg.name}.bin"] = data
        files.update(images)
    shipped = flip_green(pkg) if preset.convention == "directx" else pkg
    if preset.convention == "directx":
        notes.append("normal maps converted to DirectX (-Y): stored green q -> 255 - q")
    tex_files: dict[str, str] = {}
    compressed: dict[str, bytes] = {}
    if preset.normal_format == "bc5":
        compressed, n, _ = compressed_files(shipped, {}, {"base": "bc5", "wrinkle": "bc5"})
        notes += n
    for t in shipped.textures:
        dds = f"compressed/{t.name}.dds"
        if dds in compressed:
            rel = f"{engine}/{t.name}.dds"
            files[rel] = compressed[dds]
        else:
            rel = f"{engine}/{t.name}.png"
            files[rel] = png_bytes(t.pixels)
        tex_files[t.name] = rel
    meta = shipped.meta
    regions = [r["name"] for r in meta["regions"]]
    taken: set[str] = set()
    curve_paths = []
    for c in pkg.curves:
        for rel, data in curve_files(c, regions, taken).items():
            files[f"{engine}/{rel}"] = data
            if rel.endswith(".csv"):
                curve_paths.append(f"{engine}/{rel}")
    setup = {
        "engine": engine,
        "convention": preset.convention,
        "encoding": meta["encoding"],
        "scale": meta["scale"],
        "policy": meta["policy"],
        "base": tex_files["base_normal"],
        "states": [{"name": s["name"], "file": tex_files[s["texture"]]} for s in meta["states"]],
        "masks": {
            "layout": meta["masks"]["layout"],
            "files": [tex_files[n] for n in meta["masks"]["textures"]],
            "table": meta["masks"]["table"],
        },
        "regions": meta["regions"],
        "expressions": meta["expressions"],
        "curves": curve_paths,
        "notes": notes,
    }
    files[f"{engine}/wrinkle_setup.json"] = dumps_json(setup).encode("utf-8")
    if preset.shader and meta["encoding"] == "pd":
        template = HLSL if preset.shader == "hlsl" else GLSL
        text = template.format(
            policy=meta["policy"],
            convention=preset.convention,
            scale=format_float32(meta["scale"]),
            k=len(meta["states"]),
        )
        files[f"{engine}/wrinkle.{preset.shader}"] = text.encode("utf-8")
    return files, notes
