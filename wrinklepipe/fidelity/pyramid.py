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

_F = np.float32


def _weights() -> np.ndarray:
    # input texel j (centre j + 0.5) seen from output texel i (centre 2i + 1), in output units
    t = (np.arange(12, dtype=np.float64) - 5.5) / 2.0
    w = np.sinc(t) * np.sinc(t / 3.0)
    return (w / w.sum()).astype(_F)


WEIGHTS = _weights()


def halve_axis(a: np.ndarray, axis: int) -> np.ndarray:
    """Halve ``a`` along ``axis`` (even length) with the Lanczos-3 kernel, edges clamped.

    The kernel is symmetric, so tap pairs ``j, 11 - j`` are added before their one multiply.
    """
    x = np.asarray(a, _F)
    n = x.shape[axis]
    if n % 2:
        raise ValueError(f"halving needs an even size, got {n}")
    first = np.take(x, [0], axis=axis)
    last = np.take(x, [n - 1], axis=axis)
    pad = np.concatenate([first] * 5 + [x] + [last] * 6, axis=axis)
    m = n // 2

    def taps(j: int) -> np.ndarray:
        sl = [slice(None)] * x.ndim
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


def halve(img: np.ndarray) -> np.ndarray:
    """``[..., H, W, C]`` -> ``[..., H/2, W/2, C]``."""
    a = np.asarray(img, _F)
    return halve_axis(halve_axis(a, a.ndim - 3), a.ndim - 2)


def levels(img: np.ndarray, min_size: int = 1) -> dict[int, np.ndarray]:
    """``{side: map}`` for the input and every halving down to ``min_size`` (square maps whose
    side is a power of two times an odd number stop at the odd factor)."""
    a = np.asarray(img, _F)
    h, w = a.shape[-3], a.shape[-2]
    if h != w:
        raise ValueError(f"the pyramid needs square maps, got {w} x {h}")
    out = {h: a}
    while h % 2 == 0 and h // 2 >= min_size:
        a = halve(a)
        h //= 2
        out[h] = a
    return out
