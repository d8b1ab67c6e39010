"""The sRGB transfer functions (IEC 61966-2-1:1999), exact and piecewise, and 8/16-bit texels.

Colour maps (a base colour, the albedo of a wrinkle state) are stored as an artist paints them:
sRGB-encoded UNORM texels. The wrinkle model blends colours in *linear light*
(:func:`wrinklepipe.model.combine_color`), so every reader decodes with :func:`decode_texels`
(or a GPU's sRGB sampler, which decodes each texel before it filters) and every writer encodes
with :func:`encode_texels`.

``decode``: ``v <= 0.04045 ? v / 12.92 : ((v + 0.055) / 1.055) ** 2.4``
``encode``: ``l <= 0.0031308 ? 12.92 l : 1.055 l ** (1 / 2.4) - 0.055``

Both are evaluated in float64 and returned as float32. Integer texels decode through a table of
every code (256 or 65536 entries), and :func:`encode_texels` rounds to the nearest code, so a
decode followed by an encode gives back every 8- and 16-bit code exactly (a test checks all
of them): a colour map read and written unchanged keeps its bytes.
"""

from __future__ import annotations

import functools

import numpy as np

_F = np.float32

#: IEC 61966-2-1 constants: the decode threshold, the linear segment's slope, the power curve.
DECODE_THRESHOLD = 0.04045
ENCODE_THRESHOLD = 0.0031308
LINEAR_SLOPE = 12.92
GAMMA = 2.4
OFFSET = 0.055


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] -> linear light (float32; values outside are clamped)."""
    x = np.clip(np.asarray(v, np.float64), 0.0, 1.0)
    lin = np.where(
        x <= DECODE_THRESHOLD,
        x / LINEAR_SLOPE,
        ((x + OFFSET) / (1.0 + OFFSET)) ** GAMMA,
    )
    return lin.astype(_F)


def _encode64(lin: np.ndarray) -> np.ndarray:
    x = np.clip(np.asarray(lin, np.float64), 0.0, 1.0)
    return np.where(
        x <= ENCODE_THRESHOLD,
        x * LINEAR_SLOPE,
        (1.0 + OFFSET) * x ** (1.0 / GAMMA) - OFFSET,
    )


def linear_to_srgb(lin: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] -> sRGB-encoded values (float32; values outside are clamped)."""
    return _encode64(lin).astype(_F)


@functools.cache
def _table(bits: int) -> np.ndarray:
    codes = np.arange(1 << bits, dtype=np.float64) / float((1 << bits) - 1)
    t = srgb_to_linear(codes)
    t.setflags(write=False)
    return t


def decode_texels(texels: np.ndarray) -> np.ndarray:
    """sRGB texels (uint8 or uint16, any shape) -> linear light, float32 in [0, 1]."""
    q = np.asarray(texels)
    if q.dtype == np.uint8:
        return _table(8)[q]
    if q.dtype == np.uint16:
        return _table(16)[q]
    raise ValueError(f"sRGB texels are uint8 or uint16, got {q.dtype}")


def encode_texels(lin: np.ndarray, bits: int = 8) -> np.ndarray:
    """Linear light -> sRGB texels of ``bits`` (8 or 16), rounded to the nearest code."""
    if bits not in (8, 16):
        raise ValueError(f"sRGB texels are 8 or 16 bits, got {bits}")
    top = float((1 << bits) - 1)
    v = np.rint(_encode64(lin) * top)
    return v.astype(np.uint8 if bits == 8 else np.uint16)


__all__ = [
    "DECODE_THRESHOLD",
    "ENCODE_THRESHOLD",
    "decode_texels",
    "encode_texels",
    "linear_to_srgb",
    "srgb_to_linear",
]
