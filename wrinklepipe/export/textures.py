"""Textures in an engine's format and convention, from the codec.

- :func:`to_directx`: the base and state maps with y negated *in each map's value mapping*
  (decode, negate, encode: ``255 - q`` for normal maps, ``256 - q`` for v2 pd / diff), so a
  DirectX engine reads exactly the negated quantity.
- :func:`block_dds`: one map as a block-compressed DDS with its full mip chain (level 0 checked
  against the error budget by an independent decoder; levels 1.. from the quantity's mips,
  :mod:`wrinklepipe.normals.mips`), or ``None`` with the measured reason when the budget is
  exceeded.
- :func:`strip_png`: layers stacked top to bottom in one PNG (what Unity's and Godot's
  Texture2DArray importers slice).
- :func:`rgba_masks`: masks repacked four to an RGBA texture (for engines without texture arrays).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from wrinklepipe import codec
from wrinklepipe.io.png import png_bytes
from wrinklepipe.metadata import MaskChannel, MaskMeta
from wrinklepipe.metrics import Budget
from wrinklepipe.normals import compress as nc
from wrinklepipe.normals import mips
from wrinklepipe.normals.dds import dds_bytes
from wrinklepipe.package import PackedTexture, WrinklePackage


def mapping_version(pkg: WrinklePackage) -> int:
    return int(pkg.meta.mapping)


def _versioned(pkg: WrinklePackage, t: PackedTexture) -> bool:
    return t.role == "state" and pkg.meta.versioned


def to_directx(pkg: WrinklePackage) -> WrinklePackage:
    """OpenGL (+Y) -> DirectX (-Y) on the base and state maps; masks unchanged."""
    out = []
    for t in pkg.textures:
        if t.role in ("base_normal", "state"):
            m = codec.mapping(mapping_version(pkg) if _versioned(pkg, t) else 1)
            bits = 16 if t.pixels.dtype == np.uint16 else 8
            px = t.pixels.copy()
            px[..., 1] = m.encode(-m.decode(px[..., 1], bits), bits)
            t = replace(t, pixels=px)
        out.append(t)
    return replace(pkg, textures=out)


@dataclass(frozen=True)
class BlockResult:
    """A DDS (None when over budget) and what was measured."""

    data: bytes | None
    fmt: str
    mean_deg: float
    p99_deg: float
    levels: int


def _quantity(pkg: WrinklePackage, t: PackedTexture) -> tuple[str, np.ndarray, float]:
    """(encoding, stored quantity, parameter) of a base or state map, decoded exactly."""
    meta = pkg.meta
    enc = "full" if t.role == "base_normal" else meta.encoding
    if enc == "composite":
        enc = "full"  # a composite state is a unit normal map, checked as one
    px = t.pixels
    where = "rgb" if px.shape[-1] >= 3 else "rg"
    param = float(meta.scale) if enc in ("pd", "diff") else 1.0
    version = mapping_version(pkg) if _versioned(pkg, t) else 1
    x = codec.decode(enc, px, where, param=param, version=version)
    return enc, x, param


def block_dds(pkg: WrinklePackage, t: PackedTexture, fmt: str, budget: Budget) -> BlockResult:
    """``t`` as a ``fmt`` DDS with a full mip chain, if level 0 meets ``budget``."""
    enc, x, param = _quantity(pkg, t)
    version = mapping_version(pkg) if _versioned(pkg, t) else 1
    lay = codec.storage_format(fmt).layout_for(enc)
    packed, _ = codec.encode(enc, x, lay, param=param, version=version, bits=8)
    stored = codec.layouts.unpack(packed, lay)
    decode = nc.decoder_for(enc, scale=param, version=version)
    reference = codec.to_normal(enc, x)
    check = nc.compress_and_check(stored, reference, fmt, decode, budget, keep_decoded=False)
    h, w = t.pixels.shape[:2]
    if check.verdict != "pass":
        return BlockResult(None, fmt, check.error.mean, check.error.p99, 0)
    levels = [check.data, *mips.block_levels(enc, x, fmt, param, version)]
    return BlockResult(
        dds_bytes(fmt, w, h, levels), fmt, check.error.mean, check.error.p99, len(levels)
    )


def strip_png(layers: list[np.ndarray]) -> bytes:
    """Layers ``[H, W, C]`` (one dtype, one size) stacked vertically, layer 0 at the top."""
    return png_bytes(np.concatenate(list(layers), axis=0))


def rgba_masks(pkg: WrinklePackage) -> WrinklePackage:
    """An ``array`` table's single-channel masks repacked four to an RGBA texture (exact: texels
    only move); other layouts are returned unchanged."""
    meta = pkg.meta
    table = meta.masks.table
    if not table or not all(e.layer is not None for e in table):
        return pkg
    layers = [pkg.texture(n).pixels[..., 0] for n in meta.masks.textures]
    n_tex = (len(layers) + 3) // 4
    h, w = layers[0].shape
    new_tex, names = [], []
    for i in range(n_tex):
        px = np.zeros((h, w, 4), layers[0].dtype)
        for c in range(4):
            if 4 * i + c < len(layers):
                px[..., c] = layers[4 * i + c]
        names.append(f"mask_rgba_{i}")
        new_tex.append(PackedTexture(names[-1], px, "mask"))
    new_table = tuple(
        MaskChannel(e.region, texture=e.index // 4, channel="rgba"[e.index % 4]) for e in table
    )
    textures = [t for t in pkg.textures if t.role != "mask"] + new_tex
    masks = MaskMeta("rgba", tuple(names), new_table)
    return replace(pkg, textures=textures, meta=replace(meta, masks=masks))


def to_8bit_states(pkg: WrinklePackage) -> WrinklePackage:
    """16-bit state maps re-encoded at 8 bits from their exact quantity (same mapping)."""
    out = []
    for t in pkg.textures:
        if t.role == "state" and t.pixels.dtype == np.uint16:
            enc, x, param = _quantity(pkg, t)
            where = "rgb" if t.pixels.shape[-1] >= 3 else "rg"
            version = mapping_version(pkg) if _versioned(pkg, t) else 1
            px, _ = codec.encode(
                enc, x, where, param=param, version=version, bits=8, channels=t.pixels.shape[-1]
            )
            t = replace(t, pixels=px)
        out.append(t)
    return replace(pkg, textures=out)
