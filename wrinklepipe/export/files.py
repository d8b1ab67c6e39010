"""A packed asset -> the files of one engine's export (``{relative path: bytes}``) and notes.

Every engine gets, in one flat folder (subfolders ``textures/`` and ``curves/`` only): the mesh as
glTF (Unreal: for its Interchange importer), the textures in the engine's format and green
convention, the wrinkle shader generated from the one template (:mod:`wrinklepipe.shading`),
the engine-side code that drives the weights, the weight curves named the engine's way,
``wrinkle_setup.json`` (files, encoding, policy, the shader's slot table) and a README with the
import steps. A combination an engine cannot express is refused with one message.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe import codec
from wrinklepipe.atomic import dumps_json
from wrinklepipe.errors import input_error
from wrinklepipe.export import importers, readme
from wrinklepipe.export.gltf import plain_gltf
from wrinklepipe.export.presets import ENGINE_PRESETS, EnginePreset
from wrinklepipe.export.textures import (
    block_dds,
    mapping_version,
    rgba_masks,
    strip_png,
    to_8bit_states,
    to_directx,
)
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.package_read import wrinkled_materials
from wrinklepipe.io.png import png_bytes
from wrinklepipe.options import BudgetOptions
from wrinklepipe.outputs.curves import format_float32
from wrinklepipe.package import WrinklePackage, safe_name
from wrinklepipe.shading import godot, hlsl
from wrinklepipe.shading.setup import ShaderSetup, from_meta

RUNTIME_DIR = Path(__file__).resolve().parent.parent / "data" / "engines"
#: Unreal material-editor clipboard text of the two Custom nodes.
UNREAL_CLIPBOARD = "WP_CustomNodes.t3d"
#: Error budget for block-compressed copies (the manifest's default budget).
BUDGET = BudgetOptions().copies()


@dataclass
class Export:
    """What is being built: the package as the engine gets it, files, notes, names."""

    pkg: WrinklePackage
    preset: EnginePreset
    files: dict[str, bytes] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    setup: dict[str, Any] = field(default_factory=dict)
    names: list[str] = field(default_factory=list)  # per region: parameter / curve name
    #: the converted glTF as a document: the mesh file is then the whole character
    document: Document | None = None
    mesh_files: dict[str, bytes] = field(default_factory=dict)


def _add_mesh(ex: Export, keep_normal: bool) -> str:
    """The engine's glTF into ``ex.files`` (:func:`plain_gltf`); records the wrinkled
    material's name(s) (``materials``: where the engine applies the wrinkle shader); returns the
    base image's path."""
    mesh, base_uri = plain_gltf(ex.pkg, keep_normal, ex.document)
    ex.files.update(mesh)
    ex.mesh_files = mesh
    if ex.document is not None:
        materials = ex.document.array("materials")
        ex.setup["materials"] = [
            materials[i].get("name", "") for i in wrinkled_materials(ex.document)
        ]
    else:
        gltf = json.loads(mesh[f"{ex.pkg.name}.gltf"])
        ex.setup["materials"] = [gltf["materials"][0].get("name", "")]
    return base_uri


def _add_masks(ex: Export) -> None:
    """The mask textures as PNG files, and the setup's ``masks`` block naming them."""
    masks = ex.pkg.meta.masks
    for n in masks.textures:
        ex.files[f"textures/{n}.png"] = png_bytes(ex.pkg.texture(n).pixels)
    ex.setup["masks"] = {
        "layout": masks.layout,
        "files": [f"textures/{n}.png" for n in masks.textures],
        "table": masks.table_json(),
    }


def _color_pngs(ex: Export) -> None:
    """Unreal and Blender: each colour state's map as a PNG (sRGB, as painted) and the setup's
    ``colors`` block (nothing without colour states)."""
    meta = ex.pkg.meta
    if meta.base_color is None:
        return
    states = []
    for s in meta.states:
        if s.color is not None:
            ex.files[f"textures/{s.color}.png"] = png_bytes(ex.pkg.texture(s.color).pixels)
            states.append({"name": s.name, "file": f"textures/{s.color}.png"})
    ex.setup["colors"] = {
        "states": states,
        "colorSpace": "srgb",
        "factor": list(meta.color_factor),
    }
    ex.notes.append(
        "colour states: their maps blend over the material's base colour with the same "
        "activations, in linear light (import them as sRGB colour textures)"
    )


def _color_array(ex: Export) -> None:
    """Unity and Godot: the colour maps as one sRGB array strip ``textures/wrinkle_colors.png``
    and the setup's ``colors`` block (nothing without colour states)."""
    meta = ex.pkg.meta
    if meta.base_color is None:
        return
    names = meta.color_textures
    _same_size(ex, "colour", names)
    ex.files["textures/wrinkle_colors.png"] = strip_png(
        [ex.pkg.texture(n).pixels[..., :3] for n in names]
    )
    ex.setup["colors"] = {
        "file": "textures/wrinkle_colors.png",
        "layers": len(names),
        "states": [s.name for s in meta.states if s.color is not None],
        "colorSpace": "srgb",
        "factor": list(meta.color_factor),
    }
    ex.notes.append(
        "colour states: textures/wrinkle_colors.png holds their maps (sRGB) as a texture array; "
        "they blend over the material's base colour with the same activations, in linear light"
    )


def _names(regions: list[str], style: str) -> list[str]:
    taken: set[str] = set()
    if style == "region":
        return list(regions)
    if style == "snake":
        return [hlsl.identifier(r.lower(), taken) for r in regions]
    return [hlsl.identifier(r, taken) for r in regions]


def _mapping_affine(pkg: WrinklePackage, bits: int) -> dict[str, float]:
    """``t = v * mul + add`` for a sampled state texel (Blender's nodes use it)."""
    m = codec.mapping(mapping_version(pkg) if pkg.meta.versioned else 1)
    mul, add = m.affine(bits)
    return {"mul": float(mul), "add": float(add), "clampMin": -1.0 if m.version >= 2 else None}


def _curves(ex: Export) -> list[str]:
    """``curves/NAME.json`` (all engines) and, for Unreal, ``curves/NAME.csv`` as a CurveTable
    (first row the key times, then one row per curve, named like the material parameters)."""
    paths = []
    taken: set[str] = set()
    regions = ex.pkg.meta.region_names
    for c in ex.pkg.curves:
        stem = safe_name(c.name, taken)
        values = np.asarray(c.values, np.float32)
        js = {
            "name": c.name,
            "regions": ex.names,
            "regionNames": regions,
            "regionCount": len(regions),
            "times": [float(np.float32(t)) for t in c.times],
            "values": [float(v) for v in values.reshape(-1)],
            "interpolation": "linear",
        }
        ex.files[f"curves/{stem}.json"] = dumps_json(js).encode("utf-8")
        paths.append(f"curves/{stem}.json")
        if ex.preset.name == "unreal":
            rows = ["---," + ",".join(format_float32(t) for t in c.times)]
            for r, name in enumerate(ex.names):
                rows.append(name + "," + ",".join(format_float32(v) for v in values[:, r]))
            ex.files[f"curves/{stem}.csv"] = ("\n".join(rows) + "\n").encode("utf-8")
            paths.append(f"curves/{stem}.csv")
    return paths


def _layout(channels: int) -> str:
    return "rgb" if channels >= 3 else "rg"


def _shader_setup(ex: Export, base_layout: str, state_layout: str, bits: int) -> ShaderSetup:
    pkg = ex.pkg
    chans = [pkg.texture(n).pixels.shape[-1] for n in pkg.meta.masks.textures]
    conv = ex.preset.convention
    setup = from_meta(pkg.meta, chans, base_layout, state_layout, bits, conv, conv)
    problems = setup.problems()
    if problems:
        raise input_error(pkg.name, f"cannot export for {ex.preset.name}: " + "; ".join(problems))
    return setup


def _same_size(ex: Export, role: str, names: list[str]) -> None:
    shapes = {ex.pkg.texture(n).pixels.shape for n in names}
    if len(shapes) > 1:
        raise input_error(
            ex.pkg.name,
            f"cannot export for {ex.preset.name}: the {role} textures differ in size or channels "
            f"({sorted(shapes)}); a texture array needs one size",
        )


# ------------------------------------------------------------------------------------------------
# per engine


def _unreal(ex: Export) -> None:
    pkg = ex.pkg
    meta = pkg.meta
    _add_mesh(ex, keep_normal=False)
    ex.notes.append("normal maps converted to DirectX (-Y): y negated in each map's value mapping")
    base = next(t for t in pkg.textures if t.role == "base_normal")
    res = block_dds(pkg, base, "bc5", BUDGET)
    if res.data is not None:
        ex.files["textures/base_normal.dds"] = res.data
        ex.setup["base"] = {
            "file": "textures/base_normal.dds",
            "format": "bc5",
            "levels": res.levels,
        }
        base_layout = "rg"
    else:
        ex.files["textures/base_normal.png"] = png_bytes(base.pixels)
        ex.setup["base"] = {"file": "textures/base_normal.png", "format": "png"}
        base_layout = _layout(base.pixels.shape[-1])
        ex.notes.append(
            f"base: BC5 is over the error budget (mean {res.mean_deg:.2f}, p99 "
            f"{res.p99_deg:.2f} deg against the stored map; budget {BUDGET.mean} / "
            f"{BUDGET.p99}): shipped as PNG"
        )
    states = [pkg.texture(n) for n in meta.state_textures]
    results = []
    if meta.encoding != "diff":
        results = [block_dds(pkg, t, "bc5", BUDGET) for t in states]
    if results and all(r.data is not None for r in results):
        ex.setup["states"] = []
        for s, t, r in zip(meta.states, states, results, strict=True):
            ex.files[f"textures/{t.name}.dds"] = r.data
            ex.setup["states"].append(
                {
                    "name": s.name,
                    "file": f"textures/{t.name}.dds",
                    "format": "bc5",
                    "levels": r.levels,
                }
            )
        state_layout, bits = "rg", 8
    else:
        ex.setup["states"] = []
        for s, t in zip(meta.states, states, strict=True):
            ex.files[f"textures/{t.name}.png"] = png_bytes(t.pixels)
            ex.setup["states"].append(
                {"name": s.name, "file": f"textures/{t.name}.png", "format": "png"}
            )
        state_layout, bits = _layout(states[0].pixels.shape[-1]), states[0].bits
        if meta.encoding == "diff":
            ex.notes.append("states: diff maps hold three deltas (BC5 holds two): shipped as PNG")
        else:
            worst = max(results, key=lambda r: r.p99_deg)
            ex.notes.append(
                f"states: BC5 is over the error budget (worst p99 {worst.p99_deg:.2f} deg): "
                "shipped as PNG"
            )
    _add_masks(ex)
    _color_pngs(ex)
    setup = _shader_setup(ex, base_layout, state_layout, bits)
    try:
        nodes = hlsl.unreal_nodes(setup)
    except ValueError as exc:
        raise input_error(pkg.name, f"cannot export for unreal: {exc}") from None
    ex.names = [n for n, _ in nodes.region_inputs]
    ex.files["WP_Decode.hlsl"] = nodes.decode.code.encode("utf-8")
    ex.files["WP_Wrinkle.hlsl"] = nodes.wrinkle.code.encode("utf-8")
    ex.files[UNREAL_CLIPBOARD] = importers.unreal_t3d([nodes.decode, nodes.wrinkle]).encode()
    ex.setup["unreal"] = {
        "clipboard": UNREAL_CLIPBOARD,
        "nodes": [
            {
                "description": n.description,
                "output": n.output,
                "code": f"{n.description}.hlsl",
                "inputs": [{"name": a, "connect": b} for a, b in n.inputs],
                **(
                    {"additionalOutputs": [{"name": a, "type": b} for a, b in n.additional_outputs]}
                    if n.additional_outputs
                    else {}
                ),
            }
            for n in (nodes.decode, nodes.wrinkle)
        ],
    }
    ex.setup["shader"] = setup


def _arrays(ex: Export) -> ShaderSetup:
    """Unity and Godot: the glTF with its base normal map, states and masks as array strips."""
    pkg = ex.pkg
    meta = pkg.meta
    base_uri = _add_mesh(ex, keep_normal=True)
    states = meta.state_textures
    masks = list(meta.masks.textures)
    _same_size(ex, "state", states)
    _same_size(ex, "mask", masks)
    ex.files["textures/wrinkle_states.png"] = strip_png([pkg.texture(n).pixels for n in states])
    ex.files["textures/wrinkle_masks.png"] = strip_png([pkg.texture(n).pixels for n in masks])
    ex.setup["base"] = {"file": base_uri, "format": "png"}
    ex.setup["states"] = [
        {"name": s.name, "file": "textures/wrinkle_states.png", "layer": k}
        for k, s in enumerate(meta.states)
    ]
    ex.setup["statesArray"] = {"file": "textures/wrinkle_states.png", "layers": len(states)}
    ex.setup["masks"] = {
        "layout": meta.masks.layout,
        "file": "textures/wrinkle_masks.png",
        "layers": len(masks),
        "table": meta.masks.table_json(),
    }
    _color_array(ex)
    st = pkg.texture(states[0])
    # the engines compress imported normal maps to two channels: read x, y and rebuild z
    setup = _shader_setup(ex, "rg", _layout(st.pixels.shape[-1]), st.bits)
    ex.setup["shader"] = setup
    return setup


def _sidecars(ex: Export) -> list[tuple[str, int, int, int | None]]:
    """(file, width, height, array layers or None for the base normal map) of the textures the
    wrinkle shader samples in a Unity or Godot export."""
    pkg = ex.pkg
    base = next(t for t in pkg.textures if t.role == "base_normal").pixels
    out: list[tuple[str, int, int, int | None]] = []
    if ex.setup["base"]["file"] in ex.files:
        out.append((ex.setup["base"]["file"], base.shape[1], base.shape[0], None))
    for name, arr in (("states", ex.setup["statesArray"]), ("masks", ex.setup["masks"])):
        first = pkg.texture(
            pkg.meta.states[0].texture if name == "states" else pkg.meta.masks.textures[0]
        ).pixels
        out.append((arr["file"], first.shape[1], first.shape[0] * arr["layers"], arr["layers"]))
    if "colors" in ex.setup:
        arr = ex.setup["colors"]
        first = pkg.texture(pkg.meta.color_textures[0]).pixels
        out.append((arr["file"], first.shape[1], first.shape[0] * arr["layers"], arr["layers"]))
    return out


def _unity(ex: Export) -> None:
    ex.names = _names(ex.pkg.meta.region_names, "region")
    _arrays(ex)
    for rel, w, h, layers in _sidecars(ex):
        if max(w, h) > importers.UNITY_MAX_TEXTURE_SIZE:
            ex.notes.append(
                f"{rel}: {w} x {h} px is over Unity's import limit of "
                f"{importers.UNITY_MAX_TEXTURE_SIZE} px per side; Unity scales it down on import"
            )
        guid = importers.unity_guid(ex.pkg.name, rel)
        srgb = rel == ex.setup.get("colors", {}).get("file")
        meta = importers.unity_texture_meta(guid, importers.unity_max_size(w, h), layers, srgb)
        ex.files[rel + ".meta"] = meta.encode("utf-8")
    setup = ex.setup["shader"]
    ex.files["WrinkleMaps.hlsl"] = hlsl.unity_file(setup, f"WRINKLEPIPE_{ex.pkg.name}").encode()
    ex.files["WrinkleWeights.cs"] = (RUNTIME_DIR / "unity" / "WrinkleWeights.cs").read_bytes()


def _godot(ex: Export) -> None:
    ex.names = _names(ex.pkg.meta.region_names, "snake")
    _arrays(ex)
    for rel, _, _, layers in _sidecars(ex):
        uid = importers.godot_uid(ex.pkg.name, rel)
        text = (
            importers.godot_normal_map_import(uid)
            if layers is None
            else importers.godot_array_import(layers, uid)
        )
        ex.files[rel + ".import"] = text.encode("utf-8")
    ex.files["wrinkle.gdshader"] = godot.godot_shader(ex.setup["shader"]).encode("utf-8")
    ex.files["wrinkle_weights.gd"] = (RUNTIME_DIR / "godot" / "wrinkle_weights.gd").read_bytes()


def _blender(ex: Export) -> None:
    pkg = ex.pkg
    meta = pkg.meta
    ex.names = ["wp_" + n for n in _names(meta.region_names, "identifier")]
    base_uri = _add_mesh(ex, keep_normal=True)
    ex.setup["base"] = {"file": base_uri, "format": "png"}
    ex.setup["states"] = []
    for s in meta.states:
        t = pkg.texture(s.texture)
        ex.files[f"textures/{t.name}.png"] = png_bytes(t.pixels)
        ex.setup["states"].append({"name": s.name, "file": f"textures/{t.name}.png"})
    _add_masks(ex)
    _color_pngs(ex)
    st = pkg.texture(meta.states[0].texture)
    base = next(t for t in pkg.textures if t.role == "base_normal")
    ex.setup["shader"] = _shader_setup(
        ex, _layout(base.pixels.shape[-1]), _layout(st.pixels.shape[-1]), st.bits
    )
    ex.setup["stateMapping"] = _mapping_affine(pkg, st.bits)
    ex.files["build_wrinkles.py"] = (RUNTIME_DIR / "blender" / "build_wrinkles.py").read_bytes()


_ENGINES = {"unreal": _unreal, "unity": _unity, "godot": _godot, "blender": _blender}


def export_files(
    pkg: WrinklePackage, engine: str, document: Document | None = None
) -> tuple[dict[str, bytes], list[str]]:
    """The files of an engine export as ``{relative path: bytes}`` and the notes. ``document``:
    the converted glTF as a document (the mesh file is then the whole character). A UDIM
    asset is refused: every engine file here samples one texture per map."""
    if pkg.tiles:
        raise input_error(
            pkg.name,
            f"has UDIM tiles ({', '.join(map(str, pkg.tiles))}); the {engine} export's material "
            "and shader sample one texture per map (Unity and Godot have no UDIM; Unreal's and "
            "Blender's UDIM texture sets are not written): export a character converted "
            "without tiles, or use the USD (UDIM) or glTF (one material per tile) output",
        )
    preset = ENGINE_PRESETS[engine]
    work = rgba_masks(pkg) if engine == "unreal" else pkg
    work = to_8bit_states(work) if engine in ("unity", "godot") else work
    if preset.convention == "directx":
        work = to_directx(work)
    ex = Export(work, preset, document=document)
    if work is not pkg and engine == "unreal" and work.meta.masks != pkg.meta.masks:
        ex.notes.append("masks: the array layout repacked four to an RGBA texture (exact)")
    if engine in ("unity", "godot") and any(
        t.bits == 16 for t in pkg.textures if t.role == "state"
    ):
        ex.notes.append("states: 16-bit maps re-encoded at 8 bits (the engine imports PNG at 8)")
    _ENGINES[engine](ex)
    for rel, data in ex.mesh_files.items():
        if ex.files[rel] != data:
            raise input_error(
                pkg.name,
                f"the character's file {rel!r} has the name of a file the {engine} export "
                "writes; rename that image in the source",
            )
    setup: ShaderSetup = ex.setup.pop("shader")
    shader = setup.to_json()
    shader["slotFlat"] = [s for slots in shader["slots"] for s in slots]
    shader["slotOffsets"] = list(np.cumsum([0] + [len(s) for s in shader["slots"]]).tolist())
    meta = work.meta
    regions = meta.region_names
    doc = {
        "engine": engine,
        "title": preset.title,
        "convention": preset.convention,
        "encoding": meta.encoding,
        "scale": meta.scale,
        "mapping": int(meta.mapping),
        "policy": meta.policy,
        "mesh": f"{pkg.name}.gltf",
        **ex.setup,
        "regions": [
            {**r.to_json(), "parameter": n} for r, n in zip(meta.regions, ex.names, strict=True)
        ],
        "regionNames": regions,
        "expressions": meta.expressions,
        "shader": shader,
        "curves": _curves(ex),
        "notes": ex.notes,
    }
    ex.files["wrinkle_setup.json"] = dumps_json(doc).encode("utf-8")
    ex.files["README.md"] = readme.readme(doc, sorted(ex.files)).encode("utf-8")
    return ex.files, ex.notes
