"""Decode shipped texture bytes to stored texels and values, and sample them as the GPU does.

Everything here is numpy; BCn blocks are decoded by ``texture2ddecoder`` (BGRA output, swapped
to RGBA). Stored values become quantities through :mod:`wrinklepipe.codec` only: exactly from
integer texels (:func:`decode_texels`), or with the shaders' float arithmetic from sampled values
(:func:`decode_state`, :func:`values_to_normals`). A map declared DirectX is flipped after
decoding (``y = -y``), as the shaders do. :func:`bilinear` reproduces ``GL_LINEAR`` with
``GL_CLAMP_TO_EDGE`` and no mipmaps, which is how the render pass samples, so the numpy reference
sees the texels the shader sees.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import texture2ddecoder as t2d

from wrinklepipe import codec
from wrinklepipe.masks.stack import MaskStack
from wrinklepipe.validate.inputs import FORMATS, Texture
from wrinklepipe.workset import band_rows


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB transfer function a GPU applies when a texture is tagged sRGB."""
    c = np.asarray(c, np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def texels(tex: Texture) -> np.ndarray:
    """Level-0 texels as stored: uint8 (8-bit and BCn, decoded by texture2ddecoder), uint16, or
    float32 for float formats; ``[H, W, C]`` with C the format's channels, RGBA order.

    Raises ``ValueError`` when the byte count does not match the format and size.
    """
    ch, _, kind = FORMATS[tex.fmt]
    if len(tex.data) < tex.expected_size():
        raise ValueError(
            f"{tex.fmt} {tex.width}x{tex.height} needs {tex.expected_size()} bytes, "
            f"has {len(tex.data)}"
        )
    h, w = tex.height, tex.width
    if kind == "unorm8":
        return np.frombuffer(tex.data, np.uint8, count=h * w * ch).reshape(h, w, ch)
    if kind == "unorm16":
        return np.frombuffer(tex.data, "<u2", count=h * w * ch).reshape(h, w, ch).astype(np.uint16)
    if kind == "float":
        return np.frombuffer(tex.data, "<f4", count=h * w * ch).reshape(h, w, ch)
    return block_texels(tex.data, tex.fmt, w, h, ch)


#: Bytes per texel of a band while decoding blocks (texture2ddecoder's BGRA, its RGBA pick).
BLOCK_DECODE_BYTES = 8


def block_texels(data: bytes, fmt: str, w: int, h: int, ch: int) -> np.ndarray:
    """Level-0 texels ``[h, w, ch]`` (RGBA order) of ``fmt`` block data decoded by
    texture2ddecoder, band by band of block rows into one array: every block decodes on its
    own, so each band's texels are the whole decode's (no whole BGRA decode and RGBA copy
    besides the texels: 512 MiB at 8192²)."""
    pw, ph = (w + 3) // 4 * 4, (h + 3) // 4 * 4
    fn = getattr(t2d, f"decode_{fmt}")
    row_bytes = (pw // 4) * FORMATS[fmt][1]  # one row of blocks
    rows = max(4, band_rows(pw, BLOCK_DECODE_BYTES) // 4 * 4)
    pick = [2, 1, 0, 3][:ch]
    out = np.empty((h, w, ch), np.uint8)
    for r0 in range(0, h, rows):
        r1 = min(ph, r0 + rows)
        part = fn(bytes(data[r0 // 4 * row_bytes : r1 // 4 * row_bytes]), pw, r1 - r0)
        bgra = np.frombuffer(part, np.uint8).reshape(r1 - r0, pw, 4)
        out[r0 : min(r1, h)] = bgra[: min(r1, h) - r0, :w][..., pick]
    return out


def unorm_values(q: np.ndarray) -> np.ndarray:
    """Stored texels as values in [0, 1] (float32), each on its own: :func:`decode_values`
    without the sRGB step (so of any subset of the texels, the same floats)."""
    return codec.dequantize_unorm(q)


def decode_values(
    tex: Texture, apply_srgb: bool = False, q: np.ndarray | None = None
) -> np.ndarray:
    """Stored values of level 0 as float32 ``[H, W, C]`` in [0, 1] (C = the format's channels);
    ``q``: its :func:`texels` when they are at hand.

    Raises ``ValueError`` when the byte count does not match the format and size.
    """
    out = unorm_values(texels(tex) if q is None else q)
    if apply_srgb and tex.srgb and FORMATS[tex.fmt][2] != "float":
        rgb = min(out.shape[-1], 3)
        out = out.copy()
        out[..., :rgb] = srgb_to_linear(out[..., :rgb])
    return out


def xy_layout(tex: Texture) -> str:
    """Where a normal map keeps x, y (and z): ``"rgb"``, ``"rg"`` (z rebuilt) or ``"ag"``.

    A recorded layout is what the writer used (a two-channel BC7 copy is ``rg`` in a
    four-channel texture); without one (``None``) it follows the channel count."""
    if tex.layout in ("ag", "rg", "rg2"):  # rg2: an older name of rg
        return "ag" if tex.layout == "ag" else "rg"
    return "rgb" if tex.channels >= 3 else "rg"


def _flip(x: np.ndarray, flip_y: bool) -> np.ndarray:
    if not flip_y:
        return x
    x = np.array(x, np.float32, copy=True)
    x[..., 1] *= np.float32(-1.0)
    return x


def values_to_normals(values: np.ndarray, layout: str, flip_y: bool = False) -> np.ndarray:
    """Unit normals from stored (sampled) values: ``normalize(2 v - 1)``; two-channel layouts
    rebuild z; ``flip_y`` reads a DirectX map as +Y (the codec's ``wp_normal``)."""
    n = codec.decode_sampled("full", np.asarray(values, np.float32), layout, bits=8)
    return _flip(n, flip_y)


def raw_normals(values: np.ndarray, layout: str) -> np.ndarray:
    """``2 v - 1`` without normalising (to check unit length and z >= 0 of three-channel maps)."""
    v = np.asarray(values, np.float32)
    if layout == "rgb":
        return 2.0 * v[..., :3] - 1.0
    return values_to_normals(v, layout)


def signed_values(values: np.ndarray, tex: Texture, encoding: str) -> np.ndarray:
    """The signed values ``t`` in [-1, 1] that a texture's (sampled) values hold under its
    encoding's mapping (pd / diff: the texture's mapping version; normal maps: glTF)."""
    m = codec.encoding(encoding).mapping(tex.mapping)
    return m.decode_unorm(np.asarray(values, np.float32), tex.bits)


def decode_state(
    values: np.ndarray,
    encoding: str,
    layout: str,
    pd_scale: float,
    version: int = 1,
    bits: int = 8,
    flip_y: bool = False,
) -> np.ndarray:
    """What the model's ``combine`` takes for one state (see :func:`wrinklepipe.model.combine`)
    from sampled values ``[..., C]`` in [0, 1], with the shaders' arithmetic.

    pd: slopes ``[..., 2]`` (``t = d / scale`` under mapping ``version``); diff: ``D`` with the
    gain undone (``2 D - 1 = W - B``); full / composite: unit normals.
    """
    e = codec.encoding(encoding)
    v = np.asarray(values, np.float32)
    if e.name == "diff" and v.shape[-1] < 3:
        raise ValueError("a diff map needs three channels")
    where = "rgb" if e.name == "diff" else layout
    x = codec.decode_sampled(e, v, where, bits=bits, param=pd_scale, version=version)
    return e.combine_input(_flip(x, flip_y))


def decode_texels(
    q: np.ndarray,
    encoding: str,
    layout: str,
    pd_scale: float,
    version: int = 1,
    flip_y: bool = False,
) -> np.ndarray:
    """Like :func:`decode_state` from integer texels, exactly (:func:`wrinklepipe.codec.decode`):
    what the validator's shipped-data rules read. ``encoding="base"`` decodes a base map."""
    e = codec.encoding("full" if encoding == "base" else encoding)
    where = "rgb" if e.name == "diff" else layout
    x = codec.decode(e, q, where, param=pd_scale, version=version)
    return e.combine_input(_flip(x, flip_y))


def bilinear(
    img: np.ndarray, uv: np.ndarray, read: Callable[[np.ndarray], np.ndarray] | None = None
) -> np.ndarray:
    """Sample ``img [H, W, C]`` at ``uv [N, 2]`` like GL_LINEAR + CLAMP_TO_EDGE -> ``[N, C]``.
    ``read``: a per-texel function of ``img``'s texels (stored integers -> values), applied to
    the texels each tap reads: ``bilinear(read(img), uv)`` without ``read`` of the whole map."""
    h, w = img.shape[:2]
    flat = img.reshape(h * w, -1)

    def gather(rows: np.ndarray) -> np.ndarray:  # np.take: the same rows, ~5x faster than flat[i]
        # (normals held as integers: their texels decoded where the taps read)
        got = np.take(flat, rows, axis=0) if isinstance(flat, np.ndarray) else flat[rows]
        return got if read is None else read(got)

    return bilinear_at(gather, (h, w), uv)


def bilinear_at(
    gather: Callable[[np.ndarray], np.ndarray], shape: tuple[int, int], uv: np.ndarray
) -> np.ndarray:
    """:func:`bilinear` of the ``[H, W, C]`` map whose texels ``gather`` gives (flat indices
    ``[n]`` -> ``[n, C]``): a map made per texel is sampled from the texels the taps read."""
    h, w = shape
    x = uv[:, 0].astype(np.float64) * w - 0.5
    y = uv[:, 1].astype(np.float64) * h - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx = (x - x0).astype(np.float32)[:, None]
    fy = (y - y0).astype(np.float32)[:, None]
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xa, xb = np.clip(x0, 0, w - 1), np.clip(x0 + 1, 0, w - 1)
    ya, yb = np.clip(y0, 0, h - 1), np.clip(y0 + 1, 0, h - 1)
    top = gather(ya * w + xa) * (1 - fx) + gather(ya * w + xb) * fx
    bot = gather(yb * w + xa) * (1 - fx) + gather(yb * w + xb) * fx
    return (top * (1 - fy) + bot * fy).astype(np.float32)


def bilinear_planes(planes: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``bilinear(np.moveaxis(planes, 0, -1), uv)`` of planes ``[R, H, W]`` (masks) -> ``[N, R]``,
    the same values (every channel is sampled on its own), sampled plane by plane: no
    channels-last copy of every plane at full size (2 GB for eight 8192² masks). A
    :class:`~wrinklepipe.masks.stack.MaskStack`'s integers are read at the taps and made float32
    there (per texel: the float32 plane's values), without a float32 plane (256 MiB at 8192²)."""
    out = np.empty((len(uv), len(planes)), np.float32)
    for i in range(len(planes)):  # a plane at a time
        if isinstance(planes, MaskStack):  # its integers, made float32 at the taps only
            out[:, i] = bilinear(planes.integers(i)[..., None], uv, planes.float_of)[:, 0]
        else:
            out[:, i] = bilinear(np.asarray(planes[i])[..., None], uv)[:, 0]
    return out


def resize_bilinear(
    img: np.ndarray, h: int, w: int, read: Callable[[np.ndarray], np.ndarray] | None = None
) -> np.ndarray:
    """Resample ``[H, W, C]`` to ``[h, w, C]`` by bilinear sampling at texel centres.
    ``read``: a per-texel function of ``img``'s texels ``[n, C]`` (as :func:`bilinear`'s),
    applied to the texels the taps read (every texel at the same size)."""
    if img.shape[0] == h and img.shape[1] == w:
        if read is None:
            return img
        return np.asarray(read(img.reshape(h * w, -1))).reshape(h, w, -1)
    return bilinear(img, _centres(h, w), read).reshape(h, w, -1)


def _centres(h: int, w: int) -> np.ndarray:
    """The UVs ``[h * w, 2]`` of an ``h`` x ``w`` grid's texel centres, row by row."""
    cu = (np.arange(w) + 0.5) / w
    cv = (np.arange(h) + 0.5) / h
    uu, vv = np.meshgrid(cu, cv, indexing="xy")
    return np.stack([uu.ravel(), vv.ravel()], axis=-1)


def resize_bilinear_at(
    gather: Callable[[np.ndarray], np.ndarray], shape: tuple[int, int], h: int, w: int
) -> np.ndarray:
    """:func:`resize_bilinear` of the ``shape`` = (H, W) map whose texels ``gather`` gives
    (flat indices ``[n]`` -> ``[n, C]``, as :func:`bilinear_at`'s) to another size: only the
    texels the taps read are asked for."""
    return bilinear_at(gather, shape, _centres(h, w)).reshape(h, w, -1)
