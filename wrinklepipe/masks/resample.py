"""Resample masks to the mask resolution: box filter when shrinking by a whole factor, bilinear
otherwise (masks are low-frequency: Jimenez et al. use 64 x 64). Values stay in [0, 1]."""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def resample_masks(masks: np.ndarray, size: int | tuple[int, int]) -> np.ndarray:
    """``[R, H, W]`` -> ``[R, h, w]`` float32 (``size`` is ``n`` for n x n or ``(h, w)``)."""
    m = np.asarray(masks, dtype=np.float32)
    if m.ndim == 2:
        return resample_masks(m[None], size)[0]
    h, w = (int(size), int(size)) if np.isscalar(size) else (int(size[0]), int(size[1]))
    if h <= 0 or w <= 0:
        raise ValueError(f"size must be positive, got {h} x {w}")
    r, H, W = m.shape
    if (H, W) == (h, w):
        return m.copy()
    if H % h == 0 and W % w == 0:
        fy, fx = H // h, W // w
        out = m.reshape(r, h, fy, w, fx).mean(axis=(2, 4), dtype=np.float64)
    else:
        out = ndimage.zoom(
            m.astype(np.float64), (1.0, h / H, w / W), order=1, mode="nearest", grid_mode=True
        )
    return np.clip(out, 0.0, 1.0).astype(np.float32)
