"""Reading maps at texels, the way the measure needs them (:mod:`wrinklepipe.fidelity.metric`):
bilinear taps of a map magnified to the source grid as a GPU samples it, the gathers of a
shipped map and of its masks at the active texels, and the chunking and thread rules of
whole-map passes."""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from threadpoolctl import ThreadpoolController

from wrinklepipe import model
from wrinklepipe.masks.stack import MaskStack

_F = np.float32


_BLAS = ThreadpoolController()


_Fn = TypeVar("_Fn", bound=Callable[..., Any])


#: Texels a whole-map pass of the measure (the base over the face, the source base's
#: normalisation) handles at a time. Every step is per texel, so the values are those of one
#: pass over the whole map; but its float32 temporaries stay below numpy's huge-page size (4 MB:
#: a fresh huge page is zeroed, and on a loaded machine compacted, by the kernel: a 4M-texel
#: pass spent 0.4-0.6 s of system time in page faults, five times its own arithmetic) and in the
#: cache, and are reused from one chunk to the next.
CHUNK_TEXELS = 1 << 18


def chunks(n: int, step: int = CHUNK_TEXELS) -> list[slice]:
    """Slices of ``range(n)`` of ``step`` items (the last shorter)."""
    step = max(1, int(step))
    return [slice(i, min(i + step, n)) for i in range(0, n, step)]


def normalize_rows(v: np.ndarray) -> np.ndarray:
    """:func:`wrinklepipe.model.normalize` of ``[..., C]`` vectors, in :data:`CHUNK_TEXELS`
    chunks of the leading axis (the same values: each vector is normalised on its own)."""
    a = np.asarray(v, _F)
    if a.ndim < 2 or a.size <= CHUNK_TEXELS * a.shape[-1]:
        return model.normalize(a)
    out = np.empty(a.shape, _F)
    per = max(1, a[0].size // a.shape[-1])  # vectors per leading index
    for sl in chunks(a.shape[0], max(1, CHUNK_TEXELS // per)):
        out[sl] = model.normalize(a[sl])
    return out


def one_blas_thread(fn: _Fn) -> _Fn:
    """Run ``fn`` with one BLAS thread: the measure's products are small (a few regions by a
    few states, dots of one pose's texels), and on a shared machine OpenBLAS's threads wait on
    each other far longer than such a product takes (a 55k-texel dot: 15 ms instead of 15 us
    at load 10 on 2 cores)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        with _BLAS.limit(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def _taps(n_out: int, n_in: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each output texel centre: the two input texels and the weight of the second."""
    x = (np.arange(n_out, dtype=np.float64) + 0.5) * (n_in / n_out) - 0.5
    x0 = np.floor(x)
    f = (x - x0).astype(_F)
    i0 = np.clip(x0, 0, n_in - 1).astype(np.int64)
    i1 = np.clip(x0 + 1, 0, n_in - 1).astype(np.int64)
    return i0, i1, f


@dataclass(frozen=True)
class Reader:
    """How a map's values become what the measure compares: ``store`` (per texel, before the
    sampler filters: values -> stored texels, e.g. quantising a candidate) and ``read`` (after
    filtering: sampled texels -> the quantity, as a shader decodes). Either may be None."""

    store: Callable[[np.ndarray], np.ndarray] | None = None
    read: Callable[[np.ndarray], np.ndarray] | None = None


def sample_at(
    img: np.ndarray, shape: tuple[int, int], flat: np.ndarray, reader: Reader | None = None
) -> np.ndarray:
    """``img`` ``[h, w, C]`` sampled at texels ``flat`` (flat indices) of a ``shape`` grid
    -> ``[n, C']`` float32.

    Bilinear between texel centres with clamp to edge, the way the render pass samples (on the
    same grid a plain gather). With a ``reader``, its ``store`` runs on the texels read only
    (so a candidate encoding of a large map costs as much as the texels the measure looks at)
    and its ``read`` on the filtered values.

    Many texels of a smaller map (``h * W`` below twice their number) are filtered separably:
    each map row first at the grid's columns, then those rows at the texels (the same products
    and sums in the same order as four taps at a time, so the same values), with ``store`` on
    the whole map once.
    """
    if hasattr(img, "at") and tuple(img.shape[:2]) == tuple(shape):
        return _gathered(img, np.asarray(flat, np.int64), reader)
    a = np.asarray(img)
    if a.ndim == 2:
        a = a[..., None]
    h, w = a.shape[:2]
    H, W = shape
    flat = np.asarray(flat, np.int64)
    src = a.reshape(h * w, -1)
    store = reader.store if reader is not None and reader.store is not None else None
    read = reader.read if reader is not None and reader.read is not None else None

    def texels(i: np.ndarray | None) -> np.ndarray:
        v = src if i is None else src[i]
        return np.asarray(v if store is None else store(v), _F)

    if (h, w) == (H, W):
        out = texels(flat) if store is not None else _gather_planes(src, flat).T
    elif h * W < 2 * flat.size:
        rows, cols = flat // W, flat % W
        r0, r1, fr = _taps(H, h)
        c0, c1, fc = _taps(W, w)
        m = planes(texels(None)).reshape(-1, h, w)
        ty = fr[rows]
        at0, at1 = r0[rows] * W + cols, r1[rows] * W + cols
        res = np.empty((m.shape[0], flat.size), _F)
        for c, plane in enumerate(m):
            across = plane[:, c0] * (1 - fc) + plane[:, c1] * fc  # every map row, every column
            across = across.reshape(-1)
            res[c] = across[at0] * (1 - ty) + across[at1] * ty
        out = res.T
    else:
        rows, cols = flat // W, flat % W
        r0, r1, fr = _taps(H, h)
        c0, c1, fc = _taps(W, w)
        y0, y1, ty = r0[rows], r1[rows], fr[rows]
        x0, x1, tx = c0[cols], c1[cols], fc[cols]
        n = flat.size
        v = planes(texels(np.concatenate([y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1])))
        res = np.empty((v.shape[0], n), _F)
        for c, p in enumerate(v):
            top = p[:n] * (1 - tx) + p[n : 2 * n] * tx
            bot = p[2 * n : 3 * n] * (1 - tx) + p[3 * n :] * tx
            res[c] = top * (1 - ty) + bot * ty
        out = res.T
    return np.asarray(out if read is None else read(out), _F)


def _gathered(img: Any, flat: np.ndarray, reader: Reader | None) -> np.ndarray:
    """:func:`sample_at` on the map's own grid of a map made where it is read (e.g.
    :class:`wrinklepipe.fidelity.level.PdState`: ``img.at(flat)`` its ``[n, C]`` values): the
    gather's values in the gather's layout, then the reader's steps."""
    v = np.asarray(img.at(flat), _F)
    store = reader.store if reader is not None and reader.store is not None else None
    read = reader.read if reader is not None and reader.read is not None else None
    out = np.asarray(store(v), _F) if store is not None else np.ascontiguousarray(v.T).T
    return np.asarray(out if read is None else read(out), _F)


def _gather_planes(rows: np.ndarray, flat: np.ndarray) -> np.ndarray:
    """``rows[flat]`` of an ``[N, C]`` array as float32 planes ``[C, n]`` (one take per channel:
    several times faster than gathering C-value rows)."""
    out = np.empty((rows.shape[1], flat.size), _F)
    for c in range(rows.shape[1]):
        out[c] = rows[:, c][flat]
    return out


def taps(shape: tuple[int, int], grid: tuple[int, int], flat: np.ndarray) -> np.ndarray:
    """Flat texel indices of a ``shape`` map that bilinear sampling at texels ``flat`` of the
    ``grid`` reads (sorted, unique): what a block-format screen has to encode."""
    h, w = shape
    H, W = grid
    flat = np.asarray(flat, np.int64)
    mark = np.zeros(h * w, bool)
    if (h, w) == (H, W):
        mark[flat] = True
        return np.flatnonzero(mark)
    rows, cols = flat // W, flat % W
    r0, r1, _ = _taps(H, h)
    c0, c1, _ = _taps(W, w)
    for ys in (r0[rows], r1[rows]):
        for xs in (c0[cols], c1[cols]):
            mark[ys * w + xs] = True
    return np.flatnonzero(mark)


def sample_masks_at(masks: np.ndarray, shape: tuple[int, int], flat: np.ndarray) -> np.ndarray:
    """Masks ``[R, h, w]`` sampled at texels ``flat`` of the ``shape`` grid -> ``[R, n]``
    (masks held as integers, a :class:`~wrinklepipe.masks.stack.MaskStack`: a mask at a time,
    each sampled on its own as every channel is)."""
    if isinstance(masks, MaskStack):
        out = np.empty((len(masks), len(flat)), _F)
        for r in range(len(masks)):
            out[r] = sample_at(masks[r], shape, flat)[:, 0]
        return out
    m = np.asarray(masks, _F)
    return np.ascontiguousarray(sample_at(np.moveaxis(m, 0, -1), shape, flat).T)


def planes(v: np.ndarray) -> np.ndarray:
    """``[..., N, C]`` as contiguous planes ``[..., C, N]`` (a view when it already is one).

    The measure works on planes: a gather of one float per texel from a plane is several times
    faster than a gather of C-float rows, and every per-texel step is then a flat array op."""
    t = np.swapaxes(np.asarray(v, _F), -1, -2)
    return t if t.flags.c_contiguous else np.ascontiguousarray(t)
