"""Fidelity: the shipped asset against the full-resolution source, where the wrinkles are.

One measure (DESIGN.md section 8), used by every automatic choice and every check that judges a
loss. For each pose (region weights ``[R, K]``: an expression, or a driver frame) it compares

- the blended normal of the **shipped** data (base, states and masks as decoded from what is
  written, at their own sizes, magnified bilinearly to the source grid as a GPU samples them),
- with the blended normal of the **source** at full resolution,

on the texels where that pose's activation is non-zero (in the source, or in the shipped masks:
a mask that leaks is an error too), weighted by the activation. Per pose and per region it
reports the weighted mean, p99 and max in degrees. The base is measured on its own over the
face (the mesh's UV footprint), unweighted.

Everything is a pure function of arrays (numpy only): :func:`prepare` does the full-resolution
work once (active texels, activations and source normals of every pose); :func:`sample` gathers
shipped maps at those texels; :func:`evaluate` blends and scores. Automatic searches keep the
:class:`Reference` and the samples of what they do not change, so no full-resolution pass is
repeated.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

import numpy as np
from threadpoolctl import ThreadpoolController

from wrinklepipe import model
from wrinklepipe.codec.vectors import EPS
from wrinklepipe.geometry.rasterise import rasterise_triangle_ids
from wrinklepipe.metrics import (
    Budget,
    Stats,
    angle_deg,
    angle_deg_planes,
    weighted_stats,
    weighted_stats_many,
)
from wrinklepipe.reuse import reused

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


# ------------------------------------------------------------------------------------------------
# poses


@dataclass(frozen=True)
class Pose:
    """One set of region weights: ``[R, K]`` (``[R]`` under the ``signed`` policy)."""

    name: str
    weights: np.ndarray


def expression_poses(
    region_names: Sequence[str],
    region_states: np.ndarray,
    expressions: dict[str, dict[str, float]],
    policy: str = "clamp01",
) -> list[Pose]:
    """Every expression of a table at full amount, in name order (regions it does not know are
    skipped). ``region_states`` is the ``[R, K]`` matrix of the states each region drives."""
    names = list(region_names)
    out = []
    for e in sorted(expressions):
        per_region = np.zeros(len(names), _F)
        for r, w in expressions[e].items():
            if r in names:
                per_region[names.index(r)] += _F(w)
        if policy == "signed":
            out.append(Pose(e, per_region))
        else:
            out.append(Pose(e, per_region[:, None] * np.asarray(region_states, _F)))
    return out


# ------------------------------------------------------------------------------------------------
# sampling a map at texels of the source grid, as a GPU does (GL_LINEAR, clamp to edge)


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
    """Masks ``[R, h, w]`` sampled at texels ``flat`` of the ``shape`` grid -> ``[R, n]``."""
    m = np.asarray(masks, _F)
    return np.ascontiguousarray(sample_at(np.moveaxis(m, 0, -1), shape, flat).T)


# ------------------------------------------------------------------------------------------------
# the reference: the full-resolution source, prepared once


@dataclass
class PoseReference:
    """One pose on the source grid: its active texels and what the source shows there."""

    pose: Pose
    sel: np.ndarray  # [n] indices into Reference.union
    act: np.ndarray  # [K, n] source activations
    normal: np.ndarray  # [n, 3] the source's blended normal
    weight: np.ndarray  # [n] activation weight sum_k |a_k|
    masks: np.ndarray  # [R, N] the source masks at Reference.union (one array for every pose)
    active: np.ndarray | None = None  # flat indices of every source-active texel (all of them,
    # also in a coarse reference)
    regions: np.ndarray | None = None  # [G] the regions of ``share`` (None: all of them)
    _share: np.ndarray | None = field(default=None, repr=False, compare=False)
    #: by lattice step: the active texels on that lattice, as flat lattice indices
    _lattice: dict[int, np.ndarray] = field(default_factory=dict, repr=False, compare=False)

    @property
    def share(self) -> np.ndarray:
        """``[G, n]`` each weighted region's part of the activation, ``M_r * max_k |w_rk|``
        (what the per-region stats weigh by): made when first asked for (only the per-region
        tables read it; the searches never do)."""
        if self._share is None:
            rows = np.arange(self.masks.shape[0]) if self.regions is None else self.regions
            w = np.asarray(self.pose.weights, _F)
            per_region = np.abs(w) if w.ndim == 1 else np.abs(w).max(axis=1)
            share = np.empty((rows.size, self.sel.size), _F)
            for g, r in enumerate(rows):
                np.multiply(self.masks[r][self.sel], per_region[r], out=share[g])
            self._share = share
        return self._share


@dataclass
class Reference:
    """The source at full resolution, prepared for many measurements."""

    shape: tuple[int, int]
    encoding: str
    policy: str
    region_names: tuple[str, ...]
    base: np.ndarray  # [H, W, 3] source base (unit)
    union: np.ndarray  # flat indices: texels active in some pose
    poses: list[PoseReference]
    footprint: np.ndarray | None = None  # [H, W] bool: the mesh's UV footprint (the face)
    support: np.ndarray | None = None  # [H, W] bool: source-active in some pose
    step: int = 1  # a coarse reference keeps every step-th active texel (and leak texel)
    #: face_texels' answers by max_texels, with the footprint they were made from
    _faces: dict[int | None, tuple[np.ndarray | None, np.ndarray]] = field(
        default_factory=dict, repr=False, compare=False
    )
    #: per shipped mask samples (by identity, the array kept so its id stays its own): every
    #: pose's activations and their weight (the same for every states candidate judged with
    #: those masks)
    _acts: dict[int, tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    @property
    def texels(self) -> int:
        return int(self.shape[0] * self.shape[1])

    @property
    def active_fraction(self) -> float:
        """Fraction of the grid some pose activates (the wrinkles' share of the UV area)."""
        return float(self.union.size * self.step) / self.texels

    def face_texels(self, max_texels: int | None = None) -> np.ndarray:
        """Flat indices of the footprint's texels (all of them, or whole 4x4 blocks of it, every
        k-th block, so that about ``max_texels`` remain: a block-format screen's sample)."""
        hit = self._faces.get(max_texels)
        if hit is None or hit[0] is not self.footprint:
            hit = self._faces[max_texels] = (self.footprint, self._face_texels(max_texels))
        return hit[1]

    def _face_texels(self, max_texels: int | None) -> np.ndarray:
        H, W = self.shape
        fp = self.footprint if self.footprint is not None else np.ones((H, W), bool)
        fp = np.asarray(fp, bool).reshape(H, W)
        n = int(np.count_nonzero(fp))
        if max_texels is None or n <= max_texels:
            return np.flatnonzero(fp)
        # on the grid of 4x4 blocks (row-major block order): the blocks holding a footprint
        # texel, every k-th of them kept whole
        hb, wb = (H + 3) // 4, (W + 3) // 4
        padded = np.zeros((hb * 4, wb * 4), bool)
        padded[:H, :W] = fp
        present = padded.reshape(hb, 4, wb, 4).any(axis=(1, 3)).reshape(-1)
        k = max(1, -(-int(present.sum()) * 16 // max(int(max_texels), 1)))
        keep = present & ((np.cumsum(present) - 1) % k == 0)
        keep_texels = np.repeat(np.repeat(keep.reshape(hb, wb), 4, axis=0), 4, axis=1)[:H, :W]
        return np.flatnonzero(fp & keep_texels)

    def activations(self, masks: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per pose: :func:`wrinklepipe.model.activations` of shipped mask samples ``[R, n]``
        (at the union texels) on its active texels, and their weight ``sum_k |a_k|``; computed
        once per mask samples."""
        hit = self._acts.get(id(masks))
        if hit is None or hit[0] is not masks:
            acts = []
            for pr in self.poses:
                act = _activations_at(masks, pr.sel, pr.pose.weights, self.policy)
                acts.append((act, _activation_weight(act)))
            hit = self._acts[id(masks)] = (masks, acts)
        return hit[1]

    def coarse(self, max_texels: int) -> Reference:
        """A reference on the active texels of every k-th 4x4 block (whole blocks, so a block
        format screen encodes few blocks), about ``max_texels`` of them; itself when it is
        small enough. What a search screens candidates with."""
        n = int(self.union.size)
        if n <= max_texels:
            return self
        W = self.shape[1]
        bw = (W + 3) // 4
        block = (self.union // W) // 4 * bw + (self.union % W) // 4
        present = np.zeros(((self.shape[0] + 3) // 4) * bw, bool)
        present[block] = True
        rank = (np.cumsum(present) - 1)[block]  # the k-th block holding active texels
        k = max(2, -(-n // max(int(max_texels), 1)))
        keep = np.flatnonzero(rank % k == 0)
        new_pos = np.full(n, -1, np.int64)
        new_pos[keep] = np.arange(keep.size)
        poses = []
        masks: dict[int, np.ndarray] = {}  # the masks at the kept texels, once per array
        for pr in self.poses:
            m = new_pos[pr.sel] >= 0
            if id(pr.masks) not in masks:
                masks[id(pr.masks)] = np.ascontiguousarray(pr.masks[:, keep])
            poses.append(
                PoseReference(
                    pr.pose,
                    new_pos[pr.sel[m]],
                    pr.act[:, m],
                    planes(pr.normal)[:, m].T,
                    pr.weight[m],
                    masks[id(pr.masks)],
                    pr.active,
                    pr.regions,
                    None if pr._share is None else pr._share[:, m],
                )
            )
        return replace(self, union=self.union[keep], poses=poses, step=k * self.step)


def _regions_on(weights: np.ndarray) -> np.ndarray:
    """``[R]`` bool: the regions a pose gives a non-zero weight."""
    w = np.abs(np.asarray(weights, _F))
    return w > 0 if w.ndim == 1 else (w > 0).any(axis=1)


def _activation_weight(act: np.ndarray) -> np.ndarray:
    return np.abs(act).sum(axis=0).astype(_F)


def _weighted(weights: np.ndarray, policy: str) -> np.ndarray:
    """The regions whose masks can change this pose's activations: those it weights (every
    region under ``renormalize``, whose total counts all masks)."""
    on = _regions_on(weights)
    return np.arange(on.size) if policy == "renormalize" else np.flatnonzero(on)


def _activations_at(
    masks: np.ndarray, sel: np.ndarray | None, weights: np.ndarray, policy: str
) -> np.ndarray:
    """:func:`wrinklepipe.model.activations` of masks ``[R, n]`` at positions ``sel`` (None:
    all), reading only the masks the pose weights (a region of weight 0 adds nothing)."""
    rows = _weighted(weights, policy)
    w = np.asarray(weights, _F)
    if sel is None:
        # a run of consecutive regions is a view (no copy of the masks; the same values)
        run = rows.size > 0 and int(rows[-1] - rows[0]) + 1 == rows.size
        m = masks[int(rows[0]) : int(rows[-1]) + 1] if run else masks[rows]
    elif rows.size:
        m = np.stack([masks[r][sel] for r in rows])  # one plane at a time: contiguous gathers
    else:
        m = np.zeros((0, sel.size), _F)
    return model.activations(m, w[rows], policy)


def planes(v: np.ndarray) -> np.ndarray:
    """``[..., N, C]`` as contiguous planes ``[..., C, N]`` (a view when it already is one).

    The measure works on planes: a gather of one float per texel from a plane is several times
    faster than a gather of C-float rows, and every per-texel step is then a flat array op."""
    t = np.swapaxes(np.asarray(v, _F), -1, -2)
    return t if t.flags.c_contiguous else np.ascontiguousarray(t)


def _pd_planes(base: np.ndarray) -> np.ndarray:
    """:func:`wrinklepipe.model.normal_to_pd` of normal planes ``[3, N]`` -> ``[2, N]`` (the
    same float32 operations)."""
    inv_z = np.reciprocal(np.maximum(base[2], EPS))
    return base[:2] * inv_z


def _blend_at(
    base: np.ndarray,
    base_pd: np.ndarray | None,
    states: np.ndarray,
    sel: np.ndarray,
    act: np.ndarray,
    encoding: str,
    unit: bool = True,
) -> np.ndarray:
    """:func:`wrinklepipe.model.combine` at positions ``sel`` under ``act`` ``[K, n]``, of
    normal planes ``base`` ``[3, N]`` and state planes ``states`` ``[K, C, N]`` -> normal planes
    ``[3, n]``. PD: the base's slope planes ``base_pd`` ``[2, N]`` (computed once for every
    pose) plus the activated slopes, summed in combine's order and decoded with
    :func:`~wrinklepipe.model.pd_to_normal`'s operations (the same float32 values); the base
    itself where no state is active. ``unit=False`` (PD only): the directions ``(x, y, 1)``
    left unnormalised, for the angle (:func:`wrinklepipe.metrics.angle_deg_planes` measures
    directions, whatever their length)."""
    if encoding != "pd" or base_pd is None:
        st = np.moveaxis(states[:, :, sel], 1, -1)
        return planes(model.combine(base[:, sel].T, st, act, encoding))
    K = act.shape[0]
    out = np.empty((3, sel.size), _F)
    if K == 0:
        for c in range(3):
            out[c] = base[c][sel]
        return out
    xy = []
    for c in range(2):
        acc = states[0, c][sel]
        acc *= act[0]
        for k in range(1, K):
            term = states[k, c][sel]
            term *= act[k]
            acc += term
        xy.append(np.add(base_pd[c][sel], acc, out=acc))
    x, y = xy
    if unit:
        inv = x * x
        inv += y * y
        inv += _F(1.0)
        np.sqrt(inv, out=inv)
        np.reciprocal(inv, out=inv)
        np.multiply(x, inv, out=out[0])
        np.multiply(y, inv, out=out[1])
        out[2] = inv
    else:
        out[0], out[1], out[2] = x, y, _F(1.0)
    idle = np.flatnonzero(~np.any(act != 0, axis=0))
    if idle.size:
        at = sel[idle]
        for c in range(3):
            out[c, idle] = base[c][at]
    return out


def source_states(base: np.ndarray, states: np.ndarray, encoding: str) -> np.ndarray:
    """Source (float) wrinkled normals ``[K, H, W, 3]`` in the representation
    :func:`wrinklepipe.model.combine` takes under ``encoding`` (``base`` on their grid): PD
    slopes of the wrinkle only, the biased difference, the normals, or the wrinkle-only
    normals (composite)."""
    if encoding == "pd":
        return model.normal_to_pd(states) - model.normal_to_pd(base)[None]
    if encoding == "diff":
        return model.normal_to_diff(states, base[None])
    if encoding == "full":
        return model.normalize(states)
    return model.pd_to_normal(model.normal_to_pd(states) - model.normal_to_pd(base)[None])


@reused  # the search's full-resolution reference is the validator's (fidelity rules)
@one_blas_thread
def prepare(
    base: np.ndarray,
    states: np.ndarray,
    masks: np.ndarray,
    poses: Sequence[Pose],
    region_names: Sequence[str],
    encoding: str = "pd",
    policy: str = "clamp01",
    footprint: np.ndarray | None = None,
) -> Reference:
    """The full-resolution source on its own grid: ``base`` ``[H, W, 3]``, ``states`` in the
    representation :func:`wrinklepipe.model.combine` takes (``[K, H, W, C]``), ``masks``
    ``[R, h, w]`` (magnified to the grid when smaller), the poses and the UV footprint.

    Active texels come from the source masks at full resolution; the source's blended normal
    is computed there once per pose (the one full-resolution pass).
    """
    b = normalize_rows(base)
    st = np.asarray(states, _F)
    H, W = b.shape[:2]
    if st.shape[1:3] != (H, W):
        raise ValueError(f"source states {st.shape[1:3]} and base {(H, W)} differ in size")
    m = np.asarray(masks, _F)
    if m.shape[1:] != (H, W):
        m = sample_masks_at(m, (H, W), np.arange(H * W)).reshape(-1, H, W)
    flat_m = m.reshape(m.shape[0], H * W)
    on = [_regions_on(p.weights) for p in poses]
    used = np.flatnonzero(np.any(on, axis=0)) if on else np.zeros(0, np.int64)
    # texels some weighted region touches: one pass over the masks (then only those texels)
    any_active = np.zeros(H * W, bool)
    for r in used:
        any_active |= flat_m[r] > 0
    union = np.flatnonzero(any_active)
    m_u = flat_m[:, union]
    base_u = planes(b.reshape(H * W, 3)[union])  # [3, N]
    states_u = planes(st.reshape(st.shape[0], H * W, -1)[:, union])  # [K, C, N]
    base_pd = _pd_planes(base_u) if encoding == "pd" else None
    positive = m_u > 0  # [R, N]: where each mask touches, for every pose
    out = []
    for p, o in zip(poses, on):
        rows = np.flatnonzero(o)
        w = np.asarray(p.weights, _F)
        # activations on every union texel (flat ops on the weighted masks), then the texels
        # a weighted region touches where some state is active
        act_u = _activations_at(m_u, None, w, policy)
        weight_u = _activation_weight(act_u)
        touched = np.zeros(union.size, bool)
        for r in rows:  # one mask at a time (no copy of the weighted masks)
            touched |= positive[r]
        sel = np.flatnonzero(touched & (weight_u > 0))
        act = np.take(act_u, sel, axis=1)
        normal = _blend_at(base_u, base_pd, states_u, sel, act, encoding)
        out.append(
            PoseReference(
                pose=p,
                sel=sel,
                act=act,
                normal=normal.T,  # [n, 3], a view of the planes the measure reads
                weight=weight_u[sel],
                masks=m_u,  # the regions' shares are made from it when asked for
                active=union[sel],
                regions=rows,
            )
        )
    fp = None if footprint is None else np.asarray(footprint, bool).reshape(H, W)
    support = np.zeros(H * W, bool)
    for pr in out:
        support[union[pr.sel]] = True
    return Reference(
        shape=(H, W),
        encoding=encoding,
        policy=policy,
        region_names=tuple(region_names),
        base=b,
        union=union,
        poses=out,
        footprint=fp,
        support=support.reshape(H, W),
    )


# ------------------------------------------------------------------------------------------------
# shipped data sampled at the reference's texels


@dataclass
class Samples:
    """Shipped maps gathered at the reference's union texels (any may be None: not given)."""

    base: np.ndarray | None = None  # [n, 3]
    states: np.ndarray | None = None  # [K, n, C]
    masks: np.ndarray | None = None  # [R, n]
    leaks: list[tuple[np.ndarray, np.ndarray] | None] | None = None  # per pose, with masks
    readers: dict[str, Reader] = field(default_factory=dict)  # how raw maps are read
    raw: dict[str, np.ndarray] = field(default_factory=dict)  # the arrays, for leak texels


@one_blas_thread
def sample(
    ref: Reference,
    base: np.ndarray | None = None,
    states: np.ndarray | None = None,
    masks: np.ndarray | None = None,
    support: list[np.ndarray] | None | bool = None,
    states_reader: Reader | None = None,
    base_reader: Reader | None = None,
) -> Samples:
    """Gather shipped maps (at their own sizes) at the reference's active texels.

    ``base`` unit normals ``[hb, wb, 3]`` and ``states`` ``[K, hs, ws, C]`` in combine's
    representation, or what their :class:`Reader` turns into that; ``masks`` ``[R, hm, wm]``
    with ``support`` their :func:`leak_support` (None: computed here; False: these masks
    cannot leak, e.g. they are the source's own).
    """
    s = Samples()
    u = ref.union
    if base is not None:
        s.base = model.normalize(sample_at(base, ref.shape, u, base_reader))
        s.raw["base"] = np.asarray(base)
        s.readers["base"] = base_reader or Reader()
    if states is not None:
        st = np.asarray(states)
        s.states = np.stack([planes(sample_at(x, ref.shape, u, states_reader)) for x in st])
        s.states = np.swapaxes(s.states, 1, 2)  # [K, n, C], a view of the planes
        if ref.encoding in ("full", "composite"):
            s.states = model.normalize(s.states)
        s.raw["states"] = st
        s.readers["states"] = states_reader or Reader()
    if masks is not None:
        m = np.asarray(masks, _F)
        s.masks = sample_masks_at(m, ref.shape, u)
        s.raw["masks"] = m
        if support is not False:
            sup = (
                support
                if support is not None
                else leak_support(m, [p.pose for p in ref.poses], ref.policy)
            )
            s.leaks = [_leak_texels(ref, pr, m, g) for pr, g in zip(ref.poses, sup)]
        else:
            s.leaks = [None] * len(ref.poses)
    return s


def merge(*parts: Samples) -> Samples:
    """Later parts override earlier ones (e.g. cached base + masks, then candidate states)."""
    out = Samples()
    for p in parts:
        for name in ("base", "states", "masks", "leaks"):
            if getattr(p, name) is not None:
                setattr(out, name, getattr(p, name))
        out.raw.update(p.raw)
        out.readers.update(p.readers)  # raw maps and their readers travel together
    return out


# ------------------------------------------------------------------------------------------------
# the measure


@dataclass
class PoseFidelity:
    """One pose: overall and per-region stats, and the leak (shipped-only active texels)."""

    pose: str
    overall: Stats
    regions: dict[str, Stats] = field(default_factory=dict)
    leak_texels: int = 0

    def to_json(self) -> dict[str, Any]:
        return {
            "pose": self.pose,
            **self.overall.to_json(),
            "leak_texels": self.leak_texels,
            "regions": {r: s.to_json() for r, s in self.regions.items()},
        }


@dataclass
class Fidelity:
    """Every pose's fidelity and the base's own over the face."""

    poses: list[PoseFidelity]
    base: Stats | None = None
    active_fraction: float = 0.0
    errors: dict[str, np.ndarray] = field(default_factory=dict)  # pose -> [H, W] (on request)

    @property
    def worst(self) -> PoseFidelity | None:
        return max(self.poses, key=lambda p: (p.overall.p99, p.overall.mean), default=None)

    def worst_p99(self) -> float:
        return max((p.overall.p99 for p in self.poses), default=0.0)

    def worst_mean(self) -> float:
        return max((p.overall.mean for p in self.poses), default=0.0)

    def over(self, budget: Budget) -> list[PoseFidelity]:
        """The poses whose overall stats break ``budget`` (the verdict: :meth:`Budget.ok`)."""
        return [p for p in self.poses if not budget.ok(p.overall)]

    def meets(self, budget: Budget) -> bool:
        """Every pose within ``budget`` by the verdict (:meth:`Budget.ok`, the validator's)."""
        return not self.over(budget)

    def inside(self, budget: Budget) -> bool:
        """Every pose inside ``budget`` unrounded (:meth:`Budget.inside`: what the automatic
        choices require, half a printed unit inside the verdict)."""
        return all(budget.inside(p.overall) for p in self.poses)

    def score(self) -> tuple[float, float]:
        """What a search minimises: worst p99, then worst mean."""
        return self.worst_p99(), self.worst_mean()

    def to_json(self) -> dict[str, Any]:
        return {
            "active_fraction": round(self.active_fraction, 5),
            "base": None if self.base is None else self.base.to_json(),
            "poses": [p.to_json() for p in self.poses],
        }


def leak_support(masks: np.ndarray, poses: Sequence[Pose], policy: str) -> list[np.ndarray]:
    """Per pose, the mask-resolution texels a bilinear lookup can see a non-zero activation
    from (the active texels grown by one): where leaks can be."""
    m = np.asarray(masks, _F)
    out = []
    for p in poses:
        on = np.abs(model.activations(m, p.weights, policy)).sum(axis=0) > 0
        g = on.copy()
        g[1:] |= on[:-1]
        g[:-1] |= on[1:]
        g2 = g.copy()
        g2[:, 1:] |= g[:, :-1]
        g2[:, :-1] |= g[:, 1:]
        out.append(g2)
    return out


def _leak_texels(
    ref: Reference, pr: PoseReference, masks: np.ndarray, support: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Texels outside the source's active set that shipped ``masks`` activate in this pose:
    (flat indices, shipped activations ``[K, n]``), or None. A coarse reference looks on a
    lattice of every ``sqrt(step)``-th row and column (as sparse as its active texels)."""
    if masks.shape[0] == 0 or not support.any():
        return None
    H, W = ref.shape
    hm, wm = masks.shape[1:]
    st = max(1, int(round(np.sqrt(ref.step))))
    rows = np.arange(0, H, st)
    cols = np.arange(0, W, st)
    if H % st == 0 and W % st == 0 and rows.size % hm == 0 and cols.size % wm == 0:
        # the lattice a whole factor of the masks' grid: the support repeated
        cand = np.repeat(np.repeat(support, rows.size // hm, axis=0), cols.size // wm, axis=1)
    else:
        cand = np.ascontiguousarray(  # (a column gather is not C-ordered: flat writes need it)
            support[np.minimum((rows * hm) // H, hm - 1)][:, np.minimum((cols * wm) // W, wm - 1)]
        )
    act_idx = pr.active if pr.active is not None else ref.union[pr.sel]
    if st == 1:
        cand.reshape(-1)[act_idx] = False
    else:  # the active texels on the lattice: the same for every masks candidate, kept
        on = pr._lattice.get(st)
        if on is None:
            ar, ac = act_idx // W, act_idx % W
            on_lattice = (ar % st == 0) & (ac % st == 0)
            on = pr._lattice[st] = (ar[on_lattice] // st) * cols.size + ac[on_lattice] // st
        cand.reshape(-1)[on] = False
    k = np.flatnonzero(cand)
    if k.size == 0:
        return None
    idx = rows[k // cols.size] * W + cols[k % cols.size]
    act = model.activations(sample_masks_at(masks, ref.shape, idx), pr.pose.weights, ref.policy)
    keep = np.abs(act).sum(axis=0) > 0
    if not keep.any():
        return None
    return idx[keep], act[:, keep]


def _leak_normals(ref: Reference, s: Samples) -> tuple[np.ndarray, np.ndarray]:
    """Every pose's leak texels (sorted, unique) and the shipped base and states sampled there
    once: ``(flat indices, base [n, 3], states [K, n, C])``."""
    mark = np.zeros(ref.texels, bool)  # sorted and unique (a mark is cheaper than a sort)
    for lk in s.leaks:
        if lk is not None:
            mark[lk[0]] = True
    idx = np.flatnonzero(mark)
    b = s.raw.get("base")
    base = (
        model.normalize(sample_at(b, ref.shape, idx, s.readers.get("base")))
        if b is not None
        else ref.base.reshape(-1, 3)[idx]
    )
    rd = s.readers.get("states")
    states = np.stack([sample_at(x, ref.shape, idx, rd) for x in s.raw["states"]])
    if ref.encoding in ("full", "composite"):
        states = model.normalize(states)
    return idx, base, states


@one_blas_thread
def evaluate(
    ref: Reference,
    s: Samples,
    regions: bool = True,
    leaks: bool = True,
    base_over_face: bool = False,
    error_maps: bool = False,
) -> Fidelity:
    """Score shipped samples against the reference: per pose (and per region), weighted by
    activation. Missing parts of ``s`` are taken from the source (e.g. only the states
    shipped: their loss alone). ``base_over_face`` also measures the shipped base on its own
    over the footprint (it needs ``s.raw["base"]``)."""
    H, W = ref.shape
    if s.states is None:
        raise ValueError("evaluate needs the shipped states")
    base_u = planes(s.base if s.base is not None else ref.base.reshape(-1, 3)[ref.union])
    base_pd = _pd_planes(base_u) if ref.encoding == "pd" else None
    states = planes(s.states)
    out = []
    maps: dict[str, np.ndarray] = {}
    leak_at = None
    if leaks and s.leaks is not None and any(lk is not None for lk in s.leaks):
        leak_at = _leak_normals(ref, s)
    acts = ref.activations(s.masks) if s.masks is not None else None
    for pi, pr in enumerate(ref.poses):
        act, act_w = acts[pi] if acts is not None else (pr.act, None)
        got = _blend_at(base_u, base_pd, states, pr.sel, act, ref.encoding, unit=False)
        err = angle_deg_planes(got, planes(pr.normal))
        w = np.maximum(pr.weight, act_w if act_w is not None else _activation_weight(act))
        errs, ws = [err], [w]
        n_leak = 0
        leak = s.leaks[pi] if leak_at is not None else None
        if leak is not None:
            idx, lact = leak
            pos = np.searchsorted(leak_at[0], idx)
            shipped = model.combine(leak_at[1][pos], leak_at[2][:, pos], lact, ref.encoding)
            lerr = angle_deg(shipped, ref.base.reshape(-1, 3)[idx])
            errs.append(lerr)
            ws.append(_activation_weight(lact))
            n_leak = int(idx.size)
        overall = weighted_stats(np.concatenate(errs), np.concatenate(ws))
        per_region: dict[str, Stats] = {}
        if regions:
            # the regions that touch the pose's texels (shares are >= 0: a region's stats
            # are empty where it has no positive share)
            names = np.arange(len(ref.region_names)) if pr.regions is None else pr.regions
            for r, st in zip(names, weighted_stats_many(err, pr.share)):
                if st.texels:
                    per_region[ref.region_names[r]] = st
        out.append(PoseFidelity(pr.pose.name, overall, per_region, n_leak))
        if error_maps:
            emap = np.zeros(H * W, _F)
            emap[ref.union[pr.sel]] = err
            if leak is not None:
                emap[leak[0]] = lerr
            maps[pr.pose.name] = emap.reshape(H, W)
    fid = Fidelity(out, None, ref.active_fraction, maps)
    if base_over_face and "base" in s.raw:
        fid.base = base_fidelity(ref, s.raw["base"])
    return fid


@one_blas_thread
def base_fidelity(
    ref: Reference,
    base: np.ndarray,
    flat: np.ndarray | None = None,
    reader: Reader | None = None,
) -> Stats:
    """The shipped base (unit normals, or what ``reader`` makes of its texels; any size)
    against the source base over the footprint (or at the grid texels ``flat``)."""
    src = ref.base.reshape(-1, 3)
    same_grid = np.asarray(base).shape[:2] == ref.shape
    if flat is None and same_grid:
        # the whole footprint, a band of rows at a time (its texels in the same order as
        # face_texels gives them, without the array of all of them)
        H, W = ref.shape
        fp = ref.footprint if ref.footprint is not None else np.ones((H, W), bool)
        bands = [
            np.flatnonzero(fp[sl]) + sl.start * W
            for sl in chunks(H, max(1, CHUNK_TEXELS // max(W, 1)))
        ]
    else:
        flat = np.asarray(ref.face_texels() if flat is None else flat, np.int64)
        # in chunks of texels (module CHUNK_TEXELS: the same per-texel values, small
        # temporaries); a smaller map is sampled whole-row-first once (sample_at's separable
        # path) when the texels are many, so it is chunked only on the same grid
        bands = [flat[sl] for sl in chunks(flat.size)] if same_grid else [flat]
    err = np.empty(sum(f.size for f in bands), _F)
    at = 0
    for f in bands:
        got = planes(model.normalize(sample_at(base, ref.shape, f, reader)))
        err[at : at + f.size] = angle_deg_planes(got, _gather_planes(src, f))
        at += f.size
    return weighted_stats(err, overwrite=True)


def measure(
    ref: Reference,
    base: np.ndarray | None,
    states: np.ndarray,
    masks: np.ndarray | None,
    regions: bool = True,
    error_maps: bool = False,
) -> Fidelity:
    """The whole measure in one call: sample the decoded shipped maps and evaluate."""
    s = sample(ref, base, states, masks)
    return evaluate(ref, s, regions=regions, base_over_face=base is not None, error_maps=error_maps)


def footprint(uvs: np.ndarray, indices: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The mesh's UV footprint on an ``shape`` grid (texel centres inside a UV triangle)."""
    H, W = shape
    if H != W:
        raise ValueError("footprint needs a square grid")
    tri = np.asarray(uvs, np.float64)[np.asarray(indices, np.int64)]  # [T, 3, 2]
    # Repeat wrapping, as samplers do by default, per triangle (not per vertex: a vertex on
    # u = 1 wrapped alone would stretch its triangle over the whole texture): each triangle
    # moves whole into the tile of its centroid, and one that crosses a tile edge is also
    # drawn shifted by a tile, so the texels it covers beyond that edge count where they wrap.
    tri = tri - np.floor(tri.mean(axis=1, keepdims=True))
    lo, hi = tri.min(axis=1), tri.max(axis=1)  # [T, 2]
    copies = []
    for du in (-1.0, 0.0, 1.0):
        for dv in (-1.0, 0.0, 1.0):
            shift = np.array([du, dv])
            keep = np.all((lo + shift < 1.0) & (hi + shift > 0.0), axis=1)
            copies.append(tri[keep] + shift)
    drawn = np.concatenate(copies)
    ids = np.arange(3 * len(drawn), dtype=np.int64).reshape(-1, 3)
    return rasterise_triangle_ids(drawn.reshape(-1, 2), ids, H) >= 0


def describe(fid: Fidelity, budget: Budget | None = None) -> list[str]:
    """The fidelity table as text lines: one line per pose, worst first."""
    lines = ["pose            mean    p99     max   (degrees, inside the active region)"]
    for p in sorted(fid.poses, key=lambda p: -p.overall.p99):
        o = p.overall
        flag = "" if budget is None or budget.ok(o) else "  over budget"
        lines.append(f"{p.pose:<14} {o.mean:6.2f} {o.p99:6.2f} {o.max:7.2f}{flag}")
    if fid.base is not None:
        b = fid.base
        lines.append(f"{'base (face)':<14} {b.mean:6.2f} {b.p99:6.2f} {b.max:7.2f}")
    return lines
