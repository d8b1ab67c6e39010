"""Resample wrinkle maps and masks with a proper filter (OpenImageIO's filters), mip chains, and
what a reduction costs in degrees.

- :func:`resize` is OpenImageIO's ``ImageBufAlgo.resize`` computed separably: its filters are
  separable and it normalises the weights per axis, so the image is filtered along the rows,
  then the columns, with OpenImageIO's own per-axis weights (read once per size pair and filter
  from its resize of unit impulses, edge clamping included). Equal to OpenImageIO's result to
  float rounding (its 2-D loop sums 13 x 13 taps per texel for lanczos3 at half size; this
  sums 13 + 13), about ten times faster at 2048^2. Odd x magnifications (a reduced ratio
  with a denominator over 64) use OpenImageIO's resize as it is.
- PD slopes are linear in the height field, so they are filtered as they are (``space="pd"``);
  unit normals are filtered then renormalised (``space="normal"``).
- Masks are filtered and clipped to [0, 1].
- :func:`reduction_error` measures the cost of storing wrinkle states at a smaller size: the
  blended result at full resolution from the full-size states against the same blend from the
  reduced states magnified back (bilinear, as a GPU samples), at representative weights.
- :func:`auto_size` returns the smallest power-of-two size whose error is within budget.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterator, Sequence

import numpy as np
import OpenImageIO as oiio
from scipy import sparse

from wrinklepipe.metrics import Budget, Stats
from wrinklepipe.model import blend, normal_to_pd, normalize, pd_to_normal
from wrinklepipe.normals.compress import angular_error_stats
from wrinklepipe.normals.held import rows_of
from wrinklepipe.reuse import reused
from wrinklepipe.workset import band_rows, map_rows

_F = np.float32

#: Default minification filter (OpenImageIO name).
DEFAULT_FILTER = "lanczos3"


@reused  # the same resample asked again in one conversion is computed once
def resize(
    values: np.ndarray, size: tuple[int, int] | int, filter: str = DEFAULT_FILTER
) -> np.ndarray:
    """Resize [H, W] or [H, W, C] float values to ``size`` = (h, w) (or a square side).

    OpenImageIO's ``ImageBufAlgo.resize`` with the named filter (lanczos3, blackman-harris,
    triangle, box, ...); magnification uses the same filter. Returns float32 [h, w(, C)].
    """
    a = np.asarray(values, dtype=_F)
    squeeze = a.ndim == 2
    if squeeze:
        a = a[..., None]
    h, w = (size, size) if isinstance(size, int) else size
    if h <= 0 or w <= 0:
        raise ValueError(f"invalid target size {w} x {h}")
    if (h, w) == a.shape[:2]:
        out = a.copy()
    else:
        H, W, C = a.shape
        x_ratio = _magnification(W, w)
        if x_ratio is None:  # an odd magnification: OpenImageIO's own 2-D loop
            out = oiio_resize(a, h, w, filter)
        else:
            rows = axis_weights(H, h, filter, 0, x_ratio)
            cols = axis_weights(W, w, filter, 1)
            t = (rows @ a.reshape(H, W * C)).reshape(h, W, C)  # along the columns (y) ...
            t = cols @ np.ascontiguousarray(t.transpose(1, 0, 2)).reshape(W, h * C)  # ... x
            out = np.ascontiguousarray(t.reshape(w, h, C).transpose(1, 0, 2), dtype=_F)
    return out[..., 0] if squeeze else out


#: Bytes of temporaries a :func:`resize_bands` reader may make per source texel (a codec's
#: decode of stored texels to unit normals: float32 components, lengths and quotients).
READ_BYTES_PER_TEXEL = 48


def resize_bands(
    read: Callable[[slice], np.ndarray],
    shape: tuple[int, int, int],
    size: tuple[int, int],
    filter: str = DEFAULT_FILTER,
    rows: int | None = None,
) -> Iterator[tuple[slice, np.ndarray]]:
    """:func:`resize` of an image ``shape`` = (H, W, C) that is never whole: ``read(rows)``
    gives the float32 source rows ``[rows, W, C]`` it is asked for. Yields ``(output rows,
    values)`` band by band of at most ``rows`` output rows (default: a band of
    :func:`wrinklepipe.workset.band_rows`), each band the rows :func:`resize` of the whole
    image gives, bit for bit: every output texel is the same sum of the same weighted source
    texels in the same order (the y weights of a band are its rows of the whole image's, taken
    over the source rows they reach; the x pass is per row). A size that needs OpenImageIO's
    own 2-D loop (an odd x magnification) is resized whole."""
    H, W, C = shape
    h, w = size
    x_ratio = _magnification(W, w)
    if x_ratio is None or (h, w) == (H, W):
        whole = resize(read(slice(0, H)), (h, w), filter)
        yield slice(0, h), whole.reshape(h, w, C)
        return
    ys = axis_weights(H, h, filter, 0, x_ratio)
    cols = axis_weights(W, w, filter, 1)
    # a band's bytes: its output rows' float64 sums and the source rows they read, with what
    # the reader makes to give them (a codec decode of normals: its float32 temporaries)
    per = 8 * C + (READ_BYTES_PER_TEXEL + 4 * C) * max(1, -(-H // max(h, 1)))
    step = max(1, rows if rows is not None else band_rows(W, per))
    for r0 in range(0, h, step):
        r1 = min(h, r0 + step)
        part = ys[r0:r1]
        s0, s1 = (int(part.indices.min()), int(part.indices.max()) + 1) if part.nnz else (0, 1)
        src = np.asarray(read(slice(s0, s1)), dtype=_F)
        t = (part[:, s0:s1] @ src.reshape(s1 - s0, W * C)).reshape(r1 - r0, W, C)
        t = cols @ np.ascontiguousarray(t.transpose(1, 0, 2)).reshape(W, (r1 - r0) * C)
        yield (
            slice(r0, r1),
            np.ascontiguousarray(t.reshape(w, r1 - r0, C).transpose(1, 0, 2), dtype=_F),
        )


def oiio_resize(a: np.ndarray, h: int, w: int, filter: str = DEFAULT_FILTER) -> np.ndarray:
    """OpenImageIO's ``ImageBufAlgo.resize`` of float ``[H, W, C]`` to ``h`` x ``w`` as it is
    (the reference :func:`resize` equals; it reads its weights from it)."""
    src = oiio.ImageBuf(np.ascontiguousarray(a, dtype=_F))
    roi = oiio.ROI(0, w, 0, h, 0, 1, 0, a.shape[2])
    dst = oiio.ImageBufAlgo.resize(src, filtername=filter, roi=roi)
    if dst.has_error:
        raise ValueError(f"resize failed: {dst.geterror()}")
    return np.asarray(dst.get_pixels(oiio.FLOAT), dtype=_F).reshape(h, w, a.shape[2])


#: Impulses per OpenImageIO call when reading the weights (channels of a one-row image).
_IMPULSES = 512
#: Largest denominator of an x magnification read with a small image (others: OpenImageIO).
_MAX_DENOMINATOR = 64


def _magnification(n_in: int, n_out: int) -> tuple[int, int] | None:
    """What OpenImageIO's y weights depend on along x: ``(1, 1)`` unless x is magnified, else
    the ratio as the smallest ``(n_out, n_in)`` with the same value (None past
    :data:`_MAX_DENOMINATOR`)."""
    if n_out <= n_in:
        return (1, 1)
    g = math.gcd(n_out, n_in)
    p, q = n_out // g, n_in // g
    return (p, q) if q <= _MAX_DENOMINATOR else None


@functools.lru_cache(maxsize=64)
def axis_weights(
    n_in: int,
    n_out: int,
    filter: str = DEFAULT_FILTER,
    axis: int = 1,
    x_ratio: tuple[int, int] = (1, 1),
) -> sparse.csr_matrix:
    """OpenImageIO's resize weights along one axis (0: y, the rows; 1: x, the columns),
    ``[n_out, n_in]`` (sparse): row ``o`` holds what each source sample contributes to output
    sample ``o`` (normalised, samples past the edge clamped onto it).

    Read from OpenImageIO itself: an image constant along the other axis whose channel ``k`` is
    a unit impulse at sample ``k``, resized along the axis, gives column ``k`` of the matrix
    (the other axis's weights sum to 1). OpenImageIO sizes the y taps from the x filter's
    width, which grows with an x magnification, so y weights are read with the resize's x
    ``x_ratio`` (``(n_out, n_in)`` of x, reduced; ``(1, 1)`` when x is not magnified): without
    it, magnifying 2 -> 3 rows with lanczos3 would weigh the middle row 0.5 / 0.5 where
    OpenImageIO weighs it 0.487 / 0.513."""
    if n_in <= 0 or n_out <= 0:
        raise ValueError(f"invalid resize {n_in} -> {n_out}")
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (y) or 1 (x), got {axis}")
    blocks = []
    for k0 in range(0, n_in, _IMPULSES):
        k = min(_IMPULSES, n_in - k0)
        impulses = np.zeros((n_in, k), _F)
        impulses[k0 + np.arange(k), np.arange(k)] = 1.0
        if axis == 0:
            p, q = x_ratio
            img = np.repeat(impulses[:, None, :], q, axis=1)
            out = oiio_resize(img, n_out, p, filter)[:, 0]
        else:
            out = oiio_resize(impulses[None], 1, n_out, filter)[0]
        blocks.append(sparse.csr_matrix(out))
    return sparse.hstack(blocks, format="csr")


#: Bytes of temporaries per texel while making PD slopes of normals (1 / z, its clamp, x/z, y/z).
PD_BYTES_PER_TEXEL = 16


def resize_normals(
    normals: np.ndarray,
    size: tuple[int, int] | int,
    space: str = "pd",
    filter: str = DEFAULT_FILTER,
) -> np.ndarray:
    """Resize unit normals [H, W, 3]: filter PD slopes (linear) or the vectors, renormalise."""
    n = rows_of(normals)  # normals held as integers: their slopes made a band at a time
    if space == "pd":  # the slopes band by band (per texel: the same values, a band's temporaries)
        return pd_to_normal(resize(map_rows(normal_to_pd, n, PD_BYTES_PER_TEXEL), size, filter))
    if space == "normal":
        return normalize(resize(n, size, filter))
    raise ValueError(f"space must be 'pd' or 'normal', got {space!r}")


def resize_slopes(
    slopes: np.ndarray, size: tuple[int, int] | int, filter: str = DEFAULT_FILTER
) -> np.ndarray:
    """Resize PD slopes [H, W, 2] (linear, so no renormalisation)."""
    return resize(slopes, size, filter)


def resize_masks(
    masks: np.ndarray, size: tuple[int, int] | int, filter: str = DEFAULT_FILTER
) -> np.ndarray:
    """Resize masks [R, H, W] (channels-first) and clip to [0, 1]."""
    m = np.asarray(masks, dtype=_F)
    out = resize(np.moveaxis(m, 0, -1), size, filter)
    if out.ndim == 2:
        out = out[..., None]
    return np.clip(np.moveaxis(out, -1, 0), 0.0, 1.0)


def mip_chain(values: np.ndarray, min_size: int = 1, filter: str = "box") -> list[np.ndarray]:
    """Level 0 (the input) and every halving down to ``min_size`` (box filter by default).

    For PD maps pass slopes (filtering is linear there); for unit normals renormalise each
    level afterwards (:func:`normal_mips`).
    """
    a = np.asarray(values, dtype=_F)
    levels = [a]
    h, w = a.shape[:2]
    while max(h, w) > min_size and (h > 1 or w > 1):
        h, w = max(1, h // 2), max(1, w // 2)
        levels.append(resize(levels[-1], (h, w), filter))
    return levels


def normal_mips(normals: np.ndarray, min_size: int = 1) -> list[np.ndarray]:
    """Mip chain of unit normals filtered in PD space (linear) and decoded per level."""
    return [pd_to_normal(s) for s in mip_chain(normal_to_pd(np.asarray(normals, _F)), min_size)]


def reduction_error(
    base: np.ndarray,
    states_pd: np.ndarray,
    masks: np.ndarray,
    weights: Sequence[np.ndarray],
    size: int,
    policy: str = "clamp01",
    filter: str = DEFAULT_FILTER,
) -> Stats:
    """Angular error of the blended face when the PD states are stored at ``size`` x ``size``.

    base [H, W, 3] unit normals, states_pd [K, H, W, 2] PD slopes, masks [R, H, W], weights a
    list of [R, K] matrices (representative expressions). The states are reduced with
    ``filter`` and magnified back with a bilinear (triangle) filter; the worst texels over all
    weights are pooled into one :class:`Stats`.
    """

    st = np.asarray(states_pd, dtype=_F)
    k, h, w = st.shape[:3]
    back = np.stack([resize(resize(st[i], size, filter), (h, w), "triangle") for i in range(k)])
    errs = []
    for wt in weights:
        ref = blend(base, st, masks, wt, "pd", policy)
        got = blend(base, back, masks, wt, "pd", policy)
        errs.append((ref, got))
    ref = np.concatenate([e[0] for e in errs])
    got = np.concatenate([e[1] for e in errs])
    return angular_error_stats(got, ref)


def auto_size(
    base: np.ndarray,
    states_pd: np.ndarray,
    masks: np.ndarray,
    weights: Sequence[np.ndarray],
    budget: Budget,
    min_size: int = 16,
    policy: str = "clamp01",
) -> tuple[int, dict[int, Stats]]:
    """The smallest power-of-two size (>= ``min_size``) whose reduction error meets ``budget``.

    Returns ``(size, {size: Stats})`` for every size tried (full size always fits).
    """
    full = int(np.asarray(states_pd).shape[1])
    tried: dict[int, Stats] = {}
    sizes = []
    s = full
    while s >= min_size:
        sizes.append(s)
        s //= 2
    best = full
    for s in sorted(sizes):  # smallest first; stop at the first that fits
        e = reduction_error(base, states_pd, masks, weights, s, policy)
        tried[s] = e
        if budget.inside(e):
            best = s
            break
    return best, tried
