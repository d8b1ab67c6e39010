"""The angle between two vectors, in degrees: the one angular error of the project."""

from __future__ import annotations

import numpy as np

_F = np.float32
_DEG = _F(180.0 / np.pi)


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees (float32) between vectors ``[..., 3]`` (shapes broadcast).

    ``atan2(|a x b|, a . b)`` in float32: well conditioned at every angle (unlike ``acos`` of
    the dot product near 0, or ``asin`` of the chord near 180 degrees) and independent of the
    vectors' lengths, so an input that is not exactly unit is measured by its direction.
    Accurate to ~5e-6 degrees for unit float32 inputs. A zero vector gives 0 (atan2(0, 0));
    a NaN component gives NaN (the statistics count it as 180 degrees).
    """
    a = np.asarray(a, _F)
    b = np.asarray(b, _F)
    if a.shape[-1:] != (3,) or b.shape[-1:] != (3,):
        raise ValueError(f"angles between 3-vectors, got shapes {a.shape} and {b.shape}")
    return angle_deg_planes(np.moveaxis(a, -1, 0), np.moveaxis(b, -1, 0))


def angle_deg_planes(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """:func:`angle_deg` of vectors stored as component planes ``[3, ...]`` (the layout of
    the fidelity measure and of the block-format checks): the same float32 operations in the
    same order, with three temporaries of one plane each (``out``: where to write)."""
    a = np.asarray(a, _F)
    b = np.asarray(b, _F)
    if a.shape[:1] != (3,) or b.shape[:1] != (3,):
        raise ValueError(f"angles between 3-vector planes, got shapes {a.shape} and {b.shape}")
    shape = np.broadcast_shapes(a.shape[1:], b.shape[1:])
    s = np.empty(shape, _F)  # |a x b|^2, then |a x b|
    d = np.empty(shape, _F)
    t = np.empty(shape, _F)
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        c = s if i == 0 else d
        np.multiply(a[j], b[k], out=c)
        np.multiply(a[k], b[j], out=t)
        c -= t
        c *= c
        if i:
            s += d
    np.sqrt(s, out=s)
    np.multiply(a[0], b[0], out=d)  # a . b
    np.multiply(a[1], b[1], out=t)
    d += t
    np.multiply(a[2], b[2], out=t)
    d += t
    res = s if out is None else out
    np.arctan2(s, d, out=res)
    res *= _DEG
    return res
