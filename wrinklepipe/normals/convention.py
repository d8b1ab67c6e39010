"""Green-channel convention of a tangent-space normal map: OpenGL (+Y up) or DirectX (-Y).

Evidence: the slope field of a height map is a gradient, so its curl vanishes. With rows
running down (glTF UV origin) and ``(px, py) = (x / z, y / z)``, an OpenGL map of height ``h``
has ``px = -dh/dcol`` and ``py = +dh/drow``, so ``d(py)/dcol + d(px)/drow = 0``; a DirectX map
flips ``py`` and makes ``d(py)/dcol - d(px)/drow = 0`` instead. We measure the mean absolute
residual of both (central differences), and pick the convention whose residual is smaller.
``confidence = 1 - smaller / larger``: 0 means no evidence (a flat map, pure noise), 1 a
perfectly integrable field. Texels near the horizon (z < 0.2) and seams (slope jumps) are left
out so UV-island edges of baked maps do not drown the signal.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from wrinklepipe.workset import band_rows

_F = np.float32

CONVENTIONS: tuple[str, ...] = ("opengl", "directx")

#: Below this confidence the detection says "undetermined". Synthetic and sculpted maps score
#: above 0.8; baked hard-surface maps with mirrored or mixed islands can score ~0.2 either way
#: (DamagedHelmet: 0.19 towards DirectX although it is an OpenGL map), so those are left to the
#: manifest rather than guessed.
MIN_CONFIDENCE = 0.3
#: At or above this confidence the detection is beyond doubt: a map declared in the other
#: convention is refused before anything is written (synthetic, sculpted and wrinkle maps score
#: 0.93 to 1.0; the Khronos NormalTangentTest map 0.83; baked hard-surface maps ~0.2).
BEYOND_DOUBT = 0.9
#: Below this mean absolute mixed derivative the map is considered flat (no evidence).
MIN_SIGNAL = 1e-4


@dataclass(frozen=True)
class ConventionReport:
    """What the curl test found. ``convention`` is "opengl", "directx" or "undetermined"."""

    convention: str
    curl_opengl: float  # mean |d(py)/dcol + d(px)/drow| (0 for a perfect OpenGL map)
    curl_directx: float  # mean |d(py)/dcol - d(px)/drow| (0 for a perfect DirectX map)
    confidence: float
    texels_used: int
    reason: str

    def to_json(self) -> dict[str, object]:
        return {
            "convention": self.convention,
            "curl_opengl": round(self.curl_opengl, 8),
            "curl_directx": round(self.curl_directx, 8),
            "confidence": round(self.confidence, 6),
            "texels_used": self.texels_used,
            "reason": self.reason,
        }


def flip_green(normals: np.ndarray) -> np.ndarray:
    """Convert between DirectX and OpenGL tangent space: ``y -> -y`` (a copy, float32)."""
    n = np.array(normals, dtype=_F, copy=True)
    n[..., 1] *= -1
    return n


def detect_convention(normals: np.ndarray, mask: np.ndarray | None = None) -> ConventionReport:
    """Detect the green convention of unit normals [H, W, 3] from the curl of the slopes.

    ``mask`` ([H, W] bool) restricts the test to texels that belong to the map (e.g. UV
    islands). Returns a :class:`ConventionReport`.
    """
    # normals made where they are read (``reads_rows``: integer texels decoded a band at a
    # time) are read band by band below, never made whole
    n = normals if getattr(type(normals), "reads_rows", False) else np.asarray(normals, _F)
    if n.ndim != 3 or n.shape[-1] != 3 or n.shape[0] < 3 or n.shape[1] < 3:
        return ConventionReport("undetermined", 0.0, 0.0, 0.0, 0, "map too small (< 3 x 3)")
    m = None if mask is None else np.asarray(mask, dtype=bool)
    # band by band of interior rows (each band reads one row either side): the slopes'
    # differences at the usable texels, in the whole map's order; the map's own temporaries
    # are one band's (about 50 bytes a texel for the whole map: 3.4 GB at 8192²)
    H = n.shape[0]
    rows = band_rows(n.shape[1], DETECT_BYTES_PER_TEXEL)

    def terms() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """The differences ``a``, ``b`` at the usable texels of each band, in the map's order."""
        for r0 in range(1, H - 1, rows):
            r1 = min(H - 1, r0 + rows)
            a, b, valid, _ = _curl_terms(
                n[r0 - 1 : r1 + 1], None if m is None else m[r0 - 1 : r1 + 1]
            )
            yield a[valid], b[valid]

    # two passes over the bands, so that at most 8 bytes a usable texel are held: the seam
    # jumps (max(|a|, |b|)) for their percentile, then the kept terms |a + b| and |a - b|
    # (|a| + |b| is the larger of the two, to the last bit: rounding is symmetric), the
    # same values in the same order, summed as the whole map's
    limit, used = _seam_limit(terms(), (H - 2) * (n.shape[1] - 2))
    if used == 0:
        return ConventionReport("undetermined", 0.0, 0.0, 0.0, 0, "no usable texels")
    gl, dx = np.empty(used, _F), np.empty(used, _F)
    o = 0
    for a, b in terms():
        k = np.maximum(np.abs(a), np.abs(b)) <= limit
        a, b = a[k], b[k]
        np.abs(np.add(a, b, out=gl[o : o + a.size]), out=gl[o : o + a.size])
        np.abs(np.subtract(a, b, out=dx[o : o + a.size]), out=dx[o : o + a.size])
        o += a.size
    curl_gl = float(np.mean(gl, dtype=np.float64))
    curl_dx = float(np.mean(dx, dtype=np.float64))
    signal = float(np.mean(np.maximum(gl, dx, out=gl), dtype=np.float64)) * 0.5
    del gl, dx
    hi, lo = max(curl_gl, curl_dx), min(curl_gl, curl_dx)
    confidence = 0.0 if hi <= 0 else 1.0 - lo / hi
    if signal < MIN_SIGNAL:
        return ConventionReport(
            "undetermined", curl_gl, curl_dx, confidence, used, "map is flat: no evidence"
        )
    if confidence < MIN_CONFIDENCE:
        return ConventionReport(
            "undetermined",
            curl_gl,
            curl_dx,
            confidence,
            used,
            "mixed evidence: the slope field is not integrable either way (noise, painted "
            "detail, or islands baked with different conventions); set the convention",
        )
    conv = "opengl" if curl_gl < curl_dx else "directx"
    return ConventionReport(
        conv,
        curl_gl,
        curl_dx,
        confidence,
        used,
        f"curl of the slope field vanishes for {conv} (residual {lo:.3g} vs {hi:.3g})",
    )


def _seam_limit(terms: Iterator[tuple[np.ndarray, np.ndarray]], most: int) -> tuple[float, int]:
    """The slope jump above which a texel sits on a seam, 4 x the 99th percentile of the jumps
    ``max(|a|, |b|)`` of every usable texel (at least 1e-6), and how many texels it keeps; the
    bands' ``terms`` hold at most ``most`` texels. (inf, 0) when none is usable."""
    jumps = np.empty(most, _F)  # pages never written are never held
    o = 0
    for a, b in terms:
        np.maximum(np.abs(a), np.abs(b), out=jumps[o : o + a.size])
        o += a.size
    if o == 0:
        return float("inf"), 0
    j = jumps[:o]
    # partitioned in place: the same order statistics as a partitioned copy, no second array
    limit = max(float(np.percentile(j, 99.0, overwrite_input=True)) * 4.0, 1e-6)
    return limit, int(np.count_nonzero(j <= limit))


#: Bytes of temporaries per texel of a band while detecting the convention.
DETECT_BYTES_PER_TEXEL = 64


def _curl_terms(
    n: np.ndarray, mask: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Of rows of unit normals ``n`` [h, W, 3] (h >= 3): the central differences ``a``
    (d(py)/dcol) and ``b`` (d(px)/drow) at the interior texels (rows 1..h-2, columns 1..W-2),
    where all five texels are usable, and the larger of the two's magnitudes (``jump``)."""
    z = n[..., 2]
    ok = np.isfinite(n).all(axis=-1) & (z > 0.2)
    if mask is not None:
        ok &= mask
    zs = np.where(ok, z, _F(1.0))
    px = np.where(ok, n[..., 0] / zs, _F(0.0))
    py = np.where(ok, n[..., 1] / zs, _F(0.0))
    # central differences on the interior
    a = (py[1:-1, 2:] - py[1:-1, :-2]) * _F(0.5)  # d(py)/dcol
    b = (px[2:, 1:-1] - px[:-2, 1:-1]) * _F(0.5)  # d(px)/drow
    valid = ok[1:-1, 2:] & ok[1:-1, :-2] & ok[2:, 1:-1] & ok[:-2, 1:-1] & ok[1:-1, 1:-1]
    jump = np.maximum(np.abs(a), np.abs(b))
    return a, b, valid, jump
