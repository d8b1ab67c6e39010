"""The codec: one declaration per encoding and storage format, and the one implementation of
quantise / encode / decode / to_normal (DESIGN.md section 9).

The bottom layer of wrinklepipe (numpy only; imports nothing else of the project). Writers,
readers, the validator, the generated shader functions and the engine exports derive from it.

Declarations
    :mod:`.encodings` (``pd``, ``diff``, ``full``, ``composite``: the stored quantity, its
    parameter, whether its value mapping is versioned), :mod:`.mapping` (v1 ``0.5 + 0.5 t``,
    v2 ``128 + 127 t`` / ``32768 + 32767 t``), :mod:`.layout` (``rgb``, ``rg``, ``ag``),
    :mod:`.formats` (PNG 8/16, EXR, BC1, BC3nm, BC5, BC7, ``bc7xy``, UASTC), :mod:`.srgb` (the
    IEC 61966-2-1 transfer functions of colour maps).
Functions
    :func:`encode` (quantity -> texels), :func:`decode` (texels -> quantity, exact for integer
    texels), :func:`decode_sampled` (sampled UNORM values -> quantity, the shaders' arithmetic),
    :func:`to_normal`; :func:`wrinklepipe.codec.shaders.decode_source` for GLSL / HLSL.

Quantities: pd slopes ``[..., 2]``, diff deltas ``W - B`` ``[..., 3]``, unit normals
``[..., 3]`` (full, composite, the base). A metadata record without a mapping version reads as
:data:`LEGACY_VERSION` (v1); writers use :data:`CURRENT_VERSION` (v2).
"""

from __future__ import annotations

from wrinklepipe.codec.encodings import (
    BASE,
    COMPOSITE,
    CONVENTION,
    DIFF,
    ENCODINGS,
    FULL,
    PD,
    Encoding,
    encoding,
)
from wrinklepipe.codec.formats import (
    BLOCK_FORMATS,
    FORMATS,
    StorageFormat,
    storage_format,
)
from wrinklepipe.codec.layouts import AG, LAYOUT_IDS, LAYOUTS, RG, RGB, Layout, layout
from wrinklepipe.codec.mappings import (
    CURRENT_VERSION,
    LEGACY_VERSION,
    MAPPINGS,
    VERSIONS,
    Mapping,
    dequantize_unorm,
    mapping,
    quantize_unorm,
    texel_bits,
)
from wrinklepipe.codec.texels import decode, decode_sampled, encode, to_normal
from wrinklepipe.codec.vectors import normal_to_pd, normalize, pd_to_normal, rebuild_z

__all__ = [
    "AG",
    "BASE",
    "BLOCK_FORMATS",
    "COMPOSITE",
    "CONVENTION",
    "CURRENT_VERSION",
    "DIFF",
    "ENCODINGS",
    "FORMATS",
    "FULL",
    "LAYOUTS",
    "LAYOUT_IDS",
    "LEGACY_VERSION",
    "MAPPINGS",
    "PD",
    "RG",
    "RGB",
    "VERSIONS",
    "Encoding",
    "Layout",
    "Mapping",
    "StorageFormat",
    "decode",
    "decode_sampled",
    "dequantize_unorm",
    "encode",
    "encoding",
    "layout",
    "mapping",
    "normal_to_pd",
    "normalize",
    "pd_to_normal",
    "quantize_unorm",
    "rebuild_z",
    "storage_format",
    "texel_bits",
    "to_normal",
]
