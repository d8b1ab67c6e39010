"""Mip chains of stored maps, filtered where averaging means something (DESIGN.md section 9).

PD slopes and difference deltas are linear in the height field, so their mips are plain box
averages of the quantity; unit normals (the base, ``full`` and ``composite`` states) are
averaged as vectors and renormalised. Each level is then stored exactly as level 0 is: the
codec's texels in the format's layout, block-compressed by :func:`compress.encode_bc`.
Halving is floor(size / 2) down to 1 x 1 (the DDS / KTX2 convention).

A chain is made one level at a time: level 1 band by band from level 0's rows (level 0's
quantity is never whole: :func:`levels_of`), each next level from the one before (unnormalised,
as :func:`wrinklepipe.normals.resample.mip_chain` does), each stored and let go before the next
is made. The bytes are the whole-image chain's (:func:`resample.resize_bands`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np

from wrinklepipe import codec
from wrinklepipe.normals import bc4
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals.resample import resize, resize_bands

_F = np.float32

#: A map's quantity rows: ``read(rows)`` -> float32 ``[rows, W, C]``.
RowReader = Callable[[slice], np.ndarray]


def level_count(width: int, height: int) -> int:
    """Levels of a full chain: ``floor(log2(max(w, h))) + 1``."""
    return max(int(width), int(height)).bit_length()


def levels_of(
    encoding: str, read: RowReader, shape: tuple[int, int, int], rows: int | None = None
) -> Iterator[np.ndarray]:
    """Levels 1.. (level 0 excluded) of a map's quantity ``[H, W, C]`` (see
    :mod:`wrinklepipe.codec.encodings`), one at a time: box-averaged, normals renormalised.
    Level 0 is read band by band (``read(rows)``, bands of at most ``rows`` output rows), so
    only level 1 and one band of level 0 are held; then each level is made from the one before
    and the one before is let go. The values of :func:`quantity_mips` of the whole map."""
    e = codec.encoding(encoding)
    h, w, c = shape
    if max(h, w) <= 1:
        return
    h, w = max(1, h // 2), max(1, w // 2)
    cur = np.empty((h, w, c), _F)
    for r, band in resize_bands(read, shape, (h, w), "box", rows):
        cur[r] = band
    while True:
        yield codec.normalize(cur) if e.is_normal else cur
        if max(h, w) <= 1:
            return
        h, w = max(1, h // 2), max(1, w // 2)
        cur = resize(cur, (h, w), "box")


def _whole(x: np.ndarray) -> tuple[RowReader, tuple[int, int, int]]:
    a = np.asarray(x, _F)
    return (lambda r: a[r]), a.shape  # type: ignore[return-value]


def quantity_mips(encoding: str, x: np.ndarray) -> list[np.ndarray]:
    """Levels 1.. (level 0 excluded) of a map's quantity ``x`` [H, W, C] (see
    :mod:`wrinklepipe.codec.encodings`): box-averaged, normals renormalised."""
    return list(levels_of(encoding, *_whole(x)))


def _texels(encoding: str, lv: np.ndarray, fmt: str, param: float, version: int) -> np.ndarray:
    lay = codec.storage_format(fmt).layout_for(encoding)
    packed, _ = codec.encode(encoding, lv, lay, param=param, version=version, bits=8)
    return codec.layouts.unpack(packed, lay)


def texel_levels_of(
    encoding: str,
    read: RowReader,
    shape: tuple[int, int, int],
    fmt: str,
    param: float = 1.0,
    version: int = codec.CURRENT_VERSION,
) -> Iterator[np.ndarray]:
    """8-bit component texels [h, w, 2 or 3] of every mip level 1.. in ``fmt``'s layout, one
    level at a time, level 0's quantity read band by band (:func:`levels_of`)."""
    for lv in levels_of(encoding, read, shape):
        yield _texels(encoding, lv, fmt, param, version)


def texel_levels(
    encoding: str,
    x: np.ndarray,
    fmt: str,
    param: float = 1.0,
    version: int = codec.CURRENT_VERSION,
) -> list[np.ndarray]:
    """8-bit component texels [h, w, 2 or 3] of every mip level 1.. in ``fmt``'s layout."""
    return list(texel_levels_of(encoding, *_whole(x), fmt, param, version))


def block_levels_of(
    encoding: str,
    read: RowReader,
    shape: tuple[int, int, int],
    fmt: str,
    param: float = 1.0,
    version: int = codec.CURRENT_VERSION,
) -> list[bytes]:
    """Block data of mip levels 1.. of a map in ``fmt`` (sizes below 4 padded by edge
    replication, as every BC level is), level 0's quantity read band by band and each level
    encoded before the next is made (BC5: every level's two components, then one encoder
    pass)."""
    levels: list[bytes] = []
    pairs: list[tuple[np.ndarray, np.ndarray]] = []
    for q in texel_levels_of(encoding, read, shape, fmt, param, version):
        a = cmp.pack_rgba(cmp.pad_to_blocks(q)[0], fmt)
        if fmt == "bc5":  # every level's blocks in one encoder pass (the same bytes, faster)
            pairs.append((a[..., 0].copy(), a[..., 1].copy()))
        else:
            levels.append(cmp.encode_bc(a, fmt))
    return bc4.encode_bc5_many(pairs) if fmt == "bc5" else levels


def block_levels(
    encoding: str,
    x: np.ndarray,
    fmt: str,
    param: float = 1.0,
    version: int = codec.CURRENT_VERSION,
) -> list[bytes]:
    """Block data of mip levels 1.. of a map ``x`` [H, W, C] (its quantity) in ``fmt``
    (:func:`block_levels_of`)."""
    return block_levels_of(encoding, *_whole(x), fmt, param, version)
