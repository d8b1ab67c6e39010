"""Is an image a tangent-space normal map, and if not, what does it look like instead?

A tangent-space normal map stores unit vectors ``2 v - 1`` that point out of the surface: its
decoded texels have length 1 (to within quantisation and filtering) and ``z > 0``. Images that
are handed over as a normal map by mistake break that in ways that can be named:

- **a grey image**: R = G = B on (almost) every texel (a height, roughness, AO or mask map, or
  a greyscale photo): the vectors all lie on the diagonal ``(t, t, t)``;
- **a colour image** (a photo, an albedo): most texels decode to vectors far from unit length
  (a normal map's lengths stay within a few percent of 1, even filtered);
- **not in tangent space** (a pale colour texture, an object-space normal map): the vectors
  lean far from the surface normal (``z`` small or negative), where a tangent-space map's
  lean a few degrees.

:func:`looks_like` returns what the texels look like ('' for a tangent-space normal map). The
thresholds leave real maps alone: 8-bit quantisation moves a length by < 0.01, a mip-averaged or
blurred map keeps its median length within 0.15 of 1, and a tangent-space map's median lean
is a few degrees (the tests run the normal maps and colour textures of ``../shared/data``).
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.io.images import texel_values

_F = np.float32

#: A texel is grey when its channels differ by at most this much (1.5 8-bit levels).
GREY_TOLERANCE = 1.5 / 255.0
#: ... and the image is grey when at least this share of its texels are.
GREY_SHARE = 0.98
#: A decoded length this far from 1 is "not unit" here (a filtered normal map stays closer).
UNIT_TOLERANCE = 0.1
#: More than this share of texels not unit, and the median length off by more than
#: :data:`MEDIAN_OFF`, and the image is no normal map.
NON_UNIT_SHARE = 0.5
MEDIAN_OFF = 0.15
#: A median lean of the decoded vectors from +z beyond this, or more than BELOW_SHARE of them
#: below the surface (z < 0), and the image is no tangent-space map (theirs lean a few degrees:
#: 0.3 to 1.3 on the Khronos samples' maps; heavy wrinkles stay well below 45).
MAX_MEDIAN_TILT = 45.0
BELOW_SHARE = 0.2
#: ... named a possible object-space normal map when at least this share is unit length.
UNIT_SHARE = 0.8


#: Images with more texels are judged on a regular lattice of about this many (every k-th row
#: and column): the tests are shares, which a lattice of a million texels measures to 0.1 %.
SAMPLE_TEXELS = 1 << 20


def _share(n: int, of: int) -> str:
    return f"{100.0 * n / max(of, 1):.1f} % of its texels"


def looks_like(values: np.ndarray, layout: str = "rgb", signed: bool = False) -> str:
    """What texels ``values`` ``[H, W, C]`` (in [0, 1], or in [-1, 1] when ``signed``) look
    like when they are not a tangent-space normal map, in a few words; '' when they are one.
    Integer texels (uint8 / uint16) are judged by the float32 values OpenImageIO reads them as
    (:func:`wrinklepipe.io.images.texel_values`), made for the sampled lattice only.

    ``layout``: ``rgb`` (x, y, z stored) or ``rg`` / ``ag`` (z rebuilt: only the grey test
    and the length of ``(x, y)`` can tell)."""
    v = np.asarray(values)
    if v.ndim == 2:
        v = v[..., None]
    step = max(1, int(np.ceil(np.sqrt(v.shape[0] * v.shape[1] / SAMPLE_TEXELS))))
    v = v[::step, ::step]
    v = texel_values(v) if v.dtype.kind == "u" else np.asarray(v, _F)
    h, w, c = v.shape
    n = h * w
    if n == 0 or c < 2:
        return ""
    finite = np.isfinite(v).all(axis=-1)
    if c >= 3 and not signed:
        rgb = v[..., :3]
        spread = rgb.max(axis=-1) - rgb.min(axis=-1)
        grey = int(np.count_nonzero(spread <= _F(GREY_TOLERANCE)))
        if grey >= GREY_SHARE * n:
            return f"a grey image (R = G = B on {_share(grey, n)})"
    s = v if signed else v * _F(2.0) - _F(1.0)
    if layout == "rgb" and c >= 3:
        vec = s[..., :3]
    else:
        x = s[..., 3] if layout == "ag" and c >= 4 else s[..., 0]
        vec = np.stack([x, s[..., 1], np.zeros_like(x)], axis=-1)
    length = np.sqrt(np.einsum("...c,...c->...", vec, vec))
    length = length[finite]
    if length.size == 0:
        return ""
    if layout == "rgb" and c >= 3:
        off = np.abs(length - _F(1.0))
        bad = int(np.count_nonzero(off > _F(UNIT_TOLERANCE)))
        colour = _coloured(v[..., :3][finite])
        what = "a colour image" if colour else "an image"
        if bad > NON_UNIT_SHARE * length.size and float(np.median(off)) > MEDIAN_OFF:
            return (
                f"{what}: {_share(bad, n)} decode to vectors that are not unit length "
                f"(median length {float(np.median(length)):.2f}; a normal map's is 1)"
            )
        z = vec[..., 2][finite] / np.maximum(length, _F(1e-6))
        tilt = float(np.degrees(np.arccos(np.clip(np.median(z), -1.0, 1.0))))
        below = int(np.count_nonzero(z < _F(-0.05)))
        if tilt > MAX_MEDIAN_TILT or below > BELOW_SHARE * length.size:
            if bad <= (1 - UNIT_SHARE) * length.size:
                what = (
                    f"{what} or an object-space normal map"
                    if colour
                    else "an object-space normal map"
                )
            return (
                f"{what}: decoded as normals, half its texels lean more than {tilt:.0f} degrees "
                f"from the surface and {_share(below, n)} point below it (a tangent-space "
                "map's lean a few degrees)"
            )
    else:
        over = int(np.count_nonzero(length > _F(1.0 + UNIT_TOLERANCE)))
        if over > NON_UNIT_SHARE * length.size:
            return (
                f"an image whose (x, y) are longer than 1 on {_share(over, n)} (a normal map's "
                "never are)"
            )
    return ""


def _coloured(rgb: np.ndarray) -> bool:
    """True when a good share of the texels carry colour (chroma above 10 %)."""
    if rgb.size == 0:
        return False
    chroma = rgb.max(axis=-1) - rgb.min(axis=-1)
    return bool(np.count_nonzero(chroma > _F(0.1)) > 0.1 * chroma.size)
