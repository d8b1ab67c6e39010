"""Value mappings: how a signed value ``t`` in [-1, 1] becomes a stored texel, by version.

Every stored channel of a wrinkle map holds a signed quantity scaled to [-1, 1]: ``d / s`` for
PD slopes, ``g (W - B)`` for difference maps, a normal's component for normal maps. The
*mapping* turns it into an integer texel of ``bits`` (8 or 16; ``bits = 0`` means a float
texture) and back:

``v1`` (every asset written before the field existed; still read)
    ``v = 0.5 + 0.5 t``, ``q = round(top v)`` with ``top = 2^bits - 1``; decode
    ``t = 2 q / top - 1``.
    Zero lands on 127.5 (8 bits): not representable, so a flat PD texel decodes tilted by
    ``s / 255`` per axis.
``v2`` (what wrinklepipe writes for ``pd`` and ``diff``)
    centred on ``c = 2^(bits-1)``: ``q = round(c + (c - 1) t)`` (8 bits: ``128 + 127 t``, 16 bits:
    ``32768 + 32767 t``); decode ``t = max((q - c) / (c - 1), -1)``. Zero is exact; q = 0 (never
    written) clamps to -1, exactly as a GPU reads SNORM. The bytes are those of an SNORM texture
    with the sign bit flipped, so a container could also declare them SNORM.

Float textures (EXR, ``bits = 0``) store ``v = 0.5 + 0.5 t`` under both versions (0.5 is exact in
half and single precision).

Normal maps (the base, ``full`` and ``composite`` states) always use the glTF ``normalTexture``
mapping ``n = 2 v - 1`` (which is ``v1``): every engine, viewer and material network reads them
that way. See :mod:`wrinklepipe.codec.encodings`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_F = np.float32

#: Mapping versions wrinklepipe reads.
VERSIONS: tuple[int, ...] = (1, 2)
#: The version writers use for ``pd`` and ``diff`` maps.
CURRENT_VERSION = 2
#: The version of an asset whose metadata has no mapping field (everything written before it).
LEGACY_VERSION = 1


def check_bits(bits: int) -> int:
    if bits not in (0, 8, 16):
        raise ValueError(f"bits must be 8, 16 or 0 (float), got {bits!r}")
    return bits


@dataclass(frozen=True)
class Mapping:
    """One value mapping: ``t`` in [-1, 1] <-> stored texel (see the module docstring)."""

    version: int
    summary: str

    def centre(self, bits: int) -> tuple[float, float]:
        """``(c, h)``: the texel of ``t = 0`` and the texels per unit of ``t`` (integer bits)."""
        check_bits(bits)
        if bits == 0:
            return 0.5, 0.5
        top = float((1 << bits) - 1)
        if self.version == 1:
            return top / 2.0, top / 2.0
        c = float(1 << (bits - 1))
        return c, c - 1.0

    def encode(self, t: np.ndarray, bits: int) -> np.ndarray:
        """Signed values -> texels: uint8/uint16 (rounded half up, ``t`` clipped to [-1, 1])
        or, for ``bits = 0``, float32 ``0.5 + 0.5 t`` (not clipped)."""
        t = np.asarray(t, dtype=_F)
        if check_bits(bits) == 0:
            return (t * _F(0.5) + _F(0.5)).astype(_F)
        c, h = self.centre(bits)
        v = np.clip(t, _F(-1.0), _F(1.0)) * _F(h)
        v += _F(c + 0.5)
        np.floor(v, out=v)  # round half up (the fused kernels of wrinklepipe.normals agree)
        np.minimum(v, _F(c + h), out=v)
        return v.astype(np.uint8 if bits == 8 else np.uint16)

    def decode(self, q: np.ndarray, bits: int | None = None) -> np.ndarray:
        """Texels -> signed values (float32). Integer texels decode exactly (``t = 0`` from
        ``q = c``); ``bits`` defaults to the dtype's (uint8: 8, uint16: 16, float: 0)."""
        q = np.asarray(q)
        if bits is None:
            bits = texel_bits(q)
        if check_bits(bits) == 0:
            return (np.asarray(q, _F) * _F(2.0) - _F(1.0)).astype(_F)
        c, h = self.centre(bits)
        if self.version == 1:  # (2 q - top) / top, exact in float32 for integer texels
            top = _F((1 << bits) - 1)
            return ((np.asarray(q, _F) * _F(2.0) - top) / top).astype(_F)
        t = (np.asarray(q, _F) - _F(c)) / _F(h)
        return np.maximum(t, _F(-1.0)).astype(_F)

    def affine(self, bits: int) -> tuple[float, float]:
        """``(mul, add)`` with ``t = v mul + add`` for a *sampled* UNORM value ``v = q / top``
        (what a shader sees; the affine form commutes with bilinear filtering). Float: (2, -1)."""
        if check_bits(bits) == 0:
            return 2.0, -1.0
        c, h = self.centre(bits)
        top = float((1 << bits) - 1)
        return top / h, -c / h

    def decode_unorm(self, v: np.ndarray, bits: int) -> np.ndarray:
        """Signed values from sampled UNORM values in [0, 1] (float32), exactly as the generated
        shader functions compute them (see :mod:`wrinklepipe.codec.shaders`)."""
        mul, add = self.affine(bits)
        t = np.asarray(v, _F) * _F(mul) + _F(add)
        if self.version >= 2 and bits:
            np.maximum(t, _F(-1.0), out=t)
        return t.astype(_F, copy=False)


MAPPINGS: dict[int, Mapping] = {
    1: Mapping(1, "v = 0.5 + 0.5 t (q = round(top v)); t = 2 q / top - 1"),
    2: Mapping(2, "q = c + (c - 1) t, c = 2^(bits-1) (128 + 127 t); t = (q - c) / (c - 1)"),
}


def mapping(version: int | None) -> Mapping:
    """The mapping of ``version`` (None: the legacy v1 of assets without the field)."""
    v = LEGACY_VERSION if version is None else version
    if v not in MAPPINGS:
        raise ValueError(
            f"unknown value mapping version {version!r}; this wrinklepipe reads "
            + ", ".join(f"v{k}" for k in VERSIONS)
        )
    return MAPPINGS[int(v)]


def texel_bits(q: np.ndarray) -> int:
    """8 for uint8, 16 for uint16, 0 for float texels."""
    dt = np.asarray(q).dtype
    if dt == np.uint8:
        return 8
    if dt == np.uint16:
        return 16
    if dt.kind == "f":
        return 0
    raise ValueError(f"texels must be uint8, uint16 or float, got {dt}")


def quantization_bound(bits: int, version: int = CURRENT_VERSION) -> float:
    """Largest error in ``t`` that rounding to ``bits`` can cause: half a step, ``0.5 / h``."""
    return 0.5 / mapping(version).centre(bits)[1] if bits else 0.0


def quantize_unorm(values01: np.ndarray, bits: int = 8) -> np.ndarray:
    """Plain UNORM quantisation of values in [0, 1] (masks): ``floor(top v + 0.5)``, clipped."""
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, got {bits}")
    top = _F((1 << bits) - 1)
    v = np.asarray(values01, dtype=_F) * top
    np.clip(v, _F(0.0), top, out=v)
    v += _F(0.5)
    np.floor(v, out=v)  # round half up, as the value mappings
    return v.astype(np.uint8 if bits == 8 else np.uint16)


def dequantize_unorm(q: np.ndarray) -> np.ndarray:
    """Integer texels back to values in [0, 1] (float32): ``q / top``."""
    bits = texel_bits(q)
    if bits == 0:
        return np.asarray(q, _F)
    return (np.asarray(q, _F) * _F(1.0 / ((1 << bits) - 1))).astype(_F)
