"""Read normal maps into float32 unit normals (+Y, OpenGL tangent space).

Inputs: PNG (8/16-bit), TIFF (8/16), EXR (half/float), JPEG through OpenImageIO; DDS (BC1, BC3,
BC5, BC7) through :mod:`wrinklepipe.normals.dds` and texture2ddecoder. Layouts:

``rgb``  x, y, z in R, G, B (alpha ignored).
``rg``   x, y in R, G; z rebuilt as ``sqrt(1 - x^2 - y^2)`` (BC5 maps, two-channel PNGs).
``ag``   DXT5nm: x in alpha, y in green, z rebuilt (R = 1 and B = 0 in such files).

``auto`` picks ``rg`` for two channels and for BC5, ``ag`` when R is 1 and B is 0 everywhere
with four channels, ``rg`` when B is 0 everywhere (x and y only), else ``rgb``.

Integer texels map ``[0, 1] -> [-1, 1]``; float (EXR) texels are taken as signed when any value
is negative, else as ``[0, 1]``-encoded. Texel problems are counted: NaN, zero length (shorter
than :data:`MIN_LENGTH`: too short to carry a direction, e.g. a flat mid-grey (128, 128, 128)
image, which is no normal map), non-unit (``| |n| - 1 | > unit_tolerance``) and ``z < 0``.
An image that is no tangent-space normal map (a colour or grey image, vectors that lean far
from the surface: :mod:`wrinklepipe.normals.identify`) is refused with what it looks like.
NaN and zero-length texels stop the read unless ``repair`` (they become (0, 0, 1)); with
``repair``, ``z < 0`` is mirrored to ``|z|``. Non-unit texels are always renormalised (that is
what decoding a normal map means); the count says how many needed it beyond quantisation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wrinklepipe.errors import input_error
from wrinklepipe.io.images import DEFAULT_MAX_PIXELS, read_image, texel_values
from wrinklepipe.names import plural
from wrinklepipe.normals import compress, dds
from wrinklepipe.normals.convention import ConventionReport, detect_convention, flip_green
from wrinklepipe.normals.held import HeldMap, NormalStack
from wrinklepipe.normals.identify import looks_like
from wrinklepipe.workset import band_rows

_F = np.float32
LAYOUTS: tuple[str, ...] = ("auto", "rgb", "rg", "ag")


@dataclass(frozen=True)
class ReadOptions:
    """How to read a normal map.

    convention: "auto" (detect, fall back to opengl), "opengl" or "directx" (flipped to +Y).
    layout: "auto", "rgb", "rg" or "ag" (see the module docstring).
    repair: replace NaN / zero texels by (0, 0, 1) and mirror z < 0, instead of refusing.
    max_pixels: refuse larger images before allocating.
    unit_tolerance: how far from 1 a decoded length may be before it counts as non-unit
        (8-bit rounding stays below ~0.01).
    detect: run the convention detector even when the convention is given (to warn).
    refusal_hint: what to do instead, added to the message refusing an image that is no
        normal map (e.g. where a colour map goes).
    """

    convention: str = "auto"
    layout: str = "auto"
    repair: bool = False
    max_pixels: int = DEFAULT_MAX_PIXELS
    unit_tolerance: float = 0.05
    detect: bool = True
    refusal_hint: str = ""


#: A decoded texel shorter than this has no reliable direction (8-bit (128, 128, 128) decodes
#: to length 0.0068; a real normal map, even a filtered one, stays far above 0.5).
MIN_LENGTH = 0.5
#: More short texels than this fraction and the file is not a normal map (a flat grey image, a
#: colour texture): refused unless ``repair``. Fewer (real maps have a few) are renormalised.
MAX_SHORT_FRACTION = 0.001


@dataclass
class NormalStats:
    """Counts of problem texels found while decoding (before any repair)."""

    texels: int = 0
    nan: int = 0
    zero: int = 0
    non_unit: int = 0
    z_negative: int = 0
    repaired: bool = False
    first_nan: tuple[int, int] | None = None  # (row, col)
    first_zero: tuple[int, int] | None = None
    short: int = 0  # shorter than MIN_LENGTH but not zero: no reliable direction
    first_short: tuple[int, int] | None = None

    def to_json(self) -> dict[str, object]:
        return {
            "texels": self.texels,
            "nan": self.nan,
            "zero": self.zero,
            "non_unit": self.non_unit,
            "z_negative": self.z_negative,
            "repaired": self.repaired,
        }


@dataclass
class NormalMap:
    """A decoded normal map and how it was read."""

    #: [H, W, 3] float32, unit, +Y; None for a map read ``held`` (made from ``integers``)
    normals: np.ndarray | None
    stats: NormalStats
    path: str
    width: int
    height: int
    channels: int
    layout: str
    source_format: str  # "png", "tiff", "openexr", "jpeg", "dds:bc5", ...
    convention: str  # the convention the file was read as (flipped to +Y when "directx")
    detection: ConventionReport | None = None
    notes: list[str] = field(default_factory=list)
    #: the file's integer texels ``[H, W, C]`` (uint8 / uint16) the normals decode from texel
    #: by texel (:mod:`wrinklepipe.normals.held`); None for a float file or a repaired map
    integers: np.ndarray | None = None

    def to_json(self) -> dict[str, object]:
        return {
            "path": self.path,
            "width": self.width,
            "height": self.height,
            "channels": self.channels,
            "layout": self.layout,
            "source_format": self.source_format,
            "convention": self.convention,
            "detection": self.detection.to_json() if self.detection else None,
            "stats": self.stats.to_json(),
            "notes": list(self.notes),
        }


def _first(mask: np.ndarray) -> tuple[int, int] | None:
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return None
    r, c = divmod(int(idx[0]), mask.shape[1] if mask.ndim > 1 else 1)
    return (r, c)


def guess_layout(values: np.ndarray) -> str:
    """The layout ``auto`` resolves to for texels [H, W, C] in [0, 1]: float32 values, or
    integer texels (uint8 / uint16) judged by the float32 values they read as
    (:func:`wrinklepipe.io.images.texel_values`) without making them."""
    c = values.shape[-1]
    if c == 2:
        return "rg"
    if c == 4 and _all(values, 0, 254.5 / 255, True) and _all(values, 2, 0.5 / 255, False):
        return "ag"
    if c >= 3 and _all(values, 2, 0.5 / 255, False):
        return "rg"
    return "rgb"


def _all(values: np.ndarray, channel: int, limit: float, above: bool) -> bool:
    """``np.all(v >= limit)`` (``above``, else ``v <= limit``) of the float32 values ``v`` of
    channel ``channel``. Integer texels' values rise with ``q``, so the test holds from (up to)
    one integer on: that integer is found among the values of every ``q`` and the texels'
    least (greatest) ``q`` compared with it; the float32 values are never made."""
    ch = values[..., channel]
    if values.dtype.kind != "u":
        return bool(np.all(ch >= limit) if above else np.all(ch <= limit))
    if ch.size == 0:
        return True
    every = texel_values(np.arange(np.iinfo(values.dtype).max + 1, dtype=values.dtype))
    ok = np.flatnonzero(every >= limit if above else every <= limit)
    if ok.size == 0:
        return False
    return bool(ch.min() >= ok[0]) if above else bool(ch.max() <= ok[-1])


def decode_texels(
    values: np.ndarray,
    layout: str = "auto",
    signed: bool = False,
    unit_tolerance: float = 0.05,
    bits: int = 0,
    keep_short: bool = False,
    out: np.ndarray | None = None,
) -> tuple[np.ndarray, NormalStats]:
    """Texel values [H, W, C] -> (vectors [H, W, 3] float32, :class:`NormalStats`).

    The vectors are normalised where they can be (NaN and zero texels stay as they are, and with
    ``keep_short`` those shorter than :data:`MIN_LENGTH`; see :func:`repair_normals`).
    ``signed``: values are already in [-1, 1]. ``bits`` (8 or 16): the values are
    ``q / (2^bits - 1)`` of integer texels, decoded exactly as ``(2 q - top) / top``.
    ``out``: a float32 ``[H, W, 3]`` array to decode into (e.g. the map's place in a stack of
    maps), returned as the vectors; the same values.
    """
    v = np.asarray(values, dtype=_F)
    if v.ndim == 2:
        v = v[..., None]
    lay = resolved_layout(v, layout, signed)
    h, w = v.shape[:2]
    rows = band_rows(w, BAND_BYTES_PER_TEXEL) if v.ndim == 3 else h
    if out is not None and (out.shape != (h, w, 3) or out.dtype != _F):
        raise ValueError(f"decode_texels: out is {out.dtype} {out.shape}, not float32 {(h, w, 3)}")
    if h <= rows:
        n, st = _decode(v, lay, signed, unit_tolerance, bits, keep_short)
        if out is None:
            return n, st
        out[...] = n
        return out, st
    # band by band: every step is per texel, so the vectors are the whole image's, and the
    # temporaries are one band's (a whole 8192² map's are about 2.5 GB)
    if out is None:
        out = np.empty((h, w, 3), _F)
    stats = NormalStats()
    for r0 in range(0, h, rows):
        n, st = _decode(v[r0 : r0 + rows], lay, signed, unit_tolerance, bits, keep_short)
        out[r0 : r0 + rows] = n
        del n
        stats = _merged(stats, st, r0)
    return out, stats


def resolved_layout(values: np.ndarray, layout: str, signed: bool = False) -> str:
    """The layout (``rgb``, ``rg``, ``ag``) :func:`decode_texels` decodes texels ``values``
    [H, W, C] in when asked for ``layout``: float32 values or integer texels (as they read,
    :func:`guess_layout`). Raises ValueError for a channel count or layout that cannot be."""
    c = values.shape[-1]
    if c not in (2, 3, 4):
        raise ValueError(
            f"has {c} channel{'s' if c != 1 else ''}; a normal map needs 2 (RG), 3 (RGB) or 4 "
            "(RGBA, or DXT5nm with x in alpha)"
        )
    lay = guess_layout(values) if layout == "auto" and not signed else layout
    if lay == "auto":
        lay = "rg" if c == 2 else "rgb"
    if lay not in LAYOUTS[1:]:
        raise ValueError(f"unknown layout {layout!r}; expected one of {', '.join(LAYOUTS)}")
    if lay == "rgb" and c < 3:
        raise ValueError(f"layout 'rgb' needs 3 channels, the map has {c}")
    if lay == "ag" and c < 4:
        raise ValueError(f"layout 'ag' (DXT5nm) needs 4 channels, the map has {c}")
    return lay


def decode_integers(
    q: np.ndarray,
    layout: str,
    unit_tolerance: float = 0.05,
    out: np.ndarray | None = None,
) -> tuple[np.ndarray | None, NormalStats]:
    """:func:`decode_texels` of integer texels ``q`` [H, W, C] (uint8 / uint16) read as their
    float32 values (:func:`wrinklepipe.io.images.texel_values`), in the resolved ``layout``,
    band by band: the float values are one band's, never the whole map's. The vectors go to
    ``out`` (a float32 ``[H, W, 3]`` array) when given, else nowhere (None: the counts alone);
    the counts are the whole map's, bit for bit (every step is per texel)."""
    bits = 8 if q.dtype == np.uint8 else 16
    h, w = q.shape[:2]
    rows = band_rows(w, BAND_BYTES_PER_TEXEL + 4 * q.shape[-1])
    total = NormalStats()
    for r0 in range(0, h, rows):
        n, st = _decode(texel_values(q[r0 : r0 + rows]), layout, False, unit_tolerance, bits, False)
        if out is not None:
            out[r0 : r0 + rows] = n
        del n
        total = _merged(total, st, r0)
    return out, total


#: Bytes of temporaries per texel while decoding (float32 vectors, lengths, flags).
BAND_BYTES_PER_TEXEL = 48


def _merged(a: NormalStats, b: NormalStats, row: int) -> NormalStats:
    """Counts of ``a`` (the rows above) and ``b`` (a band starting at ``row``) together."""

    def first(x: tuple[int, int] | None, y: tuple[int, int] | None) -> tuple[int, int] | None:
        return x if x is not None else None if y is None else (y[0] + row, y[1])

    return NormalStats(
        texels=a.texels + b.texels,
        nan=a.nan + b.nan,
        zero=a.zero + b.zero,
        non_unit=a.non_unit + b.non_unit,
        z_negative=a.z_negative + b.z_negative,
        first_nan=first(a.first_nan, b.first_nan),
        first_zero=first(a.first_zero, b.first_zero),
        short=a.short + b.short,
        first_short=first(a.first_short, b.first_short),
    )


def _decode(
    v: np.ndarray, lay: str, signed: bool, unit_tolerance: float, bits: int, keep_short: bool
) -> tuple[np.ndarray, NormalStats]:
    """:func:`decode_texels` of float32 texels ``v`` [H, W, C] in the resolved layout ``lay``."""

    def sig(x: np.ndarray) -> np.ndarray:
        """A new float32 array of signed components."""
        if signed:
            return np.array(x, dtype=_F, copy=True)
        if bits:
            # exact and symmetric: (2 q - top) / top, so flipping green (q -> top - q) gives
            # exactly -y and a DirectX map read as DirectX equals the OpenGL map bit for bit
            top = _F((1 << bits) - 1)
            q = x * top
            np.rint(q, out=q)
            q *= _F(2.0)
            q -= top
            q /= top
            return q
        q = x * _F(2.0)
        q -= _F(1.0)
        return q

    if lay == "rgb":
        n = np.ascontiguousarray(sig(v[..., :3]))
    else:
        x = sig(v[..., 3] if lay == "ag" else v[..., 0])
        y = sig(v[..., 1])
        n = np.empty(x.shape + (3,), dtype=_F)
        n[..., 0] = x
        n[..., 1] = y
        z2 = _F(1.0) - x * x - y * y
        np.maximum(z2, _F(0.0), out=z2)
        np.sqrt(z2, out=n[..., 2])
    l2 = np.einsum("...c,...c->...", n, n)
    length = np.sqrt(l2, out=l2)
    if np.isfinite(length.sum(dtype=np.float64)):
        nan = np.zeros(length.shape, dtype=bool)
    else:
        nan = ~np.isfinite(length)
    zero = length < 1e-6  # NaN compares False
    short = (length < _F(MIN_LENGTH)) & ~zero
    non_unit = np.abs(length - _F(1.0)) > unit_tolerance
    non_unit &= ~zero
    zneg = n[..., 2] < 0
    stats = NormalStats(
        texels=int(nan.size),
        nan=int(np.count_nonzero(nan)),
        zero=int(np.count_nonzero(zero)),
        non_unit=int(np.count_nonzero(non_unit)),
        z_negative=int(np.count_nonzero(zneg)),
        first_nan=_first(nan),
        first_zero=_first(zero),
        short=int(np.count_nonzero(short)),
        first_short=_first(short),
    )
    # divide in place; NaN and zero texels (and short ones with keep_short) are left as they are
    keep = zero | nan | short if keep_short else zero | nan
    safe = np.where(keep, _F(1.0), length)
    n /= safe[..., None]
    return n, stats


def repair_normals(normals: np.ndarray) -> np.ndarray:
    """NaN / zero-length texels -> (0, 0, 1); z < 0 -> |z|; renormalise. Returns a copy."""
    n = np.array(normals, dtype=_F, copy=True)
    bad = ~np.isfinite(n).all(axis=-1)
    n[bad] = 0.0
    length = np.sqrt(np.einsum("...c,...c->...", n, n))
    bad |= length < _F(MIN_LENGTH)
    n[bad] = (0.0, 0.0, 1.0)
    n[..., 2] = np.abs(n[..., 2])
    length = np.sqrt(np.einsum("...c,...c->...", n, n))
    return n / length[..., None]


def _read_dds_integers(path: Path, max_pixels: int) -> tuple[np.ndarray, str, int]:
    """A DDS file's decoded 8-bit texels (its float values are ``q / 255``, as read)."""
    img = dds.read_dds(path, max_pixels)
    fmt = "bc3nm" if img.format == "bc3" else img.format
    rgba = compress.decode_bc(img.levels[0], _pad4(img.width), _pad4(img.height), fmt)
    q = rgba[: img.height, : img.width]
    q = np.ascontiguousarray(q[..., :2] if img.format == "bc5" else q)
    return q, f"dds:{img.format}", q.shape[-1]


def _pad4(x: int) -> int:
    return (x + 3) // 4 * 4


def _put(normals: np.ndarray, out: np.ndarray | None) -> np.ndarray:
    """``normals`` in ``out`` (a float32 ``[H, W, 3]`` array: the map's place in a stack of
    maps, no second copy of the map) when given: decoded there, or put there when repaired or
    flipped (a new array); else ``normals``."""
    if out is None or normals is out:
        return normals
    out[...] = normals
    return out


def _read_texels(path: Path, max_pixels: int) -> tuple[np.ndarray, str, int, int, bool]:
    """A normal map file's texels ``[H, W, C]`` (an 8- or 16-bit file's and a DDS file's as
    integers, a float file's as float32), its format, channels, bits (0: float) and whether
    its float values are signed (some below -1e-3)."""
    if path.suffix.lower() == ".dds":
        q, source_format, channels = _read_dds_integers(path, max_pixels)
        return q, source_format, channels, 8, False
    texels, info = read_image(path, max_pixels, integers=True)
    signed = False
    if info.format in ("half", "float", "double"):
        finite = texels[np.isfinite(texels)]
        signed = bool(finite.size and finite.min() < -1e-3)
        del finite
    bits = {"uint8": 8, "uint16": 16}.get(info.format, 0)
    return texels, str(info.file_format), int(info.channels), bits, signed


def _texel_problems(stats: NormalStats, too_short: bool) -> str:
    """Why a map's texels stop the read (NaN, zero-length, too many short texels)."""
    where = []
    if stats.nan:
        where.append(
            f"{plural(stats.nan, 'NaN texel')}, first at row {stats.first_nan[0]}, "
            f"col {stats.first_nan[1]}"
        )
    if stats.zero:
        where.append(
            f"{plural(stats.zero, 'zero-length texel')}, first at row "
            f"{stats.first_zero[0]}, col {stats.first_zero[1]}"
        )
    if too_short:
        flat = " (a flat mid-grey image is no normal map: flat is (128, 128, 255))"
        where.append(
            f"{stats.short} of {plural(stats.texels, 'texel')} too short to be normals "
            f"(length < {MIN_LENGTH}), first at row {stats.first_short[0]}, col "
            f"{stats.first_short[1]}" + (flat if stats.short == stats.texels else "")
        )
    return "; ".join(where) + "; fix the map (encode-normals --repair replaces them with (0, 0, 1))"


def read_normal_map(
    path: str | Path,
    options: ReadOptions | None = None,
    out: np.ndarray | None = None,
    held: bool = False,
) -> NormalMap:
    """Read a normal map file into unit +Y normals. Raises :class:`InputError` on bad input.
    ``out``: where to put the normals when it fits the map (:func:`_put`). ``held``: a map
    with integers (:attr:`NormalMap.integers`) is returned without its normals (``normals``
    None: the caller holds the integers, :class:`wrinklepipe.normals.held.HeldMap`), and its
    float32 values and normals are never made whole (a band at a time where needed)."""
    o = options or ReadOptions()
    path = Path(path)
    if o.convention not in ("auto", "opengl", "directx"):
        raise input_error(path, f"unknown convention {o.convention!r} (auto, opengl, directx)")
    texels, source_format, channels, bits, signed = _read_texels(path, o.max_pixels)
    # an 8- or 16-bit file's texels as stored (uint8 / uint16: what the map is held as); their
    # float32 values (texel_values) made a band at a time where needed, or whole for a repair
    q = texels if texels.dtype.kind == "u" else None
    if q is None:
        values = texels
    del texels
    if channels not in (2, 3, 4):
        raise input_error(
            path,
            f"has {channels} channel{'s' if channels != 1 else ''}; a normal map needs 2 (RG), "
            "3 (RGB) or 4 (RGBA, or DXT5nm with x in alpha)",
        )
    if q is not None and o.repair:  # repaired as float32 normals: no integers kept
        values = texel_values(q)
        q = None
    shape = q.shape if q is not None else values.shape
    fits = out is not None and out.shape == (*shape[:2], 3) and out.dtype == _F
    out = out if fits else None
    try:
        if q is None:
            normals, stats = decode_texels(
                values, o.layout, signed, o.unit_tolerance, bits, keep_short=o.repair, out=out
            )
        else:  # banded: the counts alone when held, else the normals too
            lay = resolved_layout(q, o.layout)
            dest = None if held else out if out is not None else np.empty((*shape[:2], 3), _F)
            normals, stats = decode_integers(q, lay, o.unit_tolerance, out=dest)
    except ValueError as exc:
        raise input_error(path, str(exc)) from None
    texels = q if q is not None else values
    layout = o.layout if o.layout != "auto" else (guess_layout(texels) if not signed else "rgb")
    if signed and channels == 2:
        layout = "rg"
    notes: list[str] = []
    too_short = stats.short > MAX_SHORT_FRACTION * stats.texels
    # integer texels only: a float image holds signed or encoded vectors, which its values
    # alone cannot always tell (the reader's rule above), so their lengths say nothing sure
    what = looks_like(texels, layout) if bits else ""
    integers = q
    del texels
    if q is None:
        del values  # the texels as read: not needed past this point (a map's worth of float32)
    if what and not (too_short and stats.short == stats.texels):
        # a colour or grey image, or no tangent-space map: refused, whatever repair says
        hint = f"; {o.refusal_hint}" if o.refusal_hint else ""
        raise input_error(path, f"is not a tangent-space normal map: it looks like {what}{hint}")
    if stats.nan or stats.zero or too_short:
        if not o.repair:
            raise input_error(path, _texel_problems(stats, too_short))
    if o.repair and (stats.nan or stats.zero or stats.short or stats.z_negative):
        normals = repair_normals(normals)
        stats.repaired = True
        notes.append(
            f"repaired {stats.nan} NaN, {stats.zero + stats.short} zero-length or short and "
            f"{stats.z_negative} z<0 texels"
        )
    if stats.non_unit:
        notes.append(f"{stats.non_unit} texels were not unit length (renormalised)")
    if stats.z_negative and not o.repair:
        notes.append(f"{stats.z_negative} texels point below the surface (z < 0)")
    # a held map's normals decoded a band of rows at a time for the curl test (the same bits;
    # green unflipped, as the reader's normals are here)
    seen = normals
    if seen is None:
        seen = NormalStack([HeldMap(integers, layout, False)], single=True)  # type: ignore[arg-type]
    detection = detect_convention(seen) if (o.detect or o.convention == "auto") else None
    del seen
    conv = o.convention
    if conv == "auto":
        conv = (
            detection.convention
            if detection and detection.convention != "undetermined"
            else "opengl"
        )
        if detection is not None and detection.convention == "undetermined":
            notes.append(f"convention undetermined ({detection.reason}); assumed opengl")
    elif detection is not None and detection.convention not in ("undetermined", conv):
        notes.append(
            f"convention given as {conv} but the map looks like {detection.convention} "
            f"(confidence {detection.confidence:.2f})"
        )
    h, w = shape[:2]
    if normals is not None:
        if conv == "directx":
            normals = flip_green(normals)
        normals = np.ascontiguousarray(_put(normals, out), dtype=_F)
    return NormalMap(
        normals=normals,  # type: ignore[arg-type]
        stats=stats,
        path=str(path),
        width=w,
        height=h,
        channels=channels,
        layout=layout,
        source_format=source_format,
        convention=conv,
        detection=detection,
        notes=notes,
        integers=integers,
    )
