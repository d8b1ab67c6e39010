"""The searches' full-size PD slopes, made where they are read (issue 42).

The wrinkle-only PD slopes of the source states on their grid (:func:`source_states` under
``pd``: ``pd(state) - pd(base)`` per texel) are ``[K, H, W, 2]`` float32: 256 MiB at 4096²,
1 GiB at 8192², beside the source normals they are made from. The searches read that level
band by band (the pyramid's first halving, the clipping counts) or at the reference's texels
(the reference, the judge's samples), so :class:`PdLevel` holds only the base and the states
and makes a band's or a gather's slopes when asked. Every step is per texel: the values are
the whole map's bit for bit, and ``np.asarray`` of it is :func:`source_states`' own array.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterator

import numpy as np

from wrinklepipe.fidelity.reference import SOURCE_BYTES_PER_TEXEL, _source_states, source_states
from wrinklepipe.normals.held import one_map, texels_at
from wrinklepipe.workset import band_rows

_F = np.float32


class PdLevel:
    """``[K, H, W, 2]`` PD slopes of ``states`` ``[K, H, W, 3]`` over ``base`` ``[H, W, 3]``
    (the caller's arrays, not copied), made a band of rows or a gather of texels at a time."""

    def __init__(self, base: np.ndarray, states: np.ndarray) -> None:
        self.base, self.states = base, states
        K, H, W = states.shape[:3]
        if base.shape[:2] != (H, W):
            raise ValueError(f"source states {(H, W)} and base {base.shape[:2]} differ in size")
        self.shape = (K, H, W, 2)

    ndim = 4
    dtype = np.dtype(_F)

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, k: int) -> PdState:
        if not isinstance(k, int | np.integer):
            raise IndexError("PdLevel: index one state")
        return PdState(self, int(k) % self.shape[0])

    def __iter__(self) -> Iterator[PdState]:
        return (PdState(self, k) for k in range(self.shape[0]))

    def band(self) -> int:
        """Rows of a band (one band's temporaries, :func:`wrinklepipe.workset.band_rows`)."""
        return band_rows(self.shape[2], SOURCE_BYTES_PER_TEXEL * max(self.shape[0], 1))

    def rows(self, r0: int, r1: int) -> np.ndarray:
        """Rows ``r0:r1`` of every state ``[K, r, W, 2]``."""
        return np.asarray(_source_states(self.base[r0:r1], self.states[:, r0:r1], "pd"), _F)

    def at(self, flat: np.ndarray) -> np.ndarray:
        """Every state's slopes at texels ``flat`` (flat indices) ``[K, n, 2]``."""
        b = texels_at(self.base, flat)
        s = texels_at(self.states, flat)
        return np.asarray(_source_states(b, s, "pd"), _F)

    def memo_digest(self) -> bytes:
        """The memo's digest of the whole array (:mod:`wrinklepipe.reuse`): its dtype, shape
        and C-ordered bytes, hashed a band at a time."""
        h = hashlib.sha256(f"{self.dtype.str}{self.shape}".encode())
        for state in self:
            for r0 in range(0, self.shape[1], self.band()):
                h.update(memoryview(state.rows(r0, r0 + self.band())).cast("B"))
        return h.digest()

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape)) * 4

    def __array__(self, dtype: object = None, copy: bool | None = None) -> np.ndarray:
        a = np.asarray(source_states(self.base, self.states, "pd"), _F)
        return a if dtype is None else a.astype(dtype, copy=False)


class PdState:
    """State ``k`` of a :class:`PdLevel` ``[H, W, 2]``: rows and gathers made when read."""

    def __init__(self, level: PdLevel, k: int) -> None:
        self.level, self.k = level, k
        self.shape = level.shape[1:]

    ndim = 3
    dtype = np.dtype(_F)

    def rows(self, r0: int, r1: int) -> np.ndarray:
        lv, k = self.level, self.k
        return np.asarray(_source_states(lv.base[r0:r1], lv.states[k : k + 1, r0:r1], "pd")[0], _F)

    def __getitem__(self, key: slice) -> np.ndarray:
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise IndexError("PdState: index a slice of rows")
        r0, r1, _ = key.indices(self.shape[0])
        return self.rows(r0, r1)

    def at(self, flat: np.ndarray) -> np.ndarray:
        """The slopes at texels ``flat`` (flat indices) ``[n, 2]``."""
        lv, k = self.level, self.k
        b = texels_at(lv.base, flat)
        s = texels_at(one_map(lv.states, k), flat)
        return np.asarray(_source_states(b, s[None], "pd")[0], _F)

    def __array__(self, dtype: object = None, copy: bool | None = None) -> np.ndarray:
        lv, H = self.level, self.shape[0]
        out = np.empty(self.shape, _F)
        for r0 in range(0, H, lv.band()):
            out[r0 : r0 + lv.band()] = self.rows(r0, r0 + lv.band())
        return out if dtype is None else out.astype(dtype, copy=False)


def row_bands(level: np.ndarray | PdLevel) -> Iterator[tuple[slice, np.ndarray]]:
    """``(rows, level[:, rows])`` band by band of a level ``[K, H, W, C]`` (an array: views;
    a :class:`PdLevel`: each band made)."""
    H = level.shape[1]
    if isinstance(level, PdLevel):
        step = level.band()
        for r0 in range(0, H, step):
            yield slice(r0, min(H, r0 + step)), level.rows(r0, r0 + step)
    else:
        yield slice(0, H), np.asarray(level)
