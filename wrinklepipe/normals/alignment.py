"""Are a base and a wrinkle state of one face? The share of the base's detail a state keeps.

A wrinkle state baked or painted over the same face carries the base's detail (pores, scars,
creases) wherever no wrinkle covers it; artists often leave the wrinkle relief everywhere and
let the masks pick where it shows, so a state may differ from the base over the whole face and
still be right. What a state of *another* face, bake or orientation does not do is keep the
base's detail. So the test is a regression, not a difference: with ``b`` and ``s`` the PD slopes
``(x/z, y/z)`` of base and state at the texels ``where`` (each minus its mean),

    kept = <s, b> / <b, b>

is 1 when the state holds the base's detail (plus anything uncorrelated with it, such as wrinkle
relief) and 0 when it holds none of it; a green flip or a mirror of the base gives about 0 as
is and about 1 once undone. A base without detail (``rms(b)`` below :data:`MIN_DETAIL`, e.g. a
flat map) gives no evidence: ``None``.

Everything is measured on a lattice of at most :data:`SAMPLE_TEXELS` of the texels (a share,
measured to a few parts in a thousand), so 8K maps cost no more than 1K ones.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wrinklepipe.codec.vectors import EPS
from wrinklepipe.normals.held import rows_of

#: rms PD slope of the base's detail (~0.6 degrees) below which it carries nothing to compare.
MIN_DETAIL = 0.01
#: A state keeping at least this share of the base's detail is of the same face and bake.
KEPT = 0.5
#: Texels of ``where`` the measure reads at most (every k-th one).
SAMPLE_TEXELS = 1 << 20

#: How a base may be turned relative to its states: name -> (texel rows, cols) -> (the base's
#: rows, cols, sign of y). The flips keep the stored values (as an image editor flips a file).
Transform = Callable[
    [np.ndarray, np.ndarray, tuple[int, int]], tuple[np.ndarray, np.ndarray, float]
]
TRANSFORMS: dict[str, Transform] = {
    "the base flipped vertically (V)": lambda r, c, hw: (hw[0] - 1 - r, c, 1.0),
    "the base flipped horizontally (U)": lambda r, c, hw: (r, hw[1] - 1 - c, 1.0),
    "the base's green channel flipped": lambda r, c, hw: (r, c, -1.0),
}


def lattice(where: np.ndarray, max_texels: int = SAMPLE_TEXELS) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of every k-th texel of ``where`` ``[H, W]`` (at most ``max_texels``)."""
    flat = np.flatnonzero(np.asarray(where, bool))
    step = max(1, -(-flat.size // max_texels))
    flat = flat[::step]
    return flat // where.shape[1], flat % where.shape[1]


def _slopes(n: np.ndarray) -> np.ndarray:
    """PD slopes ``[m, 2]`` (float64) of unit normals ``[m, 3]``, minus their mean."""
    v = np.asarray(n, np.float64)
    p = v[:, :2] / np.maximum(v[:, 2:3], EPS)
    return p - p.mean(axis=0)


def detail(base: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> float:
    """rms of the base's PD slopes at ``(rows, cols)`` (minus their mean)."""
    if rows.size == 0:
        return 0.0
    b = _slopes(np.asarray(base)[rows, cols])
    return float(np.sqrt((b * b).sum(axis=1).mean()))


def kept(
    base: np.ndarray,
    state: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    transform: Transform | None = None,
    shift: tuple[int, int] = (0, 0),
) -> float | None:
    """The share of the base's detail the state keeps at ``(rows, cols)`` (module doc): 1 for
    a state of the same face and bake, about 0 for another; ``None`` when the base has no
    detail there. ``transform`` (one of :data:`TRANSFORMS`) or ``shift`` (rows, columns: the
    base's texel ``(r + dy, c + dx)`` is compared with the state's ``(r, c)``) move the base
    first."""
    if rows.size == 0:
        return None
    b_img = rows_of(base)  # held as integers: only the texels compared are decoded
    h, w = b_img.shape[:2]
    br, bc, sy = (rows, cols, 1.0) if transform is None else transform(rows, cols, (h, w))
    br = (br + shift[0]) % h
    bc = (bc + shift[1]) % w
    b = _slopes(b_img[br, bc])
    b[:, 1] *= sy
    energy = float((b * b).sum())
    if np.sqrt(energy / rows.size) < MIN_DETAIL:
        return None
    s = _slopes(rows_of(state)[rows, cols])
    return float((s * b).sum() / energy)
