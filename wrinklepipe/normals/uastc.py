"""UASTC (Basis Universal) KTX2 output, when a Basis Universal encoder is installed.

The encoder comes from the PyPI package ``alktx2`` (a binding of Binomial's basisu encoder and
transcoder; optional: ``pip install wrinklepipe[uastc]``). Without it, asking for ``uastc``
raises a clear error and everything else works. The check decodes the written KTX2 with the
same package's transcoder (there is no second UASTC decoder on PyPI that builds here), then
measures the angular error exactly as for the BC formats.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from wrinklepipe.metrics import Budget
from wrinklepipe.normals import compress as cmp


def available() -> bool:
    """True when the ``alktx2`` Basis Universal binding imports."""
    try:
        import alktx2  # noqa: F401  # deferred: optional, UASTC only
    except ImportError:
        return False
    return True


def _lib() -> Any:
    try:
        import alktx2  # deferred: optional, UASTC only
    except ImportError:
        raise ValueError(
            "UASTC needs a Basis Universal encoder: pip install alktx2 (or wrinklepipe[uastc])"
        ) from None
    return alktx2


def encode_uastc(rgba: np.ndarray, mips: bool = True, quality: int = 100, effort: int = 4) -> bytes:
    """RGBA8 [H, W, 4] -> KTX2 bytes holding UASTC LDR 4x4 (linear, no supercompression)."""
    a = np.ascontiguousarray(rgba, dtype=np.uint8)
    h, w = a.shape[:2]
    return bytes(
        _lib().encode_raw_rgba_to_ktx2(
            a.tobytes(),
            w,
            h,
            True,
            codec="uastc",
            quality=quality,
            effort=effort,
            srgb=False,
            linear=True,
            mipmaps=mips,
            threads=1,
            check_for_alpha=False,
        )
    )


def encode_uastc_levels(levels: list[np.ndarray], quality: int = 100, effort: int = 4) -> bytes:
    """A mip chain made here (RGBA8 ``[h, w, 4]`` per level, level 0 first: PD averaged in
    slope space, normals renormalised) -> KTX2 bytes holding UASTC LDR 4x4 (linear)."""
    raw = [(np.ascontiguousarray(v, np.uint8).tobytes(), v.shape[1], v.shape[0]) for v in levels]
    return bytes(
        _lib().encode_raw_mips_to_ktx2(
            raw,
            False,
            codec="uastc",
            quality=quality,
            effort=effort,
            srgb=False,
            linear=True,
            threads=1,
            check_for_alpha=False,
        )
    )


def decode_uastc(ktx2: bytes) -> np.ndarray:
    """Level 0 of a UASTC KTX2 -> RGBA8 [H, W, 4] (transcoded by basisu)."""
    png, _ = _lib().decode_ktx2_to_bytes(ktx2, format="png")
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "level0.png"
        p.write_bytes(png)
        buf = oiio.ImageBuf(str(p))
        px = np.asarray(buf.get_pixels(oiio.UINT8))
    if px.shape[-1] == 3:
        px = np.concatenate([px, np.full(px.shape[:2] + (1,), 255, np.uint8)], axis=-1)
    return px


def uastc_check(
    stored_u8: np.ndarray,
    reference: np.ndarray,
    decode: Any,
    budget: Budget | None = None,
    mips: bool = True,
    ktx2: bytes | None = None,
) -> tuple[cmp.FormatCheck, bytes]:
    """Encode 8-bit texels [H, W, 2 or 3] as UASTC KTX2 (or take ``ktx2``, made of them), decode
    level 0, measure. Returns the check (format "uastc", bytes = file size) and the file."""
    q = np.asarray(stored_u8)
    h, w, c = q.shape
    if ktx2 is None:
        rgba = np.zeros((h, w, 4), np.uint8)
        rgba[..., :c] = q
        rgba[..., 3] = 255
        ktx2 = encode_uastc(rgba, mips=mips)
    ktx = ktx2
    dec = decode_uastc(ktx)[..., :c]
    n_dec = decode(np.ascontiguousarray(dec), slice(0, h))
    n_raw = decode(q, slice(0, h))
    check = cmp.FormatCheck(
        format="uastc",
        width=w,
        height=h,
        bytes=len(ktx),
        error=cmp.angular_error_stats(n_dec, np.asarray(reference, np.float32)),
        compression_error=cmp.angular_error_stats(n_dec, n_raw),
        psnr_db=cmp.psnr(q, dec),
        decoded=np.ascontiguousarray(dec),
    )
    if budget is not None:
        check.verdict = "pass" if budget.inside(check.error) else "fail"
    return check, ktx
