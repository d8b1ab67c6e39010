"""Colour texels from image files, and telling a colour map from a normal map.

Colour maps are 8- or 16-bit sRGB images (PNG, JPEG, TGA, TIFF ...): their texels are read as
stored (:func:`read_color_texels`), never converted, so a map that ships at its own size keeps
its bytes. A float image (EXR) holds linear data and is refused with a message saying so.

A tangent-space normal map given as a colour map is caught by what the texels hold
(:func:`normal_map_evidence`): decoded as ``2 v - 1`` nearly every texel is a unit vector
pointing out of the surface, the blue channel the brightest (a colour map of skin decodes to
vectors of length 0.4-0.9). The other mistake, a colour image given as a normal map, is the
normal reader's to refuse (:mod:`wrinklepipe.normals.identify`, one check for every verb).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wrinklepipe.errors import input_error
from wrinklepipe.io.images import DEFAULT_MAX_PIXELS, read_image

#: A texel decodes to a unit normal when ``| |2 v - 1| - 1 |`` is below this.
UNIT_TOLERANCE = 0.1
#: The share of unit texels above which an image is taken for a normal map.
NORMAL_SHARE = 0.9


def read_color_texels(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS) -> np.ndarray:
    """An sRGB colour map's texels as stored: ``[H, W, C]`` uint8 / uint16, C = 3 or 4 (a
    grey image is refused: a colour map needs RGB)."""
    values, info = read_image(path, max_pixels)
    if info.format not in ("uint8", "uint16"):
        raise input_error(
            path,
            f"a colour map holds 8- or 16-bit sRGB texels, this one is {info.format} (linear "
            "data): save it as an sRGB PNG",
        )
    if info.channels < 3:
        raise input_error(
            path, f"a colour map needs RGB or RGBA channels, this image has {info.channels}"
        )
    top = 65535.0 if info.format == "uint16" else 255.0
    dtype = np.uint16 if info.format == "uint16" else np.uint8
    texels = np.rint(values[..., : min(info.channels, 4)].astype(np.float64) * top)
    return np.ascontiguousarray(texels.astype(dtype))


def rgb_texels(texels: np.ndarray) -> np.ndarray:
    """Texels of any channel count as RGB(A): a grey (and alpha) image repeated into R, G, B."""
    t = np.asarray(texels)
    if t.ndim == 2:
        t = t[..., None]
    if t.shape[-1] >= 3:
        return t[..., :4]
    grey = np.repeat(t[..., :1], 3, axis=-1)
    return np.concatenate([grey, t[..., 1:2]], axis=-1) if t.shape[-1] == 2 else grey


def normal_map_evidence(texels: np.ndarray) -> str | None:
    """Why ``texels`` look like a tangent-space normal map (None: they do not)."""
    t = np.asarray(texels)
    top = 65535.0 if t.dtype == np.uint16 else 255.0
    n = t[..., :3].reshape(-1, 3).astype(np.float32) * np.float32(2.0 / top) - np.float32(1.0)
    if n.shape[0] == 0:
        return None
    length = np.sqrt(np.einsum("ij,ij->i", n, n))
    unit = (np.abs(length - 1.0) < UNIT_TOLERANCE) & (n[:, 2] > 0.0)
    share = float(np.count_nonzero(unit)) / n.shape[0]
    mean = t[..., :3].reshape(-1, 3).mean(axis=0) / top
    if share < NORMAL_SHARE or not (mean[2] > mean[0] and mean[2] > mean[1]):
        return None
    return (
        f"it looks like a tangent-space normal map ({share:.0%} of its texels decode to unit "
        f"normals, mean RGB ({mean[0]:.2f}, {mean[1]:.2f}, {mean[2]:.2f}))"
    )


def check_color_map(texels: np.ndarray, path: str | Path, key: str = "") -> None:
    """Refuse a normal map given as a colour map (one message naming the file)."""
    why = normal_map_evidence(texels)
    if why is not None:
        raise input_error(
            path,
            f"given as a colour map, but {why}: a state's normal map goes in map = FILE, its "
            "albedo (sRGB) in color = FILE",
            key,
        )
