"""Fidelity rules (WP-FID-*): the shipped asset against the full-resolution source.

They run when the validator knows the source (``has_source``: a manifest, ``--source
MANIFEST``, convert's own validation), with the one measure of :mod:`wrinklepipe.fidelity`:
per pose (those the drivers produce, as the render pass draws them: the expression table, each
curve's per-region peak frames) the blend of the shipped, decoded textures against the blend
of the source maps at full resolution, on the texels where the pose's
activation is non-zero, weighted by it. Without a source only the self-consistency rules run.

Also here, because a person would catch them at a glance: base and states misaligned (flipped
or offset: the wrinkled-minus-base difference spread where every mask is zero, WP-FID-006),
region sides that contradict the names (WP-MASK-006), and problem texels of the source base
(WP-MAP-007).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wrinklepipe import fidelity as fd
from wrinklepipe import model
from wrinklepipe.fidelity.level import PdLevel
from wrinklepipe.masks import infer_side
from wrinklepipe.masks.stack import float_masks
from wrinklepipe.metrics import Budget, Stats, angle_deg, weighted_stats
from wrinklepipe.names import noun
from wrinklepipe.normals import alignment as al
from wrinklepipe.normals.held import one_map, rows_of, texels_at
from wrinklepipe.validate import fidelity_pictures as fp
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context, encode_source_states, resize_normals
from wrinklepipe.validate.poses import fidelity_poses
from wrinklepipe.workset import band_rows

#: A texel outside every mask "differs" when its state and base normals are this far apart.
MISALIGNED_DEG = 1.0
#: ... and the asset is misaligned when more than this fraction of the face outside the masks does.
MISALIGNED_FRACTION = 0.10


def _cache(ctx: Context) -> dict[str, Any]:
    c = ctx.__dict__.setdefault("_fidelity", {})
    return c


def poses(ctx: Context) -> list[fd.Pose]:
    """The poses fidelity is judged on: those the drivers produce, as the render pass draws
    them (:func:`wrinklepipe.validate.poses.fidelity_poses`; cached on the context)."""
    c = _cache(ctx)
    if "poses" not in c:
        c["poses"] = fidelity_poses(ctx.inp)
    return c["poses"]


def budgets(ctx: Context) -> tuple[Budget, str]:
    """The budget that applies and which one: the compressed copies' when a base or state
    texture is block-compressed (``compressed_max_*``, else the same), else the budget."""
    b = ctx.asset.budget
    block = any(t.is_block for t in ctx.inp.textures if t.role in ("base", "state"))
    if not block or not b.compressed_given:
        return b.maps(), "budget"
    return b.copies(), "compressed budget"


# ------------------------------------------------------------------------------------------------
# the measure on the shipped textures


def _measurable(ctx: Context) -> bool:
    a = ctx.asset
    return bool(
        ctx.inp.has_source
        and a.encoding in model.ENCODINGS
        and a.policy in model.POLICIES
        and not (a.policy == "signed" and len(a.state_names) != 2)
        and len(a.states)
        and a.regions
        and poses(ctx)
    )


def footprint(ctx: Context, shape: tuple[int, int]) -> np.ndarray | None:
    """The mesh's UV footprint on a square grid (None without a mesh with UVs)."""
    mesh = ctx.asset.mesh
    if mesh is None or mesh.uvs is None or shape[0] != shape[1]:
        return None
    return fd.footprint(mesh.uvs, mesh.indices, shape)


def source_encoded(ctx: Context) -> tuple[np.ndarray, np.ndarray]:
    """The source base at the source states' size and the source states in combine's
    representation (made for the call, not held: the reference is made from them once, and the
    render pass samples them from the source maps' texels, :func:`source_sampled`)."""
    a = ctx.asset
    H, W = a.states.shape[1:3]
    base = resize_normals(a.base, H, W)
    return base, encode_source_states(base, np.asarray(a.states, np.float32), a.encoding)


def source_level(ctx: Context) -> tuple[np.ndarray, np.ndarray | PdLevel]:
    """:func:`source_encoded` for the reference: under ``pd`` the states' slopes as a
    :class:`~wrinklepipe.fidelity.level.PdLevel` (made where the reference reads them, the
    memo keyed as the whole array: the searches' reference, 256 MiB at 4096² never whole),
    else :func:`source_encoded`'s array."""
    a = ctx.asset
    if a.encoding != "pd":
        return source_encoded(ctx)
    H, W = a.states.shape[1:3]
    base = resize_normals(a.base, H, W)
    return base, PdLevel(base, rows_of(a.states))


def source_sampled(ctx: Context, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`source_encoded`'s base and states sampled at ``uv`` by
    :func:`~wrinklepipe.validate.textures.bilinear` (``[N, 3]``, ``[K, N, C]``), the states
    encoded at the texels the taps read only (the encoding is per texel: the same floats), not
    over the whole map."""
    a = ctx.asset
    H, W = a.states.shape[1:3]
    base = resize_normals(a.base, H, W)
    states = rows_of(a.states)  # held as integers: decoded at the texels the taps read
    K = states.shape[0]

    def encoded(i: np.ndarray) -> np.ndarray:  # [n, K * C]: the K states side by side
        e = encode_source_states(texels_at(base, i), texels_at(states, i), a.encoding)
        return np.moveaxis(e, 0, 1).reshape(i.size, -1)

    got = tx.bilinear_at(encoded, (H, W), uv)
    return tx.bilinear(base, uv), np.ascontiguousarray(
        np.moveaxis(got.reshape(len(uv), K, -1), 1, 0)
    )


def reference(ctx: Context) -> fd.Reference | None:
    """The full-resolution source prepared for the measure (cached on the context)."""
    c = _cache(ctx)
    if "reference" not in c:
        c["reference"] = None
        if _measurable(ctx):
            a = ctx.asset
            H, W = a.states.shape[1:3]
            base, states = source_level(ctx)
            c["reference"] = fd.prepare(
                base,
                states,
                a.masks,
                poses(ctx),
                a.region_names,
                a.encoding,
                a.policy,
                footprint(ctx, (H, W)),
            )
    return c["reference"]


def shipped_samples(ctx: Context, states: np.ndarray) -> fd.Samples | None:
    """The shipped base and masks with ``states`` (the shipped ones, or others measured
    against them) gathered at the reference's texels, as :func:`fd.measure` gathers them; the
    base and masks are gathered once per validation (cached on the context). None when
    fidelity cannot be measured."""
    ref = reference(ctx)
    masks = ctx.shipped_masks
    base = ctx.shipped_base_texels()
    if ref is None or base is None or masks is None:
        return None
    c = _cache(ctx)
    if "base_masks" not in c:  # the base's texels, decoded where they are read (not held)
        c["base_masks"] = fd.sample(ref, base[0], None, masks, base_reader=base[1])
    return fd.merge(c["base_masks"], fd.sample(ref, states=np.asarray(states)))


def shipped_fidelity(ctx: Context) -> fd.Fidelity | None:
    """The shipped textures' fidelity (per pose and region, the base over the face, error maps
    as the texels judged: :class:`wrinklepipe.fidelity.TexelErrors`), or None when it cannot be
    measured."""
    c = _cache(ctx)
    if "fidelity" not in c:
        c["fidelity"] = None
        states = ctx.shipped_states
        s = shipped_samples(ctx, np.stack(states)) if states is not None else None
        if s is not None:  # fd.measure of the shipped maps
            c["fidelity"] = fd.evaluate(
                reference(ctx), s, base_over_face=True, error_maps=True, samples=True
            )
    return c["fidelity"]


def check_fidelity(ctx: Context) -> list[Issue]:
    masks = ctx.shipped_masks
    pictures: dict[str, np.ndarray] = {}
    if masks is not None:
        pictures.update(fp.mask_pictures(masks, ctx.asset.region_names))
    ctx.metrics["fidelity_pictures"] = pictures  # the HTML page's (validate.run moves them)
    fid = shipped_fidelity(ctx)
    if fid is None:
        return []
    budget, which = budgets(ctx)
    where = ctx.inp.pointer("textures")
    ctx.metrics["fidelity"] = {**fid.to_json(), "budget": budget.to_json(), "applies": which}
    ref = reference(ctx)
    base, states = ctx.shipped_base_texels(), ctx.shipped_states
    if ref is not None and base is not None and states is not None and masks is not None:
        pictures.update(
            fp.pose_pictures(ref, fid, base[0], np.stack(states), masks, base_reader=base[1])
        )
    out: list[Issue] = []
    for p in sorted(fid.over(budget), key=lambda p: -p.overall.p99):
        o = p.overall
        region = max(p.regions.items(), key=lambda kv: kv[1].p99, default=None)
        worst = f"; worst region {region[0]}: p99 {region[1].p99:.2f}" if region else ""
        out.append(
            make_issue(
                "WP-FID-001",
                f"pose {p.pose!r}: p99 {o.p99:.2f}, mean {o.mean:.2f}, max {o.max:.2f} degrees "
                f"from the full-resolution source inside its active region ({o.texels} texels), "
                f"over the {which} ({budget.excess(o)}){worst}",
                where,
                pose=p.pose,
                p99_deg=round(o.p99, 4),
                mean_deg=round(o.mean, 4),
            )
        )
    regions: dict[str, tuple[str, Stats]] = {}
    for p in fid.poses:
        for r, st in p.regions.items():
            if r not in regions or st.p99 > regions[r][1].p99:
                regions[r] = (p.pose, st)
    for r, (pose, st) in sorted(regions.items()):
        if not budget.ok(st):
            out.append(
                make_issue(
                    "WP-FID-002",
                    f"region {r!r}: p99 {st.p99:.2f}, mean {st.mean:.2f} degrees from the "
                    f"full-resolution source in pose {pose!r} ({st.texels} texels), over the "
                    f"{which} ({budget.excess(st)})",
                    ctx.inp.pointer("masks"),
                    region=r,
                    pose=pose,
                    p99_deg=round(st.p99, 4),
                )
            )
    b = fid.base
    if b is not None and not budget.ok(b):
        out.append(
            make_issue(
                "WP-FID-003",
                f"the shipped base differs from the source base over the face by p99 "
                f"{b.p99:.2f}, mean {b.mean:.2f} degrees ({b.texels} texels), over the {which} "
                f"({budget.excess(b)})",
                ctx.base_tex.where if ctx.base_tex is not None else where,
                p99_deg=round(b.p99, 4),
            )
        )
    return out


# ------------------------------------------------------------------------------------------------
# base and states aligned (WP-FID-006)


def _outside(masks: np.ndarray, shape: tuple[int, int], fp: np.ndarray | None) -> np.ndarray:
    """Texels of the ``shape`` grid where every mask is zero (inside the footprint). The masks
    are read a mask at a time (no float32 copy of every mask: 512 MiB for eight 4096² masks)."""
    H, W = shape
    m = float_masks(masks)
    R, h, w = len(m), *m.shape[1:]
    some = np.zeros((h, w), bool)  # some mask > 0, and every mask >= 0 (NaN is not)
    nonneg = R > 0
    for r in range(R):
        mr = np.asarray(m[r], np.float32)
        some |= mr > 0
        nonneg = nonneg and bool(mr.min() >= 0) if mr.size else False
    if (h, w) == (H, W):
        inside = some
    elif nonneg:
        # Bilinear weights are >= 0: a sampled mask is > 0 exactly where one of its taps with
        # a weight > 0 is, so sampling "some mask > 0" once gives what sampling every mask
        # does (one channel instead of R)
        flags = some.astype(np.float32)[None]
        inside = fd.sample_masks_at(flags, (H, W), np.arange(H * W)).reshape(H, W) > 0
    else:
        inside = (fd.sample_masks_at(m, (H, W), np.arange(H * W)) > 0).any(axis=0)
        inside = inside.reshape(H, W)
    out = ~inside
    return out & fp if fp is not None else out


def _spread(base: np.ndarray, states: np.ndarray, outside: np.ndarray) -> float:
    """Fraction of ``outside`` texels where some state differs from the base, band by band of
    rows (the angle is per texel: the whole map's count, without the texels outside gathered
    from every map at once)."""
    n = int(np.count_nonzero(outside))
    if n == 0:
        return 0.0
    h, w = outside.shape
    rows = band_rows(w, SPREAD_BYTES * (1 + len(states)))
    count = 0
    for r0 in range(0, h, rows):
        o = outside[r0 : r0 + rows]
        b = base[r0 : r0 + rows][o]
        far = np.zeros(b.shape[0], bool)
        for k in range(len(states)):  # a map held as integers decodes this band only
            far |= angle_deg(one_map(states, k)[r0 : r0 + rows][o], b) > MISALIGNED_DEG
        count += int(np.count_nonzero(far))
    return float(np.float64(count) / np.float64(n))


#: Bytes of temporaries per texel and map of :func:`_spread` (the gathered vectors and the
#: angle's float32 planes).
SPREAD_BYTES = 32


def estimate_shift(a: np.ndarray, b: np.ndarray) -> tuple[int, int, float]:
    """Integer ``(dy, dx)`` that best aligns ``b`` onto ``a`` ([H, W], by phase correlation)
    and the peak's share of the correlation energy (near 1: a clear shift)."""
    fa = np.fft.rfft2(a - a.mean())
    fb = np.fft.rfft2(b - b.mean())
    cross = fa * np.conj(fb)
    cross /= np.maximum(np.abs(cross), 1e-12)
    corr = np.fft.irfft2(cross, s=a.shape)
    i = int(np.argmax(corr))
    dy, dx = divmod(i, a.shape[1])
    dy = dy - a.shape[0] if dy > a.shape[0] // 2 else dy
    dx = dx - a.shape[1] if dx > a.shape[1] // 2 else dx
    return int(dy), int(dx), float(corr.max())


def check_alignment(ctx: Context) -> list[Issue]:
    """Base and states of one face (:mod:`wrinklepipe.normals.alignment`): where every mask is
    zero a state keeps the base's detail (it may add wrinkle relief everywhere: the masks pick
    where it shows). A state that keeps none of it while differing from the base on a large
    part of the face is of another face or bake (WP-FID-007), or flipped or offset when that
    undone it keeps it (WP-FID-006; a green flip the convention rule WP-MAP-003 already named
    is not said twice). A base without detail gives no evidence: nothing is said."""
    a = ctx.asset
    if ctx.inp.has_source and len(a.states) and a.encoding in model.ENCODINGS:
        H, W = a.states.shape[1:3]
        base = resize_normals(a.base, H, W)
        states = rows_of(a.states)  # held as integers: read a band or some texels at a time
        masks = a.masks
        what = "source"
    else:
        sts = ctx.shipped_states
        if sts is None or not ctx.has_shipped_base or a.encoding not in model.ENCODINGS:
            return []
        H, W = sts[0].shape[:2]
        flat = np.arange(H * W)
        base = model.normalize(fd.sample_at(ctx.shipped_base, (H, W), flat)).reshape(H, W, 3)
        one = np.ones((1, H, W), np.float32)
        states = np.stack([model.combine(base, s[None], one, a.encoding) for s in sts])
        masks = ctx.shipped_masks if ctx.shipped_masks is not None else a.masks
        what = "shipped"
    if masks is None or not len(masks):
        return []
    fp = footprint(ctx, (H, W))
    outside = _outside(masks, (H, W), fp)
    spread = _spread(base, states, outside)
    rows, cols = al.lattice(outside)
    kept = [al.kept(base, one_map(states, k), rows, cols) for k in range(len(states))]
    ctx.metrics["base_state_spread"] = round(spread, 5)
    ctx.metrics["base_detail_kept"] = [None if k is None else round(k, 4) for k in kept]
    lost = [k for k, v in enumerate(kept) if v is not None and v < al.KEPT]
    if spread <= MISALIGNED_FRACTION or not lost:
        return []  # of one face: the same, or the base's detail kept under any relief
    names = [a.state_names[k] if k < len(a.state_names) else f"state {k}" for k in lost]
    share = min(kept[k] for k in lost)  # type: ignore[type-var]
    pct = 100 * max(share, 0.0)
    one = len(names) == 1
    said = (
        f"the {what} {noun(len(names), 'state')} {', '.join(repr(n) for n in names)} "
        f"{'keeps' if one else 'keep'} {pct:.0f}% of the base's detail where every mask is zero "
        f"(a state of the same face and bake keeps all of it) and {'differs' if one else 'differ'} "
        f"from the base by more than {MISALIGNED_DEG:g} degree on "
        f"{100 * spread:.1f}% of the face there"
    )
    data: dict[str, Any] = {"spread": round(spread, 4), "detail_kept": round(share, 4)}
    for label, tf in al.TRANSFORMS.items():
        if all(_keeps(al.kept(base, one_map(states, k), rows, cols, tf)) for k in lost):
            if "green" in label and _convention_said(ctx):
                return []  # WP-MAP-003 named the flipped green channel
            if "green" not in label and ctx.base_tex is not None:
                # a mirrored map also fails the curl test: WP-MAP-003's "green is flipped"
                # on the base is this mirror, said once here (validate drops it)
                data["explains"] = ctx.base_tex.where
            return [
                make_issue(
                    "WP-FID-006",
                    f"{said}; with {label} they keep it: one of them is flipped",
                    ctx.inp.pointer("textures"),
                    **data,
                )
            ]
    p = model.normal_to_pd
    dy, dx, peak = estimate_shift(p(base)[..., 0], p(states[lost[0]])[..., 0])
    if (dy, dx) != (0, 0) and peak > 0.05:
        # the base's texel (r + dy, c + dx) is the states' (r, c)
        if all(_keeps(al.kept(base, one_map(states, k), rows, cols, shift=(dy, dx))) for k in lost):
            return [
                make_issue(
                    "WP-FID-006",
                    f"{said}; the base is offset by ({dx}, {dy}) texels (x right, y down) from "
                    "the states and keeps it moved back: an offset",
                    ctx.inp.pointer("textures"),
                    **data,
                )
            ]
    return [
        make_issue(
            "WP-FID-007",
            f"{said}: maps of another face or another bake; no flip or offset explains it",
            ctx.inp.pointer("textures"),
            **data,
        )
    ]


def _keeps(k: float | None) -> bool:
    return k is not None and k >= al.KEPT


def _convention_said(ctx: Context) -> bool:
    """True when the convention rule found the base's green channel flipped (WP-MAP-003)."""
    scores = ctx.metrics.get("convention_score", {})
    t = ctx.base_tex
    return t is not None and float(scores.get(t.name, 0.0)) < -0.25


# ------------------------------------------------------------------------------------------------
# sides from names (WP-MASK-006) and the source base's texels (WP-MAP-007)


def check_sides(ctx: Context) -> list[Issue]:
    out = []
    for r in ctx.asset.regions:
        named = infer_side(r.name)
        if named != "center" and r.side != named:
            out.append(
                make_issue(
                    "WP-MASK-006",
                    f"region {r.name!r}: its name says the character's {named} but its side is "
                    f"{r.side}"
                    + (
                        ": the side check (WP-MASK-005) does not look at it"
                        if r.side == "center"
                        else ""
                    ),
                    ctx.inp.pointer("meta"),
                    region=r.name,
                    named=named,
                    side=r.side,
                )
            )
    return out


def check_source_texels(ctx: Context) -> list[Issue]:
    """Problem texels counted when the source maps were read (ingest records them)."""
    maps = ctx.asset.provenance.get("maps", {}) if ctx.inp.has_source else {}
    out = []
    for role, entry in sorted(maps.items()):
        st = entry.get("stats", {})
        bad = int(st.get("non_unit", 0)), int(st.get("z_negative", 0))
        if not any(bad):
            continue
        total = max(int(st.get("texels", 0)), 1)
        out.append(
            make_issue(
                "WP-MAP-007",
                f"source {role} {entry.get('file', '')}: {bad[0]} of {total} texels "
                f"({100 * bad[0] / total:.1f}%) are not unit length (by more than "
                f"{entry.get('tolerance', 0.01):g}), {bad[1]} point below the surface (z < 0)"
                + (
                    "; repaired as asked"
                    if st.get("repaired")
                    else "; renormalised to be blended and stored (set repair to change them)"
                ),
                entry.get("file", ctx.inp.pointer("meta")),
                non_unit=bad[0],
                z_negative=bad[1],
            )
        )
    return out


# ------------------------------------------------------------------------------------------------
# the render pass against the full-resolution source, in screen space (WP-FID-004)


def render_fidelity(
    ctx: Context, uv: np.ndarray, gpu: dict[str, np.ndarray], shipped_masks: np.ndarray
) -> tuple[list[Issue], dict[str, Any]]:
    """Each pose's GPU normal buffer (``gpu[pose]`` ``[N, 3]`` at the covered pixels' ``uv``)
    against the numpy blend of the full-resolution source sampled at the same UVs, on the pixels
    where the pose is active (source or shipped masks), weighted by the activation.

    Returns the issues and ``{pose: Stats}`` (screen-space error per pixel under ``"maps"``, the
    source's blended normal per pixel under ``"normals"``)."""
    a = ctx.asset
    if not _measurable(ctx) or not gpu:
        return [], {}
    base_at, states_src = source_sampled(ctx, uv)
    base_src = model.normalize(base_at)
    if a.encoding in ("full", "composite"):
        states_src = model.normalize(states_src)
    masks_src = tx.bilinear_planes(float_masks(a.masks), uv).T
    texture_budget, which = budgets(ctx)
    o = ctx.options
    # the GPU's own filtering error (WP-RND-001 bounds it) is allowed on top of the budget
    budget = Budget(
        None if texture_budget.mean is None else texture_budget.mean + o.gpu_max_mean_deg,
        None if texture_budget.p99 is None else texture_budget.p99 + o.gpu_max_p99_deg,
        texture_budget.max,
    )
    stats: dict[str, Stats] = {}
    errs: dict[str, np.ndarray] = {}
    normals: dict[str, np.ndarray] = {}  # the source's render: its blended normal per pixel
    for p in poses(ctx):
        if p.name not in gpu:
            continue
        act_src = model.activations(masks_src, p.weights, a.policy)
        act_ship = model.activations(shipped_masks, p.weights, a.policy)
        w = np.maximum(np.abs(act_src).sum(axis=0), np.abs(act_ship).sum(axis=0))
        src = model.combine(base_src, states_src, act_src, a.encoding)
        err = angle_deg(gpu[p.name], src)
        if not (w > 0).any():
            continue  # the pose's active region is not in view
        errs[p.name] = np.where(w > 0, err, 0.0).astype(np.float32)
        normals[p.name] = src
        stats[p.name] = weighted_stats(err, w)
    ctx.metrics["fidelity_render_deg"] = {
        k: {
            "mean": round(s.mean, 4),
            "p99": round(s.p99, 4),
            "max": round(s.max, 4),
            "pixels": s.texels,
        }
        for k, s in stats.items()
    }
    over = [(k, s) for k, s in stats.items() if s.texels and not budget.ok(s)]
    issues = []
    if over:
        k, s = max(over, key=lambda kv: kv[1].p99)
        issues.append(
            make_issue(
                "WP-FID-004",
                f"{len(over)} of {len(stats)} poses: the render of the shipped asset differs "
                f"from the numpy render of the full-resolution source over the {which} plus the "
                f"GPU's tolerance ({budget.describe()}) on the active pixels; worst {k}: p99 "
                f"{s.p99:.2f}, mean "
                f"{s.mean:.2f} degrees ({s.texels} pixels)",
                ctx.inp.pointer("meta"),
            )
        )
    return issues, {"stats": stats, "maps": errs, "normals": normals}
