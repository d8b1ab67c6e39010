"""A Lanczos-3 halving pyramid: every power-of-two size of a map from one pass per level.

Halving filters each axis with the Lanczos-3 kernel ``sinc(t) sinc(t / 3)`` (``|t| < 3``, in
units of output texels), 12 input taps per output texel, edges clamped, weights normalised to 1.
Level ``n`` is made from level ``2n``, so all sizes together cost about 4/3 of the first
halving: the automatic size search and the states convert ships both come from here, so what is
measured is what is shipped.

Only for linear quantities (PD slopes); masks keep their box filter
(:func:`wrinklepipe.masks.resample_masks`), which has no negative lobes.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe.fidelity.level import PdLevel

_F = np.float32


def _weights() -> np.ndarray:
    # input texel j (centre j + 0.5) seen from output texel i (centre 2i + 1), in output units
    t = (np.arange(12, dtype=np.float64) - 5.5) / 2.0
    w = np.sinc(t) * np.sinc(t / 3.0)
    return (w / w.sum()).astype(_F)


WEIGHTS = _weights()


#: Bytes of input a chunk of :func:`halve_axis` reads: its temporaries stay in the cache.
CHUNK_BYTES = 1 << 20


def _halve_window(pad: np.ndarray, axis: int, m: int) -> np.ndarray:
    """``m`` outputs along ``axis`` from ``pad`` (the inputs they read, 5 before the first
    output's pair and 6 after the last's). The kernel is symmetric, so tap pairs ``j, 11 - j``
    are added before their one multiply."""

    def taps(j: int) -> np.ndarray:
        sl = [slice(None)] * pad.ndim
        sl[axis] = slice(j, j + 2 * m, 2)
        return pad[tuple(sl)]

    out = np.add(taps(0), taps(11))
    out *= WEIGHTS[0]
    tmp = np.empty_like(out)
    for j in range(1, 6):
        np.add(taps(j), taps(11 - j), out=tmp)
        tmp *= WEIGHTS[j]
        out += tmp
    return out


def halve_axis(a: np.ndarray, axis: int, chunk_bytes: int = CHUNK_BYTES) -> np.ndarray:
    """Halve ``a`` along ``axis`` (even length) with the Lanczos-3 kernel, edges clamped.

    Computed in chunks of outputs along the axis, each from its own window of inputs (edge
    texels repeated at the ends): the same operations on the same values for every output as
    one pass over the whole map, with temporaries small enough to stay in the cache (about
    three times faster on a 2048^2 map)."""
    x = np.asarray(a, _F)
    axis %= x.ndim
    n = x.shape[axis]
    if n % 2:
        raise ValueError(f"halving needs an even size, got {n}")
    m = n // 2
    shape = list(x.shape)
    shape[axis] = m
    out = np.empty(shape, _F)
    per = max(1, x.size // max(n, 1) * x.itemsize)  # bytes of one index along the axis
    step = max(1, chunk_bytes // (2 * per))  # outputs per chunk
    for i0 in range(0, m, step):
        i1 = min(m, i0 + step)
        lo, hi = 2 * i0 - 5, 2 * i1 + 6
        if lo >= 0 and hi <= n:
            sl = [slice(None)] * x.ndim
            sl[axis] = slice(lo, hi)
            win = x[tuple(sl)]
        else:  # at an end: the edge texel repeated, as clamp to edge reads it
            win = np.take(x, np.clip(np.arange(lo, hi), 0, n - 1), axis=axis)
        osl = [slice(None)] * x.ndim
        osl[axis] = slice(i0, i1)
        out[tuple(osl)] = _halve_window(win, axis, i1 - i0)
    return out


def halve(img: np.ndarray, chunk_bytes: int = CHUNK_BYTES) -> np.ndarray:
    """``[..., H, W, C]`` -> ``[..., H/2, W/2, C]``: rows, then columns (on transposed copies of
    bands of about ``chunk_bytes`` of the halved rows, so that the column pass also reads whole
    rows; each output is the same operations on the same values as one pass over the map,
    without a transposed copy of the whole of it)."""
    a = np.asarray(img, _F)
    rows = halve_axis(a, a.ndim - 3)
    h2, w, c = rows.shape[-3:]
    out = np.empty(rows.shape[:-3] + (h2, w // 2, c), _F)
    _halve_columns(rows, out, chunk_bytes)
    return out


def _halve_columns(rows: np.ndarray, out: np.ndarray, chunk_bytes: int) -> None:
    """The column pass of :func:`halve`: ``rows`` ``[..., h2, W, C]`` halved along ``W`` into
    ``out``, on transposed copies of bands of about ``chunk_bytes``."""
    h2 = rows.shape[-3]
    per_row = max(1, rows.size // max(h2, 1) * rows.itemsize)  # bytes of one halved row
    step = max(1, chunk_bytes // per_row)
    for r0 in range(0, h2, step):
        band = np.ascontiguousarray(np.swapaxes(rows[..., r0 : r0 + step, :, :], -2, -3))
        out[..., r0 : r0 + step, :, :] = np.swapaxes(halve_axis(band, rows.ndim - 3), -2, -3)


def halve_level(level: PdLevel, chunk_bytes: int = CHUNK_BYTES) -> np.ndarray:
    """:func:`halve` of a :class:`~wrinklepipe.fidelity.level.PdLevel` ``[K, H, W, C]`` made
    band by band of output rows: each band's input rows (5 before, 6 after, edge rows
    repeated) made, halved along rows, then along columns. The same operations on the same
    values for every output as :func:`halve` of the whole array; the level is never whole."""
    K, H, W, C = level.shape
    if H % 2 or W % 2:
        raise ValueError(f"halving needs an even size, got {W} x {H}")
    m = H // 2
    out = np.empty((K, m, W // 2, C), _F)
    step = max(1, level.band() // 2)  # output rows a band
    for i0 in range(0, m, step):
        i1 = min(m, i0 + step)
        lo, hi = 2 * i0 - 5, 2 * i1 + 6
        a, b = max(lo, 0), min(hi, H)
        win = level.rows(a, b)
        if a != lo or b != hi:  # at an end: the edge rows repeated, as clamp to edge reads them
            win = np.take(win, np.clip(np.arange(lo, hi), 0, H - 1) - a, axis=1)
        rows = _halve_window(win, 1, i1 - i0)
        del win
        _halve_columns(rows, out[:, i0:i1], chunk_bytes)
    return out


def levels(img: np.ndarray | PdLevel, min_size: int = 1) -> dict[int, np.ndarray]:
    """``{side: map}`` for the input and every halving down to ``min_size`` (square maps whose
    side is a power of two times an odd number stop at the odd factor). A
    :class:`~wrinklepipe.fidelity.level.PdLevel` is kept as it is (the first halving made band
    by band from it: :func:`halve_level`)."""
    if not isinstance(img, PdLevel):
        img = np.asarray(img, _F)
    h, w = img.shape[-3], img.shape[-2]
    if h != w:
        raise ValueError(f"the pyramid needs square maps, got {w} x {h}")
    out: dict[int, np.ndarray] = {h: img}  # type: ignore[dict-item]
    if isinstance(img, PdLevel):
        if not (h % 2 == 0 and h // 2 >= min_size):
            return out
        h //= 2
        out[h] = halve_level(img)
    a = np.asarray(out[h], _F)
    while h % 2 == 0 and h // 2 >= min_size:
        a = halve(a)
        h //= 2
        out[h] = a
    return out
