"""The full-resolution side of the measure (:mod:`wrinklepipe.fidelity.metric`): the poses,
and :func:`prepare`, which finds each pose's active texels, their activations and the source's
blended normals once, as a :class:`Reference` the searches keep."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from wrinklepipe import model
from wrinklepipe.codec.vectors import EPS
from wrinklepipe.fidelity.sampling import (
    normalize_rows,
    one_blas_thread,
    planes,
    sample_masks_at,
)
from wrinklepipe.geometry.rasterise import triangle_ids
from wrinklepipe.masks.stack import MaskStack
from wrinklepipe.normals.held import rows_of, texels_at
from wrinklepipe.reuse import reused
from wrinklepipe.workset import band_rows

_F = np.float32


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
    base: np.ndarray  # [H, W, 3] source base (unit: a UnitRows of the base prepare was given)
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
    normals (composite).

    Made band by band of rows (every step is per texel: the whole image's values), so the
    temporaries are a band's (:func:`wrinklepipe.workset.band_rows`), not several copies of
    every state at full size."""
    st = np.asarray(states)
    if st.ndim != 4:
        return _source_states(base, states, encoding)
    K, H, W = st.shape[:3]
    rows = band_rows(W, SOURCE_BYTES_PER_TEXEL * max(K, 1))
    if H <= rows:
        return _source_states(base, st, encoding)
    out: np.ndarray | None = None
    for r0 in range(0, H, rows):
        band = _source_states(base[r0 : r0 + rows], st[:, r0 : r0 + rows], encoding)
        if out is None:
            out = np.empty((K, H, *band.shape[2:]), band.dtype)
        out[:, r0 : r0 + rows] = band
    assert out is not None
    return out


#: Bytes of temporaries per texel and state while encoding source states (float32 slopes,
#: normals and their differences).
SOURCE_BYTES_PER_TEXEL = 40


def _source_states(base: np.ndarray, states: np.ndarray, encoding: str) -> np.ndarray:
    if encoding == "pd":
        return model.normal_to_pd(states) - model.normal_to_pd(base)[None]
    if encoding == "diff":
        return model.normal_to_diff(states, base[None])
    if encoding == "full":
        return model.normalize(states)
    return model.pd_to_normal(model.normal_to_pd(states) - model.normal_to_pd(base)[None])


class UnitRows:
    """Vectors ``[..., 3]`` seen as their unit vectors (:func:`normalize_rows` of them),
    normalised where they are read: ``rows.reshape(-1, 3)[idx]`` is ``model.normalize`` of
    those vectors, the same bits as the whole map normalised (each vector on its own). Holds the
    vectors it is given (the caller's map, held for the run), not a normalised copy of the map
    (192 MiB at 4096²); ``np.asarray`` of it normalises the whole map."""

    def __init__(self, vectors: np.ndarray) -> None:
        self.v = rows_of(vectors)  # normals held as integers stay so (decoded where read)

    shape = property(lambda self: self.v.shape)
    ndim = property(lambda self: self.v.ndim)
    dtype = property(lambda self: np.dtype(_F))

    def reshape(self, *shape: int) -> UnitRows:
        return UnitRows(self.v.reshape(*shape))

    def __getitem__(self, key: object) -> np.ndarray:
        if isinstance(key, tuple) and len(key) >= self.v.ndim:
            raise IndexError("UnitRows: index whole vectors (the last axis is normalised)")
        return model.normalize(self.v[key])

    def __array__(self, dtype: object = None, copy: bool | None = None) -> np.ndarray:
        a = normalize_rows(self.v)
        return a if dtype is None else a.astype(dtype, copy=False)

    def __deepcopy__(self, memo: dict[int, object]) -> UnitRows:
        return self  # never changed: its vectors are the caller's


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
    is computed there once per pose (the one full-resolution pass). The reference's ``base`` is
    ``base`` seen as unit vectors (:class:`UnitRows`: no normalised copy of the map); the rest
    is the run's memo's, shared by every caller with the same source (the searches', the
    validator's).
    """
    ref = _prepare(base, states, masks, poses, region_names, encoding, policy, footprint)
    return replace(ref, base=UnitRows(base))


@reused  # the search's full-resolution reference is the validator's (fidelity rules)
@one_blas_thread
def _prepare(
    base: np.ndarray,
    states: np.ndarray,
    masks: np.ndarray,
    poses: Sequence[Pose],
    region_names: Sequence[str],
    encoding: str = "pd",
    policy: str = "clamp01",
    footprint: np.ndarray | None = None,
) -> Reference:
    """:func:`prepare` without its ``base`` (None: :func:`prepare` sets it, so the memo keeps
    no map the caller holds)."""
    b = rows_of(base)
    # a level made where it is read (fidelity.level.PdLevel) is gathered at the union only
    st = states if hasattr(states, "at") else rows_of(states)
    H, W = b.shape[:2]
    if st.shape[1:3] != (H, W):
        raise ValueError(f"source states {st.shape[1:3]} and base {(H, W)} differ in size")
    m = masks if isinstance(masks, MaskStack) else np.asarray(masks, _F)
    if m.shape[1:] != (H, W):
        m = sample_masks_at(np.asarray(m, _F), (H, W), np.arange(H * W)).reshape(-1, H, W)
    on = [_regions_on(p.weights) for p in poses]
    used = np.flatnonzero(np.any(on, axis=0)) if on else np.zeros(0, np.int64)
    # texels some weighted region touches: one pass over the masks (then only those texels),
    # a mask at a time (a MaskStack's masks as float32 one by one, never all at once)
    any_active = np.zeros(H * W, bool)
    for r in used:
        any_active |= np.asarray(m[r]).reshape(H * W) > 0
    union = np.flatnonzero(any_active)
    m_u = np.empty((m.shape[0], union.size), _F)
    for r in range(m.shape[0]):
        m_u[r] = np.asarray(m[r]).reshape(H * W)[union]
    base_u = planes(model.normalize(texels_at(b, union)))  # [3, N] unit
    at_u = st.at(union) if hasattr(st, "at") else texels_at(st, union)
    states_u = planes(at_u)  # [K, C, N]
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
        base=None,  # type: ignore[arg-type]  # prepare's caller's base, as UnitRows
        union=union,
        poses=out,
        footprint=fp,
        support=support.reshape(H, W),
    )


def footprint(uvs: np.ndarray, indices: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """The mesh's UV footprint on an ``shape`` grid (texel centres inside a UV triangle)."""
    H, W = shape
    if H != W:
        raise ValueError("footprint needs a square grid")
    return _footprint(np.asarray(uvs, np.float64)[np.asarray(indices, np.int64)], H)


@reused  # the search's UV footprint and the validator's (fidelity rules) are the same
def _footprint(tri: np.ndarray, size: int) -> np.ndarray:
    """:func:`footprint` of the UV triangles ``tri`` [T, 3, 2] (float64) on a ``size`` grid;
    the memo keeps this flag map (1 byte a texel), not the triangle ids it is made from."""
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
    return triangle_ids(drawn.reshape(-1, 2), ids, size) >= 0
