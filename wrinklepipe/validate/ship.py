"""Turn an in-memory asset into shipped textures (the demo and tests use this).

A small, fixed packer: 8-bit (or BCn) base, states in the asset's encoding, masks four to an
RGBA texture. Texels come from :mod:`wrinklepipe.codec` (value mapping v2, the codec's layouts)
and blocks from :func:`wrinklepipe.normals.compress.encode_bc`, the converter's own encoder, so
the validator is run on exactly what ``convert`` would ship. Real outputs are loaded by
:mod:`wrinklepipe.sources.validation`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from wrinklepipe import codec, model
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.normals import compress as nc
from wrinklepipe.pipeline.prepare import prepare_mesh
from wrinklepipe.validate.inputs import ChannelEntry, Texture, ValidationInput
from wrinklepipe.validate.textures import resize_bilinear

#: Validator format name -> codec storage format of the texels (plain formats store RGBA8).
_STORAGE = {"bc1": "bc1", "bc3": "bc3nm", "bc5": "bc5", "bc7": "bc7", "rgba8": "png8"}


@dataclass(frozen=True)
class ShipOptions:
    """``compress``: BC5 for two-channel normal data, BC7 for diff maps and masks; else 8-bit."""

    compress: bool = True
    mask_format: str = "rgba8"  # BC7 masks are exact enough but very slow on llvmpipe


def _u8(values: np.ndarray) -> np.ndarray:
    return codec.quantize_unorm(values, 8)


def _rgba(values: np.ndarray) -> np.ndarray:
    """``[H, W, C]`` values -> RGBA8; missing channels are B = 1 (z of a flat normal), A = 1."""
    v = np.asarray(values, np.float32)
    h, w, c = v.shape
    out = np.ones((h, w, 4), np.float32)
    out[..., :c] = v
    return _u8(out)


def _texture(name: str, role: str, rgba: np.ndarray, fmt: str, state: str = "") -> Texture:
    """RGBA8 texels -> a :class:`Texture` in ``fmt`` (block formats through the converter's
    encoder, sizes padded to whole blocks by edge replication)."""
    h, w = rgba.shape[:2]
    if fmt in _STORAGE and fmt != "rgba8":
        padded, _ = nc.pad_to_blocks(np.ascontiguousarray(rgba))
        data = nc.encode_bc(padded, _STORAGE[fmt])
    elif fmt == "rgba8":
        data = np.ascontiguousarray(rgba).tobytes()
    elif fmt == "rg8":
        data = np.ascontiguousarray(rgba[..., :2]).tobytes()
    elif fmt == "rgb8":
        data = np.ascontiguousarray(rgba[..., :3]).tobytes()
    else:
        raise ValueError(f"cannot encode {fmt}")
    return Texture(name, role, fmt, w, h, bytes(data), state=state, file=f"{name}")


def encode_texture(name: str, role: str, values: np.ndarray, fmt: str, state: str = "") -> Texture:
    """Stored values ``[H, W, C]`` in [0, 1] -> a :class:`Texture` in ``fmt`` (plain UNORM
    quantisation; masks and hand-made test textures)."""
    if fmt == "rgba32f":
        h, w = values.shape[:2]
        out = np.zeros((h, w, 4), np.float32)
        out[..., : values.shape[-1]] = values
        return Texture(name, role, fmt, w, h, out.tobytes(), state=state, file=f"{name}")
    return _texture(name, role, _rgba(values), fmt, state)


def encode_map(
    name: str,
    role: str,
    encoding: str,
    x: np.ndarray,
    fmt: str,
    scale: float = 1.0,
    state: str = "",
) -> Texture:
    """A map's quantity ``x`` (pd slopes, diff deltas, unit normals; see
    :mod:`wrinklepipe.codec.encodings`) -> a :class:`Texture` in ``fmt`` with the codec's layout
    and value mapping (v2), recorded on the texture."""
    f = codec.storage_format(_STORAGE[fmt])
    e = codec.encoding(encoding)
    lay = f.layout_for(e)
    q, _ = codec.encode(e, x, f, param=scale, version=codec.CURRENT_VERSION)
    t = _texture(name, role, q, fmt, state)
    t.layout = lay.name
    t.mapping = codec.CURRENT_VERSION if e.versioned else 1
    return t


def stored_state_quantities(asset: WrinkleAsset) -> np.ndarray:
    """Each state's quantity ``[K, H, W, C]`` in the asset's encoding (the codec's
    ``from_normals`` against the base at the states' size)."""
    base = model.normalize(asset.base)
    states = model.normalize(asset.states)
    if base.shape[:2] != states.shape[1:3]:
        base = model.normalize(resize_bilinear(base, *states.shape[1:3]))
    e = codec.encoding(asset.encoding)
    return np.stack([e.from_normals(s, base) for s in states])


def ship_asset(
    asset: WrinkleAsset, options: ShipOptions | None = None, has_source: bool = True
) -> ValidationInput:
    """A :class:`ValidationInput` whose textures are this asset as a converter would ship it."""
    o = options or ShipOptions()
    two = "bc5" if o.compress else "rgba8"
    three = "bc7" if o.compress else "rgba8"
    base = model.normalize(asset.base)
    textures = [encode_map("base_normal", "base", "full", base, two)]
    quantities = stored_state_quantities(asset)
    fmt = three if asset.encoding == "diff" else two
    for k, name in enumerate(asset.state_names):
        textures.append(
            encode_map(
                f"wrinkle_{name}",
                "state",
                asset.encoding,
                quantities[k],
                fmt,
                float(asset.pd_scale),
                state=name,
            )
        )
    table = []
    masks = np.clip(np.asarray(asset.masks, np.float32), 0.0, 1.0)
    for t in range((masks.shape[0] + 3) // 4):
        chunk = masks[4 * t : 4 * t + 4]
        rgba = np.zeros(chunk.shape[1:] + (4,), np.float32)
        rgba[..., : chunk.shape[0]] = np.moveaxis(chunk, 0, -1)
        textures.append(encode_texture(f"mask_{t}", "mask", rgba, o.mask_format))
        for c in range(chunk.shape[0]):
            table.append(ChannelEntry(asset.regions[4 * t + c].name, f"mask_{t}", c))
    extra = {}
    if asset.color is not None:
        textures += color_textures(asset, o.compress)
        extra["color_factor"] = list(asset.color.factor)
    if asset.mesh is not None and asset.mesh.tangents is None:
        asset = replace(asset, mesh=prepare_mesh(asset.mesh))
    return ValidationInput(
        asset=asset,
        textures=textures,
        channel_table=table,
        has_source=has_source,
        path=asset.name,
        kind="memory",
        pointers={"meta": asset.name, "mesh": f"{asset.name}#mesh"},
        extra=extra,
    )


def color_textures(asset: WrinkleAsset, compress: bool = False) -> list[Texture]:
    """The base colour and the colour states as shipped sRGB textures: the texels as they are
    (8-bit RGB), or BC7 sRGB blocks of them (the converter's encoder)."""
    c = asset.color
    if c is None:
        return []
    out = []
    named = [("base_color", "base_color", c.base, "")] + [
        (f"color_{asset.state_names[k]}", "state_color", c.states[j], asset.state_names[k])
        for j, k in enumerate(c.state_index)
    ]
    for name, role, texels, state in named:
        if texels.dtype != np.uint8:
            raise ValueError("shipped colour textures are 8-bit")
        rgb = np.ascontiguousarray(texels[..., :3])
        if compress:
            t = _texture(name, role, _rgba_u8(rgb), "bc7", state)
        else:
            h, w = rgb.shape[:2]
            t = Texture(name, role, "rgb8", w, h, rgb.tobytes(), state=state, file=name)
        t.srgb = True
        out.append(t)
    return out


def _rgba_u8(rgb: np.ndarray) -> np.ndarray:
    out = np.full(rgb.shape[:2] + (4,), 255, np.uint8)
    out[..., :3] = rgb
    return out
