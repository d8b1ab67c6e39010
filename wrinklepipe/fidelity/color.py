"""Fidelity in colour: the shipped colour blend against the full-resolution source's, in
CIEDE2000, where the colour states show.

The colour twin of :mod:`wrinklepipe.fidelity.metric` (DESIGN.md section 8). For each pose (the
same poses the normal fidelity judges) it compares

- the colour blend of the **shipped** maps (base colour and colour states decoded from their
  sRGB texels to linear light *before* filtering, at their own sizes, magnified bilinearly to
  the source grid as a GPU's sRGB sampler does; the shipped masks),
- with the colour blend of the **source** maps at full resolution,

on the texels of the base colour's grid where the pose activates a colour state, weighted by
that activation (``sum_k |a_k|`` over the colour states). Per pose and per region it reports
the weighted mean, p99 and max of ΔE00 (:mod:`wrinklepipe.metrics`: its CIEDE2000 and its
statistics and verdict, as the normals' degrees). The base colour
can be measured on its own over the face (unweighted), as the normal base is.

:func:`prepare_color` does the full-resolution work once (active texels, activations, the
source blend in CIELAB); :func:`measure_color` samples a shipped candidate and scores it, so an
automatic search pays the source's cost once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wrinklepipe import model, options
from wrinklepipe.codec import srgb
from wrinklepipe.fidelity.reference import Pose
from wrinklepipe.fidelity.sampling import Reader, sample_at, sample_masks_at
from wrinklepipe.metrics import (
    DECIMALS,
    Budget,
    Stats,
    delta_e_lab,
    linear_to_lab,
    weighted_stats,
    weighted_stats_many,
)

_F = np.float32

#: The colour budget's defaults (``[budget]`` ``max_mean_delta_e`` / ``max_p99_delta_e``, the
#: manifest schema's, :mod:`wrinklepipe.options`): inside each pose's active region, the
#: activation-weighted mean CIEDE2000 at most 1 (on average nobody sees it side by side) and
#: its 99th percentile at most 2.3 (the one just-noticeable difference usually quoted).
DEFAULT_MAX_MEAN_DELTA_E = options.DEFAULT_MAX_MEAN_DELTA_E
DEFAULT_MAX_P99_DELTA_E = options.DEFAULT_MAX_P99_DELTA_E


def color_budget(budget: options.BudgetOptions | dict[str, float] | None = None) -> Budget:
    """The colour budget of a manifest's ``[budget]`` (ΔE00; the defaults where unset):
    :meth:`wrinklepipe.options.BudgetOptions.color`."""
    if not isinstance(budget, options.BudgetOptions):
        budget = options.BudgetOptions.from_json(budget)
    return budget.color()


def stats_json(s: Stats) -> dict[str, float | int]:
    """A :class:`Stats` of ΔE00 values as JSON."""
    return {
        "mean_delta_e": round(s.mean, DECIMALS),
        "p99_delta_e": round(s.p99, DECIMALS),
        "max_delta_e": round(s.max, DECIMALS),
        "texels": s.texels,
        "weight": round(s.weight, 3),
    }


# ------------------------------------------------------------------------------------------------
# the reference


@dataclass
class ColorPoseRef:
    """One pose on the base colour's grid: where it shows colour and the source's colour."""

    pose: Pose
    sel: np.ndarray  # [n] positions in ColorReference.union
    act: np.ndarray  # [Kc, n] the source's activations of the colour states
    weight: np.ndarray  # [n] sum_k |a_k| over the colour states
    lab: np.ndarray  # [n, 3] the source's blend in CIELAB
    rows: np.ndarray  # [G] the regions the pose weights
    share: np.ndarray  # [G, n] each weighted region's part: M_r * max_k |w_rk|


@dataclass
class ColorReference:
    """The source colour maps at full resolution, prepared for many measurements."""

    shape: tuple[int, int]
    policy: str
    region_names: tuple[str, ...]
    state_index: tuple[int, ...]
    union: np.ndarray  # flat indices of the texels some pose colours
    poses: list[ColorPoseRef]
    base: np.ndarray  # [H, W, 3] the source base colour, linear (factor applied)
    footprint: np.ndarray | None = None  # [H, W] bool: the mesh's UV footprint
    step: int = 1

    @property
    def texels(self) -> int:
        return int(self.shape[0] * self.shape[1])

    @property
    def active_fraction(self) -> float:
        return float(self.union.size * self.step) / self.texels

    def coarse(self, max_texels: int) -> ColorReference:
        """Every k-th active texel, about ``max_texels`` of them (itself when small enough):
        what a search screens candidates with."""
        n = int(self.union.size)
        if n <= max_texels:
            return self
        k = -(-n // max(int(max_texels), 1))
        keep = np.zeros(n, bool)
        keep[::k] = True
        new_pos = np.cumsum(keep) - 1
        poses = []
        for pr in self.poses:
            m = keep[pr.sel]
            poses.append(
                ColorPoseRef(
                    pr.pose,
                    new_pos[pr.sel[m]],
                    pr.act[:, m],
                    pr.weight[m],
                    pr.lab[m],
                    pr.rows,
                    pr.share[:, m],
                )
            )
        return replace(self, union=self.union[keep], poses=poses, step=self.step * k)

    def face_texels(self) -> np.ndarray:
        """Flat indices of the footprint's texels (every texel without a footprint)."""
        if self.footprint is None:
            return np.arange(self.texels)
        return np.flatnonzero(self.footprint)


def _weighted_rows(weights: np.ndarray, policy: str) -> np.ndarray:
    w = np.abs(np.asarray(weights, _F))
    on = w > 0 if w.ndim == 1 else (w > 0).any(axis=1)
    return np.arange(on.size) if policy == "renormalize" else np.flatnonzero(on)


def _color_activations(
    masks: np.ndarray, weights: np.ndarray, policy: str, state_index: Sequence[int]
) -> np.ndarray:
    """The colour states' activations ``[Kc, n]`` of masks ``[R, n]`` (only the regions the
    pose weights are read: the others add nothing)."""
    rows = _weighted_rows(weights, policy)
    w = np.asarray(weights, _F)
    act = model.activations(masks[rows], w[rows], policy)
    return np.ascontiguousarray(act[list(state_index)])


def prepare_color(
    base: np.ndarray,
    states: np.ndarray,
    masks: np.ndarray,
    poses: Sequence[Pose],
    region_names: Sequence[str],
    policy: str,
    state_index: Sequence[int],
    footprint: np.ndarray | None = None,
) -> ColorReference:
    """The source on the base colour's grid: ``base`` ``[H, W, 3]`` and ``states``
    ``[Kc, H, W, 3]`` in linear light (the base's factor applied), ``masks`` ``[R, h, w]``
    (magnified to the grid when smaller), the poses (region weights over all K states),
    ``state_index`` the colour states among them."""
    b = np.asarray(base, _F)
    st = np.asarray(states, _F)
    H, W = b.shape[:2]
    if st.shape[1:3] != (H, W):
        raise ValueError(f"source colour states {st.shape[1:3]} and base {(H, W)} differ in size")
    m = np.asarray(masks, _F)
    if m.shape[1:] != (H, W):
        m = sample_masks_at(m, (H, W), np.arange(H * W)).reshape(-1, H, W)
    flat_m = m.reshape(m.shape[0], H * W)
    found = []
    for p in poses:
        act = _color_activations(flat_m, p.weights, policy, state_index)
        weight = np.abs(act).sum(axis=0)
        on = np.flatnonzero(weight > 0)
        found.append((p, on, act[:, on], weight[on]))
    union = np.unique(np.concatenate([f[1] for f in found])) if found else np.zeros(0, np.int64)
    flat_b = b.reshape(-1, 3)
    flat_s = st.reshape(st.shape[0], -1, 3)
    refs = []
    for p, on, act, weight in found:
        blend = model.combine_color(flat_b[on], flat_s[:, on], act)
        rows = _weighted_rows(p.weights, policy)
        w = np.abs(np.asarray(p.weights, _F))
        per_region = w if w.ndim == 1 else w.max(axis=1)
        share = flat_m[rows][:, on] * per_region[rows][:, None]
        refs.append(
            ColorPoseRef(
                p,
                np.searchsorted(union, on),
                act,
                weight.astype(_F),
                linear_to_lab(blend),
                rows,
                share.astype(_F),
            )
        )
    return ColorReference(
        (H, W),
        policy,
        tuple(region_names),
        tuple(int(k) for k in state_index),
        union,
        refs,
        b,
        None if footprint is None else np.asarray(footprint, bool).reshape(H, W),
    )


# ------------------------------------------------------------------------------------------------
# the measure


@dataclass
class ColorPoseFidelity:
    """One pose: overall and per-region ΔE00 stats."""

    pose: str
    overall: Stats
    regions: dict[str, Stats] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "pose": self.pose,
            **stats_json(self.overall),
            "regions": {r: stats_json(s) for r, s in self.regions.items()},
        }


@dataclass
class ColorFidelity:
    """Every pose's colour fidelity and the base colour's own over the face."""

    poses: list[ColorPoseFidelity]
    base: Stats | None = None
    active_fraction: float = 0.0
    errors: dict[str, np.ndarray] = field(default_factory=dict)  # pose -> [H, W] (on request)

    def worst_p99(self) -> float:
        return max((p.overall.p99 for p in self.poses), default=0.0)

    def worst_mean(self) -> float:
        return max((p.overall.mean for p in self.poses), default=0.0)

    def over(self, budget: Budget) -> list[ColorPoseFidelity]:
        """The poses whose overall stats break ``budget`` (the verdict: :meth:`Budget.ok`)."""
        return [p for p in self.poses if not budget.ok(p.overall)]

    def meets(self, budget: Budget) -> bool:
        """Every pose (and the base, when measured) within ``budget`` by the verdict."""
        return not self.over(budget) and (self.base is None or budget.ok(self.base))

    def inside(self, budget: Budget) -> bool:
        """Every pose (and the base) inside ``budget`` unrounded (:meth:`Budget.inside`: what
        the automatic choices require)."""
        stats = [p.overall for p in self.poses] + ([self.base] if self.base is not None else [])
        return all(budget.inside(s) for s in stats)

    def to_json(self) -> dict[str, Any]:
        return {
            "active_fraction": round(self.active_fraction, 5),
            "base": None if self.base is None else stats_json(self.base),
            "poses": [p.to_json() for p in self.poses],
        }


def srgb_reader(factor: Sequence[float] = (1.0, 1.0, 1.0)) -> Reader:
    """How shipped sRGB texels are read: decoded to linear light per texel, before the
    bilinear filter (an sRGB sampler), the colour factor applied."""
    f = np.asarray(factor, _F)
    if np.all(f == 1.0):
        return Reader(store=lambda q: srgb.decode_texels(q[..., :3]))
    return Reader(store=lambda q: srgb.decode_texels(q[..., :3]) * f)


def sample_colors(
    ref: ColorReference,
    base: np.ndarray,
    states: Sequence[np.ndarray],
    factor: Sequence[float] = (1.0, 1.0, 1.0),
    flat: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Shipped base and states (sRGB texels at their own sizes) at the grid texels ``flat``
    (default: the reference's union), linear: ``([n, 3], [Kc, n, 3])``."""
    at = ref.union if flat is None else flat
    b = sample_at(base, ref.shape, at, srgb_reader(factor))
    s = np.stack([sample_at(x, ref.shape, at, srgb_reader()) for x in states])
    return b, s


def measure_color(
    ref: ColorReference,
    base: np.ndarray,
    states: Sequence[np.ndarray],
    masks: np.ndarray,
    factor: Sequence[float] = (1.0, 1.0, 1.0),
    regions: bool = True,
    base_over_face: bool = False,
    error_maps: bool = False,
) -> ColorFidelity:
    """Score shipped colour maps against the reference: ``base`` and ``states`` are sRGB
    texels as stored (any sizes; ``factor`` multiplies the base), ``masks`` the shipped mask
    values ``[R, h, w]`` in [0, 1]."""
    H, W = ref.shape
    b, s = sample_colors(ref, base, states, factor)
    m = sample_masks_at(np.asarray(masks, _F), ref.shape, ref.union)
    out = []
    maps: dict[str, np.ndarray] = {}
    for pr in ref.poses:
        act = _color_activations(m[:, pr.sel], pr.pose.weights, ref.policy, ref.state_index)
        got = model.combine_color(b[pr.sel], s[:, pr.sel], act)
        err = delta_e_lab(linear_to_lab(got), pr.lab)
        w = np.maximum(pr.weight, np.abs(act).sum(axis=0))
        overall = weighted_stats(err, w)
        per_region: dict[str, Stats] = {}
        if regions and pr.sel.size:
            for r, st in zip(pr.rows, weighted_stats_many(err, pr.share)):
                if st.texels:
                    per_region[ref.region_names[r]] = st
        out.append(ColorPoseFidelity(pr.pose.name, overall, per_region))
        if error_maps:
            emap = np.zeros(H * W, _F)
            emap[ref.union[pr.sel]] = err
            maps[pr.pose.name] = emap.reshape(H, W)
    fid = ColorFidelity(out, None, ref.active_fraction, maps)
    if base_over_face:
        fid.base = base_color_fidelity(ref, base, factor)
    return fid


def base_color_fidelity(
    ref: ColorReference, base: np.ndarray, factor: Sequence[float] = (1.0, 1.0, 1.0)
) -> Stats:
    """The shipped base colour (sRGB texels) against the source's over the face, unweighted."""
    flat = ref.face_texels()
    got = sample_at(base, ref.shape, flat, srgb_reader(factor))
    want = ref.base.reshape(-1, 3)[flat]
    err = delta_e_lab(linear_to_lab(got), linear_to_lab(want)).astype(_F)
    return weighted_stats(err, overwrite=True)
