"""Colour states made from a base colour, as a blood-flow rig has them.

Skin changes colour with an expression because blood moves (Jimenez et al.; MetaHuman's CM1-3):
it is pushed out where the skin **stretches** (paler, less red) and pools where it
**compresses** (flushed, redder, darker). :func:`pale` and :func:`flushed` make those two maps
from a base colour in linear light, over the whole face (like the states' normal maps, the masks
say where they show), and return sRGB texels as an artist would hand them over.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.asset import ColorMaps
from wrinklepipe.codec import srgb

#: Linear-light colour the stretched skin moves towards (a bloodless, yellowish pale), and how far.
PALE_TINT = (0.80, 0.72, 0.62)
PALE_AMOUNT = 0.45
#: Linear-light gain of the compressed, flushed skin (red kept, green and blue absorbed).
FLUSH_GAIN = (1.0, 0.55, 0.55)


def _texels(lin: np.ndarray, like: np.ndarray) -> np.ndarray:
    bits = 16 if like.dtype == np.uint16 else 8
    return srgb.encode_texels(np.clip(lin, 0.0, 1.0), bits)


def pale(base: np.ndarray) -> np.ndarray:
    """The stretched pose's colour map (sRGB texels ``[H, W, 3]``) from base texels."""
    lin = srgb.decode_texels(base[..., :3]).astype(np.float64)
    tint = np.asarray(PALE_TINT, np.float64)
    return _texels(lin + PALE_AMOUNT * (tint - lin), base)


def flushed(base: np.ndarray) -> np.ndarray:
    """The compressed pose's colour map (sRGB texels ``[H, W, 3]``) from base texels."""
    lin = srgb.decode_texels(base[..., :3]).astype(np.float64)
    return _texels(lin * np.asarray(FLUSH_GAIN, np.float64), base)


#: The demo skin's linear-light albedo (sRGB about 196, 150, 128) and how much pores darken it.
SKIN = (0.55, 0.30, 0.215)
CAVITY = 0.35


def skin_color(base_height: np.ndarray) -> np.ndarray:
    """The demo's base colour (sRGB texels ``[H, W, 3]``, 8-bit) from its base height: the skin
    tone, darker in pores and the scar's groove (cavity: below the local mean height), with a
    slow warm/cool variation across the face."""
    h = np.asarray(base_height, np.float64)
    H, W = h.shape
    yy, xx = np.mgrid[0:H, 0:W] / float(max(H, W))
    low = h - _blur(h, max(H // 64, 1))
    cavity = np.clip(-low / (np.abs(low).max() + 1e-12), 0.0, 1.0)
    tone = np.asarray(SKIN, np.float64)[None, None] * (
        1.0 + 0.08 * np.sin(2 * np.pi * (1.3 * xx + 0.7 * yy))[..., None] * np.array([1, -0.5, -1])
    )
    lin = tone * (1.0 - CAVITY * cavity[..., None])
    return srgb.encode_texels(np.clip(lin, 0.0, 1.0))


def _blur(a: np.ndarray, r: int) -> np.ndarray:
    """Box blur of radius ``r`` (separable, edges clamped)."""
    k = 2 * r + 1
    p = np.pad(a, r, mode="edge")
    c = np.cumsum(np.cumsum(p, axis=0), axis=1)
    c = np.pad(c, ((1, 0), (1, 0)))
    s = c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]
    return s / (k * k)


def demo_colors(base_height: np.ndarray, state_names: tuple[str, ...]) -> ColorMaps:
    """The demo's colour states: its skin colour, ``stretch`` pale, ``compress`` flushed."""
    base = skin_color(base_height)
    maps = {"stretch": pale(base), "compress": flushed(base)}
    index = tuple(k for k, n in enumerate(state_names) if n in maps)
    return ColorMaps(base, np.stack([maps[state_names[k]] for k in index]), index)
