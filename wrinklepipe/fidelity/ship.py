"""What convert writes, decoded: the stored texels of each candidate the searches try.

The value mappings are :mod:`wrinklepipe.codec`'s (the version ``pipeline.package`` writes:
:data:`MAPPING_VERSION`); block formats are encoded with :mod:`wrinklepipe.normals.compress`
and decoded by its independent decoder (texture2ddecoder), exactly as the compressed copies are.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from wrinklepipe import codec, reuse
from wrinklepipe.fidelity.sampling import CHUNK_TEXELS, Reader, chunks
from wrinklepipe.masks import resample_masks
from wrinklepipe.masks.stack import MaskStack, float_masks
from wrinklepipe.normals import compress as nc
from wrinklepipe.normals.held import rows_of

_F = np.float32

#: The value mapping pipeline.package writes PD states with.
MAPPING_VERSION = codec.CURRENT_VERSION
#: Block formats the searches may pick, smallest blocks first (BC1: 8 bytes per 4x4 block).
BLOCK_FORMATS: tuple[str, ...] = ("bc1", "bc5", "bc3nm", "bc7")


def base_texels(base: np.ndarray) -> np.ndarray:
    """8-bit RGB texels of the base normal map (``0.5 + 0.5 n``), encoded in chunks of rows
    (:data:`~wrinklepipe.fidelity.sampling.CHUNK_TEXELS`: every step is per texel, so the bytes
    are those of one pass; the temporaries stay small and are reused)."""
    b = rows_of(base)  # normals held as integers: decoded a band of rows at a time
    if b.ndim != 3 or b.shape[0] * b.shape[1] <= CHUNK_TEXELS:
        return _base_texels(np.asarray(b, _F))
    out = np.empty(b.shape[:2] + (3,), np.uint8)
    for sl in chunks(b.shape[0], max(1, CHUNK_TEXELS // b.shape[1])):
        out[sl] = _base_texels(b[sl])
    return out


def _base_texels(base: np.ndarray) -> np.ndarray:
    q, _ = codec.encode(codec.BASE, codec.normalize(base), "png8", channels=3)
    return q


def decode_base(texels: np.ndarray, layout: str = "rgb") -> np.ndarray:
    """Unit normals from base texels (``rg``: z rebuilt, as from a two-channel block format)."""
    return codec.decode(codec.BASE, texels, layout, bits=8)


def pd_texels(slopes: np.ndarray, scale: float) -> tuple[np.ndarray, int]:
    """8-bit PD texels ``[..., 2]`` (R = x, G = y) of slopes at ``scale`` and the clipped count."""
    q, clipped = codec.encode(
        "pd", slopes, "rg", param=float(scale), version=MAPPING_VERSION, bits=8, channels=2
    )
    return q, int(clipped)


def decode_pd(texels: np.ndarray, scale: float) -> np.ndarray:
    """Slopes ``[..., 2]`` from 8-bit PD texels."""
    return codec.decode("pd", texels, "rg", param=float(scale), version=MAPPING_VERSION, bits=8)


def pd_reader(scale: float, quantise: bool = True) -> Reader:
    """How the measure reads a PD state: slopes stored as 8-bit texels (``quantise``: the map
    holds slopes, stored here; otherwise it holds the texels), filtered as texels, decoded as
    the shader decodes sampled values."""
    s = float(scale)
    store = (lambda x: pd_texels(x, s)[0]) if quantise else None
    read = lambda v: codec.decode_sampled(  # noqa: E731
        "pd", v * _F(1.0 / 255.0), "rg", bits=8, param=s, version=MAPPING_VERSION
    )
    return Reader(store, read)


def base_reader(layout: str = "rgb") -> Reader:
    """How the measure reads base texels (``rg``: two channels, z rebuilt after filtering)."""
    return Reader(
        None, lambda v: codec.decode_sampled(codec.BASE, v * _F(1.0 / 255.0), layout, bits=8)
    )


def edge_texels(texels: np.ndarray) -> int:
    """Texels of a stored 8-bit PD map whose x or y sits at the end of the range (``|t|``
    within half a step of 1): the clipped texels, counted the same way from any file that
    holds them (the report, the validator's WP-MAP-004)."""
    q = np.asarray(texels)[..., :2]
    m = codec.mapping(MAPPING_VERSION)
    half = 0.5 / m.centre(8)[1]
    t = m.decode(q, 8)
    return int(np.count_nonzero(np.any(np.abs(t) >= 1.0 - half, axis=-1)))


#: Levels from the end of the range within which a block format may move a texel onto it.
NEAR_EDGE_LEVELS = 16


def near_edge_texels(texels: np.ndarray) -> np.ndarray:
    """Flat indices of a stored 8-bit PD map's texels within :data:`NEAR_EDGE_LEVELS` of the end
    of the range: the only ones a block format can move onto it."""
    q = np.asarray(texels)[..., :2]
    m = codec.mapping(MAPPING_VERSION)
    near = np.any(np.abs(m.decode(q, 8)) >= 1.0 - NEAR_EDGE_LEVELS / m.centre(8)[1], axis=-1)
    return np.flatnonzero(near)


def block_roundtrip(xy: np.ndarray, fmt: str) -> np.ndarray:
    """Two-channel 8-bit texels ``[H, W, 2]`` through block format ``fmt`` and back (sizes not a
    multiple of 4 are padded by edge replication, as the compressed copies are)."""
    q = np.ascontiguousarray(xy[..., :2], np.uint8)
    h, w = q.shape[:2]
    qp, _ = nc.pad_to_blocks(q)
    hp, wp = qp.shape[:2]
    data = nc.encode_bc(nc.pack_rgba(qp, fmt), fmt)
    return np.ascontiguousarray(nc.unpack_u8(nc.decode_bc(data, wp, hp, fmt), fmt, 2)[:h, :w])


def block_roundtrip_at(xy: np.ndarray, fmt: str, texels: np.ndarray) -> np.ndarray:
    """Like :func:`block_roundtrip`, but only the 4x4 blocks that hold ``texels`` (flat indices)
    are encoded and decoded (blocks are independent, so those texels come out as a whole-map
    roundtrip gives them); every other texel is returned unchanged."""
    return block_roundtrip_many([xy], fmt, [texels])[0]


def block_roundtrip_many(
    maps: Sequence[np.ndarray], fmt: str, texels: Sequence[np.ndarray | None]
) -> list[np.ndarray]:
    """:func:`block_roundtrip_at` of several maps in one encoder pass: the blocks that hold each
    map's ``texels`` (None: every block of it) are laid out side by side in one tile, encoded
    and decoded once (an encoder call has a fixed cost of tens of ms on a small map, and blocks
    are independent), and scattered back. Only the picked blocks are gathered and written
    back (a copy of the map keeps every other texel)."""
    picked, layouts = [], []
    for xy, t in zip(maps, texels):
        q = np.asarray(xy)[..., :2]
        if q.dtype != np.uint8:
            q = q.astype(np.uint8)
        h, w = q.shape[:2]
        qp, _ = nc.pad_to_blocks(q)
        hp, wp = qp.shape[:2]
        bw = wp // 4
        grid = qp.reshape(hp // 4, 4, bw, 4, 2)  # [block row, y, block column, x, c]
        if t is None:
            ids = np.arange((hp // 4) * bw)
            blocks = grid.transpose(0, 2, 1, 3, 4).reshape(-1, 4, 4, 2)
        else:
            ti = np.asarray(t, np.int64)
            mark = np.zeros((hp // 4) * bw, bool)
            mark[(ti // w) // 4 * bw + (ti % w) // 4] = True
            ids = np.flatnonzero(mark)
            blocks = grid[ids // bw, :, ids % bw]  # [n, 4, 4, 2], the blocks in order
        picked.append(blocks)
        layouts.append((q, qp, ids))
    allb = np.concatenate(picked) if picked else np.zeros((0, 4, 4, 2), np.uint8)
    if allb.shape[0]:
        side = int(np.ceil(np.sqrt(allb.shape[0])))
        pad = np.repeat(allb[-1:], side * side - allb.shape[0], axis=0)
        tile = np.concatenate([allb, pad]).reshape(side, side, 4, 4, 2).transpose(0, 2, 1, 3, 4)
        tile = np.ascontiguousarray(tile.reshape(side * 4, side * 4, 2))
        data = nc.encode_bc(nc.pack_rgba(tile, fmt), fmt)
        dec = nc.unpack_u8(nc.decode_bc(data, side * 4, side * 4, fmt), fmt, 2)
        dec = dec.reshape(side, 4, side, 4, 2).transpose(0, 2, 1, 3, 4).reshape(-1, 4, 4, 2)
        # a map encoded whole here is the copy convert writes: its blocks' bytes are what
        # encoding that map alone gives (blocks are independent), so that call is a hit
        bb, at = nc.BLOCK_BYTES[fmt], 0
        for _, qp, ids in layouts:
            if ids.size == (qp.shape[0] // 4) * (qp.shape[1] // 4):  # every block: whole
                part = data[at * bb : (at + ids.size) * bb]
                reuse.remember(nc.encode_bc, part, nc.pack_rgba(np.ascontiguousarray(qp), fmt), fmt)
            at += ids.size
    out, at = [], 0
    for q, qp, ids in layouts:
        h, w = q.shape[:2]
        hp, wp = qp.shape[:2]
        got = np.array(qp, np.uint8, order="C")  # a copy: every texel not re-encoded kept
        if ids.size:
            grid = got.reshape(hp // 4, 4, wp // 4, 4, 2)
            grid[ids // (wp // 4), :, ids % (wp // 4)] = dec[at : at + ids.size]
            at += ids.size
        out.append(got if (hp, wp) == (h, w) else np.ascontiguousarray(got[:h, :w]))
    return out


class MaskLevels(dict):
    """``{side: masks as shipped}`` (see :func:`mask_levels`); a level is stored in 8 bits the
    first time it is read (:func:`mask_levels` stores its halvings so as it makes them)."""

    def __init__(
        self, levels: dict[int, np.ndarray], source: int, stored: set[int] | None = None
    ) -> None:
        super().__init__(levels)
        self.source = source
        self._stored: set[int] = {source, *(stored or ())}

    def __getitem__(self, size: int) -> np.ndarray:
        v = super().__getitem__(size)
        if size not in self._stored:
            v = _u8_values(v)
            super().__setitem__(size, v)
            self._stored.add(size)
        return v


def mask_levels(masks: np.ndarray, min_size: int = 1) -> MaskLevels:
    """``{side: masks as shipped}``: the source masks as given, and every 2 x 2 box halving of
    them down to ``min_size`` (a box of boxes is the box of the whole factor, as
    :func:`wrinklepipe.masks.resample_masks` gives) stored in 8 bits."""
    m = float_masks(masks)  # a MaskStack stays integers: its masks are read a band at a time
    h = m.shape[1]
    out = {h: m}
    acc = m
    stored: set[int] = set()
    while h % 2 == 0 and h // 2 >= min_size and acc.shape[2] % 2 == 0:
        r, w = acc.shape[0], acc.shape[2]
        half = np.empty((r, h // 2, w // 2), _F)
        # one mask and a chunk of output rows at a time: its float64 temporaries stay small
        for i in range(r):
            for sl in chunks(h // 2, max(1, CHUNK_TEXELS // w)):
                pairs = acc[i, 2 * sl.start : 2 * sl.stop].reshape(-1, 2, w)
                rows = np.add(pairs[:, 0], pairs[:, 1], dtype=np.float64).reshape(-1, w // 2, 2)
                quad = np.add(rows[..., 0], rows[..., 1])  # the 2x2 sum in float64 (exact for
                quad *= 0.25  # 4 float32 values of a mask's range), rounded to float32 once
                half[i, sl] = quad
        if h != m.shape[1]:  # the level halved from: made, now stored in 8 bits
            out[h] = _u8_level(acc)
            stored.add(h)
        acc = half
        h //= 2
        out[h] = acc
    if h != m.shape[1]:
        out[h] = _u8_level(acc)
        stored.add(h)
    return MaskLevels(out, int(m.shape[1]), stored)


#: The float32 of every 8-bit level of a shipped mask: ``k / 255`` as :func:`_u8_values` divides.
_U8_TABLE = np.arange(256, dtype=_F) / 255.0


class U8Masks(MaskStack):
    """Masks as shipped in 8 bits (a search's mask level): integers ``k`` seen as the float32
    ``k / 255`` that :func:`_u8_values` gives (not the image reader's ``k * (1 / 255)``: the
    two differ in the last bit for half the levels). A quarter of float32's memory."""

    def __getitem__(self, key: Any) -> np.ndarray:
        return _U8_TABLE[np.asarray(self.q[key])]

    def float_of(self, q: np.ndarray) -> np.ndarray:
        return _U8_TABLE[q]

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> np.ndarray:
        a = _U8_TABLE[self.q]
        return a if dtype is None else a.astype(dtype, copy=False)

    def __deepcopy__(self, memo: dict[int, Any]) -> U8Masks:
        return U8Masks(self.q.copy())


def _u8_level(m: np.ndarray) -> np.ndarray:
    """:func:`_u8_values` of masks ``[R, h, w]``, held as :class:`U8Masks` (a mask at a time;
    each mask checked to read back bit for bit, else the float32 values)."""
    q = np.empty(m.shape, np.uint8)
    for i in range(m.shape[0]):
        f = _u8_values(np.asarray(m[i], _F))
        k = np.rint(f * _F(255.0))  # the level f came from (NaN: no level, the check fails)
        with np.errstate(invalid="ignore"):
            q[i] = k.astype(np.uint8)
        if not np.array_equal(_U8_TABLE[q[i]].view(np.uint32), f.view(np.uint32)):
            return _u8_values(np.asarray(m, _F))
    return U8Masks(q)


def _u8_values(m: np.ndarray) -> np.ndarray:
    return (np.rint(np.clip(m, 0.0, 1.0) * 255.0) / 255.0).astype(_F)


def mask_values(masks: np.ndarray, size: int | None = None) -> np.ndarray:
    """Masks as shipped at ``size`` (None: as given): :func:`mask_levels` for a halving of the
    source, else :func:`wrinklepipe.masks.resample_masks`; stored in 8 bits.

    A :class:`~wrinklepipe.masks.stack.MaskStack` is read a mask (or a band) at a time: the
    float32 stack of every source mask is made only for a resample that is not a halving."""
    m = float_masks(masks)
    if size is None or size == m.shape[1]:
        out = np.empty(m.shape, _F)
        for i in range(m.shape[0]):  # per texel: the whole stack's values, a mask's temporaries
            out[i] = _u8_values(np.asarray(m[i], _F))
        return out
    levels = mask_levels(m, size)
    if size in levels:
        return np.asarray(levels[size], _F)
    return _u8_values(resample_masks(np.asarray(m, _F), size))
