"""Storage format declarations: bit depth, channels, layouts, and the container ids that say so.

================ ====== ======== ============== ============ ========= ======== ===============
format           kind   bits     normal map     2-component  DDS DXGI  KTX2 vk  KTXswizzle
================ ====== ======== ============== ============ ========= ======== ===============
``png8``         plain  8        rgb            rg           -         -        -
``png16``        plain  16       rgb            rg           -         -        -
``exr``          float  0        rgb            rg           -         -        -
``bc1``          block  8 (565)  rgb (z in B)   rg           71 / DXT1 131      rgb1 / rg01
``bc3nm``        block  8        ag (DXT5nm)    ag           77 / DXT5 137      ag01
``bc5``          block  8        rg (z rebuilt) rg           83 / ATI2 141      rg01
``bc7``          block  8        rgb (z in B)   rg           98        145      rgb1 / rg01
``bc7xy``        block  8        rg (z rebuilt) rg           98        145      rg01
``uastc``        basis  8        rgb            rg           -         (basisu) -
================ ====== ======== ============== ============ ========= ======== ===============

RGB and RGBA formats store a normal map's z in B (issue 19: that is what every consumer reads
from BC1, BC7, PNG, EXR and UASTC); BC5 and BC3nm keep their two-channel conventions.
``bc7xy`` (two-channel BC7, z rebuilt) exists only as an explicit, named option: a consumer
must be told to rebuild z. Difference maps (three deltas) need an RGB format.
"""

from __future__ import annotations

from dataclasses import dataclass

from wrinklepipe.codec.encodings import Encoding, encoding
from wrinklepipe.codec.layouts import AG, RG, RGB, Layout


@dataclass(frozen=True)
class StorageFormat:
    """One storage format and how each encoding is laid out in it."""

    name: str
    kind: str  # "plain" | "float" | "block" | "basis"
    bits: int  # 8, 16, or 0 for float storage
    rgb: bool  # can hold three components
    normal_layout: Layout  # a unit normal map (base, full, composite)
    pair_layout: Layout  # two-component data (pd slopes)
    container: str | None = None  # DDS / KTX2 block format name (bc1, bc3, bc5, bc7)
    block_bytes: int = 0
    dxgi: int | None = None
    vk_format: int | None = None
    dds_alpha_mode: int = 0  # DX10 miscFlags2: 0 unknown, 3 opaque, 4 custom (DXT5nm's x)
    explicit: bool = False  # chosen only when asked for by name
    summary: str = ""

    @property
    def is_block(self) -> bool:
        return self.kind == "block"

    def layout_for(self, enc: str | Encoding) -> Layout:
        """The layout ``enc`` maps are stored with in this format (ValueError if it cannot)."""
        e = encoding(enc) if isinstance(enc, str) else enc
        if e.is_normal:
            return self.normal_layout
        if e.components == 2:
            return self.pair_layout
        if not self.rgb:
            raise ValueError(
                f"{self.name} holds two channels; {e.name} maps have three (use an RGB format)"
            )
        return RGB

    def holds(self, enc: str | Encoding) -> bool:
        try:
            self.layout_for(enc)
        except ValueError:
            return False
        return True


def _block(
    name: str,
    container: str,
    block_bytes: int,
    dxgi: int,
    vk: int,
    normal: Layout,
    pair: Layout,
    rgb: bool,
    alpha_mode: int,
    summary: str,
    explicit: bool = False,
) -> StorageFormat:
    return StorageFormat(
        name,
        "block",
        8,
        rgb,
        normal,
        pair,
        container,
        block_bytes,
        dxgi,
        vk,
        alpha_mode,
        explicit,
        summary,
    )


PNG8 = StorageFormat("png8", "plain", 8, True, RGB, RG, summary="8-bit PNG")
PNG16 = StorageFormat("png16", "plain", 16, True, RGB, RG, summary="16-bit PNG")
EXR = StorageFormat("exr", "float", 0, True, RGB, RG, summary="half-float OpenEXR")
BC1 = _block("bc1", "bc1", 8, 71, 131, RGB, RG, True, 3, "DXT1, RGB565, 4 bpp")
BC3NM = _block("bc3nm", "bc3", 16, 77, 137, AG, AG, False, 4, "DXT5nm: x in A, y in G, 8 bpp")
BC5 = _block("bc5", "bc5", 16, 83, 141, RG, RG, False, 0, "3Dc / ATI2: two BC4 channels, 8 bpp")
BC7 = _block("bc7", "bc7", 16, 98, 145, RGB, RG, True, 3, "BC7, 8 bpp")
BC7XY = _block(
    "bc7xy", "bc7", 16, 98, 145, RG, RG, False, 3, "BC7 with x, y only (z rebuilt)", True
)
UASTC = StorageFormat("uastc", "basis", 8, True, RGB, RG, summary="Basis Universal UASTC LDR")

FORMATS: dict[str, StorageFormat] = {
    f.name: f for f in (PNG8, PNG16, EXR, BC1, BC3NM, BC5, BC7, BC7XY, UASTC)
}
#: Block formats, in the order ``auto`` tries them.
BLOCK_FORMATS: tuple[str, ...] = ("bc5", "bc1", "bc3nm", "bc7", "bc7xy")


def storage_format(name: str) -> StorageFormat:
    """The declaration of storage format ``name``."""
    if name not in FORMATS:
        raise ValueError(f"unknown storage format {name!r}; expected one of {', '.join(FORMATS)}")
    return FORMATS[name]
