"""KTX2 container for BCn payloads, written by hand per the Khronos KTX 2.0 specification.

(pyktx, the libktx binding, does not build here.) What is written:

- the 12-byte identifier, then ``vkFormat``, ``typeSize = 1``, width, height, ``pixelDepth = 0``,
  ``layerCount = 0``, ``faceCount = 1``, ``levelCount``, ``supercompressionScheme = 0``;
- the index (DFD, KVD, SGD offsets/lengths) and the level index (offset, length, uncompressed
  length per level, level 0 first);
- a Basic Data Format Descriptor (Khronos Data Format 1.3, version 2) with the BC colour model,
  BT.709 primaries, *linear* transfer (normal maps are data), 4x4 texel blocks and one sample
  per BC sub-block (BC5: red and green; BC3: alpha then colour);
- a key/value block with ``KTXorientation = rd`` (rows run down, glTF's UV origin),
  ``KTXwriter`` and, when the layout is given, ``KTXswizzle`` (``rgb1`` for x, y, z in R, G, B;
  ``rg01`` for BC5's x, y; ``ag01`` for DXT5nm's x in A, y in G);
- the mip levels, smallest first in the file, each aligned to ``lcm(block bytes, 4)``.

Formats: ``bc1`` (VK_FORMAT_BC1_RGB_UNORM_BLOCK = 131), ``bc3`` (BC3_UNORM = 137), ``bc5``
(BC5_UNORM = 141), ``bc7`` (BC7_UNORM = 145).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

from wrinklepipe import codec
from wrinklepipe.errors import input_error
from wrinklepipe.io.images import DEFAULT_MAX_PIXELS
from wrinklepipe.normals.dds import BLOCK_BYTES, container_format, level_size, mip_dims

IDENTIFIER = bytes([0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A])
VK_FORMAT = {"bc1": 131, "bc3": 137, "bc5": 141, "bc7": 145}
#: The sRGB formats of colour maps: BC1_RGB_SRGB_BLOCK, BC7_SRGB_BLOCK.
VK_FORMAT_SRGB = {"bc1": 132, "bc7": 146}
_VK_READ = {v: k for k, v in VK_FORMAT.items()} | {132: "bc1", 138: "bc3", 146: "bc7"}

# Khronos Data Format: colour models and channel ids of the BC formats
_KHR_DF_MODEL = {"bc1": 128, "bc3": 130, "bc5": 132, "bc7": 134}
_KHR_DF_PRIMARIES_BT709 = 1
_KHR_DF_TRANSFER_LINEAR = 1
_KHR_DF_TRANSFER_SRGB = 2
# (bitOffset, bitLength, channelId) per sample
_SAMPLES = {
    "bc1": [(0, 64, 0)],  # BC1A_COLOR
    "bc3": [(0, 64, 15), (64, 64, 0)],  # BC3_ALPHA, BC3_COLOR
    "bc5": [(0, 64, 0), (64, 64, 1)],  # BC5_RED, BC5_GREEN
    "bc7": [(0, 128, 0)],  # BC7_COLOR
}
WRITER = "wrinklepipe"


@dataclass
class KTX2Image:
    """A parsed KTX2 file: format, size and the block data of each level (level 0 first)."""

    format: str
    vk_format: int
    width: int
    height: int
    levels: list[bytes] = field(default_factory=list)
    key_values: dict[str, bytes] = field(default_factory=dict)
    dfd: bytes = b""

    @property
    def srgb(self) -> bool:
        """An sRGB format (a colour map's texels)."""
        return self.vk_format in VK_FORMAT_SRGB.values()


def data_format_descriptor(fmt: str, srgb: bool = False) -> bytes:
    """The DFD block (including its leading ``dfdTotalSize``) for a BC format (``srgb``: the
    sRGB transfer function of a colour map, else linear)."""
    fmt = container_format(fmt)
    samples = _SAMPLES[fmt]
    block_size = 24 + 16 * len(samples)
    words = [
        0,  # vendorId 0 (Khronos) | descriptorType 0 (basic)
        2 | (block_size << 16),  # versionNumber 2 | descriptorBlockSize
        _KHR_DF_MODEL[fmt]
        | (_KHR_DF_PRIMARIES_BT709 << 8)
        | ((_KHR_DF_TRANSFER_SRGB if srgb else _KHR_DF_TRANSFER_LINEAR) << 16)
        | (0 << 24),  # flags: alpha straight
        3 | (3 << 8),  # texelBlockDimension 4 x 4 x 1 x 1 (stored minus one)
        BLOCK_BYTES[fmt],  # bytesPlane0
        0,  # bytesPlane4..7
    ]
    for offset, length, channel in samples:
        words += [offset | ((length - 1) << 16) | (channel << 24), 0, 0, 0xFFFFFFFF]
    body = struct.pack(f"<{len(words)}I", *words)
    return struct.pack("<I", 4 + len(body)) + body


def _kvd(pairs: dict[str, str]) -> bytes:
    out = b""
    for key in sorted(pairs):
        kv = key.encode("utf-8") + b"\0" + pairs[key].encode("utf-8") + b"\0"
        entry = struct.pack("<I", len(kv)) + kv
        out += entry + b"\0" * ((-len(entry)) % 4)
    return out


def _align(n: int, a: int) -> int:
    return (n + a - 1) // a * a


def ktx2_bytes(
    fmt: str,
    width: int,
    height: int,
    levels: list[bytes],
    layout: str | None = None,
    srgb: bool = False,
) -> bytes:
    """A complete KTX2 file with ``levels`` (level 0 first) of BC block data.

    ``layout`` (a codec layout: ``rgb``, ``rg``, ``ag``) writes the ``KTXswizzle`` key that
    says where the logical R, G, B, A come from (``rgb1``, ``rg01``, ``ag01``). ``srgb``: a
    colour map, ``VK_FORMAT_BC1_RGB_SRGB_BLOCK`` (132) / ``BC7_SRGB_BLOCK`` (146) and the sRGB
    transfer in the data format descriptor."""
    fmt = container_format(fmt)
    if fmt not in VK_FORMAT:
        raise ValueError(f"KTX2 writer supports bc1, bc3, bc5, bc7; got {fmt!r}")
    if not levels:
        raise ValueError("no levels to write")
    if srgb and fmt not in VK_FORMAT_SRGB:
        raise ValueError(f"{fmt} has no sRGB format; colour maps are bc1 or bc7")
    for i, ((w, h), data) in enumerate(zip(mip_dims(width, height, len(levels)), levels)):
        need = level_size(fmt, w, h)
        if len(data) != need:
            raise ValueError(f"level {i} ({w} x {h}) must hold {need} bytes, got {len(data)}")
    n = len(levels)
    dfd = data_format_descriptor(fmt, srgb)
    pairs = {"KTXorientation": "rd", "KTXwriter": WRITER}
    if layout is not None:
        pairs["KTXswizzle"] = codec.layout(layout).swizzle
    kvd = _kvd(pairs)
    dfd_off = 80 + 24 * n
    kvd_off = dfd_off + len(dfd)
    end = kvd_off + len(kvd)
    align = BLOCK_BYTES[fmt] if BLOCK_BYTES[fmt] % 4 == 0 else 4 * BLOCK_BYTES[fmt]
    # levels are stored smallest first
    offsets = [0] * n
    pos = end
    for i in reversed(range(n)):
        pos = _align(pos, align)
        offsets[i] = pos
        pos += len(levels[i])
    vk = VK_FORMAT_SRGB[fmt] if srgb else VK_FORMAT[fmt]
    header = IDENTIFIER + struct.pack("<9I", vk, 1, width, height, 0, 0, 1, n, 0)
    index = struct.pack("<4I2Q", dfd_off, len(dfd), kvd_off, len(kvd), 0, 0)
    level_index = b"".join(
        struct.pack("<3Q", offsets[i], len(levels[i]), len(levels[i])) for i in range(n)
    )
    out = bytearray(header + index + level_index + dfd + kvd)
    for i in reversed(range(n)):
        out += b"\0" * (offsets[i] - len(out))
        out += levels[i]
    return bytes(out)


def read_ktx2(
    source: str | Path | bytes, max_pixels: int = DEFAULT_MAX_PIXELS, name: str = ""
) -> KTX2Image:
    """Parse a KTX2 file with BC payloads (no supercompression). Raises :class:`InputError`."""
    if isinstance(source, (bytes, bytearray, memoryview)):
        raw, where = bytes(source), name or "<ktx2 bytes>"
    else:
        p = Path(source)
        where = str(p)
        if not p.exists():
            raise input_error(where, "file not found")
        raw = p.read_bytes()
    if len(raw) == 0:
        raise input_error(where, "file is empty")
    if len(raw) < 80 or raw[:12] != IDENTIFIER:
        raise input_error(where, "not a KTX2 file (bad identifier or truncated header)")
    vk, type_size, width, height, depth, layers, faces, count, scheme = struct.unpack_from(
        "<9I", raw, 12
    )
    if width * height > max_pixels:
        raise input_error(
            where, f"image is {width} x {height}, over the cap of {max_pixels} pixels"
        )
    if vk not in _VK_READ:
        raise input_error(where, f"vkFormat {vk} is not a supported BC format")
    if scheme != 0:
        raise input_error(where, f"supercompression scheme {scheme} is not supported")
    if depth or layers or faces != 1 or type_size != 1:
        raise input_error(where, "only single 2D BC textures are supported")
    fmt = _VK_READ[vk]
    dfd_off, dfd_len, kvd_off, kvd_len = struct.unpack_from("<4I", raw, 48)
    count = max(1, count)
    if len(raw) < 80 + 24 * count:
        raise input_error(where, "truncated level index")
    levels = []
    for i, (w, h) in enumerate(mip_dims(width, height, count)):
        off, length, _ = struct.unpack_from("<3Q", raw, 80 + 24 * i)
        if length != level_size(fmt, w, h) or off + length > len(raw):
            raise input_error(where, f"level {i} is truncated or has the wrong size")
        levels.append(raw[off : off + length])
    kv: dict[str, bytes] = {}
    pos, end = kvd_off, kvd_off + kvd_len
    while pos + 4 <= end:
        (length,) = struct.unpack_from("<I", raw, pos)
        entry = raw[pos + 4 : pos + 4 + length]
        key, _, value = entry.partition(b"\0")
        kv[key.decode("utf-8", "replace")] = value.rstrip(b"\0")
        pos += 4 + length
        pos += (-pos) % 4
    return KTX2Image(fmt, vk, width, height, levels, kv, raw[dfd_off : dfd_off + dfd_len])
