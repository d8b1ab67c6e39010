"""Wrinkle-map encodings: partial derivatives (``pd``), difference maps (``diff``), ``full``.

All functions take and return numpy arrays (float32); no I/O. "values01" are channel values in
[0, 1] as a texture stores them (``q / 255`` for 8 bits, ``q / 65535`` for 16 bits).

``pd`` (Jimenez et al., without the minus sign)
    slopes ``d = (x / z, y / z)``; stored as ``v = 0.5 + 0.5 d / s`` in two channels (R = x,
    G = y), so an 8-bit map holds slopes in ``[-s, s]``: the cone of half-angle ``atan(s)``
    (s = 1: 45 degrees, the paper's limit). Texels outside are clipped and counted.
``diff``
    ``D = 0.5 + 0.5 g (W - B)`` in three channels; ``g`` (gain, default 1) spreads small
    differences over more of the 8-bit range and must be divided out when decoding.
``full``
    ``0.5 + 0.5 n``; two-channel outputs keep x in R and y in G and rebuild z on decode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_F = np.float32
_EPS = np.float32(1e-12)

#: Range of automatic PD scales (powers of two).
MIN_PD_SCALE = 2.0**-6
MAX_PD_SCALE = 2.0**6


@dataclass(frozen=True)
class PDResult:
    """A PD-encoded map: ``values01`` [H, W, 2] (R = x, G = y), the scale, clipped texels."""

    values01: np.ndarray
    scale: float
    clipped: int  # texels with |x/z| > s or |y/z| > s (or z <= 0), clipped to the cone
    cone_deg: float  # half-angle of the cone the scale represents, atan(s) in degrees

    @property
    def texels(self) -> int:
        return int(self.values01.shape[0] * self.values01.shape[1])


@dataclass(frozen=True)
class DiffResult:
    """A difference map ``0.5 + 0.5 gain (W - B)`` [H, W, 3] and how many texels were clipped."""

    values01: np.ndarray
    gain: float
    clipped: int


def cone_deg(scale: float) -> float:
    """Half-angle in degrees of the normal cone an 8-bit PD map of scale ``s`` can hold."""
    return math.degrees(math.atan(float(scale)))


def normal_slopes(normals: np.ndarray) -> np.ndarray:
    """PD slopes ``(x/z, y/z)`` [H, W, 2] of unit normals; z <= 0 gives +-inf slopes (clipped)."""
    n = np.asarray(normals, dtype=_F)
    z = n[..., 2:3]
    with np.errstate(divide="ignore", invalid="ignore"):
        d = n[..., :2] / np.where(z > 0, z, _F(0.0))
    # x/0 -> +-inf (or nan for x = 0, which we treat as 0 slope); keep signs of x and y.
    return np.nan_to_num(d, nan=0.0, posinf=np.inf, neginf=-np.inf).astype(_F, copy=False)


def auto_pd_scale(normals_or_slopes: np.ndarray, percentile: float = 99.9) -> float:
    """The smallest power of two >= the ``percentile`` of per-texel ``max(|x/z|, |y/z|)``.

    Accepts unit normals ``[..., 3]`` or slopes ``[..., 2]``. Clamped to
    [``MIN_PD_SCALE``, ``MAX_PD_SCALE``]. A flat map gives ``MIN_PD_SCALE``.
    """
    a = np.asarray(normals_or_slopes, dtype=_F)
    d = normal_slopes(a) if a.shape[-1] == 3 else a
    m = np.max(np.abs(d), axis=-1).ravel()
    m = m[np.isfinite(m)]
    if m.size == 0:
        return MIN_PD_SCALE
    p = float(np.percentile(m, percentile))
    if p <= MIN_PD_SCALE:
        return MIN_PD_SCALE
    s = 2.0 ** math.ceil(math.log2(p))
    return float(min(max(s, MIN_PD_SCALE), MAX_PD_SCALE))


_TINY_Z = np.float32(1e-30)
_HALF_RANGE = np.float32(127.5)


def _cone_factor(n: np.ndarray, scale: float) -> np.ndarray:
    """``127.5 / (s max(z, tiny))``: multiplying x or y by it gives the slope in half-steps."""
    r = np.maximum(n[..., 2], _TINY_Z)
    np.divide(_F(127.5 / scale), r, out=r)
    return r


def _clipped_in(ux: np.ndarray, uy: np.ndarray) -> int:
    a = np.abs(ux)
    b = np.abs(uy)
    np.maximum(a, b, out=a)
    return int(np.count_nonzero(a > _HALF_RANGE))


def pd_clipped_count(normals: np.ndarray, scale: float) -> int:
    """Texels whose slope leaves the cone: ``|x / z| > s`` or ``|y / z| > s``.

    ``z`` is clamped to 1e-30 first, so texels with z <= 0 count unless x = y = 0 (those are
    degenerate texels that :mod:`wrinklepipe.normals.read` reports on their own).
    """
    n = np.asarray(normals, dtype=_F)
    r = _cone_factor(n, scale)
    return _clipped_in(n[..., 0] * r, n[..., 1] * r)


def _pd_u8_kernel(n: np.ndarray, scale: float, out: np.ndarray) -> int:
    """Quantise one chunk of normals [h, w, 3] to 8-bit PD texels in ``out`` [h, w, 2]."""
    r = _cone_factor(n, scale)
    ux = n[..., 0] * r
    uy = n[..., 1] * r
    clipped = _clipped_in(ux, uy)
    for u, c in ((ux, 0), (uy, 1)):
        u += _F(128.0)
        np.clip(u, _F(0.0), _F(255.0), out=u)
        np.copyto(out[..., c], u, casting="unsafe")  # truncation of u + 0.5: round half up
    return clipped


def encode_pd_u8(normals: np.ndarray, scale: float | str = 1.0) -> tuple[np.ndarray, float, int]:
    """8-bit PD texels [H, W, 2] (R = x, G = y) of unit normals, chunked over threads.

    ``q = round_half_up(127.5 + 127.5 (x / z) / s)`` clipped to [0, 255]; this is what every
    8-bit PD output (PNG, BCn) stores. Returns ``(q, scale, clipped_texels)``.
    """
    from wrinklepipe.normals._chunks import map_rows

    n = np.asarray(normals, dtype=_F)
    if n.ndim != 3 or n.shape[-1] != 3:
        raise ValueError(f"normals must be [H, W, 3], got shape {n.shape}")
    s = auto_pd_scale(n) if scale == "auto" else float(scale)
    if not s > 0 or not math.isfinite(s):
        raise ValueError(f"PD scale must be a positive number, got {scale!r}")
    h, w = n.shape[:2]
    q = np.empty((h, w, 2), dtype=np.uint8)
    clipped = sum(map_rows(lambda rows: _pd_u8_kernel(n[rows], s, q[rows]), h, w))
    return q, s, int(clipped)


def encode_pd(normals: np.ndarray, scale: float | str = 1.0) -> PDResult:
    """Encode unit normals [H, W, 3] as PD values01 [H, W, 2] with slope scale ``s``.

    ``scale="auto"`` picks :func:`auto_pd_scale`. Slopes beyond ``[-s, s]`` are clipped (per
    component) and the texels counted; ``cone_deg`` is the half-angle ``atan(s)``.
    """
    n = np.asarray(normals, dtype=_F)
    if n.ndim < 1 or n.shape[-1] != 3:
        raise ValueError(f"normals must be [..., 3], got shape {n.shape}")
    s = auto_pd_scale(n) if scale == "auto" else float(scale)
    if not s > 0 or not math.isfinite(s):
        raise ValueError(f"PD scale must be a positive number, got {scale!r}")
    d = normal_slopes(n)
    clipped = pd_clipped_count(n, s)
    v = d * _F(0.5 / s)
    v += _F(0.5)
    np.clip(v, 0.0, 1.0, out=v)
    return PDResult(values01=v, scale=s, clipped=clipped, cone_deg=cone_deg(s))


def pd_values_to_slopes(values01: np.ndarray, scale: float) -> np.ndarray:
    """Stored PD values01 [..., 2] -> slopes ``(2 v - 1) s`` [..., 2] (float32)."""
    v = np.asarray(values01, dtype=_F)[..., :2]
    return (v * _F(2.0 * scale)) - _F(scale)


def slopes_to_normal(d: np.ndarray) -> np.ndarray:
    """``normalize(d.x, d.y, 1)`` [..., 3] (float32, no float64 temporaries)."""
    d = np.asarray(d, dtype=_F)
    dx = d[..., 0]
    dy = d[..., 1]
    inv = dx * dx
    inv += dy * dy
    inv += _F(1.0)
    np.sqrt(inv, out=inv)
    np.divide(_F(1.0), inv, out=inv)
    out = np.empty(d.shape[:-1] + (3,), dtype=_F)
    np.multiply(dx, inv, out=out[..., 0])
    np.multiply(dy, inv, out=out[..., 1])
    out[..., 2] = inv
    return out


def decode_pd(values01: np.ndarray, scale: float) -> np.ndarray:
    """Decode a PD map (values01 [H, W, >=2]) to unit normals [H, W, 3]."""
    return slopes_to_normal(pd_values_to_slopes(values01, scale))


def _abs_percentile(x: np.ndarray, percentile: float) -> float:
    a = np.abs(np.asarray(x, dtype=_F)).ravel()
    a = a[np.isfinite(a)]
    return float(np.percentile(a, percentile)) if a.size else 0.0


def auto_diff_gain(wrinkled: np.ndarray, base: np.ndarray, percentile: float = 99.9) -> float:
    """Largest power of two (>= 1, <= 64) with ``gain * |W - B| <= 1`` at the percentile."""
    delta = np.asarray(wrinkled, _F) - np.asarray(base, _F)
    p = _abs_percentile(delta, percentile)
    if p <= 1.0 / 64:
        return 64.0
    g = 2.0 ** math.floor(math.log2(1.0 / p))
    return float(min(max(g, 1.0), 64.0))


def encode_diff(wrinkled: np.ndarray, base: np.ndarray, gain: float | str = 1.0) -> DiffResult:
    """Difference map ``D = 0.5 + 0.5 gain (W - B)`` [H, W, 3], clipped to [0, 1] and counted."""
    w = np.asarray(wrinkled, dtype=_F)
    b = np.asarray(base, dtype=_F)
    if w.shape != b.shape or w.shape[-1] != 3:
        raise ValueError(f"wrinkled {w.shape} and base {b.shape} must both be [H, W, 3]")
    g = auto_diff_gain(w, b) if gain == "auto" else float(gain)
    if not g > 0 or not math.isfinite(g):
        raise ValueError(f"diff gain must be a positive number, got {gain!r}")
    v = (w - b) * _F(0.5 * g)
    v += _F(0.5)
    out_of_range = np.any((v < 0.0) | (v > 1.0), axis=-1)
    np.clip(v, 0.0, 1.0, out=v)
    return DiffResult(values01=v, gain=g, clipped=int(np.count_nonzero(out_of_range)))


def decode_diff(values01: np.ndarray, gain: float = 1.0) -> np.ndarray:
    """The delta ``W - B`` a difference map stores: ``(2 D - 1) / gain``."""
    v = np.asarray(values01, dtype=_F)
    return (v * _F(2.0 / gain)) - _F(1.0 / gain)


def encode_full(normals: np.ndarray, channels: int = 3) -> np.ndarray:
    """Absolute normal map ``0.5 + 0.5 n``; ``channels=2`` keeps x (R) and y (G) only."""
    n = np.asarray(normals, dtype=_F)
    if channels not in (2, 3):
        raise ValueError(f"channels must be 2 or 3, got {channels}")
    v = n[..., :channels] * _F(0.5)
    v += _F(0.5)
    return np.clip(v, 0.0, 1.0, out=v)


def rebuild_z(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``z = sqrt(max(0, 1 - x^2 - y^2))`` (float32)."""
    z = _F(1.0) - x * x - y * y
    np.maximum(z, 0.0, out=z)
    return np.sqrt(z, out=z)


def decode_full(values01: np.ndarray) -> np.ndarray:
    """Decode ``full`` values01 [H, W, 2 or 3] to unit normals (z rebuilt for two channels)."""
    v = np.asarray(values01, dtype=_F)
    xyz = v * _F(2.0) - _F(1.0)
    if v.shape[-1] == 2:
        x, y = xyz[..., 0], xyz[..., 1]
        xyz = np.stack([x, y, rebuild_z(x, y)], axis=-1)
    n = np.sqrt(np.einsum("...c,...c->...", xyz, xyz))
    return xyz / np.maximum(n, _EPS)[..., None]


def quantize(values01: np.ndarray, bits: int = 8) -> np.ndarray:
    """Round values in [0, 1] to ``bits`` (8 -> uint8, 16 -> uint16), clipping outside values."""
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, got {bits}")
    top = _F((1 << bits) - 1)
    v = np.asarray(values01, dtype=_F) * top
    np.clip(v, 0.0, top, out=v)
    np.rint(v, out=v)
    return v.astype(np.uint8 if bits == 8 else np.uint16)


def dequantize(q: np.ndarray) -> np.ndarray:
    """Integer texels back to values01 (float32): ``q / 255`` or ``q / 65535``."""
    q = np.asarray(q)
    if q.dtype == np.uint8:
        return q.astype(_F) * _F(1.0 / 255.0)
    if q.dtype == np.uint16:
        return q.astype(_F) * _F(1.0 / 65535.0)
    raise ValueError(f"dequantize expects uint8 or uint16 texels, got {q.dtype}")


def quantization_bound_deg(scale: float, bits: int = 8) -> float:
    """Worst-case angle (degrees) that rounding a PD map of scale ``s`` to ``bits`` can cause.

    Rounding moves each slope component by at most ``h = s / (2^bits - 1)`` (half a step of
    ``2 s / (2^bits - 1)``), so the slope point moves by at most ``e = h sqrt(2)`` on the plane
    z = 1. Seen from the origin, a displacement on that plane subtends at most its length in
    radians (the angular rate is largest at d = 0, where it is 1), so the bound is ``e`` rad.
    float32 rounding adds ~1e-5 degrees on top.
    """
    h = float(scale) / ((1 << bits) - 1)
    return math.degrees(h * math.sqrt(2.0))
