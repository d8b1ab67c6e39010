"""Block-compressed copies of the colour maps: sRGB BC1 / BC7, mips made in linear light.

What ``convert`` ships beside the colour PNGs (``compressed/NAME.dds`` and ``.ktx2``), made
from the stored sRGB texels:

- ``bc1`` (``DXGI_FORMAT_BC1_UNORM_SRGB`` = 72, ``VK_FORMAT_BC1_RGB_SRGB_BLOCK`` = 132; 4 bits
  per texel, quicktex) or ``bc7`` (``DXGI_FORMAT_BC7_UNORM_SRGB`` = 99,
  ``VK_FORMAT_BC7_SRGB_BLOCK`` = 146; 8 bits per texel, ispc_texcomp): the blocks hold the sRGB
  texels as painted, so a GPU's sRGB sampler decodes each texel to linear light before it
  filters; the KTX2 data format descriptor says so (sRGB transfer);
- every level of the full mip chain is made **in linear light**: decoded, box-averaged,
  encoded back to sRGB texels, then block-compressed like level 0 (averaging the encoded
  values darkens every edge: a black and white checkerboard would average to 128, not 188);
- each copy's level 0 is decoded by an independent decoder (texture2ddecoder) for the check:
  the choice of format is made by CIEDE2000 inside each pose's active region
  (:mod:`wrinklepipe.fidelity.color`), by the caller.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wrinklepipe.codec import srgb
from wrinklepipe.metadata import CompressedCopy
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals.dds import dds_bytes
from wrinklepipe.normals.ktx2 import ktx2_bytes
from wrinklepipe.normals.resample import mip_chain

#: The block formats a colour map is copied in, smallest blocks first (what ``auto`` tries).
FORMATS: tuple[str, ...] = ("bc1", "bc7")


def linear_mips(texels: np.ndarray) -> list[np.ndarray]:
    """sRGB texels ``[H, W, 3]`` of every level 1.. of the full chain (floor halving down to
    1 x 1), each level box-averaged in linear light from the one above and encoded back."""
    lin = srgb.decode_texels(np.asarray(texels)[..., :3])
    levels = mip_chain(lin, min_size=1, filter="box")[1:]
    return [srgb.encode_texels(np.clip(lv, 0.0, 1.0)) for lv in levels]


def _rgba(texels: np.ndarray) -> np.ndarray:
    t = np.asarray(texels)[..., :3]
    out = np.full(t.shape[:2] + (4,), 255, np.uint8)
    out[..., :3] = t
    return out


def encode_level(texels: np.ndarray, fmt: str) -> bytes:
    """One level's sRGB texels ``[h, w, 3]`` (uint8) as ``fmt`` blocks (padded to whole blocks
    by edge replication)."""
    if fmt not in FORMATS:
        raise ValueError(f"colour maps are copied in {', '.join(FORMATS)}, not {fmt!r}")
    padded, _ = cmp.pad_to_blocks(_rgba(texels))
    return cmp.encode_bc(np.ascontiguousarray(padded), fmt)


def decode_level(data: bytes, width: int, height: int, fmt: str) -> np.ndarray:
    """Block data back to sRGB texels ``[height, width, 3]`` (texture2ddecoder)."""
    pw, ph = -(-width // 4) * 4, -(-height // 4) * 4
    return np.ascontiguousarray(cmp.decode_bc(data, pw, ph, fmt)[:height, :width, :3])


@dataclass
class ColorCopy:
    """One colour map's copy: every level's block data, and level 0 decoded."""

    texture: str
    format: str
    width: int
    height: int
    levels: list[bytes]
    decoded: np.ndarray  # [H, W, 3] sRGB texels of level 0, as a GPU decodes the blocks

    def files(self) -> dict[str, bytes]:
        w, h = self.width, self.height
        return {
            f"compressed/{self.texture}.dds": dds_bytes(self.format, w, h, self.levels, srgb=True),
            f"compressed/{self.texture}.ktx2": ktx2_bytes(
                self.format, w, h, self.levels, layout="rgb", srgb=True
            ),
        }

    def record(self) -> CompressedCopy:
        """The extension / USD record of this copy (``colorSpace`` sRGB)."""
        return CompressedCopy(
            texture=self.texture,
            format=self.format,
            layout="rgb",
            mapping=1,
            levels=len(self.levels),
            ktx2=f"compressed/{self.texture}.ktx2",
            dds=f"compressed/{self.texture}.dds",
            color_space="srgb",
        )


def color_copy(name: str, texels: np.ndarray, fmt: str, with_mips: bool = True) -> ColorCopy:
    """The ``fmt`` copy of a colour map's sRGB texels (8-bit), its mips made in linear light."""
    t = np.asarray(texels)[..., :3]
    if t.dtype != np.uint8:
        raise ValueError("block formats hold 8-bit colour maps")
    h, w = t.shape[:2]
    first = encode_level(t, fmt)
    levels = [first]
    if with_mips and max(h, w) > 1:
        levels += [encode_level(lv, fmt) for lv in linear_mips(t)]
    return ColorCopy(name, fmt, w, h, levels, decode_level(first, w, h, fmt))
