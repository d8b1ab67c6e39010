"""Headless OpenGL for the render pass: a moderngl EGL context plus the few raw GL calls
moderngl lacks (compressed and array texture uploads), loaded through ``eglGetProcAddress``.

moderngl cannot upload block-compressed data, so textures are created here with
``glCompressedTexImage2D/3D`` (or ``glTexImage2D/3D``) and bound by name before drawing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from dataclasses import dataclass

import numpy as np

from wrinklepipe.validate.inputs import FORMATS, Texture

GL_TEXTURE_2D = 0x0DE1
GL_TEXTURE_2D_ARRAY = 0x8C1A
GL_TEXTURE0 = 0x84C0
GL_LINEAR = 0x2601
GL_CLAMP_TO_EDGE = 0x812F
GL_UNPACK_ALIGNMENT = 0x0CF5

_PARAMS = {
    "min": 0x2801,
    "mag": 0x2800,
    "wrap_s": 0x2802,
    "wrap_t": 0x2803,
    "base_level": 0x813C,
    "max_level": 0x813D,
}

#: fmt -> (internal, sRGB internal or 0, format, type) for uncompressed textures
_PLAIN = {
    "r8": (0x8229, 0, 0x1903, 0x1401),
    "rg8": (0x822B, 0, 0x8227, 0x1401),
    "rgb8": (0x8051, 0x8C41, 0x1907, 0x1401),
    "rgba8": (0x8058, 0x8C43, 0x1908, 0x1401),
    "r16": (0x822A, 0, 0x1903, 0x1403),
    "rg16": (0x822C, 0, 0x8227, 0x1403),
    "rgb16": (0x8054, 0, 0x1907, 0x1403),
    "rgba16": (0x805B, 0, 0x1908, 0x1403),
    "r32f": (0x822E, 0, 0x1903, 0x1406),
    "rg32f": (0x8230, 0, 0x8227, 0x1406),
    "rgb32f": (0x8815, 0, 0x1907, 0x1406),
    "rgba32f": (0x8814, 0, 0x1908, 0x1406),
}
#: fmt -> (internal, sRGB internal or 0) for block-compressed textures
_BLOCK = {
    "bc1": (0x83F1, 0x8C4D),
    "bc3": (0x83F3, 0x8C4F),
    "bc4": (0x8DBB, 0),
    "bc5": (0x8DBD, 0),
    "bc7": (0x8E8C, 0x8E8D),
}


class GLUnavailable(RuntimeError):
    """No usable OpenGL 3.3 context (no EGL, no driver)."""


@dataclass
class RawGL:
    """The raw GL entry points the render pass needs."""

    gen: object
    bind: object
    active: object
    param: object
    tex2d: object
    tex3d: object
    ctex2d: object
    ctex3d: object
    delete: object
    pixel_store: object
    get_error: object

    @classmethod
    def load(cls) -> RawGL:
        lib = None
        for name in ("libEGL.so.1", ctypes.util.find_library("EGL") or ""):
            if not name:
                continue
            try:
                lib = ctypes.CDLL(name)
                break
            except OSError:
                continue
        if lib is None:
            raise GLUnavailable("libEGL not found")
        lib.eglGetProcAddress.restype = ctypes.c_void_p
        lib.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        u, i, p = ctypes.c_uint, ctypes.c_int, ctypes.c_void_p

        def fn(name: str, *args: object) -> object:
            addr = lib.eglGetProcAddress(name.encode())
            if not addr:
                raise GLUnavailable(f"{name} not available")
            return ctypes.CFUNCTYPE(None, *args)(addr)

        get_error_addr = lib.eglGetProcAddress(b"glGetError")
        return cls(
            gen=fn("glGenTextures", i, ctypes.POINTER(u)),
            bind=fn("glBindTexture", u, u),
            active=fn("glActiveTexture", u),
            param=fn("glTexParameteri", u, u, i),
            tex2d=fn("glTexImage2D", u, i, i, i, i, i, u, u, p),
            tex3d=fn("glTexImage3D", u, i, i, i, i, i, i, u, u, p),
            ctex2d=fn("glCompressedTexImage2D", u, i, u, i, i, i, i, p),
            ctex3d=fn("glCompressedTexImage3D", u, i, u, i, i, i, i, i, p),
            delete=fn("glDeleteTextures", i, ctypes.POINTER(u)),
            pixel_store=fn("glPixelStorei", u, i),
            get_error=ctypes.CFUNCTYPE(u)(get_error_addr),
        )


def create_context() -> object:
    """A headless moderngl context on EGL (GPU when present, Mesa llvmpipe otherwise)."""
    try:
        import moderngl  # deferred: only where a GL context is made (GLUnavailable below)

        ctx = moderngl.create_context(standalone=True, backend="egl")
    except Exception as exc:  # noqa: BLE001 - any driver failure means "no GL here"
        raise GLUnavailable(f"cannot create an EGL OpenGL context: {exc}") from None
    if ctx.version_code < 330:
        ctx.release()
        raise GLUnavailable(f"OpenGL {ctx.version_code} < 3.3")
    return ctx


def upload(gl: RawGL, layers: list[Texture], array: bool) -> int:
    """Create a GL texture (2D, or 2D array of ``layers``) holding the exact shipped bytes."""
    t0 = layers[0]
    name = ctypes.c_uint()
    gl.gen(1, ctypes.byref(name))
    target = GL_TEXTURE_2D_ARRAY if array else GL_TEXTURE_2D
    gl.bind(target, name.value)
    gl.pixel_store(GL_UNPACK_ALIGNMENT, 1)
    w, h, n = t0.width, t0.height, len(layers)
    if t0.fmt in _BLOCK:
        internal, srgb = _BLOCK[t0.fmt]
        if t0.srgb and srgb:
            internal = srgb
        host = _host_bytes(layers, t0.expected_size())
        ptr = host.ctypes.data_as(ctypes.c_void_p)
        if array:
            gl.ctex3d(target, 0, internal, w, h, n, 0, host.nbytes, ptr)
        else:
            gl.ctex2d(target, 0, internal, w, h, 0, host.nbytes, ptr)
    else:
        internal, srgb, fmt, typ = _PLAIN[t0.fmt]
        if t0.srgb and srgb:
            internal = srgb
        host = _host_bytes(layers, t0.expected_size())
        if FORMATS[t0.fmt][2] == "unorm16" and np.little_endian is False:  # pragma: no cover
            host = host.view("<u2").astype("=u2").view(np.uint8)
        ptr = host.ctypes.data_as(ctypes.c_void_p)
        if array:
            gl.tex3d(target, 0, internal, w, h, n, 0, fmt, typ, ptr)
        else:
            gl.tex2d(target, 0, internal, w, h, 0, fmt, typ, ptr)
    for key, val in (
        ("min", GL_LINEAR),
        ("mag", GL_LINEAR),
        ("wrap_s", GL_CLAMP_TO_EDGE),
        ("wrap_t", GL_CLAMP_TO_EDGE),
        ("base_level", 0),
        ("max_level", 0),
    ):
        gl.param(target, _PARAMS[key], val)
    err = gl.get_error()
    if err:
        raise GLUnavailable(f"GL error 0x{err:04X} uploading {t0.name!r} ({t0.fmt})")
    return name.value


def _host_bytes(layers: list[Texture], size: int) -> np.ndarray:
    """The first ``size`` bytes of every layer, back to back, for GL to copy: one layer's own
    bytes (no copy: 192 MiB twice for an 8192² RGB8 map before), several layers' in one array."""
    parts = [np.frombuffer(t.data, np.uint8, count=size) for t in layers]
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def bind(gl: RawGL, unit: int, name: int, array: bool) -> None:
    gl.active(GL_TEXTURE0 + unit)
    gl.bind(GL_TEXTURE_2D_ARRAY if array else GL_TEXTURE_2D, name)


def delete(gl: RawGL, names: list[int]) -> None:
    for n in names:
        v = ctypes.c_uint(n)
        gl.delete(1, ctypes.byref(v))
