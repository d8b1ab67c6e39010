"""DDS container for BCn data: writer and reader (no pixel decoding here).

Header layout per Microsoft's DDS_HEADER / DDS_PIXELFORMAT / DDS_HEADER_DXT10. Formats use the
container names ``bc1``, ``bc3``, ``bc5``, ``bc7`` (a DXT5nm normal map is ``bc3`` data).

- ``bc5`` and ``bc7`` default to the DX10 extension header (``DXGI_FORMAT_BC5_UNORM`` = 83,
  ``DXGI_FORMAT_BC7_UNORM`` = 98); ``bc5`` can also be written with the legacy FourCC ``ATI2``
  that older engines and tools want (``dx10=False``). BC7 has no FourCC.
- ``bc1`` and ``bc3`` default to the legacy FourCCs ``DXT1`` / ``DXT5`` (what every engine
  reads); ``dx10=True`` writes ``DXGI_FORMAT_BC1_UNORM`` (71) / ``BC3_UNORM`` (77) instead.
- Storage format names are accepted too (``bc3nm`` -> ``bc3``, ``bc7xy`` -> ``bc7``); the DX10
  header then records the layout's alpha mode (``miscFlags2``): custom (4) for DXT5nm, whose
  alpha holds x, opaque (3) for BC1 / BC7 normal maps. Which channels hold x, y and z is
  recorded beside the file (the glTF extension / USD schema), DDS has no field for it.

The reader checks the size against a pixel cap before it allocates anything, and that the file
holds all the bytes its header promises.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

from wrinklepipe import codec
from wrinklepipe.errors import input_error
from wrinklepipe.io.images import DEFAULT_MAX_PIXELS

MAGIC = b"DDS "
_HEADER_SIZE = 124
_PF_SIZE = 32

DDSD_CAPS, DDSD_HEIGHT, DDSD_WIDTH, DDSD_PIXELFORMAT = 0x1, 0x2, 0x4, 0x1000
DDSD_MIPMAPCOUNT, DDSD_LINEARSIZE = 0x20000, 0x80000
DDPF_FOURCC = 0x4
DDSCAPS_COMPLEX, DDSCAPS_TEXTURE, DDSCAPS_MIPMAP = 0x8, 0x1000, 0x400000
D3D10_RESOURCE_DIMENSION_TEXTURE2D = 3

BLOCK_BYTES = {"bc1": 8, "bc3": 16, "bc5": 16, "bc7": 16}
DXGI = {"bc1": 71, "bc3": 77, "bc5": 83, "bc7": 98}
#: The sRGB formats of colour maps (always with the DX10 header: DXT1 has no sRGB FourCC).
DXGI_SRGB = {"bc1": 72, "bc7": 99}
_DXGI_READ = {71: "bc1", 72: "bc1", 77: "bc3", 78: "bc3", 83: "bc5", 98: "bc7", 99: "bc7"}
_DXGI_UNSUPPORTED = {80: "BC4_UNORM", 81: "BC4_SNORM", 84: "BC5_SNORM", 95: "BC6H_UF16"}
_FOURCC_WRITE = {"bc1": b"DXT1", "bc3": b"DXT5", "bc5": b"ATI2"}
_FOURCC_READ = {b"DXT1": "bc1", b"DXT5": "bc3", b"DXT4": "bc3", b"ATI2": "bc5", b"BC5U": "bc5"}


@dataclass
class DDSImage:
    """A parsed DDS file: container format, size, and the block data of each mip level."""

    format: str
    width: int
    height: int
    levels: list[bytes] = field(default_factory=list)
    dx10: bool = False
    fourcc: str = ""
    srgb: bool = False  # BC1_UNORM_SRGB / BC7_UNORM_SRGB: a colour map's texels


def level_size(fmt: str, width: int, height: int) -> int:
    """Bytes of one mip level: ``ceil(w / 4) * ceil(h / 4) * block bytes``."""
    return max(1, (width + 3) // 4) * max(1, (height + 3) // 4) * BLOCK_BYTES[fmt]


def mip_dims(width: int, height: int, count: int) -> list[tuple[int, int]]:
    """(w, h) of ``count`` mip levels, halving (floor) down to 1."""
    return [(max(1, width >> i), max(1, height >> i)) for i in range(count)]


def container_format(fmt: str) -> str:
    """Map a storage format name (``bc3nm`` is DXT5nm data, ``bc7xy`` two-channel BC7) to the
    container's block format name (:mod:`wrinklepipe.codec.formats`)."""
    if fmt in BLOCK_BYTES:
        return fmt
    try:
        container = codec.storage_format(fmt).container
    except ValueError:
        return fmt
    return container or fmt


def alpha_mode(fmt: str) -> int:
    """DX10 ``miscFlags2`` alpha mode of a storage format: 4 (custom) for DXT5nm, whose alpha
    holds x; 3 (opaque) for BC1 / BC7 (A = 1); 0 (unknown) for BC5, which has no alpha."""
    try:
        return codec.storage_format(fmt).dds_alpha_mode
    except ValueError:
        return 0


def dds_bytes(
    fmt: str,
    width: int,
    height: int,
    levels: list[bytes],
    dx10: bool | None = None,
    srgb: bool = False,
) -> bytes:
    """A complete DDS file holding ``levels`` (level 0 first) of block data.

    ``dx10=None`` picks the engine-friendly default (DX10 header for bc5/bc7, FourCC for
    bc1/bc3). ``srgb``: a colour map's sRGB texels, ``DXGI_FORMAT_BC1_UNORM_SRGB`` (72) or
    ``BC7_UNORM_SRGB`` (99), always in the DX10 header. Level sizes are checked against the
    format.
    """
    mode = alpha_mode(fmt)
    fmt = container_format(fmt)
    if fmt not in BLOCK_BYTES:
        raise ValueError(f"DDS writer supports bc1, bc3, bc5, bc7; got {fmt!r}")
    if width <= 0 or height <= 0:
        raise ValueError(f"invalid size {width} x {height}")
    if not levels:
        raise ValueError("no levels to write")
    if srgb and fmt not in DXGI_SRGB:
        raise ValueError(f"{fmt} has no sRGB format; colour maps are bc1 or bc7")
    use_dx10 = srgb or (fmt in ("bc5", "bc7") if dx10 is None else bool(dx10))
    if fmt == "bc7" and not use_dx10:
        raise ValueError("BC7 has no legacy FourCC; it needs the DX10 header")
    for i, ((w, h), data) in enumerate(zip(mip_dims(width, height, len(levels)), levels)):
        need = level_size(fmt, w, h)
        if len(data) != need:
            raise ValueError(f"level {i} ({w} x {h}) must hold {need} bytes, got {len(data)}")
    flags = DDSD_CAPS | DDSD_HEIGHT | DDSD_WIDTH | DDSD_PIXELFORMAT | DDSD_LINEARSIZE
    caps = DDSCAPS_TEXTURE
    if len(levels) > 1:
        flags |= DDSD_MIPMAPCOUNT
        caps |= DDSCAPS_COMPLEX | DDSCAPS_MIPMAP
    fourcc = b"DX10" if use_dx10 else _FOURCC_WRITE[fmt]
    pf = struct.pack("<II4s5I", _PF_SIZE, DDPF_FOURCC, fourcc, 0, 0, 0, 0, 0)
    header = struct.pack(
        "<7I44s32s5I",
        _HEADER_SIZE,
        flags,
        height,
        width,
        len(levels[0]),  # pitch or linear size: bytes of level 0
        0,  # depth
        len(levels),
        b"\0" * 44,
        pf,
        caps,
        0,
        0,
        0,
        0,
    )
    parts = [MAGIC, header]
    if use_dx10:
        dxgi = DXGI_SRGB[fmt] if srgb else DXGI[fmt]
        parts.append(struct.pack("<5I", dxgi, D3D10_RESOURCE_DIMENSION_TEXTURE2D, 0, 1, mode))
    parts.extend(levels)
    return b"".join(parts)


def read_dds(
    source: str | Path | bytes, max_pixels: int = DEFAULT_MAX_PIXELS, name: str = ""
) -> DDSImage:
    """Parse a DDS file (path or bytes). Raises :class:`InputError` naming what is wrong.

    The header is checked (magic, sizes, format, pixel cap) before any level is copied.
    """
    if isinstance(source, (bytes, bytearray, memoryview)):
        raw = bytes(source)
        where = name or "<dds bytes>"
    else:
        p = Path(source)
        where = str(p)
        if not p.exists():
            raise input_error(where, "file not found")
        if p.stat().st_size == 0:
            raise input_error(where, "file is empty")
        with open(p, "rb") as f:
            head = f.read(4 + _HEADER_SIZE + 20)
            _check_header(head, where, max_pixels)  # refuse before reading the rest
            raw = head + f.read()
    if len(raw) == 0:
        raise input_error(where, "file is empty")
    fmt, width, height, count, dx10, fourcc, offset = _check_header(raw, where, max_pixels)
    levels = []
    pos = offset
    for i, (w, h) in enumerate(mip_dims(width, height, count)):
        need = level_size(fmt, w, h)
        if pos + need > len(raw):
            if i == 0:
                raise input_error(
                    where,
                    f"truncated: level 0 ({w} x {h} {fmt}) needs {need} bytes, the file has "
                    f"{max(0, len(raw) - pos)}",
                )
            raise input_error(where, f"truncated: mip level {i} ({w} x {h}) is incomplete")
        levels.append(raw[pos : pos + need])
        pos += need
    srgb = dx10 and struct.unpack_from("<I", raw, 4 + _HEADER_SIZE)[0] in DXGI_SRGB.values()
    return DDSImage(fmt, width, height, levels, dx10, fourcc, bool(srgb))


def _check_header(
    raw: bytes, where: str, max_pixels: int
) -> tuple[str, int, int, int, bool, str, int]:
    if len(raw) < 4 + _HEADER_SIZE:
        raise input_error(where, f"truncated: {len(raw)} bytes is shorter than a DDS header (128)")
    if raw[:4] != MAGIC:
        raise input_error(where, "not a DDS file (missing 'DDS ' magic)")
    size, _flags, height, width = struct.unpack_from("<4I", raw, 4)
    if size != _HEADER_SIZE:
        raise input_error(where, f"bad DDS header size {size} (expected 124)")
    count = struct.unpack_from("<I", raw, 4 + 24)[0] or 1
    pf_flags, fourcc_b = struct.unpack_from("<I4s", raw, 4 + 76)
    if width <= 0 or height <= 0:
        raise input_error(where, f"invalid size {width} x {height}")
    if width * height > max_pixels:
        raise input_error(
            where,
            f"image is {width} x {height} = {width * height} pixels, over the cap of "
            f"{max_pixels} pixels",
        )
    if not pf_flags & DDPF_FOURCC:
        raise input_error(where, "uncompressed DDS is not supported; expected BC1/BC3/BC5/BC7")
    fourcc = fourcc_b.decode("latin-1")
    offset = 4 + _HEADER_SIZE
    dx10 = fourcc_b == b"DX10"
    if dx10:
        if len(raw) < offset + 20:
            raise input_error(where, "truncated: DX10 header is incomplete")
        dxgi, dim, _misc, array_size, _misc2 = struct.unpack_from("<5I", raw, offset)
        offset += 20
        if dxgi in _DXGI_UNSUPPORTED:
            raise input_error(where, f"DXGI format {_DXGI_UNSUPPORTED[dxgi]} is not supported")
        if dxgi not in _DXGI_READ:
            raise input_error(where, f"DXGI format {dxgi} is not supported (BC1/BC3/BC5/BC7 only)")
        if dim != D3D10_RESOURCE_DIMENSION_TEXTURE2D or array_size > 1:
            raise input_error(where, "only single 2D textures are supported (no arrays/volumes)")
        fmt = _DXGI_READ[dxgi]
    else:
        if fourcc_b not in _FOURCC_READ:
            raise input_error(where, f"FourCC {fourcc!r} is not supported (DXT1/DXT5/ATI2/DX10)")
        fmt = _FOURCC_READ[fourcc_b]
    max_levels = max(width, height).bit_length()
    count = min(count, max_levels)
    return fmt, width, height, count, dx10, fourcc, offset
