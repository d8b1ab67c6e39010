"""PNG bytes: a deterministic minimal encoder and a decoder of stored pixels.

The encoder writes IHDR, IDAT and IEND only (no gAMA/eXIf/time chunks: the Khronos validator
flags colour-space chunks), so the same pixels and zlib level give the same bytes.
"""

from __future__ import annotations

import contextlib
import io
import os
import struct
import tempfile
import zlib
from collections.abc import Iterator
from typing import BinaryIO

import numpy as np
import OpenImageIO as oiio

from wrinklepipe.errors import input_error
from wrinklepipe.io.quiet import native_stderr_silenced, oiio_message
from wrinklepipe.reuse import reused
from wrinklepipe.workset import band_rows

#: zlib level of the PNGs wrinklepipe writes: 6, zlib's and libpng's default. Level 9 makes the
#: demo's textures and validation pictures 1-6 % smaller for 2-11x the time (measured on the 64
#: and 512 demos: 0.75 s against 0.07 s for one 512^2 render); 1 is fastest (files ~25 % larger).
#: The validation page's pictures are always at level 1 (validate.report.PICTURE_PNG_LEVEL).
DEFAULT_PNG_LEVEL = 6


def png_bytes(
    pixels: np.ndarray, level: int = DEFAULT_PNG_LEVEL, shared: bool = True, linear: bool = False
) -> bytes:
    """Encode ``[H, W, C]`` uint8/uint16 (C = 1..4) as a minimal PNG: IHDR, IDAT, IEND only
    (with ``linear``, a gAMA chunk of gamma 1.0 too).

    Rows use the Up filter (vectorised); zlib at ``level`` (0-9; a run passes its own, e.g.
    ``ConvertOptions.png_level``). Same pixels and level -> same bytes.
    ``shared=False``: not through the run's memo (an image nothing else encodes, e.g. a
    report's picture: keying it would only cost a hash of its pixels).
    ``linear``: tag the values linear (gAMA 1.0; OpenImageIO reads the file as
    ``lin_rec709``): the files :func:`wrinklepipe.io.images.write_image` makes (maps, masks and
    pictures other tools read). Textures inside glTF carry no colour-space chunk (the Khronos
    validator flags them).
    """
    if not 0 <= int(level) <= 9:
        raise ValueError(f"PNG compression level must be 0..9, got {level}")
    encode = _png if shared else _png.__wrapped__  # type: ignore[attr-defined]
    return encode(np.asarray(pixels), int(level), bool(linear))


@reused  # a texture the glTF document and the folder (or the GLB) both hold is encoded once
def _png(px: np.ndarray, level: int, linear: bool = False) -> bytes:
    if px.ndim == 2:
        px = px[..., None]
    h, w, c = px.shape
    depth = 16 if px.dtype == np.uint16 else 8
    # band by band (:class:`PngRows`: the same bytes as zlib over every row at once), so the
    # filtered rows of the whole image are never held beside the pixels
    rows = band_rows(w, 4 * c * px.itemsize)
    if h <= rows:
        data = zlib.compress(_filtered(px, None), level)
        return _head(w, h, c, depth, linear) + _chunk(b"IDAT", data) + _chunk(b"IEND", b"")
    out = io.BytesIO()
    writer = PngRows(out, w, h, c, depth, level, linear)
    for r0 in range(0, h, rows):
        writer.add(px[r0 : r0 + rows])
    writer.close()
    return out.getvalue()


def _filtered(px: np.ndarray, above: np.ndarray | None) -> bytes:
    """Rows ``[h, w, c]`` as PNG scanlines with the Up filter (``above``: the stored bytes of
    the row before the first, None at the top of the image)."""
    h = px.shape[0]
    raw = px.astype(">u2").view(np.uint8) if px.dtype == np.uint16 else px.astype(np.uint8)
    rows = raw.reshape(h, -1)
    up = rows.copy()
    up[1:] = rows[1:] - rows[:-1]  # uint8 wraps mod 256 as PNG requires
    if above is not None:
        up[0] = rows[0] - above
    return np.concatenate([np.full((h, 1), 2, np.uint8), up], axis=1).tobytes()


def _chunk(tag: bytes, payload: bytes) -> bytes:
    crc = zlib.crc32(tag + payload) & 0xFFFFFFFF
    return struct.pack(">I", len(payload)) + tag + payload + struct.pack(">I", crc)


def _head(w: int, h: int, c: int, depth: int, linear: bool) -> bytes:
    """Signature, IHDR (and gAMA 1.0 when ``linear``)."""
    color_type = {1: 0, 2: 4, 3: 2, 4: 6}[c]
    ihdr = struct.pack(">IIBBBBB", w, h, depth, color_type, 0, 0, 0)
    gama = _chunk(b"gAMA", struct.pack(">I", 100000)) if linear else b""  # gamma 1.0 (x 1e5)
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + gama


class PngRows:
    """A PNG written band by band into a seekable binary file, with the bytes
    :func:`png_bytes` gives for the whole image (one IDAT: zlib fed row by row makes the same
    stream as zlib over all rows at once; the chunk's length and CRC are filled in at the end).
    Memory: one band and zlib's window, whatever the image size.

    ``add(rows)`` takes the next rows ``[n, w, c]`` (uint8 or uint16, the dtype of the first
    band for all), ``close()`` checks that ``h`` rows came and writes the end."""

    def __init__(
        self, file: BinaryIO, w: int, h: int, c: int, depth: int, level: int, linear: bool = False
    ) -> None:
        if not 0 <= int(level) <= 9:
            raise ValueError(f"PNG compression level must be 0..9, got {level}")
        self._f, self._w, self._h, self._c, self._depth = file, w, h, c, depth
        self._z = zlib.compressobj(int(level))
        self._f.write(_head(w, h, c, depth, linear))
        self._start = self._f.tell()
        self._f.write(b"\0\0\0\0IDAT")
        self._crc = zlib.crc32(b"IDAT")
        self._size = 0
        self._rows = 0
        self._above: np.ndarray | None = None

    def _put(self, data: bytes) -> None:
        self._f.write(data)
        self._crc = zlib.crc32(data, self._crc)
        self._size += len(data)

    def add(self, rows: np.ndarray) -> None:
        px = rows[..., None] if rows.ndim == 2 else rows
        want = np.uint16 if self._depth == 16 else np.uint8
        if px.shape[1:] != (self._w, self._c) or px.dtype != want:
            raise ValueError(
                f"rows {px.shape} {px.dtype} do not fit a {self._w}-wide {self._c}-channel "
                f"{self._depth}-bit PNG"
            )
        if self._rows + px.shape[0] > self._h:
            raise ValueError(f"more than {self._h} rows")
        self._put(self._z.compress(_filtered(px, self._above)))
        raw = px[-1:].astype(">u2").view(np.uint8) if self._depth == 16 else px[-1:]
        self._above = raw.reshape(-1).copy()
        self._rows += px.shape[0]

    def close(self) -> None:
        if self._rows != self._h:
            raise ValueError(f"{self._rows} rows written of {self._h}")
        self._put(self._z.flush())
        end = self._f.tell()
        self._f.seek(self._start)
        self._f.write(struct.pack(">I", self._size))
        self._f.seek(end)
        self._f.write(struct.pack(">I", self._crc & 0xFFFFFFFF) + _chunk(b"IEND", b""))


@contextlib.contextmanager
def _bytes_path(data: bytes) -> Iterator[str]:
    """A path OpenImageIO can open (it reads only files) holding ``data``: an anonymous memory
    file where the system has them (Linux: nothing on disk, so a run killed while it reads
    leaves no file behind), else a temporary file, removed after."""
    if hasattr(os, "memfd_create") and os.path.isdir("/proc/self/fd"):
        fd = os.memfd_create("wrinklepipe-png", os.MFD_CLOEXEC)
        try:
            with os.fdopen(fd, "wb", closefd=False) as f:
                f.write(data)
            yield f"/proc/self/fd/{fd}"
        finally:
            os.close(fd)
        return
    fd, tmp = tempfile.mkstemp(suffix=".png")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        yield tmp
    finally:
        os.unlink(tmp)


def _open_problem(data: bytes) -> str:
    """Why OpenImageIO could not open ``data`` as an image, in words (the memory file has no
    name, so its own text would be about a format reader for ``/proc/self/fd/N``)."""
    said = oiio_message(oiio.geterror())
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        return "not a PNG file"
    if "format reader" in said or "/proc/self/fd" in said:
        return "damaged PNG data (its chunks cannot be read)"
    return said


def png_pixels(data: bytes, file: str = "") -> np.ndarray:
    """Decode a PNG's pixels as stored (uint8/uint16 ``[H, W, C]``) via OpenImageIO."""

    with _bytes_path(data) as tmp:
        config = oiio.ImageSpec()
        config.attribute("oiio:UnassociatedAlpha", 1)
        with native_stderr_silenced():  # libpng's own "libpng error: ..." line
            inp = oiio.ImageInput.open(tmp, config)
            if inp is None:
                raise input_error(file, f"cannot decode image: {_open_problem(data)}")
            try:
                spec = inp.spec()
                fmt = oiio.UINT16 if spec.format == oiio.UINT16 else oiio.UINT8
                arr = inp.read_image(0, 0, 0, spec.nchannels, fmt)
                err = inp.geterror()
            finally:
                inp.close()
    if arr is None:
        raise input_error(
            file, f"cannot decode image pixels (truncated or corrupt?): {oiio_message(err)}"
        )
    arr = np.asarray(arr)
    if arr.ndim == 2:
        arr = arr[..., None]
    return np.ascontiguousarray(arr.reshape(spec.height, spec.width, spec.nchannels))
