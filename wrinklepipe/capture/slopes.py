"""Slopes and normals of a height field, relative to the neutral surface (the shape-from-shading
solve's inputs and results: :mod:`wrinklepipe.capture.sfs`)."""

from __future__ import annotations

import numpy as np


def neutral_slopes(n0: np.ndarray) -> np.ndarray:
    """Pixel-frame slopes ``(dh/dcol, dh/drow)`` of a surface with camera-frame normals ``n0``
    (+Y up, so ``dh/drow = +n_y / n_z``)."""
    n = np.asarray(n0, np.float64)
    z = np.maximum(n[..., 2], 1e-3)
    return np.stack([-n[..., 0] / z, n[..., 1] / z], axis=-1)


def slopes_to_normals(p: np.ndarray) -> np.ndarray:
    """Camera-frame unit normals (+Y up) of pixel-frame slopes ``p`` ``[..., 2]``."""
    p = np.asarray(p, np.float64)
    n = np.stack([-p[..., 0], p[..., 1], np.ones(p.shape[:-1])], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def relative_to(n1: np.ndarray, n0: np.ndarray) -> np.ndarray:
    """``n1`` turned by the smallest rotation taking ``n0`` to +Z: the wrinkle alone, in the
    neutral surface's frame (Rodrigues' formula), ``[..., 3]``."""
    n1 = np.asarray(n1, np.float64)
    n0 = np.asarray(n0, np.float64)
    v = np.stack([n0[..., 1], -n0[..., 0], np.zeros(n0.shape[:-1])], axis=-1)  # n0 x z
    vx = np.cross(v, n1)
    out = n1 + vx + np.cross(v, vx) / np.maximum(1.0 + n0[..., 2], 1e-6)[..., None]
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def normals_from_slopes(
    p: np.ndarray, n0: np.ndarray, n1z: np.ndarray | None = None, min_slope: float = 1e-3
) -> np.ndarray:
    """The wrinkle normals (relative to ``n0``) of expression slopes ``p``; with ``n1z`` the
    tilt from the camera is set to the measured ``N1_z`` along ``p``'s direction."""
    p = np.asarray(p, np.float64)
    if n1z is not None:
        z = np.clip(np.asarray(n1z, np.float64), 1e-3, 1.0)
        t = np.sqrt(1.0 / (z * z) - 1.0)
        mag = np.hypot(p[..., 0], p[..., 1])
        use = mag > min_slope
        p = np.where(use[..., None], p * (t / np.maximum(mag, 1e-12))[..., None], p)
    return relative_to(slopes_to_normals(p), n0)


def expression_normals(m: np.ndarray, n0: np.ndarray) -> np.ndarray:
    """The inverse of :func:`relative_to`: a wrinkle normal ``m`` (neutral frame) back in the
    camera frame (the smallest rotation taking +Z to ``n0``)."""
    n0 = np.asarray(n0, np.float64)
    return relative_to(m, np.stack([-n0[..., 0], -n0[..., 1], n0[..., 2]], axis=-1))
