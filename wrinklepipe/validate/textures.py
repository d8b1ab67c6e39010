"""Decode shipped texture bytes to stored values, and sample them the way the GPU does.

Everything here is numpy; BCn blocks are decoded by ``texture2ddecoder`` (BGRA output, swapped
to RGBA). :func:`bilinear` reproduces ``GL_LINEAR`` with ``GL_CLAMP_TO_EDGE`` and no mipmaps,
which is how the render pass samples, so the numpy reference sees the texels the shader sees.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.model import normalize
from wrinklepipe.normals.encode import pd_values_to_slopes
from wrinklepipe.validate.inputs import FORMATS, Texture


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB transfer function a GPU applies when a texture is tagged sRGB."""
    c = np.asarray(c, np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def decode_values(tex: Texture, apply_srgb: bool = False) -> np.ndarray:
    """Stored values of level 0 as float32 ``[H, W, C]`` in [0, 1] (C = the format's channels).

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
        out = np.frombuffer(tex.data, np.uint8, count=h * w * ch).reshape(h, w, ch) / 255.0
    elif kind == "unorm16":
        out = np.frombuffer(tex.data, "<u2", count=h * w * ch).reshape(h, w, ch) / 65535.0
    elif kind == "float":
        out = np.frombuffer(tex.data, "<f4", count=h * w * ch).reshape(h, w, ch)
    else:
        import texture2ddecoder as t2d

        pw, ph = (w + 3) // 4 * 4, (h + 3) // 4 * 4
        fn = getattr(t2d, f"decode_{tex.fmt}")
        bgra = np.frombuffer(fn(tex.data, pw, ph), np.uint8).reshape(ph, pw, 4)[:h, :w]
        rgba = bgra[..., [2, 1, 0, 3]]
        out = rgba[..., :ch] / 255.0
    out = np.asarray(out, np.float32)
    if apply_srgb and tex.srgb and kind != "float":
        rgb = min(ch, 3)
        out = out.copy()
        out[..., :rgb] = srgb_to_linear(out[..., :rgb])
    return out


def xy_layout(tex: Texture) -> str:
    """Where a normal map keeps x, y (and z): ``"rgb"``, ``"rg"`` (z rebuilt) or ``"ag"``."""
    if tex.layout == "ag":
        return "ag"
    return "rgb" if tex.channels >= 3 and tex.layout != "rg2" else "rg"


def values_to_normals(values: np.ndarray, layout: str) -> np.ndarray:
    """Unit normals from stored values: ``normalize(2 v - 1)``; two-channel layouts rebuild z."""
    v = np.asarray(values, np.float32)
    if layout == "rgb":
        return normalize(2.0 * v[..., :3] - 1.0)
    xy = 2.0 * (v[..., [3, 1]] if layout == "ag" else v[..., :2]) - 1.0
    z = np.sqrt(np.maximum(1.0 - np.einsum("...c,...c->...", xy, xy), 0.0))
    return normalize(np.concatenate([xy, z[..., None]], axis=-1))


def raw_normals(values: np.ndarray, layout: str) -> np.ndarray:
    """``2 v - 1`` without normalising (to check unit length and z >= 0 of three-channel maps)."""
    v = np.asarray(values, np.float32)
    if layout == "rgb":
        return 2.0 * v[..., :3] - 1.0
    return values_to_normals(v, layout)


def decode_state(values: np.ndarray, encoding: str, layout: str, pd_scale: float) -> np.ndarray:
    """What the model's ``combine`` takes for one state (see :func:`wrinklepipe.model.combine`).

    pd: slopes ``[H, W, 2]`` (stored ``0.5 + 0.5 d / scale``); diff: ``D`` ``[H, W, 3]`` with
    the gain undone (stored ``0.5 + 0.5 g (W - B)`` with ``g = scale``; returned
    ``0.5 + (v - 0.5) / g`` so that ``2 D - 1 = W - B``); full / composite: unit normals.
    """
    v = np.asarray(values, np.float32)
    if encoding == "pd":
        return pd_values_to_slopes(v, pd_scale)
    if encoding == "diff":
        if v.shape[-1] < 3:
            raise ValueError("a diff map needs three channels")
        if float(pd_scale) == 1.0:
            return v[..., :3]
        return (0.5 + (v[..., :3] - 0.5) / np.float32(pd_scale)).astype(np.float32)
    return values_to_normals(v, layout)


def bilinear(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Sample ``img [H, W, C]`` at ``uv [N, 2]`` like GL_LINEAR + CLAMP_TO_EDGE -> ``[N, C]``."""
    h, w = img.shape[:2]
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
    flat = img.reshape(h * w, -1)
    top = flat[ya * w + xa] * (1 - fx) + flat[ya * w + xb] * fx
    bot = flat[yb * w + xa] * (1 - fx) + flat[yb * w + xb] * fx
    return (top * (1 - fy) + bot * fy).astype(np.float32)


def resize_bilinear(img: np.ndarray, h: int, w: int) -> np.ndarray:
    """Resample ``[H, W, C]`` to ``[h, w, C]`` by bilinear sampling at texel centres."""
    if img.shape[0] == h and img.shape[1] == w:
        return img
    cu = (np.arange(w) + 0.5) / w
    cv = (np.arange(h) + 0.5) / h
    uu, vv = np.meshgrid(cu, cv, indexing="xy")
    uv = np.stack([uu.ravel(), vv.ravel()], axis=-1)
    return bilinear(img, uv).reshape(h, w, -1)
