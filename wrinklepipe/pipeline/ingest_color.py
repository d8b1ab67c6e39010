"""Ingest of the colour maps: the base colour and each state's colour map as sRGB texels.

The base colour is the manifest's ``base_color`` file, else the wrinkled glTF material's own
``baseColorTexture`` (with its ``baseColorFactor``; :func:`wrinklepipe.gltf.wrinkled.
material_base_color`). Every state's colour map is read as stored
(:func:`wrinklepipe.color.read.read_color_texels`) and must be the base colour's size (it is
painted on the same UV layout); a normal map given as a colour map is refused
(:func:`wrinklepipe.color.read.check_color_map`). States keep the base colour's bit depth.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wrinklepipe.asset import ColorMaps
from wrinklepipe.codec import srgb
from wrinklepipe.color.read import check_color_map, read_color_texels, rgb_texels
from wrinklepipe.errors import input_error
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.images import texture_texels
from wrinklepipe.gltf.wrinkled import material_base_color


@dataclass(frozen=True)
class MaterialColor:
    """A glTF material's base colour: its texture's texels, the RGB factor and where it is."""

    texels: np.ndarray
    factor: tuple[float, float, float]
    texture: int
    where: str


def material_color(doc: Document, materials: list[int], manifest: Any) -> MaterialColor:
    """The wrinkled materials' shared base colour (checked as :func:`material_base_color`)."""
    info, factor = material_base_color(doc, materials, manifest.path)
    where = f"{doc.path.name} /materials/{materials[0]}/pbrMetallicRoughness/baseColorTexture"
    texels = rgb_texels(texture_texels(doc, int(info["index"])))
    check_color_map(texels, where)
    return MaterialColor(texels, factor, int(info["index"]), where)


def _same_depth(texels: np.ndarray, dtype: np.dtype) -> np.ndarray:
    if texels.dtype == dtype:
        return texels
    return srgb.encode_texels(srgb.decode_texels(texels), 16 if dtype == np.uint16 else 8)


def read_colors(
    manifest: Any, material: MaterialColor | None = None
) -> tuple[ColorMaps | None, list[str]]:
    """The colour maps a manifest names (None when no state has one) and notes."""
    if not manifest.has_color:
        return None, []
    notes: list[str] = []
    if manifest.base_color is not None:
        base = read_color_texels(manifest.base_color)
        check_color_map(base, manifest.base_color, "base_color")
        factor, from_material, label = (1.0, 1.0, 1.0), False, manifest.base_color.name
    elif material is not None:
        base, factor, from_material, label = material.texels, material.factor, True, material.where
    else:  # the manifest's own checks ask for base_color first
        raise input_error(manifest.path, "colour states need a base colour", "base_color")
    h, w = base.shape[:2]
    bits = 16 if base.dtype == np.uint16 else 8
    notes.append(f"base colour: {label} ({w}x{h}, {bits}-bit sRGB, factor {list(factor)})")
    states, index = [], []
    for k, s in enumerate(manifest.states):
        if s.color is None:
            continue
        key = f"states[{k}].color"
        t = read_color_texels(s.color)
        check_color_map(t, s.color, key)
        if t.shape[:2] != (h, w):
            raise input_error(
                s.color,
                f"colour map of state {s.name!r} is {t.shape[1]}x{t.shape[0]}, the base colour "
                f"({label}) is {w}x{h}: a state's colour map is painted on the base colour's UV "
                "layout, at its size",
                key,
            )
        if t.shape[-1] == 4 and np.any(t[..., 3] != t[..., 3].max(initial=0)):
            notes.append(f"{s.color.name}: alpha ignored (a state's colour map is RGB)")
        if t.dtype != base.dtype:
            notes.append(f"{s.color.name}: stored at the base colour's {bits} bits")
        states.append(_same_depth(t[..., :3], base.dtype))
        index.append(k)
    notes.append(
        f"colour states: {', '.join(manifest.states[k].name for k in index)} "
        f"({len(index)} of {len(manifest.states)} states)"
    )
    return ColorMaps(base, np.stack(states), tuple(index), factor, from_material), notes
