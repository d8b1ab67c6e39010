"""Regions, masks and driver rows from a mesh's morph targets (blend shapes).

Per target, Oat's area change at full weight (:class:`wrinklepipe.geometry.dynamic.DynamicWeights`:
``(A_rest - A_target) / A_rest`` per triangle, positive where the skin compresses, smoothed per
vertex with angle weights over every render vertex of the same spatial-hash vertex ID, so UV
seams get one value). Each target's change is scaled by its ``reference`` quantile (the 99th
percentile of its non-zero magnitudes maps to 1, larger values clip), and values below
``threshold`` of that are 0, so a mask is exactly zero where the target leaves the skin alone.

Two ways to make regions:

- **one mask per target** (the default, Open 3D Engine's convention: a wrinkle mask per morph
  target driven by that target's weight), split by state because a target both compresses and
  stretches skin: region ``<target>_compress`` drives the ``compress`` state where the target
  compresses, ``<target>_stretch`` the ``stretch`` state where it stretches (a target that only
  compresses gets one region). Rows ``[target, region:state, 0, 1, 1, 0]``.
- **N clustered regions** (``regions = N``): the vertices the targets move are grouped by which
  targets move them and how (k-means on the per-vertex compress/stretch profile, mirror twins
  of sided targets merged, with the position folded across the symmetry plane), so a group and
  its mirror image are one group; a group whose mask is zero along the symmetry plane becomes a
  left and a right region (``_l`` / ``_r``, the character's sides), a group that crosses the
  plane stays one centre region (a cut there would show as a seam when the sides' weights
  differ). Memberships are soft (a softmax of the k-means distances), so neighbouring regions
  blend. The largest number of groups whose regions fit in N is used. Rows: per target and
  state, the non-negative least-squares weights of the regions that best rebuild that target's
  own compress (stretch) profile, area-weighted; the fit's relative residual is reported.

Masks are the per-vertex values rendered into the UV layout by
:mod:`wrinklepipe.geometry.uv_samples`: ``supersample`` x ``supersample`` samples per texel
(barycentric interpolation, box filter), a Gaussian of ``blur`` texels over the covered
texels, and ``padding`` texels of edge padding beyond UV island borders. Where UV islands
overlap, triangles some target moves own the texels.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np
from scipy.cluster.vq import kmeans2
from scipy.optimize import nnls

from wrinklepipe.asset import Mesh, Region
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.dynamic import DynamicWeights, morph_pose, triangle_areas
from wrinklepipe.geometry.symmetry import SymmetryPlane, mirror_partners, symmetry_plane
from wrinklepipe.geometry.uv_samples import render_sparse, uv_samples
from wrinklepipe.geometry.vertex_ids import compute_vertex_ids
from wrinklepipe.model import MAX_REGIONS
from wrinklepipe.names import plural
from wrinklepipe.presets.targets import describe, mirror_name

NAME = "regions"
#: The two states of Oat's dynamic wrinkles, in the order the manifest lists them.
STATES: tuple[str, ...] = ("stretch", "compress")


#: The widest mask blur (sigma, texels) the commands take: a Gaussian costs its width per texel
#: (--blur 5000 on 1024² masks ran over ten minutes; 1e300 was an internal error), and a blur
#: wider than this smears a wrinkle region over a sixteenth of a 1024² texture.
MAX_BLUR_TEXELS = 64.0


@dataclass(frozen=True)
class TargetRegionsOptions:
    """Options of :func:`regions_from_targets`.

    size: masks are ``size`` x ``size`` texels.
    supersample: samples per texel per axis (anti-aliasing; 2 = 4 samples a texel).
    blur: sigma in texels of the Gaussian over covered texels (0: none).
    padding: texels of edge padding beyond UV island borders.
    reference: quantile of a target's non-zero area-change magnitudes that maps to mask 1.
    threshold: fraction of that reference below which a mask is 0.
    regions: None: one mask per target and state; N: at most N clustered regions.
    split_band: clustered: half-width of the symmetry-plane band, as a fraction of the mesh's
        bounding-box diagonal, inside which a group's mask must be (nearly) 0 to be split.
    seed: clustered: seed of the k-means initialisation (results are deterministic).
    """

    size: int = 1024
    supersample: int = 2
    blur: float = 1.0
    padding: int = 8
    reference: float = 0.99
    threshold: float = 0.02
    regions: int | None = None
    split_band: float = 0.01
    seed: int = 0


@dataclass
class TargetRegions:
    """What :func:`regions_from_targets` made: regions (each with its side and the states it
    drives), masks ``[R, size, size]`` float32 in [0, 1] (glTF UV convention), per-vertex masks
    ``[R, V]``, driver rows ``(input, output, from, to, slope, cut)``, the targets used and
    skipped, per-target fit residuals (clustered), the symmetry plane and notes."""

    regions: tuple[Region, ...]
    masks: np.ndarray
    vertex_masks: np.ndarray
    rows: list[tuple[str, str, float, float, float, float]]
    targets: tuple[str, ...]
    skipped: tuple[str, ...]
    plane: SymmetryPlane
    change: np.ndarray  # [M, V] signed area change per target used (positive: compressed)
    fit: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def safe_name(name: str) -> str:
    """A region name (letters, digits and ``_``) from a target name."""
    out = re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_")
    return out or "target"


def _unique(names: list[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for n in names:
        k = seen.get(n, 0)
        seen[n] = k + 1
        out.append(n if k == 0 else f"{n}_{k + 1}")
    return out


def target_changes(mesh: Mesh, source: str = "") -> tuple[tuple[str, ...], np.ndarray]:
    """Oat's smoothed per-vertex area change ``[M, V]`` (float64, positive: compressed) of each
    morph target of ``mesh`` at full weight (inbetweens ``name@w`` are not targets of their
    own), and the target names."""
    src = source or mesh.name
    names = tuple(n for n in mesh.morph_names if "@" not in n)
    if mesh.morph_deltas is None or not names:
        raise input_error(src, "the mesh has no morph targets (blend shapes)")
    ids = mesh.vertex_ids
    if ids is None:
        ids = compute_vertex_ids(mesh.positions, source=src)
    rest = np.asarray(mesh.positions, np.float64)
    op = DynamicWeights.build(rest, mesh.indices, ids, options=None, source=src)
    out = np.stack([op.frame(morph_pose(mesh, {n: 1.0}, src)) for n in names]).astype(np.float64)
    return names, out


def _vertex_areas(positions: np.ndarray, indices: np.ndarray) -> np.ndarray:
    a = triangle_areas(positions, indices) / 3.0
    out = np.zeros(len(positions))
    for c in range(3):
        out += np.bincount(indices[:, c], a, minlength=len(positions))
    return out


def _scaled(change: np.ndarray, o: TargetRegionsOptions) -> np.ndarray:
    """``change`` ``[M, V]`` scaled per target to its reference quantile, clipped to [-1, 1],
    zero below the threshold."""
    out = np.zeros_like(change)
    for m, w in enumerate(change):
        mag = np.abs(w)
        nz = mag[mag > 0]
        if not len(nz):
            continue
        ref = float(np.quantile(nz, o.reference))
        s = np.clip(w / ref, -1.0, 1.0)
        s[np.abs(s) < o.threshold] = 0.0
        out[m] = s
    return out


def _side_of(values: np.ndarray, dist: np.ndarray, area: np.ndarray) -> str:
    mass = values * area
    total = float(mass.sum())
    if total <= 0:
        return "center"
    left = float(mass[dist > 0].sum()) / total
    right = float(mass[dist < 0].sum()) / total
    return "left" if left >= 0.9 else "right" if right >= 0.9 else "center"


def regions_from_targets(
    mesh: Mesh, options: TargetRegionsOptions | None = None, source: str = ""
) -> TargetRegions:
    """Regions, masks and rows from ``mesh``'s morph targets (see the module doc). ``mesh``
    needs UVs; its vertex IDs are used when present (else computed)."""
    o = options or TargetRegionsOptions()
    src = source or mesh.name
    if mesh.uvs is None:
        raise input_error(src, "the mesh has no UVs (masks need a UV layout)")
    if o.regions is not None and o.regions < 1:
        raise input_error(src, f"--regions must be at least 1, got {o.regions}", "--regions")
    top = min(MAX_BLUR_TEXELS, o.size)
    if not 0 <= o.blur <= top:  # (a wider one: an internal error, or many minutes of filtering)
        raise input_error("--blur", f"{o.blur:g} is out of range; expected 0..{top:g} texels")
    names, change = target_changes(mesh, src)
    scaled = _scaled(change, o)
    moved = np.abs(scaled).max(axis=1) > 0
    skipped = tuple(n for n, k in zip(names, moved) if not k)
    names = tuple(n for n, k in zip(names, moved) if k)
    scaled, change = scaled[moved], change[moved]
    if not names:
        raise input_error(src, "no morph target changes the area of any triangle (no wrinkles)")
    p = np.asarray(mesh.positions, np.float64)
    idx = np.asarray(mesh.indices, np.int64)
    plane = symmetry_plane(p)
    dist = plane.distance(p)
    area = _vertex_areas(p, idx)
    notes = [
        f"symmetry plane: normal ({', '.join(f'{x:+.3f}' for x in plane.normal)}), offset "
        f"{plane.offset:+.4g}, mirror residual {plane.residual:.2e} of the mesh's size"
    ]
    if skipped:
        notes.append(f"targets that change no triangle's area (no region): {list(skipped)}")
    if o.regions is None:
        regions, vmasks, rows = _per_target(names, scaled, dist, area)
        fit: dict[str, float] = {}
    else:
        regions, vmasks, rows, fit, more = _clustered(names, scaled, p, idx, plane, area, o)
        notes += more
    if len(regions) > MAX_REGIONS:
        raise input_error(
            src,
            f"{len(regions)} regions, more than the {MAX_REGIONS} an asset holds; use --regions N",
            "--regions",
        )
    active = np.abs(scaled).max(axis=0) > 0
    masks = render_vertex_masks(mesh, vmasks, active, o)
    kept = masks.reshape(len(masks), -1).max(axis=1) >= 0.5 / 255.0
    if not kept.all():
        gone = {r.name for r, k in zip(regions, kept) if not k}
        notes.append(f"regions too small to cover a texel at {o.size}^2 (dropped): {sorted(gone)}")
        regions = tuple(r for r, k in zip(regions, kept) if k)
        masks, vmasks = masks[kept], vmasks[kept]
        rows = [r for r in rows if r[1].partition(":")[0] not in gone]
    if not regions:
        raise input_error(
            src,
            f"no region covers a texel of the UV layout at {o.size}^2: the triangles the targets "
            "move have no area in UV (a degenerate layout, e.g. a front projection of a mesh "
            "seen edge-on?)",
        )
    return TargetRegions(regions, masks, vmasks, rows, names, skipped, plane, change, fit, notes)


def _per_target(
    names: tuple[str, ...], scaled: np.ndarray, dist: np.ndarray, area: np.ndarray
) -> tuple[tuple[Region, ...], np.ndarray, list]:
    base = _unique([safe_name(n) for n in names])
    regions: list[Region] = []
    values: list[np.ndarray] = []
    rows = []
    for name, b, s in zip(names, base, scaled):
        for state, part in (("compress", np.maximum(s, 0.0)), ("stretch", np.maximum(-s, 0.0))):
            if not part.any():
                continue
            region = f"{b}_{state}"
            regions.append(Region(region, _side_of(part, dist, area), (state,)))
            values.append(part)
            rows.append((name, f"{region}:{state}", 0.0, 1.0, 1.0, 0.0))
    return tuple(regions), np.stack(values), rows


def _features(
    names: tuple[str, ...], scaled: np.ndarray, partner: np.ndarray
) -> tuple[np.ndarray, list[str]]:
    """Per-vertex compress/stretch profile ``[V, 2G]`` with mirror-twin targets merged into one
    column group (G groups) and made equal for mirror-twin vertices; and the groups' names."""
    pos = {n: i for i, n in enumerate(names)}
    group_of: list[int] = []
    labels: list[str] = []
    key_group: dict[int, int] = {}
    for i, n in enumerate(names):
        twin = pos.get(mirror_name(n), i)
        key = min(i, twin)
        if key not in key_group:
            key_group[key] = len(labels)
            info = describe(n)
            labels.append(info.base if twin != i else n)
        group_of.append(key_group[key])
    g = np.array(group_of)
    f = np.zeros((scaled.shape[1], 2 * len(labels)))
    for i in range(len(names)):
        np.maximum(f[:, 2 * g[i]], np.maximum(scaled[i], 0.0), out=f[:, 2 * g[i]])
        np.maximum(f[:, 2 * g[i] + 1], np.maximum(-scaled[i], 0.0), out=f[:, 2 * g[i] + 1])
    return 0.5 * (f + f[partner]), labels


def _kmeans(x: np.ndarray, k: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Centroids ``[k', D]`` and labels of a deterministic k-means (empty clusters dropped)."""
    k = min(k, len(np.unique(x, axis=0)))
    cent, lab = kmeans2(x, k, minit="++", seed=np.random.default_rng(seed))
    used = np.unique(lab)
    remap = np.full(len(cent), -1)
    remap[used] = np.arange(len(used))
    return cent[used], remap[lab]


def _soft(x: np.ndarray, cent: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Soft memberships ``[N, k]`` (rows sum to 1): softmax of minus the squared distances over
    their mean within-cluster value."""
    d2 = ((x[:, None, :] - cent[None, :, :]) ** 2).sum(axis=-1)
    tau = max(float(d2[np.arange(len(x)), labels].mean()), 1e-12)
    z = -(d2 - d2.min(axis=1, keepdims=True)) / tau
    e = np.exp(z)
    return e / e.sum(axis=1, keepdims=True)


def _clustered(
    names: tuple[str, ...],
    scaled: np.ndarray,
    p: np.ndarray,
    idx: np.ndarray,
    plane: SymmetryPlane,
    area: np.ndarray,
    o: TargetRegionsOptions,
) -> tuple[tuple[Region, ...], np.ndarray, list, dict[str, float], list[str]]:
    partner, _ = mirror_partners(p, plane)
    feat, labels = _features(names, scaled, partner)
    activity = feat.max(axis=1)
    act = np.flatnonzero(activity > 0)
    diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))
    dist = plane.distance(p)
    # fold the position across the plane: (|d|, the two in-plane coordinates) / size
    basis = np.linalg.svd(np.eye(3) - np.outer(plane.normal, plane.normal))[0][:, :2]
    folded = np.column_stack([np.abs(dist), p @ basis]) / max(diag, 1e-30)
    unit = feat / np.maximum(np.linalg.norm(feat, axis=1, keepdims=True), 1e-30)
    x = np.column_stack([unit, 2.0 * folded])[act]
    band = o.split_band * diag
    near = np.abs(dist) <= band
    best = None
    for k in range(min(o.regions, len(act)), 0, -1):
        cent, lab = _kmeans(x, k, o.seed)
        member = np.zeros((len(p), len(cent)))
        member[act] = _soft(x, cent, lab) * activity[act, None]
        split = [
            bool(
                member[:, g].max() > 0
                and member[near, g].max(initial=0.0) <= 0.1 * member[:, g].max()
            )
            for g in range(len(cent))
        ]
        count = sum(2 if s else 1 for s in split)
        if count <= o.regions:
            best = (member, lab, split)
            break
    if best is None:  # N = 1 and the one group would split: keep it whole
        cent, lab = _kmeans(x, 1, o.seed)
        member = np.zeros((len(p), 1))
        member[act, 0] = activity[act]
        best = (member, lab, [False])
    member, lab, split = best
    regions: list[Region] = []
    values: list[np.ndarray] = []
    group_names = _group_names(member, feat, labels, names)
    for g, (name, s) in enumerate(zip(group_names, split)):
        m = member[:, g]
        if s:
            regions.append(Region(f"{name}_l", "left"))
            values.append(np.where(dist > 0, m, 0.0))
            regions.append(Region(f"{name}_r", "right"))
            values.append(np.where(dist < 0, m, 0.0))
        else:
            regions.append(Region(name, "center"))
            values.append(m)
    vm = np.stack(values)
    rows, fit = _fit_rows(names, scaled, vm, [r.name for r in regions], area)
    notes = [
        f"clustered the {len(act)} moved vertices into {len(group_names)} groups -> "
        f"{plural(len(regions), 'region')} ({sum(split)} split left/right)"
    ]
    return tuple(regions), vm, rows, fit, notes


def _group_names(
    member: np.ndarray, feat: np.ndarray, labels: list[str], names: tuple[str, ...]
) -> list[str]:
    """Each group after the target group that moves its vertices most (its face area when a
    preset knows the target); groups that share a name add the state they mostly carry."""
    base: list[str] = []
    state: list[str] = []
    for g in range(member.shape[1]):
        col = (member[:, g : g + 1] * feat).sum(axis=0)  # [2G]: compress, stretch per group
        j = int(np.argmax(col))
        label = labels[j // 2]
        src = next((n for n in names if describe(n).base == label or n == label), label)
        base.append(safe_name(describe(src).area or label))
        state.append("compress" if j % 2 == 0 else "stretch")
    out = [f"{b}_{s}" if base.count(b) > 1 else b for b, s in zip(base, state)]
    return _unique(out)


def _fit_rows(
    names: tuple[str, ...],
    scaled: np.ndarray,
    vmasks: np.ndarray,
    region_names: list[str],
    area: np.ndarray,
) -> tuple[list, dict[str, float]]:
    w = np.sqrt(area)
    a = (vmasks * w[None, :]).T  # [V, R]
    rows = []
    fit: dict[str, float] = {}
    for n, s in zip(names, scaled):
        num = 0.0
        den = 0.0
        for state, t in (("compress", np.maximum(s, 0.0)), ("stretch", np.maximum(-s, 0.0))):
            if not t.any():
                continue
            c, res = nnls(a, t * w)
            num += res**2
            den += float(((t * w) ** 2).sum())
            for r, cr in zip(region_names, c):
                slope = round(float(cr), 4)
                if slope >= 1e-3:
                    rows.append((n, f"{r}:{state}", 0.0, 1.0, slope, 0.0))
        fit[n] = float(np.sqrt(num / den)) if den > 0 else 0.0
    return rows, fit


def render_vertex_masks(
    mesh: Mesh,
    values: np.ndarray,
    priority: np.ndarray | None,
    options: TargetRegionsOptions | None = None,
) -> np.ndarray:
    """Per-vertex values ``[R, V]`` in [0, 1] rendered as masks ``[R, size, size]`` float32
    (supersampled, blurred, padded; see the module doc). ``priority`` ``[V]`` bool: triangles
    with a priority vertex own texels where UV islands overlap."""
    o = options or TargetRegionsOptions()
    idx = np.asarray(mesh.indices, np.int64)
    order = None
    if priority is not None:
        hot = np.asarray(priority, bool)[idx].any(axis=1)
        order = np.concatenate([np.flatnonzero(~hot), np.flatnonzero(hot)])
    samples = uv_samples(mesh.uvs, idx, o.size, o.supersample, order)
    masks = render_sparse(samples, idx, np.asarray(values, np.float64), o.blur, o.padding)
    return np.clip(masks, 0.0, 1.0)
