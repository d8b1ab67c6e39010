"""The usdz archive: what USD's package reader opens, written byte for byte the same on a rerun."""

from __future__ import annotations

import io
import struct
import zipfile


def usdz_bytes(entries: list[tuple[str, bytes]]) -> bytes:
    """A usdz archive: uncompressed zip, every file's data 64-byte aligned, fixed timestamps.

    The first entry must be the root layer. Alignment uses a padding extra field (id 0x1986, as
    USD's own writer does); the date is 1980-01-01 so the bytes never depend on the clock.
    """

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as zf:
        for name, data in entries:
            info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_STORED
            info.create_system = 3
            info.external_attr = 0o644 << 16
            start = buf.tell() + 30 + len(name.encode("utf-8"))
            pad = (-start) % 64
            if 0 < pad < 4:
                pad += 64
            if pad:
                info.extra = struct.pack("<HH", 0x1986, pad - 4) + b"\0" * (pad - 4)
            zf.writestr(info, data)
    return buf.getvalue()
