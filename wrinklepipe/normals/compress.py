"""Block compression of normal and wrinkle maps, and how much it costs in degrees.

Encoders (each the lowest-error one measured by ``wrinklepipe bench normals``): BC5 and the
alpha half of BC3nm by :mod:`wrinklepipe.normals.bc4` (vectorised numpy, within ~2 % of an
exhaustive endpoint search), BC1 and BC3nm's colour half by quicktex, BC7 by ispc_texcomp.
Decoding uses texture2ddecoder (which returns BGRA; this module hands back RGBA).
Channel layouts are the codec's (:mod:`wrinklepipe.codec.formats`):

``bc5``    3Dc / ATI2: R = x, G = y, each an independent 8-bit-endpoint BC4 block (8 bpp).
``bc1``    DXT1 (4 bpp): a normal map stores x, y, z in R, G, B; two-component data (PD
           slopes) R = x, G = y, B = 0.
``bc3nm``  DXT5nm: x in alpha (BC4-like block), y in green (6-bit endpoints), R = 1, B = 0
           (8 bpp) -- the swizzle Unity/Unreal "DXT5nm" normal maps use.
``bc7``    BC7 (8 bpp): x, y, z in R, G, B for a normal map (A = 1); PD slopes in R, G.
``bc7xy``  BC7 with x, y only and z rebuilt: an explicit option, never chosen by ``auto``.

Three-channel data (``diff`` maps, normal maps with z) goes to ``bc1`` and ``bc7``.

Stored texels are integers under the codec's value mapping; :func:`decoder_for` decodes them
exactly (or sampled 8-bit values in [0, 1] with the shaders' arithmetic).

Error metrics: the angle between the decoded and the reference unit normals (mean, p99, max,
degrees) by the one measure (:mod:`wrinklepipe.metrics`: its angle, its nearest-rank p99, its
budget verdict), PSNR per stored channel against the uncompressed 8-bit texels.
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import ispc_texcomp
import numpy as np
import quicktex
import quicktex.s3tc.bc1 as quicktex_bc1
import quicktex.s3tc.bc3 as quicktex_bc3
import texture2ddecoder

from wrinklepipe import codec
from wrinklepipe.metrics import Budget, Stats, angle_deg, weighted_stats
from wrinklepipe.normals import bc4
from wrinklepipe.normals._chunks import map_rows
from wrinklepipe.normals.blocks import encode_distinct
from wrinklepipe.reuse import reused
from wrinklepipe.workset import band_rows

_F = np.float32

FORMATS: tuple[str, ...] = ("bc5", "bc1", "bc3nm", "bc7", "bc7xy")
#: Formats ``auto`` chooses from (``bc7xy`` only when asked for by name).
AUTO_FORMATS: tuple[str, ...] = tuple(f for f in FORMATS if not codec.storage_format(f).explicit)
#: Bytes per 4x4 block.
BLOCK_BYTES: dict[str, int] = {f: codec.storage_format(f).block_bytes for f in FORMATS}
#: Formats that can hold three channels (x, y, z or a difference map).
RGB_FORMATS: tuple[str, ...] = tuple(f for f in FORMATS if codec.storage_format(f).rgb)


# ------------------------------------------------------------------------------------------
# packing, padding, encode, decode


def check_format(fmt: str) -> str:
    """Validate a format name; returns it."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown block format {fmt!r}; expected one of {', '.join(FORMATS)}")
    return fmt


def pad_to_blocks(values: np.ndarray) -> tuple[np.ndarray, tuple[int, int]]:
    """Pad [H, W, ...] to multiples of 4 by repeating the last row/column; returns the old size."""
    a = np.asarray(values)
    h, w = a.shape[:2]
    ph, pw = (-h) % 4, (-w) % 4
    if ph == 0 and pw == 0:
        return a, (h, w)
    pad = [(0, ph), (0, pw)] + [(0, 0)] * (a.ndim - 2)
    return np.pad(a, pad, mode="edge"), (h, w)


def layout_of(fmt: str, channels: int) -> codec.Layout:
    """The codec layout ``channels`` components take in ``fmt``: three -> x, y, z in R, G, B;
    two -> the format's two-component layout (R, G; DXT5nm: A, G)."""
    f = codec.storage_format(check_format(fmt))
    if channels == 3:
        if not f.rgb:
            raise ValueError(f"{fmt} holds two channels; three-channel data needs bc1 or bc7")
        return codec.RGB
    if channels == 2:
        return f.pair_layout
    raise ValueError(f"expected 2 or 3 channels, got {channels}")


def pack_rgba(q: np.ndarray, fmt: str, out: np.ndarray | None = None) -> np.ndarray:
    """Place 8-bit texels [H, W, 2 or 3] into the RGBA layout ``fmt`` expects [H, W, 4] uint8.

    Two channels (x, y): bc5/bc1/bc7/bc7xy -> (x, y, 0, 255); bc3nm -> (255, y, 0, x) (DXT5nm).
    Three channels (bc1/bc7 only): (x, y, z, 255).
    """
    q = np.asarray(q)
    if q.dtype != np.uint8:
        raise ValueError(f"pack_rgba expects uint8 texels, got {q.dtype}")
    packed = codec.layouts.pack(q, layout_of(fmt, q.shape[-1]), 4)
    if out is None:
        return packed
    out[...] = packed
    return out


#: quicktex's preset levels for BC1 and BC3's colour blocks: each block keeps the encoding of
#: lower squared RGB error (a tie keeps the first). Level 5 (its default; 18 is ~30x slower for
#: ~2 % less error) alone leaves some near-flat blocks far off (a block of 95-99 blue stored as
#: 85, 14 levels, where level 0 is within 3): on three 2048 maps of ../shared/data level 0 is
#: better on 0-10 % of the blocks and the best of the two has 0.4-28 % less squared error, for
#: about twice the (native, fast) encoding time.
QUICKTEX_LEVELS = (5, 0)
#: The level the bench's plain "quicktex" rows use.
QUICKTEX_LEVEL = QUICKTEX_LEVELS[0]
#: ispc_texcomp's BC7 profile ("basic": the lowest error of its opaque profiles).
ISPC_BC7_PROFILE = "basic"


@reused  # the search's roundtrip and the copy encode the same texels once per conversion
def encode_bc(rgba: np.ndarray, fmt: str, targets: np.ndarray | None = None) -> bytes:
    """Compress RGBA8 [H, W, 4] (H, W multiples of 4) in the layout of ``fmt``; returns the
    block data (row-major blocks).

    Encoders, each the lowest-error one measured in ``wrinklepipe bench normals``: BC5 and
    BC3nm's alpha (x) half by :mod:`wrinklepipe.normals.bc4` (near the exhaustive search);
    BC1 and BC3nm's colour half by quicktex; BC7 by ispc_texcomp. ``targets`` ([H, W, C]
    float texel values, the unrounded map) lets the BC4-based encoders fit the source instead
    of its 8-bit rounding: BC5 reads x, y from its two components, BC3nm x from the first.
    Without ``targets`` each distinct 4x4 block is encoded once, and inside a conversion not
    again when this run encoded it before (:func:`wrinklepipe.normals.blocks.encode_distinct`:
    the same bytes).
    """
    check_format(fmt)
    a = np.ascontiguousarray(rgba, dtype=np.uint8)
    if a.ndim != 3 or a.shape[2] != 4:
        raise ValueError(f"encode_bc expects [H, W, 4] uint8, got {a.shape}")
    h, w = a.shape[:2]
    if h % 4 or w % 4 or h == 0 or w == 0:
        raise ValueError(f"block formats need sizes that are multiples of 4, got {w} x {h}")
    if targets is None:
        memo = f"encode_bc:{fmt}:{QUICKTEX_LEVELS}:{ISPC_BC7_PROFILE}:{bc4.HARD_STEP}"
        return encode_distinct(a, lambda t: _encode_bc(t, fmt, None), BLOCK_BYTES[fmt], memo)
    return _encode_bc(a, fmt, targets)


def _encode_bc(a: np.ndarray, fmt: str, targets: np.ndarray | None) -> bytes:
    h, w = a.shape[:2]
    if fmt == "bc5":
        if targets is not None:
            return bc4.encode_bc5(targets[..., 0], targets[..., 1])
        return bc4.encode_bc5(a[..., 0], a[..., 1])
    if fmt == "bc1":
        return _quicktex_best(a, fmt).tobytes()
    if fmt == "bc3nm":
        blocks = _quicktex_best(a, fmt)
        blocks[:, :8] = bc4.bc4_blocks(a[..., 3] if targets is None else targets[..., 0])
        return blocks.tobytes()
    surface = ispc_texcomp.RGBASurface(a.tobytes(), w, h, w * 4)
    settings = ispc_texcomp.BC7EncSettings.from_profile(ISPC_BC7_PROFILE)
    return bytes(ispc_texcomp.compress_blocks_bc7(surface, settings))  # bc7 and bc7xy


_QUICKTEX = {"bc1": quicktex_bc1.BC1Encoder, "bc3nm": quicktex_bc3.BC3Encoder}
#: Built quicktex encoders not in use, by (format, level).
_QUICKTEX_FREE: dict[tuple[str, int], list[Any]] = {}
_QUICKTEX_LOCK = threading.Lock()


@contextlib.contextmanager
def _quicktex_encoder(fmt: str, level: int) -> Iterator[Any]:
    """quicktex's encoder of ``fmt`` at ``level``, for this thread while the block lasts, then
    kept for the next caller: building one takes 20-27 ms (its tables), encoding a small level
    with it microseconds (mip levels and the searches' partial round trips are many small
    encodings, often on short-lived pool threads). No encoder serves two threads at once; its
    settings are all its state, so a kept encoder gives the bytes a new one gives."""
    with _QUICKTEX_LOCK:
        free = _QUICKTEX_FREE.setdefault((fmt, level), [])
        encoder = free.pop() if free else None
    if encoder is None:
        encoder = _QUICKTEX[fmt](level)
    try:
        yield encoder
    finally:
        with _QUICKTEX_LOCK:
            _QUICKTEX_FREE[fmt, level].append(encoder)


def keep_quicktex_encoders() -> None:
    """Build one quicktex encoder of each format and level now and keep it for the first
    caller (a process that forks many workers builds them once instead of once per worker)."""
    for fmt in _QUICKTEX:
        for level in QUICKTEX_LEVELS:
            if not _QUICKTEX_FREE.get((fmt, level)):
                with _quicktex_encoder(fmt, level):
                    pass


def _quicktex_best(a: np.ndarray, fmt: str) -> np.ndarray:
    """quicktex's blocks [N, bytes] of RGBA8 ``a`` at each of :data:`QUICKTEX_LEVELS`, each
    block the one whose decoded R, G, B (:func:`decode_bc_bgra`) are nearest ``a``'s (squared
    error; a tie keeps the first level); BC3's alpha half is left to the caller.

    Band by band of block rows (every block is encoded and judged on its own: the whole map's
    blocks), so the int32 errors are a band's (:func:`wrinklepipe.workset.band_rows`)."""
    h, w = a.shape[:2]
    rows = max(4, band_rows(w, QUICKTEX_BYTES_PER_TEXEL) // 4 * 4)
    if h <= rows:
        return _quicktex_band(a, fmt)
    return np.concatenate([_quicktex_band(a[r : r + rows], fmt) for r in range(0, h, rows)])


#: Bytes of temporaries per texel while picking quicktex's blocks (int32 texels and errors).
QUICKTEX_BYTES_PER_TEXEL = 48


def _quicktex_band(a: np.ndarray, fmt: str) -> np.ndarray:
    h, w = a.shape[:2]
    tex = quicktex.RawTexture.frombytes(a.tobytes(), w, h)
    want = a[..., 2::-1].astype(np.int32)  # B, G, R: texture2ddecoder's order
    blocks, errors = [], []
    for level in QUICKTEX_LEVELS:
        with _quicktex_encoder(fmt, level) as encoder:
            data = bytes(encoder.encode(tex).tobytes())
        # not the memo's decode: a candidate level's band is decoded once, never asked again
        # (the memo kept every level's decoded band, about 128 MiB at 4096²)
        d = _decode_bgra(data, w, h, fmt)[..., :3].astype(np.int32) - want
        errors.append((d * d).reshape(h // 4, 4, w // 4, 4, 3).sum(axis=(1, 3, 4)).ravel())
        blocks.append(np.frombuffer(data, np.uint8).reshape(errors[-1].size, -1))
    pick = np.argmin(np.stack(errors), axis=0)  # the first of equal errors
    return np.stack(blocks)[pick, np.arange(pick.size)]


def block_data_size(fmt: str, width: int, height: int) -> int:
    """Bytes of one level: ``ceil(w/4) * ceil(h/4) * block bytes``."""
    return ((width + 3) // 4) * ((height + 3) // 4) * BLOCK_BYTES[check_format(fmt)]


_DECODERS = {
    "bc1": texture2ddecoder.decode_bc1,
    "bc3nm": texture2ddecoder.decode_bc3,
    "bc5": texture2ddecoder.decode_bc5,
    "bc7": texture2ddecoder.decode_bc7,
    "bc7xy": texture2ddecoder.decode_bc7,
}


@reused
def decode_bc_bgra(data: bytes, width: int, height: int, fmt: str) -> np.ndarray:
    """texture2ddecoder's output as is: [H, W, 4] uint8 in B, G, R, A order."""
    return _decode_bgra(data, width, height, fmt)


def _decode_bgra(data: bytes, width: int, height: int, fmt: str) -> np.ndarray:
    """:func:`decode_bc_bgra` without the memo (a decode asked once)."""
    check_format(fmt)
    need = block_data_size(fmt, width, height)
    if len(data) < need:
        raise ValueError(f"{fmt} data for {width} x {height} needs {need} bytes, got {len(data)}")
    raw = _DECODERS[fmt](bytes(data[:need]), width, height)
    return np.frombuffer(raw, dtype=np.uint8).reshape(height, width, 4)


def decode_bc(data: bytes, width: int, height: int, fmt: str) -> np.ndarray:
    """Decode block data to RGBA8 [H, W, 4] with texture2ddecoder (independent of etcpak)."""
    return decode_bc_bgra(data, width, height, fmt)[..., [2, 1, 0, 3]]


# channel index of x and y in texture2ddecoder's BGRA output, per format
_BGRA_XY = {"bc5": (2, 1), "bc1": (2, 1), "bc7": (2, 1), "bc7xy": (2, 1), "bc3nm": (3, 1)}


def unpack_u8(
    bgra_or_rgba: np.ndarray, fmt: str, channels: int = 2, bgra: bool = False
) -> np.ndarray:
    """The stored 8-bit channels [H, W, channels] (x, y[, z]) from decoded texels."""
    check_format(fmt)
    a = np.asarray(bgra_or_rgba)
    if channels == 3:
        if fmt not in RGB_FORMATS:
            raise ValueError(f"{fmt} holds two channels")
        idx = [2, 1, 0] if bgra else [0, 1, 2]
    else:
        ix, iy = _BGRA_XY[fmt]
        if not bgra:
            ix, iy = {2: 0, 1: 1, 3: 3}[ix], {2: 0, 1: 1, 3: 3}[iy]
        idx = [ix, iy]
    return a[..., idx]


# ------------------------------------------------------------------------------------------
# error metrics


def error_stats(angles: np.ndarray, mask: np.ndarray | None = None) -> Stats:
    """Mean / p99 / max of per-texel angles in degrees (every texel weighs 1; ``mask``: only
    those texels), by :func:`wrinklepipe.metrics.weighted_stats`."""
    a = np.asarray(angles, dtype=_F)
    if mask is not None:
        a = a[np.asarray(mask, dtype=bool)]
    return weighted_stats(a)


def angular_error_stats(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None) -> Stats:
    """:func:`error_stats` of the angle between normals ``a`` and ``b`` ``[..., 3]``."""
    return error_stats(angle_deg(a, b), mask)


def squared_errors(reference: np.ndarray, decoded: np.ndarray) -> np.ndarray:
    """Per channel (last axis), the sum of squared differences of 8-bit texels, exact (int64):
    what :func:`psnr` takes, summed band by band (:func:`psnr_of`)."""
    r = np.asarray(reference)
    c = r.shape[-1]
    r = r.reshape(-1, c).astype(np.int32)
    d = np.asarray(decoded).reshape(r.shape).astype(np.int32)
    e = r - d
    return np.einsum("ij,ij->j", e, e, dtype=np.int64)


def psnr_of(sse: np.ndarray, texels: int) -> list[float]:
    """PSNR in dB per channel from :func:`squared_errors` over ``texels`` texels (``inf`` where
    identical). The mean of exact integer squares, each partial sum exact in float64, is
    the sum divided by the count: the whole image's :func:`psnr` bit for bit."""
    out = []
    for s in np.asarray(sse, np.int64):
        mse = float(int(s)) / texels if texels else 0.0
        out.append(float("inf") if mse == 0 else 10.0 * math.log10(255.0**2 / mse))
    return out


def psnr(reference: np.ndarray, decoded: np.ndarray) -> list[float]:
    """PSNR in dB per channel (last axis) of 8-bit texels; ``inf`` where identical."""
    r = np.asarray(reference)
    n = r.size // r.shape[-1] if r.ndim else 0
    return psnr_of(squared_errors(r, decoded), n)


# ------------------------------------------------------------------------------------------
# checks


@dataclass
class FormatCheck:
    """What one block format does to a map: bytes, error in degrees, PSNR, verdict."""

    format: str
    width: int
    height: int
    bytes: int
    error: Stats  # decoded normals vs the reference (float) normals
    compression_error: Stats  # decoded vs the uncompressed 8-bit map (the codec's share)
    psnr_db: list[float]
    blended: dict[str, Stats] = field(default_factory=dict)  # weight -> error of the blend
    verdict: str = "pass"
    padded: bool = False
    data: bytes = b""  # level-0 block data (what a DDS/KTX2 writer stores)
    decoded: np.ndarray | None = None  # decoded stored channels, uint8 [H, W, C]

    def to_json(self) -> dict[str, Any]:
        return {
            "format": self.format,
            "width": self.width,
            "height": self.height,
            "bytes": self.bytes,
            "error": self.error.to_json(),
            "compression_error": self.compression_error.to_json(),
            "psnr_db": [round(p, 4) if math.isfinite(p) else None for p in self.psnr_db],
            "blended": {k: v.to_json() for k, v in sorted(self.blended.items())},
            "verdict": self.verdict,
            "padded": self.padded,
        }


#: Representative activations at which the blended result is checked.
BLEND_WEIGHTS: tuple[float, ...] = (0.5, 1.0)


def decoder_for(
    encoding: str,
    scale: float = 1.0,
    gain: float = 1.0,
    base: np.ndarray | None = None,
    version: int | None = codec.CURRENT_VERSION,
) -> Callable[[np.ndarray, slice], np.ndarray]:
    """``f(texels chunk, rows) -> normals chunk`` for an encoding (diff needs ``base``).

    Integer texels (components x, y[, z]) are decoded exactly by :func:`wrinklepipe.codec.decode`
    under the mapping ``version``; float texels are sampled 8-bit values in [0, 1] and decoded
    with the shaders' arithmetic (:func:`wrinklepipe.codec.decode_sampled`).
    """
    e = codec.encoding(encoding)
    if e.name == "composite":
        raise ValueError("composite maps are checked as full normal maps")
    param = scale if e.name == "pd" else gain
    if e.name == "diff":
        if base is None:
            raise ValueError("decoding a diff map needs the base normals")
        b = np.asarray(base, _F)

    def dec(v: np.ndarray, rows: slice) -> np.ndarray:
        v = np.asarray(v)
        where = codec.RGB if v.shape[-1] == 3 else codec.RG
        if v.dtype.kind == "f":
            x = codec.decode_sampled(e, v, where, bits=8, param=param, version=version)
        else:
            x = codec.decode(e, v, where, param=param, version=version)
        return e.to_normal(x, b[rows] if e.name == "diff" else None)

    return dec


def _blocks_rgba(q: np.ndarray, fmt: str) -> np.ndarray:
    """``q`` padded to whole blocks and placed in ``fmt``'s RGBA layout, band by band."""
    qp, _ = pad_to_blocks(q)
    hp, wp = qp.shape[:2]
    rgba = np.empty((hp, wp, 4), dtype=np.uint8)
    map_rows(lambda r: pack_rgba(qp[r], fmt, out=rgba[r]), hp, wp)
    return rgba


def compress_and_check(
    stored_u8: np.ndarray,
    reference: np.ndarray | None,
    fmt: str,
    decode: Callable[[np.ndarray, slice], np.ndarray],
    budget: Budget | None = None,
    pad: bool = True,
    blend: Callable[[np.ndarray, float], tuple[np.ndarray, np.ndarray]] | None = None,
    keep_decoded: bool = True,
) -> FormatCheck:
    """Compress 8-bit stored texels, decode them independently, measure the damage.

    stored_u8: [H, W, 2 or 3] uint8 texels of the map (x, y[, z]) as an 8-bit file would hold;
               three components go to x, y, z in R, G, B (bc1 / bc7), two to the format's
               two-component layout.
    reference: [H, W, 3] float unit normals the map is meant to reproduce; None: the
               uncompressed map itself (``decode`` of ``stored_u8``, band by band: the error
               is then the compression error, and no full-size reference is held).
    decode:    texels chunk -> normals chunk (see :func:`decoder_for`).
    blend:     optional ``f(decoded normals, weight) -> (blended, reference blended)``.
    Sizes that are not multiples of 4 are padded by edge replication (``pad``) or refused.
    The measures are made band by band of rows (the decoded normals, angles' temporaries and
    PSNR sums of one band); the angles of every texel are kept for the statistics.
    """
    check_format(fmt)
    q = np.asarray(stored_u8)
    h, w, c = q.shape
    padded = bool(h % 4 or w % 4)
    if padded and not pad:
        raise ValueError(
            f"{fmt} needs sizes that are multiples of 4; {w} x {h} is not (allow padding or resize)"
        )
    hp, wp = -(-h // 4) * 4, -(-w // 4) * 4
    data = encode_bc(_blocks_rgba(q, fmt), fmt)  # the RGBA texels let go once encoded
    bgra = decode_bc_bgra(data, wp, hp, fmt)[:h, :w]
    ref = None if reference is None else np.asarray(reference, _F)
    angles = np.empty((h, w), dtype=_F)
    angles_c = angles if ref is None else np.empty((h, w), dtype=_F)
    dec_u8 = np.empty((h, w, c), dtype=np.uint8) if keep_decoded or blend else None

    def work(rows: slice) -> np.ndarray:
        d8 = unpack_u8(bgra[rows], fmt, c, bgra=True)
        if dec_u8 is not None:
            dec_u8[rows] = d8
        n_dec = decode(d8, rows)
        n_raw = decode(q[rows], rows)
        if ref is not None:
            angles[rows] = angle_deg(n_dec, ref[rows])
        angles_c[rows] = angle_deg(n_dec, n_raw)
        return squared_errors(q[rows], d8)

    # squared errors per channel, summed over the bands (exact integers: any order)
    sse = np.sum(map_rows(work, h, w), axis=0, dtype=np.int64)
    cerr = error_stats(angles_c)
    err = cerr if ref is None else error_stats(angles)
    check = FormatCheck(
        format=fmt,
        width=w,
        height=h,
        bytes=len(data),
        error=err,
        compression_error=cerr,
        psnr_db=psnr_of(sse, h * w),
        padded=padded,
        data=data,
        decoded=dec_u8 if keep_decoded else None,
    )
    if blend is not None:
        assert dec_u8 is not None
        n_all = decode(dec_u8, slice(0, h))
        for wgt in BLEND_WEIGHTS:
            got, want = blend(n_all, wgt)
            check.blended[f"{wgt:g}"] = angular_error_stats(got, want)
    if budget is not None:
        worst = [check.error] + list(check.blended.values())
        check.verdict = "pass" if all(budget.inside(e) for e in worst) else "fail"
    return check


def choose_format(checks: Sequence[FormatCheck], budget: Budget) -> FormatCheck | None:
    """The check with the fewest bytes that meets the budget (ties: lower mean error)."""
    ok = [c for c in checks if all(budget.inside(e) for e in [c.error, *c.blended.values()])]
    if not ok:
        return None
    return min(ok, key=lambda c: (c.bytes, c.error.mean, FORMATS.index(c.format)))
