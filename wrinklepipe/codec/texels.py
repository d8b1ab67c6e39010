"""Encode and decode stored texels: quantity -> signed -> mapped integers in a layout, and back.

The one implementation of quantise / encode / decode / to_normal that writers, readers, the
validator and the shaders (:mod:`wrinklepipe.codec.shaders`) share. Texels are RGBA-ordered
arrays ``[..., C]`` (uint8, uint16 or float32 for float storage); components are x, y[, z].
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.codec import layouts as lay
from wrinklepipe.codec.encodings import Encoding, encoding
from wrinklepipe.codec.formats import StorageFormat, storage_format
from wrinklepipe.codec.mappings import CURRENT_VERSION, texel_bits

_F = np.float32


def _enc(e: str | Encoding) -> Encoding:
    return encoding(e) if isinstance(e, str) else e


def _layout(where: str | lay.Layout | StorageFormat, e: Encoding) -> lay.Layout:
    if isinstance(where, lay.Layout):
        return where
    if isinstance(where, StorageFormat):
        return where.layout_for(e)
    if where in lay.LAYOUTS:
        return lay.layout(where)
    return storage_format(where).layout_for(e)


def encode(
    enc: str | Encoding,
    x: np.ndarray,
    where: str | lay.Layout | StorageFormat = "png8",
    *,
    param: float = 1.0,
    version: int = CURRENT_VERSION,
    bits: int | None = None,
    channels: int = 4,
) -> tuple[np.ndarray, int]:
    """The texels ``[..., channels]`` that store quantity ``x`` (see
    :mod:`wrinklepipe.codec.encodings`) and the number of clipped texels.

    ``where`` is a storage format name (its layout and bit depth) or a layout name / object
    (then ``bits`` must be given). Normal maps in a layout without z store x and y only.
    """
    e = _enc(enc)
    lo = _layout(where, e)
    if bits is None:
        if not isinstance(where, (str, StorageFormat)) or where in lay.LAYOUTS:
            raise ValueError("encoding into a bare layout needs bits (8, 16 or 0)")
        bits = (where if isinstance(where, StorageFormat) else storage_format(where)).bits
    t, clipped = e.to_signed(x, param)
    if t.shape[-1] == 3 and not lo.stores_z:
        t = t[..., :2]
    q = e.mapping(version).encode(t, bits)
    return lay.pack(q, lo, channels), clipped


def decode(
    enc: str | Encoding,
    texels: np.ndarray,
    where: str | lay.Layout | StorageFormat = "png8",
    *,
    param: float = 1.0,
    version: int | None = CURRENT_VERSION,
    bits: int | None = None,
) -> np.ndarray:
    """The quantity stored in integer (or float) texels: pd slopes ``[..., 2]``, diff deltas
    ``[..., 3]``, unit normals ``[..., 3]`` (z rebuilt where the layout has none). Exact for
    integer texels: a texel at the mapping's centre decodes to 0. ``version=None``: v1."""
    e = _enc(enc)
    lo = _layout(where, e)
    q = lay.unpack(texels, lo)
    t = e.mapping(version).decode(q, texel_bits(q) if bits is None else bits)
    return e.from_signed(t, param)


def decode_sampled(
    enc: str | Encoding,
    values: np.ndarray,
    where: str | lay.Layout | StorageFormat,
    *,
    bits: int,
    param: float = 1.0,
    version: int | None = CURRENT_VERSION,
) -> np.ndarray:
    """Like :func:`decode`, from *sampled* UNORM values in [0, 1] (what a GPU's sampler returns,
    possibly filtered): the float32 arithmetic of the generated shader functions."""
    e = _enc(enc)
    lo = _layout(where, e)
    v = lay.unpack(np.asarray(values, _F), lo)
    t = e.mapping(version).decode_unorm(v, bits)
    return e.from_signed(t, param)


def to_normal(enc: str | Encoding, x: np.ndarray, base: np.ndarray | None = None) -> np.ndarray:
    """Unit normals of a decoded quantity (see :meth:`Encoding.to_normal`)."""
    return _enc(enc).to_normal(x, base)
