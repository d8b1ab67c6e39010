"""Raster I/O through OpenImageIO: float32 arrays in, quantised files out, atomically.

Reading checks the header before allocating (``max_pixels``), so a file that claims to be
100000 x 100000 is refused without touching its pixels. Values come back as float32 in [0, 1]
for integer formats (0..255 or 0..65535 mapped exactly), as stored for float formats.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from wrinklepipe.atomic import check_not_input, temp_path, write_bytes
from wrinklepipe.errors import input_error
from wrinklepipe.io.png import png_bytes
from wrinklepipe.io.quiet import native_stderr_silenced, oiio_message

#: Default cap on width x height for any image read (64 Mpx, e.g. 8192 x 8192).
DEFAULT_MAX_PIXELS = 8192 * 8192

_BITS_TO_TYPE = {8: oiio.UINT8, 16: oiio.UINT16, 32: oiio.FLOAT, "half": oiio.HALF}


@dataclass(frozen=True)
class ImageInfo:
    """What the header said: size, channels, storage and colour space."""

    path: str
    width: int
    height: int
    channels: int
    format: str  # e.g. "uint8", "uint16", "half", "float"
    colorspace: str
    file_format: str  # e.g. "png", "tiff", "openexr"


def read_header(path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS) -> ImageInfo:
    """Open an image's header only; refuse missing, unreadable or oversized files."""
    path = Path(path)
    if not path.exists():
        raise input_error(path, "file not found")
    if path.is_dir():
        raise input_error(path, "is a folder, expected an image file")
    if path.stat().st_size == 0:
        raise input_error(path, "file is empty")
    declared = _declared_size(path)
    if declared is not None:
        _check_size(path, *declared, max_pixels)  # before OpenImageIO's own limits speak
    with native_stderr_silenced():
        inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise input_error(path, f"cannot read image: {oiio_message(oiio.geterror())}")
    try:
        spec = inp.spec()
        info = ImageInfo(
            path=str(path),
            width=int(spec.width),
            height=int(spec.height),
            channels=int(spec.nchannels),
            format=str(spec.format),
            colorspace=str(spec.get_string_attribute("oiio:ColorSpace", "")),
            file_format=str(inp.format_name()),
        )
    finally:
        inp.close()
    _check_size(path, info.width, info.height, max_pixels)
    return info


_PNG = b"\x89PNG\r\n\x1a\n"

# The pixel cap (--max-pixels) is the tool's: OpenImageIO's own size limit (its text, "raise
# the OIIO attribute limits:imagesize_MB") is set out of the way, so a header over the cap is
# refused by _check_size in the tool's words; headers are read, never pixels, before that.
oiio.attribute("limits:imagesize_MB", 1 << 30)


def _declared_size(path: Path) -> tuple[int, int] | None:
    """The size a PNG's header declares (IHDR), read without OpenImageIO; None for other files
    (OpenImageIO reads their header; it refuses a PNG bomb with its own words otherwise)."""
    try:
        with open(path, "rb") as f:
            head = f.read(24)
    except OSError:
        return None
    if len(head) == 24 and head[:8] == _PNG and head[12:16] == b"IHDR":
        w, h = struct.unpack(">II", head[16:24])
        return int(w), int(h)
    return None


def _check_size(path: Path, width: int, height: int, max_pixels: int) -> None:
    if width <= 0 or height <= 0:
        raise input_error(path, f"invalid size {width} x {height}")
    if width * height > max_pixels:
        raise input_error(
            path,
            f"image is {width} x {height} = {width * height} pixels, over the cap of "
            f"{max_pixels} pixels",
        )


def texel_values(q: np.ndarray) -> np.ndarray:
    """Integer texels (uint8 / uint16) as the float32 in [0, 1] OpenImageIO reads them as:
    ``float32(q) * float32(1 / (2^bits - 1))``, bit for bit."""
    top = 255 if q.dtype == np.uint8 else 65535
    return q.astype(np.float32) * np.float32(1.0 / top)


_NATIVE = {"uint8": oiio.UINT8, "uint16": oiio.UINT16}


def read_image(
    path: str | Path, max_pixels: int = DEFAULT_MAX_PIXELS, integers: bool = False
) -> tuple[np.ndarray, ImageInfo]:
    """Read an image as float32 ``[H, W, C]`` (integers scaled to [0, 1]) and its header.
    ``integers``: an 8- or 16-bit file's texels as stored (uint8 / uint16 ``[H, W, C]``, half
    the bytes of float32 or less; :func:`texel_values` gives the float32 read bit for bit);
    any other file's as float32 still."""
    info = read_header(path, max_pixels)
    pixel_type = _NATIVE.get(info.format, oiio.FLOAT) if integers else oiio.FLOAT
    # Keep alpha unassociated: masks and data textures must not be premultiplied on read.
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    with native_stderr_silenced():
        inp = oiio.ImageInput.open(str(path), config)
        if inp is None:
            raise input_error(path, f"cannot read image: {oiio_message(oiio.geterror())}")
        try:
            data = inp.read_image(0, 0, 0, info.channels, pixel_type)
            err = inp.geterror()
        finally:
            inp.close()
    if data is None or (err and not isinstance(data, np.ndarray)):
        raise input_error(
            path, f"cannot decode pixels (truncated or corrupt?): {oiio_message(err)}"
        )
    arr = np.asarray(data)
    if pixel_type == oiio.FLOAT:
        arr = np.asarray(arr, dtype=np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    arr = arr.reshape(info.height, info.width, info.channels)
    return np.ascontiguousarray(arr), info


def quantize(values: np.ndarray, bits: int) -> np.ndarray:
    """Round [0, 1] floats to unsigned integers of ``bits`` (8 or 16), clipping outside values."""
    top = (1 << bits) - 1
    dtype = np.uint8 if bits == 8 else np.uint16
    return np.clip(np.rint(np.asarray(values, np.float64) * top), 0, top).astype(dtype)


def write_image(
    path: str | Path,
    values: np.ndarray,
    bits: int | str = 8,
    inputs: tuple[str | Path, ...] = (),
) -> Path:
    """Write ``[H, W]`` or ``[H, W, C]`` values in [0, 1] (or floats for EXR) atomically.

    ``bits`` is 8 or 16 (quantised with round-to-nearest), ``"half"`` or 32 (float, EXR/TIFF).
    Colour space is tagged linear (normals and masks are data, never sRGB). A PNG is made by the
    one PNG encoder, :func:`wrinklepipe.io.png.png_bytes` (``linear``: a gAMA 1.0 chunk; alpha
    unassociated, as stored); other formats by OpenImageIO (alpha written unassociated).
    Deterministic bytes: no timestamps or software tags.
    """
    path = Path(path)
    check_not_input(path, inputs)
    arr = np.asarray(values)
    if arr.ndim == 2:
        arr = arr[..., None]
    h, w, c = arr.shape
    if bits in (8, 16):
        pixels = quantize(arr, int(bits))
    else:
        pixels = np.asarray(arr, dtype=np.float32)
    if path.suffix.lower() == ".png" and bits in (8, 16):
        return write_bytes(path, png_bytes(pixels, shared=False, linear=True))
    spec = oiio.ImageSpec(w, h, c, _BITS_TO_TYPE[bits])
    spec.attribute("oiio:ColorSpace", "Linear")
    spec.attribute("oiio:UnassociatedAlpha", 1)
    spec.attribute("Software", "")
    if path.suffix.lower() in (".tif", ".tiff"):
        spec.attribute("compression", "zip")
        spec.attribute("DateTime", "")
    if path.suffix.lower() == ".exr":
        spec.attribute("compression", "zip")
    with temp_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None:
            raise input_error(path, f"no writer for this extension: {oiio.geterror().strip()}")
        ok = out.open(str(tmp), spec) and out.write_image(np.ascontiguousarray(pixels))
        msg = out.geterror()
        out.close()
        if not ok:
            raise OSError(f"{path}: write failed: {msg}")
    return path
