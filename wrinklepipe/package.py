"""The packaged (encoded) form of a wrinkle asset: what the glTF/USD writers write, readers read.

A :class:`WrinklePackage` holds the mesh, the textures *as stored* (integer pixels, row 0 at the
top of the image, i.e. glTF's v = 0) and a format-neutral description of the wrinkle setup
(``meta``, a :class:`~wrinklepipe.metadata.WrinkleMeta`) in which textures are named, not
indexed. Both writers serialise the same package, so a
glTF -> USD -> glTF round trip compares packages field by field and pixel by pixel.

Plain data types (core): the package is made from an asset by
:func:`wrinklepipe.pipeline.package.package_from_asset` and decoded back by
:func:`~wrinklepipe.pipeline.package.asset_from_package`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.metadata import WrinkleMeta
from wrinklepipe.names import unique_name

CHANNELS = "rgba"
#: Largest integer a float32 holds exactly: vertex IDs are stored as FLOAT accessors.
MAX_FLOAT_ID = 1 << 24


def safe_name(name: str, taken: set[str] | None = None) -> str:
    """A file stem made from ``name``: letters, digits, ``_ . -`` only, no leading dot, unique
    within ``taken`` (which it updates; compared case-insensitively, so ``Ab`` and ``ab`` give
    ``Ab`` and ``ab_2``). Texture and curve files are named with it, so names from a manifest or
    a foreign glTF can never point outside the output folder nor overwrite each other."""

    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(name)).lstrip(".") or "unnamed"
    # unique case-insensitively: two stems differing in case are one file on macOS / Windows
    return stem if taken is None else unique_name(stem, taken, fold_case=True)


@dataclass
class PackedTexture:
    """One stored texture: integer pixels ``[H, W, C]`` (uint8/uint16), row 0 = top (glTF v=0)."""

    name: str  # stable identifier and file stem: "base_normal", "wrinkle_stretch", "mask_0"
    pixels: np.ndarray
    role: str  # "base_normal" | "state" | "mask" | "base_color" | "state_color"

    @property
    def bits(self) -> int:
        return 16 if self.pixels.dtype == np.uint16 else 8


@dataclass
class WeightCurves:
    """Region weights keyed over time: ``times`` [T] seconds, ``values`` [T, R] (float32), and
    optionally the morph-target weights ``morph_weights`` [T, M] that drive them (a blendshapes
    driver's inputs), played together. ``driver``: what made the curve (JSON: its driver's
    index, name and kind, and what it read: :attr:`wrinklepipe.drivers.base.DriverResult.source`),
    for the report and the validator's rig rules; None when not known (a curve read back from a
    file)."""

    name: str
    times: np.ndarray
    values: np.ndarray
    morph_weights: np.ndarray | None = None
    driver: dict[str, Any] | None = None


@dataclass
class WrinklePackage:
    """Mesh + stored textures + wrinkle description (``meta``, texture references by name)."""

    name: str
    mesh: Mesh
    textures: list[PackedTexture]
    meta: WrinkleMeta
    curves: list[WeightCurves] = field(default_factory=list)
    #: UDIM tiles (:mod:`wrinklepipe.udim`), ascending; empty: one texture per map. A tiled
    #: package holds each tile's textures as ``NAME.TILE``; ``meta`` names them ``NAME``.
    tiles: tuple[int, ...] = ()

    def texture(self, name: str) -> PackedTexture:
        """The texture ``name``; in a tiled package, a name ``meta`` uses (``NAME``) gives
        its first tile's texture (every tile of a map has its depth and channels)."""
        for t in self.textures:
            if t.name == name:
                return t
        if self.tiles:
            return self.texture(f"{name}.{self.tiles[0]}")
        raise KeyError(name)

    @property
    def base_name(self) -> str:
        """The base normal map's texture name as ``meta`` would name it: ``base_normal`` (one
        tile of a tiled package, :func:`wrinklepipe.udim.tile_package`: ``base_normal.1001``)."""
        name = next((t.name for t in self.textures if t.role == "base_normal"), "base_normal")
        return name.rsplit(".", 1)[0] if self.tiles and "." in name else name
