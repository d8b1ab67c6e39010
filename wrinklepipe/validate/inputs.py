"""What the validator works on: the in-memory asset plus the exact texture bytes that ship.

A :class:`ValidationInput` is built by :mod:`wrinklepipe.sources.validation` from a converted
folder, a glTF/GLB/USD, a manifest, a corpus bundle or the demo. Rules and the render pass only
read it.

``asset`` holds float data: when ``has_source`` is true its maps are the *source* (independent of
the shipped bytes, e.g. the manifest's 16-bit PNGs or the demo's analytic normals), so rules can
measure what shipping lost; otherwise they were decoded from the shipped textures and only
self-consistency rules run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe.asset import WrinkleAsset

#: Texture formats the validator understands: channels, bytes per texel or per 4x4 block, kind.
FORMATS: dict[str, tuple[int, int, str]] = {
    "r8": (1, 1, "unorm8"),
    "rg8": (2, 2, "unorm8"),
    "rgb8": (3, 3, "unorm8"),
    "rgba8": (4, 4, "unorm8"),
    "r16": (1, 2, "unorm16"),
    "rg16": (2, 4, "unorm16"),
    "rgb16": (3, 6, "unorm16"),
    "rgba16": (4, 8, "unorm16"),
    "r32f": (1, 4, "float"),
    "rg32f": (2, 8, "float"),
    "rgb32f": (3, 12, "float"),
    "rgba32f": (4, 16, "float"),
    "bc1": (4, 8, "block"),
    "bc3": (4, 16, "block"),
    "bc4": (1, 8, "block"),
    "bc5": (2, 16, "block"),
    "bc7": (4, 16, "block"),
}
BLOCK_FORMATS = tuple(k for k, v in FORMATS.items() if v[2] == "block")
CHANNELS = "rgba"


@dataclass
class Texture:
    """One texture as it ships: level-0 bytes in ``fmt``, rows top to bottom (glTF v = 0).

    Stored values (after the unorm/BC decode, in [0, 1]) are: ``0.5 + 0.5 n`` for normal maps
    (base, ``full`` and ``composite`` states; two-channel formats rebuild z), ``0.5 + 0.5 d / s``
    for ``pd`` states (R = x, G = y), ``D`` for ``diff`` states and the mask value for masks.
    ``layout`` says where x, y (and z) live: ``"rgb"``, ``"rg"`` (z rebuilt), ``"ag"`` (DXT5nm)
    or ``None`` (not recorded: ``rgb`` with three or more channels, else ``rg``).
    ``mapping`` is the value-mapping version of ``pd`` / ``diff`` values
    (:mod:`wrinklepipe.codec.mappings`; 1 for assets that do not record one).
    """

    name: str
    role: str  # "base" | "state" | "mask" | "base_color" | "state_color"
    fmt: str
    width: int
    height: int
    data: bytes | np.ndarray  # the texels' bytes (or a flat uint8 view of them)
    srgb: bool = False
    file: str = ""
    pointer: str = ""
    state: str = ""  # state name when role == "state" or "state_color"
    convention: str = "opengl"  # declared green convention of a normal map
    layout: str | None = None
    mapping: int = 1

    @property
    def channels(self) -> int:
        return FORMATS[self.fmt][0]

    @property
    def bits(self) -> int:
        """Bits per stored channel as the codec counts them: 8 (8-bit and BCn), 16, 0 (float)."""
        return {"unorm8": 8, "block": 8, "unorm16": 16, "float": 0}[FORMATS[self.fmt][2]]

    @property
    def is_block(self) -> bool:
        return self.fmt in BLOCK_FORMATS

    @property
    def where(self) -> str:
        return self.file + (f"#{self.pointer}" if self.pointer else "")

    def expected_size(self) -> int:
        """Bytes level 0 must hold for the declared format and size."""
        ch, nbytes, kind = FORMATS[self.fmt]
        if kind == "block":
            return ((self.width + 3) // 4) * ((self.height + 3) // 4) * nbytes
        return self.width * self.height * nbytes


@dataclass
class ChannelEntry:
    """Where region ``region``'s mask lives: texture name and channel index (0..3)."""

    region: str
    texture: str
    channel: int
    split: tuple[str, int] | None = None  # lr-split layout: (texture, channel) of the split
    side: str = "center"  # with a split: left takes c * s, right c * (1 - s)


@dataclass
class ValidationInput:
    """The asset to validate: float data, shipped textures, channel table and pointers."""

    asset: WrinkleAsset
    textures: list[Texture] = field(default_factory=list)
    channel_table: list[ChannelEntry] = field(default_factory=list)
    has_source: bool = False
    path: str = ""
    kind: str = "memory"  # "folder" | "gltf" | "usd" | "manifest" | "bundle" | "demo" | "memory"
    pointers: dict[str, str] = field(default_factory=dict)  # item -> "file#pointer"
    vertex_weights: dict[str, np.ndarray] = field(default_factory=dict)  # name -> [V] or [V, K]
    weight_curves: dict[str, np.ndarray] = field(default_factory=dict)  # name -> [T, R] weights
    #: The curves with their times and morph weights (``WeightCurves``), when the input has
    #: them: the render pass draws the frames where each region's weight peaks.
    curves: list[Any] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    #: UDIM: one plain input per tile (its textures, the mesh of its triangles with UVs in
    #: [0, 1]); this input then describes the whole asset and the validator runs the tiles
    #: (:mod:`wrinklepipe.validate.tiles`)
    tiles: dict[int, ValidationInput] = field(default_factory=dict)

    def texture(self, name: str) -> Texture | None:
        return next((t for t in self.textures if t.name == name), None)

    def by_role(self, role: str) -> list[Texture]:
        return [t for t in self.textures if t.role == role]

    def state_textures(self) -> list[Texture | None]:
        """Shipped texture of each state, in ``asset.state_names`` order (None when missing)."""
        found = {t.state: t for t in self.by_role("state")}
        return [found.get(s) for s in self.asset.state_names]

    def pointer(self, item: str, default: str = "") -> str:
        return self.pointers.get(item, default or self.path)
