"""Turn an in-memory asset into shipped textures (the demo and tests use this).

A small, fixed packer: 8-bit (or BCn through etcpak) base, states in the asset's encoding, masks
four to an RGBA texture. It exists so the validator can be run on the demo without the full
``convert`` pipeline; real outputs are loaded by :mod:`wrinklepipe.validate.loader`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from wrinklepipe import model
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.validate.context import encode_source_states
from wrinklepipe.validate.inputs import ChannelEntry, Texture, ValidationInput


@dataclass(frozen=True)
class ShipOptions:
    """``compress``: BC5 for two-channel normal data, BC7 for diff maps and masks; else 8-bit."""

    compress: bool = True
    mask_format: str = "rgba8"  # BC7 masks are exact enough but very slow on llvmpipe


def _u8(values: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(values, np.float64) * 255.0), 0, 255).astype(np.uint8)


def _rgba(values: np.ndarray) -> np.ndarray:
    """``[H, W, C]`` values -> RGBA8; missing channels are B = 1 (z of a flat normal), A = 1."""
    v = np.asarray(values, np.float32)
    h, w, c = v.shape
    out = np.ones((h, w, 4), np.float32)
    out[..., :c] = v
    return _u8(out)


def encode_texture(name: str, role: str, values: np.ndarray, fmt: str, state: str = "") -> Texture:
    """Stored values ``[H, W, C]`` in [0, 1] -> a :class:`Texture` in ``fmt``."""
    h, w = values.shape[:2]
    rgba = _rgba(values)
    if fmt in ("bc1", "bc3", "bc4", "bc5", "bc7"):
        import etcpak

        data = getattr(etcpak, f"compress_{fmt}")(np.ascontiguousarray(rgba).tobytes(), w, h)
    elif fmt == "rgba8":
        data = rgba.tobytes()
    elif fmt == "rg8":
        data = np.ascontiguousarray(rgba[..., :2]).tobytes()
    elif fmt == "rgb8":
        data = np.ascontiguousarray(rgba[..., :3]).tobytes()
    elif fmt == "rgba32f":
        out = np.zeros((h, w, 4), np.float32)
        out[..., : values.shape[-1]] = values
        data = out.tobytes()
    else:
        raise ValueError(f"cannot encode {fmt}")
    return Texture(name, role, fmt, w, h, bytes(data), state=state, file=f"{name}")


def stored_state_values(asset: WrinkleAsset) -> np.ndarray:
    """Stored values ``[K, H, W, C]`` of the states in the asset's encoding (float, unclipped
    except for pd, which is clipped to the cone of ``pd_scale``)."""
    base = model.normalize(asset.base)
    states = model.normalize(asset.states)
    if base.shape[:2] != states.shape[1:3]:
        from wrinklepipe.validate.textures import resize_bilinear

        base = model.normalize(resize_bilinear(base, *states.shape[1:3]))
    enc = encode_source_states(base, states, asset.encoding)
    if asset.encoding == "pd":
        return 0.5 + 0.5 * np.clip(enc / np.float32(asset.pd_scale), -1.0, 1.0)
    if asset.encoding == "diff":  # gain g = pd_scale: 0.5 + 0.5 g (W - B)
        return np.clip(0.5 + (enc - 0.5) * np.float32(asset.pd_scale), 0.0, 1.0)
    return 0.5 + 0.5 * enc


def ship_asset(
    asset: WrinkleAsset, options: ShipOptions | None = None, has_source: bool = True
) -> ValidationInput:
    """A :class:`ValidationInput` whose textures are this asset as a converter would ship it."""
    o = options or ShipOptions()
    two = "bc5" if o.compress else "rgba8"
    three = "bc7" if o.compress else "rgba8"
    textures = [encode_texture("base_normal", "base", 0.5 + 0.5 * model.normalize(asset.base), two)]
    stored = stored_state_values(asset)
    fmt = three if asset.encoding == "diff" else two
    for k, name in enumerate(asset.state_names):
        vals = stored[k] if asset.encoding == "diff" else stored[k][..., :2]
        if fmt == "rgba8" and asset.encoding in ("full", "composite"):
            vals = stored[k]
        textures.append(encode_texture(f"wrinkle_{name}", "state", vals, fmt, state=name))
    table = []
    masks = np.clip(np.asarray(asset.masks, np.float32), 0.0, 1.0)
    for t in range((masks.shape[0] + 3) // 4):
        chunk = masks[4 * t : 4 * t + 4]
        rgba = np.zeros(chunk.shape[1:] + (4,), np.float32)
        rgba[..., : chunk.shape[0]] = np.moveaxis(chunk, 0, -1)
        textures.append(encode_texture(f"mask_{t}", "mask", rgba, o.mask_format))
        for c in range(chunk.shape[0]):
            table.append(ChannelEntry(asset.regions[4 * t + c].name, f"mask_{t}", c))
    # two-channel formats for normals: z is rebuilt; rgba8 keeps all three
    for t in textures:
        if t.role in ("base", "state") and t.fmt == "rgba8":
            t.layout = "rgb" if (t.role == "base" or asset.encoding != "pd") else "rg"
    if asset.mesh is not None and asset.mesh.tangents is None:
        from wrinklepipe.pipeline import prepare_mesh

        asset = replace(asset, mesh=prepare_mesh(asset.mesh))
    return ValidationInput(
        asset=asset,
        textures=textures,
        channel_table=table,
        has_source=has_source,
        path=asset.name,
        kind="memory",
        pointers={"meta": asset.name, "mesh": f"{asset.name}#mesh"},
    )
