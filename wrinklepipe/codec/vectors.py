"""Unit-normal and slope primitives every encoding is built from (float32, last axis).

These are the maths of DESIGN.md section 1 that the stored encodings rest on; the wrinkle model
(:mod:`wrinklepipe.model`) re-exports them under its historical names.
"""

from __future__ import annotations

import numpy as np

_F = np.float32
EPS = _F(1e-12)


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis (float32); zero vectors stay zero."""
    v = np.asarray(v, dtype=_F)
    n = np.sqrt(np.einsum("...c,...c->...", v, v))
    return v / np.maximum(n, EPS)[..., None]


def normal_to_pd(n: np.ndarray) -> np.ndarray:
    """Partial-derivative slopes ``(x/z, y/z)`` (Jimenez et al., no minus sign); ``z`` is clamped
    to 1e-12 so a horizon texel gives a large finite slope."""
    n = np.asarray(n, dtype=_F)
    inv_z = np.reciprocal(np.maximum(n[..., 2], EPS))
    return n[..., :2] * inv_z[..., None]


def pd_to_normal(d: np.ndarray) -> np.ndarray:
    """Decode PD slopes: ``normalize(d.x, d.y, 1)`` (float32, no float64 temporaries)."""
    d = np.asarray(d, dtype=_F)
    x, y = d[..., 0], d[..., 1]
    inv = np.asarray(x * x)  # 0-d stays an array so the in-place ops below work
    inv += y * y
    inv += _F(1.0)
    np.sqrt(inv, out=inv)
    np.reciprocal(inv, out=inv)
    out = np.empty(d.shape[:-1] + (3,), dtype=_F)
    np.multiply(x, inv, out=out[..., 0])
    np.multiply(y, inv, out=out[..., 1])
    out[..., 2] = inv
    return out


def rebuild_z(xy: np.ndarray) -> np.ndarray:
    """Unit normals from their x and y ``[..., 2]``: ``z = sqrt(max(0, 1 - x^2 - y^2))``, then
    normalised (an |xy| > 1 texel lands on the horizon)."""
    xy = np.asarray(xy, dtype=_F)
    z = _F(1.0) - np.einsum("...c,...c->...", xy, xy)
    np.maximum(z, _F(0.0), out=z)
    np.sqrt(z, out=z)
    return normalize(np.concatenate([xy, z[..., None]], axis=-1))


def composite(base: np.ndarray, detail: np.ndarray) -> np.ndarray:
    """Detail-preserving composite (Oat; Dutreve et al.): add x and y, multiply z, renormalise."""
    b = np.asarray(base, _F)
    w = np.asarray(detail, _F)
    out = np.concatenate([b[..., :2] + w[..., :2], (b[..., 2] * w[..., 2])[..., None]], axis=-1)
    return normalize(out)
