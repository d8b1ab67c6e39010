"""Colour states made from a base colour, as a blood-flow rig has them.

Skin changes colour with an expression because blood moves (Jimenez et al.; MetaHuman's CM1-3):
it is pushed out where the skin **stretches** (paler, less red) and pools where it
**compresses** (flushed, redder, darker). :func:`pale` and :func:`flushed` make those two maps
from a base colour in linear light, over the whole face (like the states' normal maps, the masks
say where they show), and return sRGB texels as an artist would hand them over.
"""

from __future__ import annotations

import numpy as np

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
