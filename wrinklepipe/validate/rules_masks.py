"""Rules on region masks and the channel table (WP-MASK-*)."""

from __future__ import annotations

import numpy as np

from wrinklepipe.masks.stack import float_masks
from wrinklepipe.names import plural
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.inputs import CHANNELS


def _slot(inp: object, region: str) -> str:
    e = next((e for e in inp.channel_table if e.region == region), None)
    if e is None:
        return inp.pointer("masks")
    t = inp.texture(e.texture)
    where = t.where if t is not None else inp.pointer("masks")
    return f"{where} (channel {CHANNELS[e.channel] if e.channel < 4 else e.channel})"


def stored_step(masks: np.ndarray) -> float:
    """The value step of masks read from integer files: 1/255 when every value is a multiple
    of it (8-bit files), 1/65535 (16-bit), 0 for float values (EXR, or painted in memory)."""
    m = np.nan_to_num(np.asarray(masks, np.float64))
    for levels in (255.0, 65535.0):
        v = m * levels
        if np.all(np.abs(v - np.rint(v)) <= 1e-2):
            return 1.0 / levels
    return 0.0


def check_channel_table(ctx: Context) -> list[Issue]:
    inp, a = ctx.inp, ctx.asset
    if not inp.by_role("mask"):
        return []
    out = []
    where = inp.pointer("channels")
    seen: dict[tuple[str, int], str] = {}
    regions = set(a.region_names)
    for e in inp.channel_table:
        t = inp.texture(e.texture)
        if e.region not in regions:
            out.append(make_issue("WP-MASK-004", f"entry for unknown region {e.region!r}", where))
        if t is None:
            out.append(
                make_issue(
                    "WP-MASK-004",
                    f"region {e.region!r} points at texture {e.texture!r}, which does not ship",
                    where,
                )
            )
            continue
        if e.channel >= t.channels:
            out.append(
                make_issue(
                    "WP-MASK-004",
                    f"region {e.region!r} uses channel {e.channel} of {t.name!r}, a {t.fmt} "
                    f"texture with {plural(t.channels, 'channel')}",
                    where,
                )
            )
        # an lr-split pair shares one channel: its left and right halves are different slots
        key = (e.texture, e.channel, e.side if e.split is not None else "")
        if key in seen:
            out.append(
                make_issue(
                    "WP-MASK-004",
                    f"regions {seen[key]!r} and {e.region!r} share channel {e.channel} of "
                    f"{e.texture!r}",
                    where,
                )
            )
        seen[key] = e.region
    listed = {e.region for e in inp.channel_table}
    for r in a.region_names:
        if r not in listed:
            out.append(make_issue("WP-MASK-004", f"region {r!r} has no channel-table entry", where))
    if out or not inp.has_source or ctx.shipped_masks is None:
        return out
    # Content: each packed channel must hold its own region's source mask.
    ship = ctx.shipped_masks
    src = ctx.source_at_shipped_size["masks"] if ctx.source_at_shipped_size else None
    if src is None or src.shape != ship.shape:
        return out
    flat_s = ship.reshape(ship.shape[0], -1)
    flat_r = src.reshape(src.shape[0], -1)
    # fraction of texels where a shipped channel and a source mask differ by more than 0.1;
    # only a channel that differs from its own mask is compared with every other mask
    own_all = (np.abs(flat_s - flat_r) > 0.1).mean(axis=-1)
    for i, r in enumerate(a.region_names):
        own = own_all[i]
        if own <= 0.01:
            continue
        row = (np.abs(flat_s[i][None, :] - flat_r) > 0.1).mean(axis=-1)
        j = int(np.argmin(row))
        if j != i and row[j] < 0.5 * own:
            out.append(
                make_issue(
                    "WP-MASK-004",
                    f"the channel of region {r!r} holds the mask of {a.region_names[j]!r} "
                    f"({100 * own:.1f}% of texels differ from its own source mask, "
                    f"{100 * row[j]:.1f}% from {a.region_names[j]!r}): channels swapped?",
                    _slot(inp, r),
                )
            )
        else:
            out.append(
                make_issue(
                    "WP-MASK-004",
                    f"the channel of region {r!r} differs from its source mask by more than 0.1 "
                    f"at {100 * own:.1f}% of texels",
                    _slot(inp, r),
                )
            )
    return out


def _masks_for_rules(ctx: Context) -> list[tuple[np.ndarray, str]]:
    """(masks, label) pairs: the source masks, and the shipped ones when they differ."""
    out = [(float_masks(ctx.asset.masks), "source")]  # used a mask at a time
    if ctx.shipped_masks is not None:
        out.append((ctx.shipped_masks, "shipped"))
    return out


def check_masks(ctx: Context) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    out: list[Issue] = []
    names = a.region_names
    reported: set[tuple[str, str]] = set()
    for masks, label in _masks_for_rules(ctx):
        if masks.shape[0] != len(names):
            continue

        def ptr(r: str, label: str = label) -> str:
            return _slot(inp, r) if label == "shipped" else inp.pointer("masks")

        for i, r in enumerate(names):
            m = masks[i]
            bad = ~np.isfinite(m) | (m < 0.0) | (m > 1.0)
            if bad.any() and ("001", r) not in reported:
                reported.add(("001", r))
                y, x = np.unravel_index(int(np.flatnonzero(bad)[0]), m.shape)
                out.append(
                    make_issue(
                        "WP-MASK-001",
                        f"{label} mask of region {r!r}: {int(bad.sum())} texels NaN or outside "
                        f"[0, 1] (range {np.nanmin(m):.3f}..{np.nanmax(m):.3f}); first at texel "
                        f"({x}, {y})",
                        ptr(r),
                    )
                )
            if np.nan_to_num(m).max() < 1.0 / 255.0 and ("003", r) not in reported:
                reported.add(("003", r))
                out.append(
                    make_issue("WP-MASK-003", f"{label} mask of region {r!r} is empty", ptr(r))
                )
        if a.policy == "additive" and ("002", "") not in reported:
            total = np.nan_to_num(masks).sum(axis=0)
            # stored channels may each round up by half a step where several overlap: the
            # shipped ones are 8-bit, the source's have the step of the files they came from
            step = 1.0 / 255.0 if label == "shipped" else stored_step(masks)
            slack = (0.5 * step) * (masks > 0).sum(axis=0) + 1e-4
            over = total > 1.0 + slack
            if over.any():
                reported.add(("002", ""))
                out.append(
                    make_issue(
                        "WP-MASK-002",
                        f"{label} masks sum above 1 at {int(over.sum())} texels (max "
                        f"{total.max():.2f}) under policy 'additive'",
                        inp.pointer("masks"),
                    )
                )
    out += _check_sides(ctx)
    return out


def side_centroids(masks: np.ndarray, mesh: object | None) -> tuple[np.ndarray, float, str]:
    """Mask-weighted lateral position of every region and the face centre between them.

    With a mesh: the character's X of the vertices, masks sampled at vertex UVs (left = +X).
    Without: the U coordinate (left = larger u, as the demo and most face UV layouts).
    """
    r = masks.shape[0]
    if mesh is not None and getattr(mesh, "uvs", None) is not None:
        vals = tx.bilinear_planes(masks, np.asarray(mesh.uvs, np.float32))  # [V, R]
        x = np.asarray(mesh.positions, np.float64)[:, 0]
        unit = "x"
    else:
        h, w = masks.shape[1:]
        vals = np.moveaxis(masks, 0, -1).reshape(-1, r)
        x = np.tile((np.arange(w) + 0.5) / w, h).astype(np.float64)
        unit = "u"
    cent, centre = _centroids(vals, x)
    return cent, centre, unit


def _centroids(vals: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, float]:
    """Each region's ``vals``-weighted mean of ``x`` (``[V, R]``, ``[V]``) and the centre of
    their union (a region without weight: the centre)."""
    vals = np.nan_to_num(vals).astype(np.float64)
    wsum = vals.sum(axis=0)
    cent = (vals * x[:, None]).sum(axis=0) / np.maximum(wsum, 1e-12)
    union = vals.sum(axis=1)
    centre = float((union * x).sum() / max(union.sum(), 1e-12))
    return np.where(wsum > 0, cent, centre), centre


def _check_sides(ctx: Context) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    if inp.extra.get("tile") is not None:
        return []  # one UDIM tile: the sides are the whole face's (check_face_sides)
    masks = ctx.shipped_masks if ctx.shipped_masks is not None else np.asarray(a.masks)
    if masks.shape[0] != len(a.regions) or masks.shape[0] == 0:
        return []
    cent, centre, unit = side_centroids(masks, a.mesh)
    if a.mesh is not None and a.mesh.uvs is not None:
        x = np.asarray(a.mesh.positions, np.float64)[:, 0]
        half = max(float(x.max() - x.min()) / 2.0, 1e-12)
    else:
        half = 0.5
    return _side_issues(ctx, cent, centre, half, unit)


def check_face_sides(ctxs: list[Context]) -> list[Issue]:
    """WP-MASK-005 over a UDIM asset's whole face: every tile's masks (shipped, else source)
    sampled at that tile's vertices, one centre for the face."""
    vals, xs = [], []
    for ctx in ctxs:
        a = ctx.asset
        masks = ctx.shipped_masks if ctx.shipped_masks is not None else np.asarray(a.masks)
        if a.mesh is None or a.mesh.uvs is None or masks.shape[0] != len(a.regions):
            return []
        uv = np.asarray(a.mesh.uvs, np.float32)
        vals.append(tx.bilinear(np.moveaxis(masks, 0, -1), uv))
        xs.append(np.asarray(a.mesh.positions, np.float64)[:, 0])
    if not vals or not len(ctxs[0].asset.regions):
        return []
    x = np.concatenate(xs)
    cent, centre = _centroids(np.concatenate(vals), x)
    half = max(float(x.max() - x.min()) / 2.0, 1e-12)
    return _side_issues(ctxs[0], cent, centre, half, "x")


def _side_issues(
    ctx: Context, cent: np.ndarray, centre: float, half: float, unit: str
) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    out = []
    for i, reg in enumerate(a.regions):
        off = (cent[i] - centre) / half  # -1..1 across the whole head (or texture)
        if reg.side == "left" and off < -0.02 or reg.side == "right" and off > 0.02:
            actual = "right" if off < 0 else "left"
            out.append(
                make_issue(
                    "WP-MASK-005",
                    f"region {reg.name!r} is declared {reg.side} but its mask lies on the "
                    f"character's {actual} (mask-weighted {unit} {cent[i]:+.4f}, face centre "
                    f"{centre:+.4f})",
                    _slot(inp, reg.name) if ctx.shipped_masks is not None else inp.pointer("masks"),
                )
            )
    return out
