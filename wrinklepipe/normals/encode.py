"""Wrinkle-map encodings: partial derivatives (``pd``), difference maps (``diff``), ``full``.

All functions take and return numpy arrays; no I/O. Every quantise / encode / decode goes
through :mod:`wrinklepipe.codec` (the one implementation): results are integer *texels*
(uint8 / uint16, components x, y[, z]) under a value mapping ``version`` (v2 by default:
``q = 128 + 127 t`` at 8 bits, ``32768 + 32767 t`` at 16, so zero is exact; v1 is the legacy
``0.5 + 0.5 t``).

``pd`` (Jimenez et al., without the minus sign)
    slopes ``d = (x / z, y / z)``, ``t = d / s`` in two channels (R = x, G = y), so a map holds
    slopes in ``[-s, s]``: the cone of half-angle ``atan(s)`` (s = 1: 45 degrees, the paper's
    limit). Texels outside are clipped and counted.
``diff``
    ``t = g (W - B)`` in three channels; ``g`` (gain, default 1) spreads small differences over
    more of the range and is divided out when decoding.
``full``
    the unit normal in the glTF mapping ``0.5 + 0.5 n``; two-channel outputs keep x in R and y
    in G and rebuild z on decode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wrinklepipe import codec
from wrinklepipe.normals._chunks import map_rows

_F = np.float32
_EPS = np.float32(1e-12)

#: Range of automatic PD scales (powers of two).
MIN_PD_SCALE = 2.0**-6
MAX_PD_SCALE = 2.0**6


@dataclass(frozen=True)
class PDResult:
    """A PD-encoded map: ``texels`` [H, W, 2] (R = x, G = y), the scale, clipped texels."""

    texels: np.ndarray
    scale: float
    clipped: int  # texels with |x/z| > s or |y/z| > s (or z <= 0), clipped to the cone
    cone_deg: float  # half-angle of the cone the scale represents, atan(s) in degrees
    version: int = codec.CURRENT_VERSION


@dataclass(frozen=True)
class DiffResult:
    """A difference map's texels ``t = gain (W - B)`` [H, W, 3] and how many were clipped."""

    texels: np.ndarray
    gain: float
    clipped: int
    version: int = codec.CURRENT_VERSION


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
    """The smallest power of two ``s`` at which at most ``100 - percentile`` % of the texels of
    *every* map reach the edge of the stored range: ``max(|x/z|, |y/z|) >= s (1 - 0.5/127)``, the
    texels an 8-bit map stores at its extremes (what the validator counts as clipped, WP-MAP-004).

    Accepts unit normals ``[..., 3]`` or slopes ``[..., 2]``; a stack of maps ``[K, H, W, c]``
    is judged map by map (the scale serves the steepest). Clamped to [``MIN_PD_SCALE``,
    ``MAX_PD_SCALE``]. A flat map gives ``MIN_PD_SCALE``.
    """
    a = np.asarray(normals_or_slopes, dtype=_F)
    d = normal_slopes(a) if a.shape[-1] == 3 else a
    m = np.max(np.abs(d), axis=-1)
    maps = m.reshape(m.shape[0], -1) if m.ndim == 3 else m.reshape(1, -1)
    p = 0.0
    for row in maps:  # K maps, not texels
        row = row[np.isfinite(row)]
        if row.size:
            p = max(p, float(np.percentile(row, percentile)))
    p /= 1.0 - 0.5 / 127.0  # half an 8-bit step (128 + 127 t) below s still rounds to the edge
    if p <= MIN_PD_SCALE:
        return MIN_PD_SCALE
    s = 2.0 ** math.ceil(math.log2(p))
    return float(min(max(s, MIN_PD_SCALE), MAX_PD_SCALE))


_TINY_Z = np.float32(1e-30)


def _cone_factor(n: np.ndarray, scale: float, half: float) -> np.ndarray:
    """``h / (s max(z, tiny))``: multiplying x or y by it gives ``h t``, the slope in steps."""
    r = np.maximum(n[..., 2], _TINY_Z)
    np.divide(_F(half / scale), r, out=r)
    return r


def _clipped_in(ux: np.ndarray, uy: np.ndarray, half: float) -> int:
    a = np.abs(ux)
    b = np.abs(uy)
    np.maximum(a, b, out=a)
    return int(np.count_nonzero(a > _F(half)))


def pd_clipped_count(normals: np.ndarray, scale: float) -> int:
    """Texels whose slope leaves the cone: ``|x / z| > s`` or ``|y / z| > s``.

    ``z`` is clamped to 1e-30 first, so texels with z <= 0 count unless x = y = 0 (those are
    degenerate texels that :mod:`wrinklepipe.normals.read` reports on their own).
    """
    n = np.asarray(normals, dtype=_F)
    r = _cone_factor(n, scale, 1.0)
    return _clipped_in(n[..., 0] * r, n[..., 1] * r, 1.0)


def _pd_u8_kernel(n: np.ndarray, scale: float, version: int, out: np.ndarray) -> int:
    """Quantise one chunk of normals [h, w, 3] to 8-bit PD texels in ``out`` [h, w, 2]."""
    c, half = codec.mapping(version).centre(8)
    r = _cone_factor(n, scale, half)
    ux = n[..., 0] * r
    uy = n[..., 1] * r
    clipped = _clipped_in(ux, uy, half)
    lo, hi = _F(c - half), _F(c + half)  # t clipped to [-1, 1]
    for u, ch in ((ux, 0), (uy, 1)):
        u += _F(c + 0.5)
        np.clip(u, lo, hi + _F(0.5), out=u)
        np.floor(u, out=u)
        np.minimum(u, hi, out=u)
        np.copyto(out[..., ch], u, casting="unsafe")  # floor(x + 0.5): round half up
    return clipped


def encode_pd_u8(
    normals: np.ndarray, scale: float | str = 1.0, version: int = codec.CURRENT_VERSION
) -> tuple[np.ndarray, float, int]:
    """8-bit PD texels [H, W, 2] (R = x, G = y) of unit normals, chunked over threads.

    ``q = round_half_up(c + h t)``, ``t = clip((x / z) / s, -1, 1)`` with the mapping's centre
    ``c`` and steps ``h`` (v2: 128, 127); this is what every 8-bit PD output (PNG, BCn) stores.
    Returns ``(q, scale, clipped_texels)``.
    """

    n = np.asarray(normals, dtype=_F)
    if n.ndim != 3 or n.shape[-1] != 3:
        raise ValueError(f"normals must be [H, W, 3], got shape {n.shape}")
    s = auto_pd_scale(n) if scale == "auto" else float(scale)
    if not s > 0 or not math.isfinite(s):
        raise ValueError(f"PD scale must be a positive number, got {scale!r}")
    h, w = n.shape[:2]
    q = np.empty((h, w, 2), dtype=np.uint8)
    clipped = sum(map_rows(lambda rows: _pd_u8_kernel(n[rows], s, version, q[rows]), h, w))
    return q, s, int(clipped)


def encode_pd(
    normals: np.ndarray,
    scale: float | str = 1.0,
    bits: int = 8,
    version: int = codec.CURRENT_VERSION,
) -> PDResult:
    """Encode unit normals [H, W, 3] as PD texels [H, W, 2] with slope scale ``s``.

    ``scale="auto"`` picks :func:`auto_pd_scale`. Slopes beyond ``[-s, s]`` are clipped (per
    component) and the texels counted; ``cone_deg`` is the half-angle ``atan(s)``.
    """
    n = np.asarray(normals, dtype=_F)
    if n.ndim < 1 or n.shape[-1] != 3:
        raise ValueError(f"normals must be [..., 3], got shape {n.shape}")
    s = auto_pd_scale(n) if scale == "auto" else float(scale)
    if not s > 0 or not math.isfinite(s):
        raise ValueError(f"PD scale must be a positive number, got {scale!r}")
    d = np.nan_to_num(normal_slopes(n), posinf=1e30, neginf=-1e30)
    q, _ = codec.encode("pd", d, "rg", param=s, version=version, bits=bits, channels=2)
    return PDResult(q, s, pd_clipped_count(n, s), cone_deg(s), version)


def decode_pd_slopes(
    texels: np.ndarray, scale: float, version: int | None = codec.CURRENT_VERSION
) -> np.ndarray:
    """Stored PD texels [..., >= 2] -> slopes ``t s`` [..., 2] (exact for integer texels)."""
    return codec.decode("pd", np.asarray(texels), "rg", param=scale, version=version)


def slopes_to_normal(d: np.ndarray) -> np.ndarray:
    """``normalize(d.x, d.y, 1)`` [..., 3] (float32, no float64 temporaries)."""
    return codec.pd_to_normal(d)


def decode_pd(
    texels: np.ndarray, scale: float, version: int | None = codec.CURRENT_VERSION
) -> np.ndarray:
    """Decode PD texels [H, W, >= 2] to unit normals [H, W, 3]."""
    return slopes_to_normal(decode_pd_slopes(texels, scale, version))


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


def encode_diff(
    wrinkled: np.ndarray,
    base: np.ndarray,
    gain: float | str = 1.0,
    bits: int = 8,
    version: int = codec.CURRENT_VERSION,
) -> DiffResult:
    """Difference-map texels ``t = gain (W - B)`` [H, W, 3], clipped to [-1, 1] and counted."""
    w = np.asarray(wrinkled, dtype=_F)
    b = np.asarray(base, dtype=_F)
    if w.shape != b.shape or w.shape[-1] != 3:
        raise ValueError(f"wrinkled {w.shape} and base {b.shape} must both be [H, W, 3]")
    g = auto_diff_gain(w, b) if gain == "auto" else float(gain)
    if not g > 0 or not math.isfinite(g):
        raise ValueError(f"diff gain must be a positive number, got {gain!r}")
    q, clipped = codec.encode("diff", w - b, "rgb", param=g, version=version, bits=bits, channels=3)
    return DiffResult(q, g, clipped, version)


def decode_diff(
    texels: np.ndarray, gain: float = 1.0, version: int | None = codec.CURRENT_VERSION
) -> np.ndarray:
    """The delta ``W - B`` a difference map stores: ``t / gain``."""
    return codec.decode("diff", np.asarray(texels), "rgb", param=gain, version=version)


def encode_full(normals: np.ndarray, channels: int = 3, bits: int = 8) -> np.ndarray:
    """Absolute normal map texels (glTF ``0.5 + 0.5 n``); ``channels=2`` keeps x (R), y (G)."""
    if channels not in (2, 3):
        raise ValueError(f"channels must be 2 or 3, got {channels}")
    lay = "rgb" if channels == 3 else "rg"
    return codec.encode("full", normals, lay, bits=bits, channels=channels)[0]


def rebuild_z(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``z = sqrt(max(0, 1 - x^2 - y^2))`` (float32)."""
    z = _F(1.0) - x * x - y * y
    np.maximum(z, 0.0, out=z)
    return np.sqrt(z, out=z)


def decode_full(texels: np.ndarray) -> np.ndarray:
    """Decode ``full`` texels [H, W, 2 or 3] to unit normals (z rebuilt for two channels)."""
    t = np.asarray(texels)
    return codec.decode("full", t, "rg" if t.shape[-1] == 2 else "rgb")


def quantize(values01: np.ndarray, bits: int = 8) -> np.ndarray:
    """Round UNORM values in [0, 1] to ``bits`` (8 -> uint8, 16 -> uint16), clipping."""
    return codec.quantize_unorm(values01, bits)


def dequantize(q: np.ndarray) -> np.ndarray:
    """Integer texels back to UNORM values in [0, 1] (float32): ``q / 255`` or ``q / 65535``."""
    q = np.asarray(q)
    if q.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"dequantize expects uint8 or uint16 texels, got {q.dtype}")
    return codec.dequantize_unorm(q)


def quantization_bound_deg(
    scale: float, bits: int = 8, version: int = codec.CURRENT_VERSION
) -> float:
    """Worst-case angle (degrees) that rounding a PD map of scale ``s`` to ``bits`` can cause.

    Rounding moves each slope component by at most ``s / (2 h)`` (half a step of the mapping:
    ``h = 127`` at 8 bits under v2, 127.5 under v1), so the slope point moves by at most
    ``e = sqrt(2) s / (2 h)`` on the plane z = 1. Seen from the origin, a displacement on that
    plane subtends at most its length in radians (the angular rate is largest at d = 0, where
    it is 1), so the bound is ``e`` rad. float32 rounding adds ~1e-5 degrees on top.
    """
    h = codec.mapping(version).centre(bits)[1]
    return math.degrees(float(scale) / (2.0 * h) * math.sqrt(2.0))
