"""Mip chains of stored maps, filtered where averaging means something (DESIGN.md section 9).

PD slopes and difference deltas are linear in the height field, so their mips are plain box
averages of the quantity; unit normals (the base, ``full`` and ``composite`` states) are
averaged as vectors and renormalised. Each level is then stored exactly as level 0 is: the
codec's texels in the format's layout, block-compressed by :func:`compress.encode_bc`.
Halving is floor(size / 2) down to 1 x 1 (the DDS / KTX2 convention).
"""

from __future__ import annotations

import numpy as np

from wrinklepipe import codec
from wrinklepipe.normals import bc4
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals.resample import mip_chain

_F = np.float32


def level_count(width: int, height: int) -> int:
    """Levels of a full chain: ``floor(log2(max(w, h))) + 1``."""
    return max(int(width), int(height)).bit_length()


def quantity_mips(encoding: str, x: np.ndarray) -> list[np.ndarray]:
    """Levels 1.. (level 0 excluded) of a map's quantity ``x`` [H, W, C] (see
    :mod:`wrinklepipe.codec.encodings`): box-averaged, normals renormalised."""
    e = codec.encoding(encoding)
    levels = mip_chain(np.asarray(x, _F), min_size=1, filter="box")[1:]
    if e.is_normal:
        levels = [codec.normalize(lv) for lv in levels]
    return levels


def texel_levels(
    encoding: str,
    x: np.ndarray,
    fmt: str,
    param: float = 1.0,
    version: int = codec.CURRENT_VERSION,
) -> list[np.ndarray]:
    """8-bit component texels [h, w, 2 or 3] of every mip level 1.. in ``fmt``'s layout."""
    lay = codec.storage_format(fmt).layout_for(encoding)
    out = []
    for lv in quantity_mips(encoding, x):
        packed, _ = codec.encode(encoding, lv, lay, param=param, version=version, bits=8)
        out.append(codec.layouts.unpack(packed, lay))
    return out


def block_levels(
    encoding: str,
    x: np.ndarray,
    fmt: str,
    param: float = 1.0,
    version: int = codec.CURRENT_VERSION,
) -> list[bytes]:
    """Block data of mip levels 1.. of a map in ``fmt`` (sizes below 4 padded by edge
    replication, as every BC level is)."""
    levels = [
        cmp.pack_rgba(cmp.pad_to_blocks(q)[0], fmt)
        for q in texel_levels(encoding, x, fmt, param, version)
    ]
    if fmt == "bc5":  # every level's blocks in one encoder pass (the same bytes, faster)
        return bc4.encode_bc5_many([(a[..., 0], a[..., 1]) for a in levels])
    return [cmp.encode_bc(a, fmt) for a in levels]
