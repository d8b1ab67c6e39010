"""Every block-compressed copy an asset lists, read whole and decoded: the verdict covers the
bytes an engine loads, not only the PNGs.

For each base or state texture with copies (the ``compressed`` records of the wrinkle metadata,
and any ``compressed/NAME.dds`` / ``NAME.ktx2`` beside it), each copy is

- parsed whole, every mip level (:func:`~wrinklepipe.normals.dds.read_dds`,
  :func:`~wrinklepipe.normals.ktx2.read_ktx2`; UASTC through basisu): a truncated or damaged
  container, a level missing or short;
- checked against its record and its texture: format, size, a full mip chain;
- decoded with the codec (texture2ddecoder), every level: level 0 against the lossless PNG, each
  further level against the box halving of the level above (how the chain is made,
  :mod:`wrinklepipe.normals.mips`), 4 x 4 block by 4 x 4 block (:func:`damaged_block`: a block
  further from its reference than the reference block's own spread, and than
  :data:`BLOCK_TOLERANCE` codes, holds bytes no encoder wrote for it);
- compared with the other copy of the same texture: DDS and KTX2 hold the same blocks.

Each finding is one problem ``{"file", "message"}`` (the validator's WP-TEX-004).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.errors import InputError
from wrinklepipe.io.confine import confine
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals import uastc
from wrinklepipe.normals.dds import container_format, mip_dims, read_dds
from wrinklepipe.normals.ktx2 import read_ktx2
from wrinklepipe.normals.mips import level_count
from wrinklepipe.validate.inputs import Texture, ValidationInput
from wrinklepipe.workset import band_rows

#: Mean |difference| (8-bit codes) over a 4 x 4 block that no block is refused below
#: (:func:`damaged_block`: a block is damaged beyond this and beyond its own spread).
BLOCK_TOLERANCE = 16.0
#: Bytes of temporaries per texel while a band of blocks is judged (float32 codes of both maps,
#: their difference, the blocks padded and regrouped, NaN-free copies of them).
BLOCK_BYTES = 96


@dataclass
class Copy:
    """One copy as read: its file, container format and levels (block data, level 0 first)."""

    file: Path
    format: str
    width: int
    height: int
    levels: list[bytes]


def _problem(file: Path | str, message: str) -> dict[str, str]:
    return {"file": str(file), "message": message}


def _decoder_format(fmt: str, layout: str | None) -> str:
    """The codec's name for a container format read with ``layout`` (BC3 holding x in alpha is
    DXT5nm)."""
    if fmt == "bc3":
        return "bc3nm"
    return fmt


def _png_xy_rows(t: Texture) -> Callable[[int, int], np.ndarray] | None:
    """The PNG texture's stored x, y as 8-bit codes (float32), rows ``r0:r1`` at a time
    (``[r1 - r0, W, 2]``, from its bytes: no float copy of the whole image), or None."""
    ch = t.channels
    if t.is_block or t.bits == 0 or ch < 2:
        return None
    dtype = np.uint16 if t.bits == 16 else np.uint8
    a = np.frombuffer(t.data, dtype, count=t.height * t.width * ch).reshape(t.height, t.width, ch)
    idx = [3, 1] if t.layout == "ag" and ch == 4 else [0, 1]

    def rows(r0: int, r1: int) -> np.ndarray:
        x = a[r0:r1][..., idx].astype(np.float32)
        if t.bits == 16:
            x /= 257.0
        return x

    return rows


def _xy_of_png(t: Texture) -> np.ndarray | None:
    """The PNG texture's stored x, y as 8-bit codes [H, W, 2] (float), or None."""
    rows = _png_xy_rows(t)
    return None if rows is None else rows(0, t.height)


def _block_view(a: np.ndarray, fill: float) -> np.ndarray:
    """``a`` [H, W, C] padded with ``fill`` to whole 4 x 4 blocks -> [hb, wb, 16, C]."""
    h, w, c = a.shape
    hb, wb = -(-h // 4), -(-w // 4)
    padded = np.full((hb * 4, wb * 4, c), fill, np.float32)
    padded[:h, :w] = a
    return padded.reshape(hb, 4, wb, 4, c).transpose(0, 2, 1, 3, 4).reshape(hb, wb, 16, c)


def _block_excess(decoded: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per 4 x 4 block of rows of ``decoded`` and ``reference`` (:func:`damaged_block`): how far
    its mean difference exceeds what is allowed, and that mean ``[hb, wb]`` each."""
    d = np.abs(decoded - reference).max(axis=-1, keepdims=True)
    err = _block_view(d, np.nan)[..., 0]
    ref = _block_view(reference, np.nan)
    spread = (np.nanmax(ref, axis=2) - np.nanmin(ref, axis=2)).max(axis=-1)
    mean = np.nanmean(err, axis=2)
    return mean - np.maximum(spread, BLOCK_TOLERANCE), mean


def damaged_block(decoded: np.ndarray, reference: np.ndarray) -> tuple[float, int, int] | None:
    """The worst damaged 4 x 4 block of ``decoded`` against ``reference`` (both [H, W, 2],
    8-bit codes): its mean difference and texel x, y; None when no block is damaged.

    A block is damaged when its mean difference (the larger channel's, per texel) exceeds both
    :data:`BLOCK_TOLERANCE` and the spread of the reference block (its largest max - min over
    a channel): any block format that encodes a block at all stays within the block's own
    range on average (its endpoints span it), whatever the format's error on busy content;
    random or zeroed bytes over smooth content land far outside it."""
    h, w = decoded.shape[:2]
    return damaged_block_rows(lambda a, b: decoded[a:b], lambda a, b: reference[a:b], h, w)


def damaged_block_rows(
    decoded: Callable[[int, int], np.ndarray],
    reference: Callable[[int, int], np.ndarray],
    h: int,
    w: int,
) -> tuple[float, int, int] | None:
    """:func:`damaged_block` of two ``[h, w, 2]`` maps given as rows ``r0:r1`` at a time
    (float32 codes), taken in bands of whole block rows: every block is judged on its own, so
    the blocks' numbers are the whole maps', and the worst is the first of the largest excess
    over all of them, as in one pass (the float temporaries are a band's)."""
    rows = max(4, band_rows(max(w, 1), BLOCK_BYTES) // 4 * 4)
    parts = [
        _block_excess(decoded(r0, r0 + rows), reference(r0, r0 + rows)) for r0 in range(0, h, rows)
    ]
    excess = np.concatenate([e for e, _ in parts])
    mean = np.concatenate([m for _, m in parts])
    i = int(np.argmax(excess))
    if excess.flat[i] <= 0:
        return None
    wb = excess.shape[1]
    return float(mean.flat[i]), (i % wb) * 4, (i // wb) * 4


def _decoded_level(data: bytes, w: int, h: int, fmt: str) -> np.ndarray:
    """One level decoded with the codec: its stored x, y as 8-bit codes [h, w, 2] (the
    decoder's integers: float32 where a band of it is compared), picked from the decoder's
    BGRA texels as they are (no RGBA copy of the level: 256 MiB at 8192²)."""
    bgra = cmp.decode_bc_bgra(data, w, h, fmt)
    return np.ascontiguousarray(cmp.unpack_u8(bgra, fmt, channels=2, bgra=True))


def _judge_copy(
    copy: Copy, fmt: str, png: Callable[[int, int], np.ndarray] | None, png_shape: tuple[int, int]
) -> tuple[list[str], str | None]:
    """Every level decoded in turn (the one above held as its integers): level 0 against the
    PNG (rows ``png``, of ``png_shape``), each level against the halving of the one above.
    Returns what was found, or the decoder's refusal of a level (then nothing is judged)."""
    found = []
    above: np.ndarray | None = None
    dims = mip_dims(copy.width, copy.height, len(copy.levels))
    for k, ((w, h), data) in enumerate(zip(dims, copy.levels)):
        try:
            here = _decoded_level(data, w, h, fmt)
        except ValueError as exc:
            return [], f"cannot be decoded: {exc}"

        def at(a: int, b: int, x: np.ndarray = here) -> np.ndarray:
            return x[a:b].astype(np.float32)

        bad = None
        if k == 0:
            what = "level 0 does not decode to the texture it copies"
            if png is not None and png_shape == here.shape[:2]:
                bad = damaged_block_rows(at, png, h, w)
        elif above is not None and above.shape[0] == 2 * h and above.shape[1] == 2 * w:
            what = f"mip level {k} ({w} x {h}) is not the halving of level {k - 1}"

            def half(a: int, b: int, x: np.ndarray = above, h: int = h, w: int = w) -> np.ndarray:
                b = min(b, h)
                return (
                    x[2 * a : 2 * b].astype(np.float32).reshape(b - a, 2, w, 2, 2).mean(axis=(1, 3))
                )

            bad = damaged_block_rows(at, half, h, w)
        if bad is not None:
            worst, x, y = bad
            found.append(
                f"{what}: the block at texel ({x}, {y}) is {worst:.0f} codes away on average "
                "(damaged blocks)"
            )
        above = here
    return found, None


def _read(path: Path, kind: str) -> Copy:
    img = read_dds(path) if kind == "dds" else read_ktx2(path)
    return Copy(path, str(img.format).lower(), int(img.width), int(img.height), list(img.levels))


def copy_path(inp: ValidationInput, folder: Path, rel: str, texture: str) -> Path:
    """The file of a copy the asset lists (or the default ``compressed/NAME.dds``), refused
    unless it lies inside the asset's folder (or an ``--allow-root``), as every path an input
    names is: a copy listed as ``/etc/hostname`` or ``../x.ktx2`` is never opened."""
    confine(folder, rel, inp.path or folder, key=f"the copies of {texture}", what="compressed copy")
    return folder / rel  # as the asset names it (messages show it so)


def check_copies(inp: ValidationInput, folder: Path) -> list[dict[str, str]]:
    """The problems of every compressed copy of ``inp``'s base and state textures in the asset
    folder ``folder`` (see the module doc); empty when every copy reads back whole."""
    recorded = {str(c["texture"]): c for c in inp.extra.get("compressed", [])}
    problems: list[dict[str, str]] = []
    for t in inp.textures:
        if t.role not in ("base", "state", "base_color", "state_color"):
            continue
        rec: dict[str, Any] | None = recorded.get(t.name)
        names = {"dds": f"compressed/{t.name}.dds", "ktx2": f"compressed/{t.name}.ktx2"}
        listed = {k: str(rec.get(k) or "") for k in ("dds", "ktx2")} if rec else {}
        files = {k: copy_path(inp, folder, listed.get(k) or names[k], t.name) for k in names}
        wanted = {k for k in names if listed.get(k) or files[k].is_file()}
        if rec is not None and str(rec.get("format")) == "uastc":
            problems += _check_uastc(t, files["ktx2"], rec)
            continue
        copies: dict[str, Copy] = {}
        for kind in sorted(wanted):
            path = files[kind]
            if not path.is_file():
                problems.append(_problem(path, f"the compressed copy of {t.name} is missing"))
                continue
            try:
                copies[kind] = _read(path, kind)
            except InputError as exc:
                problems += [_problem(path, p.message) for p in exc.problems]
        for _kind, c in sorted(copies.items()):
            problems += [_problem(c.file, m) for m in _agreement(c, t, rec)]
            fmt = _decoder_format(c.format, rec.get("layout") if rec else None)
            found, refused = _judge_copy(c, fmt, _png_xy_rows(t), (t.height, t.width))
            if refused is not None:
                problems.append(_problem(c.file, refused))
                continue
            problems += [_problem(c.file, m) for m in found]
        if len(copies) == 2:
            a, b = copies["dds"], copies["ktx2"]
            differ = [k for k, (x, y) in enumerate(zip(a.levels, b.levels)) if x != y]
            if a.format != b.format or len(a.levels) != len(b.levels) or differ:
                where = f"level {differ[0]}" if differ else "format or level count"
                problems.append(
                    _problem(
                        b.file,
                        f"{b.file.name} and {a.file.name} copy the same texture but differ "
                        f"({where}): one of them is damaged",
                    )
                )
    return problems


def _agreement(c: Copy, t: Texture, rec: dict[str, Any] | None) -> list[str]:
    found = []
    if (c.width, c.height) != (t.width, t.height):
        found.append(f"is {c.width} x {c.height}; the texture it copies is {t.width} x {t.height}")
    want = int(rec["levels"]) if rec and rec.get("levels") else level_count(c.width, c.height)
    if len(c.levels) != want:
        found.append(f"holds {len(c.levels)} mip levels; {want} are listed")
    if rec and rec.get("format"):
        fmt = container_format(str(rec["format"]))
        if fmt != c.format:
            found.append(f"holds {c.format}; the asset lists it as {rec['format']}")
    return found


def _check_uastc(t: Texture, path: Path, rec: dict[str, Any]) -> list[dict[str, str]]:
    """A UASTC copy (KTX2 only): transcoded by basisu; level 0 against the PNG."""
    if not path.is_file():
        return [_problem(path, f"the compressed copy of {t.name} is missing")]
    try:
        rgba = uastc.decode_uastc(path.read_bytes()).astype(np.float32)
    except Exception as exc:  # noqa: BLE001 - basisu's own message, whatever it raises
        return [_problem(path, f"cannot be transcoded (basisu: {str(exc).strip()[:200]})")]
    if rgba.shape[:2] != (t.height, t.width):
        w, h = rgba.shape[1], rgba.shape[0]
        return [_problem(path, f"is {w} x {h}; the texture it copies is {t.width} x {t.height}")]
    png = _xy_of_png(t)
    xy = rgba[..., [3, 1]] if rec.get("layout") == "ag" else rgba[..., :2]
    bad = damaged_block(xy, png) if png is not None else None
    if bad is None:
        return []
    worst, x, y = bad
    return [
        _problem(
            path,
            f"level 0 does not decode to the texture it copies: the block at texel ({x}, {y}) "
            f"is {worst:.0f} codes away on average (damaged blocks)",
        )
    ]
