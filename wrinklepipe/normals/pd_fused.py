"""The fused PD path: encode unit normals to 8-bit PD texels, pack, block-compress and measure the
angle error in one pass over row chunks (per-thread workspaces, no full-size temporaries): what
the benchmarks time and the whole-map checks of :mod:`wrinklepipe.normals.compress` agree with."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from wrinklepipe import codec
from wrinklepipe.metrics import Stats, angle_deg_planes
from wrinklepipe.normals import encode as enc
from wrinklepipe.normals._chunks import map_rows
from wrinklepipe.normals.compress import (
    _BGRA_XY,
    check_format,
    decode_bc_bgra,
    encode_bc,
    error_stats,
    pad_to_blocks,
)

_F = np.float32


#: Byte position of x and y inside a little-endian RGBA8 texel (R = 0 ... A = 3) per format,
#: the constant bytes around them, and where texture2ddecoder's BGRA output puts x and y.
_PACK = {
    "bc5": (0, 1, 0xFF000000),
    "bc1": (0, 1, 0xFF000000),
    "bc7": (0, 1, 0xFF000000),
    "bc7xy": (0, 1, 0xFF000000),
    "bc3nm": (3, 1, 0x000000FF),
}


_LOCAL = threading.local()


def _ws(name: str, shape: tuple[int, ...], dtype: type = np.float32) -> np.ndarray:
    """A per-thread scratch array, reused across chunks (fresh arrays cost page faults)."""
    cache = getattr(_LOCAL, "ws", None)
    if cache is None:
        cache = _LOCAL.ws = {}
    key = (name, dtype)
    arr = cache.get(key)
    size = int(np.prod(shape))
    if arr is None or arr.size < size:
        arr = cache[key] = np.empty(size, dtype=dtype)
    return arr[:size].reshape(shape)


def _half_planes(nc: np.ndarray) -> np.ndarray:
    """Planar normals [3, h, w] (a plain copy: contiguous planes are ~3x faster to work on
    than strided ones, and a copy is cheaper than a scaled copy)."""
    p = _ws("planes", (3,) + nc.shape[:2])
    np.copyto(p, nc.transpose(2, 0, 1))
    return p


def _byte_plane(v: np.ndarray, byte: int, out: np.ndarray, centre: float) -> np.ndarray:
    """``float32(byte ``byte`` of each uint32 texel) - centre`` into ``out`` (cheapest path
    found per byte: narrowing casts truncate, so no masking is needed)."""
    shape = v.shape
    if byte == 1:
        t16 = _ws("u16", shape, np.uint16)
        np.copyto(t16, v, casting="unsafe")  # B | G << 8
        np.right_shift(t16, np.uint16(8), out=t16)
        np.copyto(out, t16, casting="unsafe")
    else:
        t32 = _ws("u32", shape, np.uint32)
        np.right_shift(v, np.uint32(8 * byte), out=t32)
        t8 = _ws("u8", shape, np.uint8)
        np.copyto(t8, t32, casting="unsafe")
        np.copyto(out, t8, casting="unsafe")
    out -= _F(centre)
    return out


def _pd_pack_chunk(
    p: np.ndarray, s: float, fmt: str, version: int, targets: np.ndarray | None = None
) -> tuple[np.ndarray, int]:
    """8-bit PD texels of normal planes, packed as RGBA8 for ``fmt``; clipped count.

    ``q = floor(c + h t + 0.5)`` with the mapping's centre ``c`` and steps ``h``, t clipped to
    [-1, 1] (as :func:`wrinklepipe.normals.encode.encode_pd_u8`). The RGBA array is a
    per-thread scratch buffer: use it before the next call.
    """
    c, half = codec.mapping(version).centre(8)
    hx, hy, hz = p
    shape = hx.shape
    k = _F(half / s)
    r = _ws("f0", shape)
    if float(hz.min()) <= 0.0:
        np.maximum(hz, _F(5e-31), out=r)
        np.divide(k, r, out=r)
    else:
        np.divide(k, hz, out=r)
    ux = np.multiply(hx, r, out=_ws("f1", shape))
    uy = np.multiply(hy, r, out=r)
    lim = _F(half)
    if max(float(ux.max()), -float(ux.min()), float(uy.max()), -float(uy.min())) <= lim:
        clipped = 0  # the common case, from four reductions
    else:
        a = np.abs(ux, out=_ws("f2", shape))
        b = np.abs(uy, out=_ws("f3", shape))
        np.maximum(a, b, out=a)
        clipped = int(np.count_nonzero(np.greater(a, lim, out=_ws("m", shape, np.bool_))))
    # quantise: floor(clip(c + u + 0.5, c - h, c + h + 0.5)), capped at c + h; ``targets``
    # receives the unrounded texels c + h t (t clipped), which the BC4-based encoders fit
    for ch, u in enumerate((ux, uy)):
        u += _F(c + 0.5)
        np.clip(u, _F(c - half), _F(c + half + 0.5), out=u)
        if targets is not None:
            np.subtract(u, _F(0.5), out=targets[..., ch])
            np.maximum(targets[..., ch], _F(c - half), out=targets[..., ch])
        np.floor(u, out=u)
        np.minimum(u, _F(c + half), out=u)
    px, py, const = _PACK[fmt]
    lo, hi = (ux, uy) if px < py else (uy, ux)
    hi *= _F(1 << (abs(px - py) * 8))
    hi += lo  # exact: < 2^24
    pix = _ws("u0", shape, np.uint32)
    np.copyto(pix, hi, casting="unsafe")
    if min(px, py):
        np.left_shift(pix, np.uint32(8 * min(px, py)), out=pix)
    if fmt != "bc5":  # BC5 reads R and G only
        np.bitwise_or(pix, np.uint32(const), out=pix)
    return pix.view(np.uint8).reshape(shape + (4,)), clipped


def _pd_measure_chunk(
    raw: np.ndarray, p: np.ndarray, s: float, fmt: str, out: np.ndarray, version: int
) -> np.ndarray:
    """Angles in degrees (:func:`wrinklepipe.metrics.angle_deg_planes`, into ``out``) between
    decoded PD texels (BGRA) and normal planes ``p``.

    With ``u = q - c`` (texel units; v2 clamps at -h like the codec) the decoded slope is
    ``u t`` (``t = s / h``), so ``n = (u_x, u_y, 1 / t) / sqrt(u_x^2 + u_y^2 + 1 / t^2)``.
    """
    c, half = codec.mapping(version).centre(8)
    shape = p.shape[1:]
    ix, iy = _BGRA_XY[fmt]
    kk = _F((half / s) ** 2)  # 1 / t^2
    kz = _F(half / s)  # 1 / t
    v = raw.view(np.uint32).reshape(shape)
    n = _ws("n", (3,) + shape)
    dx = _byte_plane(v, ix, n[0], c)
    dy = _byte_plane(v, iy, n[1], c)
    if version >= 2:
        np.maximum(dx, _F(-half), out=dx)
        np.maximum(dy, _F(-half), out=dy)
    inv = np.multiply(dx, dx, out=n[2])
    a = np.multiply(dy, dy, out=_ws("f3", shape))
    inv += a
    inv += kk
    np.sqrt(inv, out=inv)
    np.divide(_F(1.0), inv, out=inv)
    dx *= inv  # nx
    dy *= inv  # ny
    inv *= kz  # nz
    return angle_deg_planes(n, p, out=out)


def pd_pack(
    normals: np.ndarray, scale: float, fmt: str = "bc5", version: int = codec.CURRENT_VERSION
) -> tuple[np.ndarray, int]:
    """Unit normals [H, W, 3] (H, W multiples of 4) -> RGBA8 PD texels for ``fmt``; clipped."""
    n = np.asarray(normals, dtype=_F)
    h, w = n.shape[:2]
    rgba = np.empty((h, w, 4), dtype=np.uint8)

    def work(rows: slice) -> int:
        packed, clipped = _pd_pack_chunk(_half_planes(n[rows]), float(scale), fmt, version)
        rgba[rows] = packed
        return clipped

    return rgba, int(sum(map_rows(work, h, w)))


@dataclass
class PDCheck:
    """Result of :func:`pd_compress_check`: the block data and what it costs in degrees."""

    format: str
    width: int
    height: int
    scale: float
    clipped: int
    data: bytes
    error: Stats  # decoded (texture2ddecoder) vs the source normals
    padded: bool = False


def pd_compress_check(
    normals: np.ndarray,
    scale: float | str = 1.0,
    fmt: str = "bc5",
    pad: bool = True,
    angles_out: np.ndarray | None = None,
    version: int = codec.CURRENT_VERSION,
) -> PDCheck:
    """PD-encode unit normals [H, W, 3] to 8 bits, block-compress, decode, measure.

    The same texels as :func:`encode.encode_pd_u8` then :func:`pack_rgba`, :func:`encode_bc`
    and :func:`decode_bc`: packing and measuring are fused per row chunk on the threads, the
    encoder runs once over the whole map (BC5 / BC3nm fit the unrounded texels).
    ``angles_out`` ([H, W] float32) receives per-texel angles in degrees.
    """
    check_format(fmt)
    n = np.asarray(normals, dtype=_F)
    if n.ndim != 3 or n.shape[-1] != 3:
        raise ValueError(f"normals must be [H, W, 3], got shape {n.shape}")
    s = enc.auto_pd_scale(n) if scale == "auto" else float(scale)
    h, w = n.shape[:2]
    padded = bool(h % 4 or w % 4)
    if padded and not pad:
        raise ValueError(
            f"{fmt} needs sizes that are multiples of 4; {w} x {h} is not (allow padding or resize)"
        )
    src = n
    if padded:
        n, _ = pad_to_blocks(n)
    hp, wp = n.shape[:2]
    angles = np.empty((hp, wp), dtype=_F)

    rgba = np.empty((hp, wp, 4), dtype=np.uint8)
    targets = np.empty((hp, wp, 2), dtype=_F)

    def work(rows: slice) -> int:
        packed, clipped = _pd_pack_chunk(_half_planes(n[rows]), s, fmt, version, targets[rows])
        rgba[rows] = packed
        return clipped

    results = map_rows(work, hp, wp)
    clipped = sum(results)
    data = encode_bc(rgba, fmt, targets)  # one call: the encoder's choices see the whole map
    bgra = decode_bc_bgra(data, wp, hp, fmt)

    def measure(rows: slice) -> None:
        _pd_measure_chunk(bgra[rows], _half_planes(n[rows]), s, fmt, angles[rows], version)

    map_rows(measure, hp, wp)
    if padded:
        clipped = enc.pd_clipped_count(src, s)
        angles = np.ascontiguousarray(angles[:h, :w])
    err = error_stats(angles)
    if angles_out is not None:
        np.copyto(angles_out, angles)
    return PDCheck(fmt, w, h, s, int(clipped), data, err, padded)
