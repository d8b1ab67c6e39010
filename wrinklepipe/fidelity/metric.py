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

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe import model
from wrinklepipe.fidelity.reference import (
    Pose,
    PoseReference,
    Reference,
    _activation_weight,
    _blend_at,
    _pd_planes,
)
from wrinklepipe.fidelity.sampling import (
    CHUNK_TEXELS,
    Reader,
    chunks,
    one_blas_thread,
    planes,
    sample_at,
    sample_masks_at,
)
from wrinklepipe.masks.stack import float_masks
from wrinklepipe.metrics import (
    Budget,
    Stats,
    angle_deg,
    angle_deg_planes,
    weighted_stats,
    weighted_stats_many,
)

_F = np.float32
#: The key of the base's own errors over the face in :attr:`Fidelity.samples`.
BASE_SAMPLES = "(base over the face)"


# ------------------------------------------------------------------------------------------------
# poses


# ------------------------------------------------------------------------------------------------
# sampling a map at texels of the source grid, as a GPU does (GL_LINEAR, clamp to edge)


# ------------------------------------------------------------------------------------------------
# the reference: the full-resolution source, prepared once


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
        st = states if hasattr(states, "at") else np.asarray(states)  # a PdLevel: gathered
        s.states = np.stack([planes(sample_at(x, ref.shape, u, states_reader)) for x in st])
        s.states = np.swapaxes(s.states, 1, 2)  # [K, n, C], a view of the planes
        if ref.encoding in ("full", "composite"):
            s.states = model.normalize(s.states)
        s.raw["states"] = st
        s.readers["states"] = states_reader or Reader()
    if masks is not None:
        m = float_masks(masks)  # masks held as integers stay so (sampled a mask at a time)
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


@dataclass(frozen=True)
class TexelErrors:
    """A pose's error map on the source grid as the texels the measure judges (its active
    texels and its leaks): their flat indices, sorted, and their errors; every other texel of
    the ``shape`` grid is 0. The map without the grid: a few percent of it on a face, not a
    float per texel of the UV square (384 MiB for six poses at 4096²)."""

    shape: tuple[int, int]
    flat: np.ndarray  # [n] int64, sorted, unique
    values: np.ndarray  # [n] float32

    @classmethod
    def of(
        cls, shape: tuple[int, int], parts: Sequence[tuple[np.ndarray, np.ndarray]]
    ) -> TexelErrors:
        """The map that writing each part's ``(flat, values)`` in turn onto a grid of zeros
        makes (a texel written twice keeps the later value)."""
        idx = np.concatenate([np.asarray(f, np.int64) for f, _ in parts])
        val = np.concatenate([np.asarray(v, _F) for _, v in parts])
        order = np.argsort(idx, kind="stable")  # equal indices keep their order
        idx, val = idx[order], val[order]
        last = np.ones(idx.size, bool)
        last[:-1] = idx[1:] != idx[:-1]
        return cls((int(shape[0]), int(shape[1])), idx[last], val[last])

    def at(self, flat: np.ndarray) -> np.ndarray:
        """The map's values at grid texels ``flat`` (0 where nothing was judged)."""
        flat = np.asarray(flat, np.int64)
        out = np.zeros(flat.shape, _F)
        if self.flat.size == 0:
            return out
        pos = np.minimum(np.searchsorted(self.flat, flat), self.flat.size - 1)
        hit = self.flat[pos] == flat
        out[hit] = self.values[pos[hit]]
        return out

    def dense(self) -> np.ndarray:
        """The whole ``[H, W]`` map."""
        out = np.zeros(self.shape[0] * self.shape[1], _F)
        out[self.flat] = self.values
        return out.reshape(self.shape)


@dataclass
class Fidelity:
    """Every pose's fidelity and the base's own over the face."""

    poses: list[PoseFidelity]
    base: Stats | None = None
    active_fraction: float = 0.0
    #: pose -> its error map as judged texels (on request: ``evaluate(error_maps=True)``)
    errors: dict[str, TexelErrors] = field(default_factory=dict)
    #: on request (``evaluate(samples=True)``): per pose its texels' errors and weights, and
    #: under :data:`BASE_SAMPLES` the base's over the face (weights None: unweighted), to pool the
    #: stats of several grids (UDIM tiles: :func:`pooled`)
    samples: dict[str, tuple[np.ndarray, np.ndarray | None]] = field(default_factory=dict)
    step: int = 1  # the reference's: each sampled texel stands for ``step`` texels

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
    samples: bool = False,
) -> Fidelity:
    """Score shipped samples against the reference: per pose (and per region), weighted by
    activation. Missing parts of ``s`` are taken from the source (e.g. only the states
    shipped: their loss alone). ``base_over_face`` also measures the shipped base on its own
    over the footprint (it needs ``s.raw["base"]``). ``samples``: keep every pose's errors
    and weights (:attr:`Fidelity.samples`)."""
    H, W = ref.shape
    if s.states is None:
        raise ValueError("evaluate needs the shipped states")
    base_u = planes(s.base if s.base is not None else ref.base.reshape(-1, 3)[ref.union])
    base_pd = _pd_planes(base_u) if ref.encoding == "pd" else None
    states = planes(s.states)
    out = []
    maps: dict[str, TexelErrors] = {}
    kept: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}
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
        if samples:
            kept[pr.pose.name] = (np.concatenate(errs), np.concatenate(ws))
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
            parts = [(ref.union[pr.sel], err)]
            if leak is not None:
                parts.append((leak[0], lerr))
            maps[pr.pose.name] = TexelErrors.of((H, W), parts)
    fid = Fidelity(out, None, ref.active_fraction, maps, kept, ref.step)
    if base_over_face and "base" in s.raw:
        base_err: list[np.ndarray] | None = [] if samples else None
        fid.base = base_fidelity(ref, s.raw["base"], reader=s.readers.get("base"), errors=base_err)
        if base_err:
            kept[BASE_SAMPLES] = (base_err[0], None)
    return fid


@one_blas_thread
def base_fidelity(
    ref: Reference,
    base: np.ndarray,
    flat: np.ndarray | None = None,
    reader: Reader | None = None,
    errors: list[np.ndarray] | None = None,
) -> Stats:
    """The shipped base (unit normals, or what ``reader`` makes of its texels; any size)
    against the source base over the footprint (or at the grid texels ``flat``); ``errors``:
    a list the per-texel errors are appended to (then kept, not overwritten)."""
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
        err[at : at + f.size] = angle_deg_planes(got, planes(src[f]))
        at += f.size
    if errors is not None:
        errors.append(err)
        return weighted_stats(err)
    return weighted_stats(err, overwrite=True)


def pooled(parts: Sequence[tuple[Fidelity, float]]) -> Fidelity:
    """Several grids' fidelity as one (UDIM tiles over the whole face): per pose, every
    part's texels pooled, each weighted by its activation times ``area`` (what one texel of
    its grid covers: ``1 / (H W)`` of a tile) times the part's ``step``; the base over the
    face likewise by area. The parts must have kept their samples (``evaluate(samples=
    True)``); a pose some part lacks is pooled over the parts that have it. No per-region
    stats (they are each part's)."""
    names: list[str] = []
    for fid, _ in parts:
        names += [p.pose for p in fid.poses if p.pose not in names]
    poses = []
    for name in names:
        errs, ws = [], []
        leaks = 0
        for fid, area in parts:
            got = fid.samples.get(name)
            if got is None:
                continue
            e, w = got
            errs.append(e)
            ws.append(np.asarray(w, np.float64) * (area * fid.step))
            leaks += next(p.leak_texels for p in fid.poses if p.pose == name)
        if errs:
            stats = weighted_stats(np.concatenate(errs), np.concatenate(ws))
            poses.append(PoseFidelity(name, stats, {}, leaks))
    out = Fidelity(poses)
    base = [
        (fid.samples[BASE_SAMPLES][0], area) for fid, area in parts if BASE_SAMPLES in fid.samples
    ]
    if base:
        out.base = weighted_stats(
            np.concatenate([e for e, _ in base]),
            np.concatenate([np.full(e.size, a) for e, a in base]),
        )
    total = sum(area for _, area in parts)
    if total > 0:
        out.active_fraction = sum(f.active_fraction * a for f, a in parts) / total
    return out


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
