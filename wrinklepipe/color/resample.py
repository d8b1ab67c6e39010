"""Colour maps at another size, filtered in linear light.

An sRGB map is decoded to linear light (:mod:`wrinklepipe.codec.srgb`), resized with the
pipeline's filter (:func:`wrinklepipe.normals.resample.resize`, lanczos3 by default), clipped
to [0, 1] and encoded back to sRGB texels: averaging the encoded values instead darkens every
edge between a light and a dark colour (a checkerboard of black and white averages to sRGB 188,
not 128).
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.codec import srgb
from wrinklepipe.normals.resample import DEFAULT_FILTER, resize


def resize_linear(
    lin: np.ndarray, size: tuple[int, int], filter: str = DEFAULT_FILTER
) -> np.ndarray:
    """Linear colours ``[H, W, C]`` resized to ``size`` = (h, w), clipped to [0, 1]."""
    a = np.asarray(lin, np.float32)
    if a.shape[:2] == tuple(size):
        return a
    return np.clip(resize(a, size, filter), 0.0, 1.0).astype(np.float32)


def resize_texels(
    texels: np.ndarray, size: tuple[int, int], filter: str = DEFAULT_FILTER
) -> np.ndarray:
    """sRGB texels ``[H, W, 3]`` resized in linear light to ``size`` (same dtype; the texels
    themselves when the size is theirs). Colour channels only: an alpha channel is data."""
    t = np.asarray(texels)[..., :3]
    if t.shape[:2] == tuple(size):
        return t
    bits = 16 if t.dtype == np.uint16 else 8
    return srgb.encode_texels(resize_linear(srgb.decode_texels(t), size, filter), bits)
