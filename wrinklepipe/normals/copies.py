"""Block-compressed copies of a package's maps: choose, encode with mips, measure, write.

What ``convert`` ships beside its PNGs (``compressed/NAME.dds`` and ``compressed/NAME.ktx2``),
made from the stored 8-bit texels (the PNGs the glTF references):

- each format stores a map in the codec's layout (:mod:`wrinklepipe.codec.formats`): a normal
  map (the base, ``full`` and ``composite`` states) keeps x, y, z in R, G, B in BC1 and BC7 (what
  every RGB reader expects), x, y in BC5 (z rebuilt), x in A and y in G in BC3nm; ``pd`` slopes
  take R, G (A, G in BC3nm); ``diff`` maps need BC1 or BC7;
- the check decodes the blocks with texture2ddecoder, reads them with that layout and reports the
  angle to the uncompressed map (:func:`compress.compress_and_check`); ``auto`` keeps the
  smallest format whose every map of the group meets the budget (all states share one format);
- every level of the full mip chain is stored like level 0 (:mod:`wrinklepipe.normals.mips`:
  PD slopes and diff deltas averaged, normals averaged and renormalised);
- DDS records the DXGI format (DX10 header for BC5 / BC7) and the DX10 alpha mode; KTX2 the
  vkFormat, the DFD and ``KTXswizzle``; :func:`records` is what the glTF extension and the USD
  schema record per copy (format, layout, mapping, levels, files).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wrinklepipe import codec
from wrinklepipe.metadata import CompressedCopy
from wrinklepipe.metrics import Budget
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals import mips, uastc
from wrinklepipe.normals.dds import dds_bytes
from wrinklepipe.normals.ktx2 import ktx2_bytes
from wrinklepipe.options import BudgetOptions, FormatOptions
from wrinklepipe.udim import split_name

#: Formats ``auto`` tries, smallest blocks first (BC1: 8 bytes; then BC5, BC3nm, BC7: 16).
AUTO_FORMATS: tuple[str, ...] = ("bc1", "bc5", "bc3nm", "bc7")
#: What a manifest's ``formats.base`` / ``formats.wrinkle`` may name (``uastc``: a Basis
#: Universal KTX2 only, never chosen by ``auto``).
REQUESTABLE: tuple[str, ...] = ("auto", *cmp.FORMATS, "uastc")


@dataclass
class Copy:
    """One compressed map: its format, layout, every mip level and the level-0 check."""

    texture: str
    encoding: str
    format: str
    layout: str
    mapping: int
    width: int
    height: int
    levels: list[bytes]  # block data per level; uastc: the whole KTX2 file
    check: cmp.FormatCheck
    level_count: int = 0

    def files(self) -> dict[str, bytes]:
        w, h = self.width, self.height
        if self.format == "uastc":  # basisu writes the KTX2 (its DFD); no DDS holds UASTC
            return {f"compressed/{self.texture}.ktx2": self.levels[0]}
        return {
            f"compressed/{self.texture}.dds": dds_bytes(self.format, w, h, self.levels),
            f"compressed/{self.texture}.ktx2": ktx2_bytes(
                self.format, w, h, self.levels, layout=self.layout
            ),
        }

    def record(self) -> CompressedCopy:
        """The extension / USD record of this copy."""
        return CompressedCopy(
            texture=self.texture,
            format=self.format,
            layout=self.layout,
            mapping=self.mapping,
            levels=self.level_count or len(self.levels),
            ktx2=f"compressed/{self.texture}.ktx2",
            dds="" if self.format == "uastc" else f"compressed/{self.texture}.dds",
        )


@dataclass(frozen=True)
class _Map:
    name: str
    encoding: str
    texels: np.ndarray  # stored texels [H, W, >= 3] (uint8)
    param: float
    version: int


def _components(m: _Map, fmt: str) -> np.ndarray:
    """The map's texel components in ``fmt``'s layout (z kept where the layout stores it)."""
    lay = codec.storage_format(fmt).layout_for(m.encoding)
    return np.ascontiguousarray(m.texels[..., : 3 if lay.stores_z else 2])


def _decoder(m: _Map, base: np.ndarray | None):  # noqa: ANN202 - compress.decoder_for's type
    enc = "full" if m.encoding == "composite" else m.encoding
    scale = m.param if enc == "pd" else 1.0
    gain = m.param if enc == "diff" else 1.0
    return cmp.decoder_for(enc, scale, gain, base, m.version)


def _check(
    m: _Map, fmt: str, budget: Budget, base: np.ndarray | None, with_mips: bool = True
) -> cmp.FormatCheck:
    q = _components(m, fmt)
    decode = _decoder(m, base)
    if fmt == "uastc":  # one KTX2 with the whole chain, level 0 measured from it
        reference = decode(q, slice(0, q.shape[0]))  # what the uncompressed map decodes to
        ktx = _uastc_file(m, with_mips)
        check = uastc.uastc_check(q, reference, decode, budget, ktx2=ktx)[0]
        check.data = ktx
        return check
    # measured against what the uncompressed map decodes to, band by band (no full-size copy)
    return cmp.compress_and_check(q, None, fmt, decode, budget, keep_decoded=False)


#: The validator's WP-MAP-004 limit on the PD texels stored at the end of the range.
MAX_CLIPPED_FRACTION = 0.001


def _edge_texels(m: _Map, xy: np.ndarray) -> int:
    """PD texels whose x or y sits within half a step of the end of the range (WP-MAP-004)."""
    mp = codec.mapping(m.version)
    t = np.abs(mp.decode(xy[..., :2], 8))
    return int(np.count_nonzero(np.any(t >= 1.0 - 0.5 / mp.centre(8)[1], axis=-1)))


def _clips(m: _Map, check: cmp.FormatCheck) -> bool:
    """Whether a PD copy puts more texels at the end of the range than the validator allows
    and than the PNG already has (a block format's error can move a steep texel there)."""
    if m.encoding != "pd":
        return False
    h, w = m.texels.shape[:2]
    hp, wp = -(-h // 4) * 4, -(-w // 4) * 4
    dec = cmp.unpack_u8(cmp.decode_bc(check.data, wp, hp, check.format), check.format, 2)
    limit = max(MAX_CLIPPED_FRACTION * h * w, _edge_texels(m, m.texels))
    return _edge_texels(m, dec[:h, :w]) > limit


def _quantity(m: _Map) -> np.ndarray:
    """The map's quantity decoded from its stored texels (mips are filtered in it)."""
    return _quantity_rows(m)(slice(0, m.texels.shape[0]))


def _quantity_rows(m: _Map) -> mips.RowReader:
    """``read(rows)``: the map's quantity of those rows (decoding is per texel: a band's values
    are the whole map's), so a mip chain never holds level 0's quantity whole."""
    e = codec.encoding(m.encoding)
    where = "rg" if e.components == 2 else "rgb"

    def read(rows: slice) -> np.ndarray:
        px = m.texels[rows, :, : e.components]
        return codec.decode(e, px, where, param=m.param, version=m.version)

    return read


def _shape(m: _Map) -> tuple[int, int, int]:
    """The shape of the map's quantity (pd slopes: 2 components; normals, deltas: 3)."""
    h, w = m.texels.shape[:2]
    return h, w, int(_quantity_rows(m)(slice(0, 1)).shape[-1])


def _uastc_levels(m: _Map, with_mips: bool) -> int:
    h, w = m.texels.shape[:2]
    return mips.level_count(w, h) if with_mips else 1


def _uastc_file(m: _Map, with_mips: bool) -> bytes:
    """The UASTC KTX2 of a map: level 0 and (``with_mips``) the chain made here (PD averaged
    in slope space, normals renormalised), encoded by basisu in one file."""
    lay = codec.storage_format("uastc").layout_for(m.encoding)
    texels = [_components(m, "uastc")]
    if _uastc_levels(m, with_mips) > 1:
        texels += mips.texel_levels(m.encoding, _quantity(m), "uastc", m.param, m.version)
    return uastc.encode_uastc_levels([codec.layouts.pack(t, lay, 4) for t in texels])


def _uastc_copy(m: _Map, check: cmp.FormatCheck, with_mips: bool) -> Copy:
    h, w = m.texels.shape[:2]
    lay = codec.storage_format("uastc").layout_for(m.encoding).name
    n = _uastc_levels(m, with_mips)
    return Copy(m.name, m.encoding, "uastc", lay, m.version, w, h, [check.data], check, n)


def _copy(m: _Map, fmt: str, check: cmp.FormatCheck, with_mips: bool) -> Copy:
    if fmt == "uastc":
        return _uastc_copy(m, check, with_mips)
    h, w = m.texels.shape[:2]
    levels = [check.data]
    if with_mips and max(h, w) > 1:
        levels += mips.block_levels_of(
            m.encoding, _quantity_rows(m), _shape(m), fmt, m.param, m.version
        )
    lay = codec.storage_format(fmt).layout_for(m.encoding).name
    return Copy(m.name, m.encoding, fmt, lay, m.version, w, h, levels, check)


def compressed_copies(
    pkg: Any,
    budget: BudgetOptions | None = None,
    formats: FormatOptions | None = None,
    with_mips: bool = True,
) -> tuple[list[Copy], list[str], dict[str, Any]]:
    """Compressed copies of the base and the states of a
    :class:`~wrinklepipe.package.WrinklePackage`.

    ``formats``: ``{"base": ..., "wrinkle": ...}`` from the manifest (``auto`` by default, or a
    format of :data:`REQUESTABLE`). Returns the copies, notes and the per-group choices for the
    report (requested, chosen, layout, levels and every check tried).
    """
    limits = (budget or BudgetOptions()).copies()
    formats = formats or FormatOptions()
    meta = pkg.meta
    enc = meta.encoding
    version = int(meta.mapping)
    param = float(meta.scale)
    # a UDIM package's tiles are maps of one group each (one format for every tile)
    bases = [t for t in pkg.textures if t.role == "base_normal"]
    groups: list[tuple[str, str, list[_Map]]] = []
    if bases:
        groups.append(
            (
                "base",
                formats.base,
                [_Map(t.name, "full", t.pixels, 1.0, 1) for t in bases],
            )
        )
    states = [t for t in pkg.textures if t.role == "state"]
    groups.append(
        (
            "wrinkle",
            formats.wrinkle,
            [_Map(t.name, enc, t.pixels, param, version) for t in states],
        )
    )
    copies: list[Copy] = []
    notes: list[str] = []
    choices: dict[str, Any] = {}
    base_normals: dict[int | None, np.ndarray] = {}
    for group, want, maps in groups:
        if not maps:
            continue
        if want not in REQUESTABLE:  # png8 / png16 / exr: the group ships as its PNG only
            continue
        if any(m.texels.dtype != np.uint8 for m in maps):
            notes.append(f"{group}: 16-bit maps ship as PNG only (block formats are 8-bit)")
            continue
        base: dict[int | None, np.ndarray] | None = None
        if maps[0].encoding == "diff":
            if not base_normals:
                for t in bases:  # by tile (one, without tiles)
                    px = t.pixels[..., :3]
                    base_normals[split_name(t.name)[1]] = codec.decode("full", px, "rgb")
            base = base_normals or None
            if base is not None and any(
                b.shape[:2] != maps[0].texels.shape[:2] for b in base.values()
            ):
                notes.append(f"{group}: diff states at another size than the base; PNG only")
                continue
        holds = [f for f in REQUESTABLE[1:] if codec.storage_format(f).holds(maps[0].encoding)]
        if want != "auto" and want not in holds:
            notes.append(f"{group}: {want} cannot hold {maps[0].encoding} maps; PNG only")
            continue
        candidates = [f for f in AUTO_FORMATS if f in holds] if want == "auto" else [want]
        checks: dict[str, list[cmp.FormatCheck]] = {}
        for f in candidates:
            checks[f] = [_check(m, f, limits, _tile_base(base, m), with_mips) for m in maps]
            if want == "auto":
                for m, c in zip(maps, checks[f]):
                    if c.verdict == "pass" and _clips(m, c):
                        c.verdict = "fail"  # the validator would count clipped texels
                if all(c.verdict == "pass" for c in checks[f]):
                    break
        passing = [f for f in checks if all(c.verdict == "pass" for c in checks[f])]
        pick: str | None
        if want != "auto":
            pick = want
            if not passing:
                notes.append(f"{group}: {want} as requested, over the error budget")
        elif passing:
            pick = passing[0]
        else:
            pick = None
            best = min(checks, key=lambda f: max(c.error.mean for c in checks[f]))
            worst = max(checks[best], key=lambda c: c.error.mean)
            notes.append(
                f"{group}: no block format meets the budget (best {best}: mean "
                f"{worst.error.mean:.2f}, p99 {worst.error.p99:.2f} deg); PNG only"
            )
        made = (
            []
            if pick is None
            else [_copy(m, pick, c, with_mips) for m, c in zip(maps, checks[pick])]
        )
        copies += made
        choices[group] = {
            "requested": want,
            "chosen": pick or "png",
            "layout": made[0].layout if made else None,
            "levels": made[0].record().levels if made else 0,
            "checks": {
                f: {m.name: c.to_json() for m, c in zip(maps, cs)} for f, cs in checks.items()
            },
        }
    return copies, notes, choices


def _tile_base(bases: dict[int | None, np.ndarray] | None, m: _Map) -> np.ndarray | None:
    """The base (decoded) a diff state of ``m``'s tile is stored over."""
    if bases is None:
        return None
    return bases.get(split_name(m.name)[1], next(iter(bases.values())))


def files(copies: list[Copy]) -> dict[str, bytes]:
    """``{relative path: bytes}`` of every copy's DDS and KTX2."""
    out: dict[str, bytes] = {}
    for c in copies:
        out.update(c.files())
    return out


def records(copies: list[Copy]) -> tuple[CompressedCopy, ...]:
    """What the glTF extension / USD schema record of the copies (sorted by texture)."""
    return tuple(c.record() for c in sorted(copies, key=lambda c: c.texture))
