"""Packaging, the stage after the drivers: an asset's float maps and masks -> stored textures.

:func:`package_from_asset` encodes an in-memory :class:`~wrinklepipe.asset.WrinkleAsset` (float
unit normals, float masks) into a :class:`~wrinklepipe.package.WrinklePackage`;
:func:`asset_from_package` decodes a package back into one (what the validator works on). The
per-texel encodings are those of :mod:`wrinklepipe.model`, through :mod:`wrinklepipe.codec`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wrinklepipe import codec, model
from wrinklepipe import masks as wm
from wrinklepipe.asset import ColorMaps, Region, WrinkleAsset
from wrinklepipe.color.resample import resize_texels
from wrinklepipe.errors import input_error
from wrinklepipe.metadata import (
    MaskMeta,
    RegionMeta,
    StateMeta,
    WrinkleMeta,
    table_from_json,
)
from wrinklepipe.normals.resample import (
    DEFAULT_FILTER,
    PD_BYTES_PER_TEXEL,
    resize,
    resize_bands,
    resize_normals,
)
from wrinklepipe.package import PackedTexture, WeightCurves, WrinklePackage, safe_name
from wrinklepipe.workset import band_rows, map_rows


@dataclass(frozen=True)
class PackOptions:
    """How :func:`package_from_asset` stores maps.

    ``bits``: 8 or 16 per channel for the base and state maps (masks are always 8-bit).
    ``mask_layout``: a layout of :mod:`wrinklepipe.masks` (docs/regions.md): ``"rgba"`` packs
    four masks per RGBA texture (Jimenez), ``"array"`` stores one single-channel texture per
    region (Reis' texture array), ``"lr-split"``, ``"jimenez8"``, ``"metahuman"``.
    """

    bits: int = 8
    mask_layout: str = "rgba"


def _plain_format(bits: int) -> str:
    if bits not in (8, 16):
        raise ValueError(f"maps are stored at 8 or 16 bits, got {bits}")
    return f"png{bits}"


def _q(values01: np.ndarray, bits: int) -> np.ndarray:
    """Mask values in [0, 1] -> uint8/uint16 (round to nearest, clipped)."""
    return codec.quantize_unorm(values01, bits)


def _dq(q: np.ndarray) -> np.ndarray:
    """Integer mask texels back to values in [0, 1] (float32)."""
    return codec.dequantize_unorm(q)


def encode_base(base: np.ndarray, bits: int = 8, normalize: bool = False) -> np.ndarray:
    """The base normal map's texels ``[H, W, 3]`` (glTF ``normalTexture``: xyz in RGB), made
    band by band (per texel: the whole map's texels; float64 temporaries of one band only).
    ``normalize``: each band's vectors made unit first (``model.normalize``: the texels of the
    whole map normalised, without the unit map)."""
    fmt = _plain_format(bits)

    def band(b: np.ndarray) -> np.ndarray:
        return codec.encode("full", model.normalize(b) if normalize else b, fmt, channels=3)[0]

    return map_rows(band, base, CODEC_BYTES)


def decode_base(texels: np.ndarray) -> np.ndarray:
    """Unit normals of stored base texels (``[H, W, >= 3]``), band by band as
    :func:`encode_base`."""
    return map_rows(
        lambda b: codec.decode("full", b, "rgb"), np.asarray(texels)[..., :3], CODEC_BYTES
    )


#: Bytes of temporaries per texel while encoding or decoding texels (float64 vectors).
CODEC_BYTES = 96


def encode_state(
    base: np.ndarray,
    state: np.ndarray,
    encoding: str,
    scale: float,
    bits: int = 8,
    version: int = codec.CURRENT_VERSION,
) -> np.ndarray:
    """Stored texels ``[H, W, 3]`` (uint8/uint16) of one wrinkled-face normal map over ``base``.

    pd: wrinkle-only slopes ``pd(W) - pd(B)``, ``t = d / scale`` in R, G (B = 0); diff:
    ``t = scale (W - B)`` (scale = gain) in RGB; full: ``W``; composite: the wrinkle-only normal
    ``normalize(pd(W) - pd(B), 1)``. pd and diff use the value mapping ``version``
    (:mod:`wrinklepipe.codec.mappings`); normal maps the glTF mapping.
    """
    e = codec.encoding(encoding)
    x = e.from_normals(state, base)
    return codec.encode(e, x, _plain_format(bits), param=scale, version=version, channels=3)[0]


def decode_state(
    base: np.ndarray,
    texels: np.ndarray,
    encoding: str,
    scale: float,
    version: int | None = codec.CURRENT_VERSION,
) -> np.ndarray:
    """Inverse of :func:`encode_state`: the wrinkled-face unit normal ``[H, W, 3]``.

    ``version=None`` is the legacy v1 mapping (an asset that records none)."""
    e = codec.encoding(encoding)
    where = "rg" if e.components == 2 else "rgb"
    x = codec.decode(e, np.asarray(texels), where, param=scale, version=version)
    return e.to_normal(x, base)


_F32 = np.float32

#: Bytes of temporaries per texel while normalising (float32 lengths, their clamp, the result).
NORMALIZE_BYTES_PER_TEXEL = 20


def resize_normals_pd(normals: np.ndarray, h: int, w: int) -> np.ndarray:
    """Unit normals resampled to ``h`` x ``w`` in PD space (linear, so wrinkle slopes add up).

    :func:`wrinklepipe.normals.resample.resize_normals` with ``space="pd"``.
    """
    if normals.shape[0] == h and normals.shape[1] == w:
        return normals

    return np.asarray(resize_normals(normals, (h, w), space="pd"), np.float32)


def _base_at(
    base: np.ndarray, shape: tuple[int, ...], cache: dict[tuple[int, ...], np.ndarray]
) -> np.ndarray:
    """The base at a state's size (PD-space resample, computed once per size)."""
    if base.shape[:2] == tuple(shape):
        return base
    if tuple(shape) not in cache:
        cache[tuple(shape)] = resize_normals_pd(base, int(shape[0]), int(shape[1]))
    return cache[tuple(shape)]


def _unit_base_at(
    base: np.ndarray, shape: tuple[int, ...], cache: dict[tuple[int, ...], np.ndarray]
) -> np.ndarray:
    """:func:`_base_at` of ``model.normalize(base)``, without the whole unit map when the size
    differs: the PD slopes of the unit vectors band by band, resampled (what
    :func:`resize_normals_pd` of the unit map computes, bit for bit)."""
    key = tuple(int(x) for x in shape)
    if key not in cache:
        if base.shape[:2] == key:
            cache[key] = map_rows(model.normalize, base, NORMALIZE_BYTES_PER_TEXEL)
        else:
            pd = map_rows(
                lambda r: model.normal_to_pd(model.normalize(r)), base, NORMALIZE_BYTES_PER_TEXEL
            )
            cache[key] = np.asarray(model.pd_to_normal(resize(pd, key, DEFAULT_FILTER)), _F32)
    return cache[key]


def decoded_base_at(texels: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """:func:`decode_base` of stored base texels resampled to ``shape`` (``[h, w]``) as
    :func:`_base_at` resamples the decoded base (PD space), made band by band: each band of
    output rows reads the texels' rows it reaches, decoded and turned into slopes there (per
    texel: the whole map's values), so the base's normals at full size are never whole
    (192 MiB at 4096²). The same floats bit for bit (:func:`resize_bands`)."""
    q = np.asarray(texels)
    H, W = q.shape[:2]
    h, w = int(shape[0]), int(shape[1])
    if (h, w) == (H, W):
        return decode_base(q)

    def slopes(rows: slice) -> np.ndarray:
        return map_rows(lambda b: model.normal_to_pd(decode_base(b)), q[rows], PD_BYTES_PER_TEXEL)

    out = np.empty((h, w, 3), np.float32)
    step = max(1, band_rows(W, PD_BYTES_PER_TEXEL) * h // H)  # a band's share of source rows
    for rows, band in resize_bands(slopes, (H, W, 2), (h, w), rows=step):
        out[rows] = model.pd_to_normal(band)
    return out


def pack_masks(
    masks: np.ndarray, names: list[str], layout: str, sides: list[str] | None = None
) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
    """Masks ``[R, H, W]`` -> (textures as values01 ``[H, W, C]``, channel table).

    :func:`wrinklepipe.masks.pack` does the packing (docs/regions.md); ``array`` layers become
    single-channel textures, the others RGBA textures.
    """

    p = wm.pack(masks, names, layout=layout, sides=sides)
    tex = np.asarray(p.textures, np.float32)
    if tex.ndim == 3:
        return [t[..., None] for t in tex], [dict(e) for e in p.table]
    return list(tex), [dict(e) for e in p.table]


def unpack_masks(textures: list[np.ndarray], table: list[dict[str, Any]]) -> np.ndarray:
    """Channel table + textures (values01 ``[H, W, C]``) -> masks ``[R, H, W]`` in table order."""

    if not table:
        return np.zeros((0, 1, 1), np.float32)
    if all("layer" in e for e in table):
        stack = np.stack([t[..., 0] for t in textures])
    else:
        stack = np.stack([t if t.shape[-1] == 4 else _rgba(t) for t in textures])
    return wm.unpack(stack, table)[1]


def _rgba(t: np.ndarray) -> np.ndarray:
    out = np.zeros(t.shape[:2] + (4,), np.float32)
    out[..., : t.shape[-1]] = t
    return out


def package_from_asset(
    asset: WrinkleAsset,
    options: PackOptions | None = None,
    curves: list[WeightCurves] | None = None,
) -> WrinklePackage:
    """Encode an in-memory asset into stored textures and a wrinkle description.

    The maps are stored at the asset's own sizes (resampling is a stage of its own, before this).
    """
    opt = options or PackOptions()
    if asset.mesh is None:
        raise input_error(asset.name, "the asset has no mesh; glTF and USD output need one")
    # pd: the slope range; diff is stored with gain 1 (what shaders and the validator assume)
    scale = float(asset.pd_scale) if asset.encoding == "pd" else 1.0
    # the unit base band by band (per texel: the same vectors), made whole only for states of
    # its own size
    base_tex = encode_base(asset.base, opt.bits, normalize=True)
    textures = [PackedTexture("base_normal", base_tex, "base_normal")]
    taken = {"base_normal"}
    cache: dict[tuple[int, ...], np.ndarray] = {}
    states_meta = []
    for k, name in enumerate(asset.state_names):
        st = model.normalize(asset.states[k])
        b = _unit_base_at(asset.base, st.shape[:2], cache)
        tex = PackedTexture(
            safe_name(f"wrinkle_{name}", taken),
            encode_state(b, st, asset.encoding, scale, opt.bits, codec.CURRENT_VERSION),
            "state",
        )
        textures.append(tex)
        states_meta.append(StateMeta(name, tex.name))
    masks = np.clip(np.asarray(asset.masks, np.float32), 0.0, 1.0)
    names = [r.name for r in asset.regions]
    mask_tex, table = pack_masks(masks, names, opt.mask_layout, [r.side for r in asset.regions])
    mask_names = []
    for i, t in enumerate(mask_tex):
        mask_names.append(safe_name(f"mask_{i}", taken))
        textures.append(PackedTexture(mask_names[-1], _q(t, 8), "mask"))
    base_color = None
    if asset.color is not None:
        base_color, states_meta = _pack_colors(asset.color, asset.state_names, states_meta, taken)
        textures += base_color
    for k in asset.color_only:
        states_meta[k] = replace(states_meta[k], normal=False)
    meta = WrinkleMeta(
        encoding=asset.encoding,
        policy=asset.policy,
        states=tuple(states_meta),
        masks=MaskMeta(opt.mask_layout, tuple(mask_names), table_from_json(table)),
        regions=tuple(RegionMeta(r.name, r.side, tuple(r.states)) for r in asset.regions),
        scale=scale,
        mapping=codec.CURRENT_VERSION,
        expressions={
            e: {r: float(w) for r, w in sorted(row.items())}
            for e, row in sorted(asset.expressions.items())
        },
        drivers=tuple(dict(d) for d in asset.drivers),
        weights=(0.0,) * len(names),  # float32 values (they are animated as FLOAT)
        base_color=base_color[0].name if base_color else None,
        color_factor=asset.color.factor if asset.color is not None else (1.0, 1.0, 1.0),
    )
    return WrinklePackage(asset.name, asset.mesh, textures, meta, list(curves or []))


def _pack_colors(
    color: ColorMaps, state_names: tuple[str, ...], states_meta: list[StateMeta], taken: set[str]
) -> tuple[list[PackedTexture], list[StateMeta]]:
    """The base colour and the states' colour maps as stored textures (sRGB texels as they are:
    a map that ships at its own size keeps its bytes), and the states' descriptions naming
    them."""
    out = [PackedTexture(safe_name("base_color", taken), np.asarray(color.base), "base_color")]
    states_meta = list(states_meta)
    for j, k in enumerate(color.state_index):
        tex = PackedTexture(
            safe_name(f"color_{state_names[k]}", taken), np.asarray(color.states[j]), "state_color"
        )
        out.append(tex)
        states_meta[k] = replace(states_meta[k], color=tex.name)
    return out, states_meta


def mapping_version(meta: WrinkleMeta) -> int:
    """The value-mapping version an asset's metadata records (absent: the legacy v1);
    ValueError for a version this wrinklepipe cannot read."""
    return codec.mapping(int(meta.mapping)).version


def asset_from_package(pkg: WrinklePackage, maps: bool = True) -> WrinkleAsset:
    """Decode a package into float maps and masks (what validation and rendering work on).
    ``maps=False``: the normal maps are not decoded (base ``[0, 0, 3]``, states ``[K, 0, 0,
    3]``): for a caller that replaces them with the source's (the validator given a source:
    at 8192² the decode and its resample take 1.3 GB and seconds)."""
    meta = pkg.meta
    enc, scale = meta.encoding, float(meta.scale)
    version = mapping_version(meta)
    if not maps:
        base = np.zeros((0, 0, 3), np.float32)
    else:
        base = decode_base(pkg.texture(pkg.base_name).pixels)
    states = []
    cache: dict[tuple[int, ...], np.ndarray] = {}
    for s in meta.states if maps else ():
        stored = pkg.texture(s.texture).pixels
        b = _base_at(base, stored.shape[:2], cache)
        states.append(decode_state(b, stored, enc, scale, version))
    mask_tex = [_dq(pkg.texture(n).pixels) for n in meta.masks.textures]
    masks = unpack_masks(mask_tex, meta.masks.table_json())
    color_only = tuple(k for k, s in enumerate(meta.states) if not s.normal)
    return WrinkleAsset(
        name=pkg.name,
        base=base,
        states=np.stack(states)
        if states
        else np.zeros((0 if maps else len(meta.states),) + base.shape, np.float32),
        state_names=tuple(meta.state_names),
        masks=masks,
        regions=tuple(Region(r.name, r.side, r.states) for r in meta.regions),
        expressions={e: dict(row) for e, row in meta.expressions.items()},
        encoding=enc,
        policy=meta.policy,
        pd_scale=scale,
        mesh=pkg.mesh,
        drivers=[dict(d) for d in meta.drivers],
        color=colors_from_package(pkg),
        color_only=color_only,
    )


def colors_from_package(pkg: WrinklePackage) -> ColorMaps | None:
    """The package's colour maps as stored (None without colour states). States stored at
    different sizes are brought to the largest of them (in linear light), as one array."""
    meta = pkg.meta
    index = tuple(meta.color_states)
    if meta.base_color is None or not index:
        return None
    base = pkg.texture(meta.base_color).pixels
    states = [pkg.texture(meta.states[k].color).pixels[..., :3] for k in index]
    size = max((s.shape[:2] for s in states), key=lambda hw: hw[0] * hw[1])
    same = [resize_texels(s, size) for s in states]
    dtype = base.dtype
    same = [s if s.dtype == dtype else _as_depth(s, dtype) for s in same]
    return ColorMaps(base, np.stack(same), index, meta.color_factor, False)


def _as_depth(texels: np.ndarray, dtype: np.dtype) -> np.ndarray:
    from_bits = 16 if texels.dtype == np.uint16 else 8
    to_bits = 16 if dtype == np.uint16 else 8
    q = texels.astype(np.float64) * ((1 << to_bits) - 1) / ((1 << from_bits) - 1)
    return np.rint(q).astype(dtype)
