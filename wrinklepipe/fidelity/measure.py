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
from wrinklepipe.fidelity.stats import Budget, Stats, weighted_stats
from wrinklepipe.geometry.rasterise import rasterise_triangle_ids
from wrinklepipe.normals.compress import angle_deg

_F = np.float32


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


def sample_at(img: np.ndarray, shape: tuple[int, int], flat: np.ndarray) -> np.ndarray:
    """``img`` ``[h, w, C]`` sampled at texels ``flat`` (flat indices) of a ``shape`` grid
    -> ``[n, C]`` float32.

    Bilinear between texel centres with clamp to edge, the way the render pass samples; on the
    same grid it is a plain gather.
    """
    a = np.asarray(img, _F)
    if a.ndim == 2:
        a = a[..., None]
    h, w = a.shape[:2]
    H, W = shape
    flat = np.asarray(flat, np.int64)
    rows, cols = flat // W, flat % W
    src = a.reshape(h * w, -1)
    if (h, w) == (H, W):
        return src[flat]
    r0, r1, fr = _taps(H, h)
    c0, c1, fc = _taps(W, w)
    y0, y1, ty = r0[rows], r1[rows], fr[rows][:, None]
    x0, x1, tx = c0[cols], c1[cols], fc[cols][:, None]
    top = src[y0 * w + x0] * (1 - tx) + src[y0 * w + x1] * tx
    bot = src[y1 * w + x0] * (1 - tx) + src[y1 * w + x1] * tx
    return (top * (1 - ty) + bot * ty).astype(_F)


def sample_masks_at(masks: np.ndarray, shape: tuple[int, int], flat: np.ndarray) -> np.ndarray:
    """Masks ``[R, h, w]`` sampled at texels ``flat`` of the ``shape`` grid -> ``[R, n]``."""
    m = np.asarray(masks, _F)
    return sample_at(np.moveaxis(m, 0, -1), shape, flat).T


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
    share: np.ndarray  # [R, n] each region's part: M_r * max_k |w_rk|


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
    _cache: dict[str, Any] = field(default_factory=dict)

    @property
    def texels(self) -> int:
        return int(self.shape[0] * self.shape[1])

    @property
    def active_fraction(self) -> float:
        """Fraction of the grid some pose activates (the wrinkles' share of the UV area)."""
        return float(self.union.size) / self.texels


def _activation_weight(act: np.ndarray) -> np.ndarray:
    return np.abs(act).sum(axis=0).astype(_F)


def _region_share(masks_at: np.ndarray, weights: np.ndarray) -> np.ndarray:
    w = np.asarray(weights, _F)
    per_region = np.abs(w) if w.ndim == 1 else np.abs(w).max(axis=1)
    return masks_at * per_region[:, None]


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
    b = model.normalize(np.asarray(base, _F))
    st = np.asarray(states, _F)
    H, W = b.shape[:2]
    if st.shape[1:3] != (H, W):
        raise ValueError(f"source states {st.shape[1:3]} and base {(H, W)} differ in size")
    m = np.asarray(masks, _F)
    if m.shape[1:] != (H, W):
        m = sample_masks_at(m, (H, W), np.arange(H * W)).reshape(-1, H, W)
    flat_b = b.reshape(H * W, 3)
    flat_s = st.reshape(st.shape[0], H * W, -1)
    flat_m = m.reshape(m.shape[0], H * W)
    # texels some region of some pose touches (masks non-zero where a weight is non-zero)
    per_pose_active = []
    any_active = np.zeros(H * W, bool)
    for p in poses:
        w = np.asarray(p.weights, _F)
        on = (np.abs(w) > 0) if w.ndim == 1 else (np.abs(w) > 0).any(axis=1)
        cand = (flat_m[on] > 0).any(axis=0) if on.any() else np.zeros(H * W, bool)
        per_pose_active.append(cand)
        any_active |= cand
    union = np.flatnonzero(any_active)
    pos_in_union = np.full(H * W, -1, np.int64)
    pos_in_union[union] = np.arange(union.size)
    m_u = flat_m[:, union]
    out = []
    for p, cand in zip(poses, per_pose_active):
        idx = np.flatnonzero(cand)
        sel = pos_in_union[idx]
        act = model.activations(m_u[:, sel], p.weights, policy)
        keep = np.abs(act).sum(axis=0) > 0
        sel, idx, act = sel[keep], idx[keep], act[:, keep]
        normal = model.combine(flat_b[idx], flat_s[:, idx], act, encoding)
        out.append(
            PoseReference(
                pose=p,
                sel=sel,
                act=act,
                normal=normal,
                weight=_activation_weight(act),
                share=_region_share(m_u[:, sel], p.weights),
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
    raw: dict[str, np.ndarray] = field(default_factory=dict)  # the arrays, for leak texels


def sample(
    ref: Reference,
    base: np.ndarray | None = None,
    states: np.ndarray | None = None,
    masks: np.ndarray | None = None,
) -> Samples:
    """Gather decoded shipped maps (at their own sizes) at the reference's active texels.

    ``base`` unit normals ``[hb, wb, 3]``; ``states`` ``[K, hs, ws, C]`` in combine's
    representation; ``masks`` ``[R, hm, wm]``.
    """
    s = Samples()
    u = ref.union
    if base is not None:
        s.base = model.normalize(sample_at(base, ref.shape, u))
        s.raw["base"] = np.asarray(base, _F)
    if states is not None:
        st = np.asarray(states, _F)
        s.states = np.stack([sample_at(x, ref.shape, u) for x in st])
        if ref.encoding in ("full", "composite"):
            s.states = model.normalize(s.states)
        s.raw["states"] = st
    if masks is not None:
        s.masks = sample_masks_at(masks, ref.shape, u)
        s.raw["masks"] = np.asarray(masks, _F)
    return s


def merge(*parts: Samples) -> Samples:
    """Later parts override earlier ones (e.g. cached base + masks, then candidate states)."""
    out = Samples()
    for p in parts:
        for name in ("base", "states", "masks"):
            if getattr(p, name) is not None:
                setattr(out, name, getattr(p, name))
        out.raw.update(p.raw)
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
        """The poses whose overall stats break ``budget``."""
        return [p for p in self.poses if not budget.ok(p.overall)]

    def meets(self, budget: Budget) -> bool:
        return not self.over(budget)

    def score(self) -> tuple[float, float]:
        """What a search minimises: worst p99, then worst mean."""
        return self.worst_p99(), self.worst_mean()

    def to_json(self) -> dict[str, Any]:
        return {
            "active_fraction": round(self.active_fraction, 5),
            "base": None if self.base is None else self.base.to_json(),
            "poses": [p.to_json() for p in self.poses],
        }


def _leak(
    ref: Reference, pr: PoseReference, s: Samples
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Texels outside the source's active set that the shipped masks activate: (flat indices,
    shipped normals there, shipped activation weight)."""
    masks = s.raw.get("masks")
    if masks is None or masks.shape[0] == 0:
        return None
    H, W = ref.shape
    hm, wm = masks.shape[1:]
    act_lo = model.activations(masks, pr.pose.weights, ref.policy)
    on_lo = np.abs(act_lo).sum(axis=0) > 0
    if not on_lo.any():
        return None
    # a grid texel can see a non-zero mask texel when it lies within one mask texel of it
    grow = on_lo.copy()
    grow[1:] |= on_lo[:-1]
    grow[:-1] |= on_lo[1:]
    g2 = grow.copy()
    g2[:, 1:] |= grow[:, :-1]
    g2[:, :-1] |= grow[:, 1:]
    rows = np.minimum((np.arange(H) * hm) // H, hm - 1)
    cols = np.minimum((np.arange(W) * wm) // W, wm - 1)
    cand = g2[rows][:, cols].reshape(-1)
    cand[ref.union[pr.sel]] = False
    idx = np.flatnonzero(cand)
    if idx.size == 0:
        return None
    m_at = sample_masks_at(masks, ref.shape, idx)
    act = model.activations(m_at, pr.pose.weights, ref.policy)
    keep = np.abs(act).sum(axis=0) > 0
    if not keep.any():
        return None
    idx, act = idx[keep], act[:, keep]
    b = s.raw.get("base")
    base = model.normalize(sample_at(b, ref.shape, idx)) if b is not None else None
    if base is None:
        base = ref.base.reshape(-1, 3)[idx]
    st = s.raw["states"]
    states = np.stack([sample_at(x, ref.shape, idx) for x in st])
    if ref.encoding in ("full", "composite"):
        states = model.normalize(states)
    return idx, model.combine(base, states, act, ref.encoding), _activation_weight(act)


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
    src_base_u = ref.base.reshape(-1, 3)[ref.union]
    out = []
    maps: dict[str, np.ndarray] = {}
    for pr in ref.poses:
        base = (s.base if s.base is not None else src_base_u)[pr.sel]
        if s.masks is not None:
            act = model.activations(s.masks[:, pr.sel], pr.pose.weights, ref.policy)
        else:
            act = pr.act
        got = model.combine(base, s.states[:, pr.sel], act, ref.encoding)
        err = angle_deg(got, pr.normal)
        w = np.maximum(pr.weight, _activation_weight(act))
        errs, ws = [err], [w]
        n_leak = 0
        leak = _leak(ref, pr, s) if leaks else None
        if leak is not None:
            idx, n_leak_normal, lw = leak
            lerr = angle_deg(n_leak_normal, ref.base.reshape(-1, 3)[idx])
            errs.append(lerr)
            ws.append(lw)
            n_leak = int(idx.size)
        overall = weighted_stats(np.concatenate(errs), np.concatenate(ws))
        per_region: dict[str, Stats] = {}
        if regions:
            for r, name in enumerate(ref.region_names):
                share = pr.share[r]
                if share.any():
                    per_region[name] = weighted_stats(err, share)
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


def base_fidelity(ref: Reference, base: np.ndarray) -> Stats:
    """The shipped base (decoded, any size) against the source base over the footprint."""
    H, W = ref.shape
    flat = np.flatnonzero(ref.footprint.reshape(-1)) if ref.footprint is not None else None
    if flat is None:
        flat = np.arange(H * W)
    got = model.normalize(sample_at(base, ref.shape, flat))
    err = angle_deg(got, ref.base.reshape(-1, 3)[flat])
    return weighted_stats(err, np.ones(err.shape, _F))


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
    uv = np.asarray(uvs, np.float64)
    uv = uv - np.floor(uv)  # repeat wrapping, as samplers do by default
    return rasterise_triangle_ids(uv, indices, H) >= 0


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
