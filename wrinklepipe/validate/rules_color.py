"""Colour rules (WP-COL-*, WP-FID-008): the colour states against their base colour and the
full-resolution source, in CIEDE2000.

- **UV layout and size** (WP-COL-001): a colour state is painted on the base colour's UV layout,
  so its texture has the base colour's aspect (it may ship smaller: the automatic size).
- **Flipped** (WP-COL-002, error) or **another layout** (WP-COL-003, warning): a colour state
  is the face in that pose, so where every mask is zero it is the base colour, or a recolour
  of it (a state may be painted pale or flushed all over: the masks say where it shows). So
  outside the masks each state is fitted by an affine colour transform of the base colour
  (least squares, linear light, per channel of R, G, B and 1); where the fit is off by more
  than one just-noticeable difference on more than :data:`OUTSIDE_FRACTION` of the face, the
  state does not follow the base colour's texels. Against the base flipped in U or in V: one
  of them halving that share is a flip (an error: the colour lands on the wrong part of the
  face), else a map of another UV layout (a warning).
- **A colour state that never changes the colour** (WP-COL-004, warning): under the masks of
  the regions that drive it, it is within :data:`SAME_DELTA_E` of the base everywhere.
- **Fidelity** (WP-FID-008, error): with the source known, a pose whose shipped colour blend is
  over the colour budget against the full-resolution source's (:mod:`wrinklepipe.fidelity.
  color`), as WP-FID-001 is for the normals.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wrinklepipe.asset import ColorMaps
from wrinklepipe.codec import srgb
from wrinklepipe.color.resample import resize_linear
from wrinklepipe.fidelity import color as fc
from wrinklepipe.fidelity import footprint, sample_masks_at
from wrinklepipe.metrics import delta_e
from wrinklepipe.pipeline.color import color_reference
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.inputs import Texture
from wrinklepipe.validate.rules_fidelity import poses

#: A texel "differs" from the base colour by more than one just-noticeable difference.
DIFFERS_DELTA_E = 2.3
#: ... and a state differs outside the masks when more than this share of the face does.
OUTSIDE_FRACTION = 0.10
#: A colour state "never changes the colour" when it is this close to the base everywhere
#: under its regions' masks.
SAME_DELTA_E = 0.5
#: Texels the layout checks look at, at most (every k-th row and column beyond).
MAX_CHECK_TEXELS = 1 << 18


def _textures(ctx: Context) -> tuple[Texture | None, list[Texture | None]]:
    inp = ctx.inp
    base = inp.by_role("base_color")
    found = {t.state: t for t in inp.by_role("state_color")}
    colored = [s for s in ctx.asset.state_names if s in found]
    return (base[0] if base else None), [found[s] for s in colored]


def _shipped(ctx: Context) -> tuple[np.ndarray, list[np.ndarray]] | None:
    """The shipped base colour and colour states as sRGB texels (None when undecodable)."""
    base_t, states_t = _textures(ctx)
    if base_t is None or not states_t:
        return None
    base = ctx.texels(base_t)
    states = [ctx.texels(t) for t in states_t if t is not None]
    if base is None or any(s is None for s in states) or len(states) != len(states_t):
        return None
    return base, states  # type: ignore[return-value]


def check_color(ctx: Context) -> list[Issue]:
    """Every colour rule (nothing without colour states)."""
    base_t, states_t = _textures(ctx)
    if base_t is None and not states_t and ctx.asset.color is None:
        return []
    out = _layout_and_size(ctx, base_t, states_t)
    color = ctx.asset.color
    if color is not None:
        out += _outside_masks(ctx, color)
        out += _unchanged(ctx, color)
    out += _fidelity(ctx)
    return out


def _layout_and_size(
    ctx: Context, base_t: Texture | None, states_t: list[Texture | None]
) -> list[Issue]:
    if base_t is None:
        return []
    out = []
    for t in states_t:
        if t is None:
            continue
        # same aspect: the larger side over the smaller, within a texel of the base colour's
        if abs(t.width * base_t.height - t.height * base_t.width) > max(t.width, t.height):
            out.append(
                make_issue(
                    "WP-COL-001",
                    f"the colour map of state {t.state!r} is {t.width}x{t.height}, the base colour "
                    f"{base_t.width}x{base_t.height}: another aspect, so another UV layout",
                    t.where,
                    state=t.state,
                )
            )
    return out


def _grid_of(color: ColorMaps) -> tuple[int, int, int]:
    """The check grid: the states' size, every k-th texel when it is large."""
    h, w = color.states.shape[1:3]
    k = max(1, int(np.ceil(np.sqrt(h * w / MAX_CHECK_TEXELS))))
    return h, w, k


def _state_and_base(color: ColorMaps) -> tuple[np.ndarray, np.ndarray, int]:
    """The states and the base colour (at the states' size) in linear light, every k-th
    texel."""
    h, w, k = _grid_of(color)
    base = resize_linear(color.base_linear(), (h, w))[::k, ::k]
    states = srgb.decode_texels(color.states)[:, ::k, ::k]
    return np.ascontiguousarray(states), np.ascontiguousarray(base), k


def _masks_at(ctx: Context, h: int, w: int, k: int) -> np.ndarray:
    m = np.asarray(ctx.asset.masks, np.float32)
    if m.shape[1:] != (h, w):
        m = sample_masks_at(m, (h, w), np.arange(h * w)).reshape(-1, h, w)
    return m[:, ::k, ::k]


def _misfit(state: np.ndarray, base: np.ndarray) -> float:
    """Share of texels where ``state`` is more than a JND from the best affine colour
    transform of ``base`` (``[n, 3]`` each, linear light)."""
    if not len(base):
        return 0.0
    x = np.concatenate([base.astype(np.float64), np.ones((len(base), 1))], axis=1)
    m, *_ = np.linalg.lstsq(x, state.astype(np.float64), rcond=None)
    fit = np.clip(x @ m, 0.0, 1.0)
    return float((delta_e(fit, state) > DIFFERS_DELTA_E).mean())


def _outside_masks(ctx: Context, color: ColorMaps) -> list[Issue]:
    states, base, k = _state_and_base(color)
    h, w = color.states.shape[1:3]
    outside = ~(_masks_at(ctx, h, w, k) > 0).any(axis=0)
    mesh = ctx.asset.mesh
    if mesh is not None and mesh.uvs is not None and h == w:
        outside &= footprint(mesh.uvs, mesh.indices, (h, w))[::k, ::k]
    names = [ctx.asset.state_names[i] for i in color.state_index]
    misfit = [_misfit(s[outside], base[outside]) for s in states]
    ctx.metrics["color_outside_misfit"] = {n: round(m, 5) for n, m in zip(names, misfit)}
    out = []
    where = ctx.inp.pointer("textures")
    for j, (name, share) in enumerate(zip(names, misfit)):
        if share <= OUTSIDE_FRACTION:
            continue
        flips = {"flipped vertically (V)": base[::-1], "flipped horizontally (U)": base[:, ::-1]}
        fits = {how: _misfit(states[j][outside], b[outside]) for how, b in flips.items()}
        how = min(fits, key=lambda x: fits[x])
        if fits[how] < 0.5 * share:
            out.append(
                make_issue(
                    "WP-COL-002",
                    f"the colour map of state {name!r} does not follow the base colour where "
                    f"every mask is zero ({100 * share:.1f}% of that face more than "
                    f"{DIFFERS_DELTA_E:g} CIEDE2000 off any recolour of it); against the base "
                    f"colour {how} {100 * fits[how]:.1f}%: one of them is flipped",
                    where,
                    state=name,
                    misfit=round(share, 4),
                )
            )
        else:
            out.append(
                make_issue(
                    "WP-COL-003",
                    f"the colour map of state {name!r} does not follow the base colour where "
                    f"every mask is zero ({100 * share:.1f}% of that face more than "
                    f"{DIFFERS_DELTA_E:g} CIEDE2000 off any recolour of it), and no flip "
                    "explains it: a map of another UV layout, or colour no mask ever shows",
                    where,
                    state=name,
                    misfit=round(share, 4),
                )
            )
    return out


def _unchanged(ctx: Context, color: ColorMaps) -> list[Issue]:
    states, base, k = _state_and_base(color)
    h, w = color.states.shape[1:3]
    masks = _masks_at(ctx, h, w, k)
    a = ctx.asset
    drives = a.region_state_matrix()  # [R, K]
    out = []
    for j, si in enumerate(color.state_index):
        under = (masks[drives[:, si] > 0] > 0).any(axis=0) if drives[:, si].any() else None
        if under is None or not under.any():
            continue
        worst = float(delta_e(states[j][under], base[under]).max())
        if worst < SAME_DELTA_E:
            name = a.state_names[si]
            out.append(
                make_issue(
                    "WP-COL-004",
                    f"the colour map of state {name!r} is within {worst:.2f} CIEDE2000 of the "
                    "base colour everywhere under the masks of the regions that drive it: it "
                    "never changes the colour",
                    ctx.inp.pointer("textures"),
                    state=name,
                    max_delta_e=round(worst, 4),
                )
            )
    return out


def _fidelity(ctx: Context) -> list[Issue]:
    """WP-FID-008: the shipped colour blend against the full-resolution source's."""
    a = ctx.asset
    shipped = _shipped(ctx)
    masks = ctx.shipped_masks
    if not ctx.inp.has_source or a.color is None or shipped is None or masks is None:
        return []
    ps = poses(ctx)
    if not ps:
        return []
    ref = color_reference(a, ps)
    base, states = shipped
    factor = _factor(ctx)
    fid = fc.measure_color(ref, base, states, masks, factor, base_over_face=True)
    budget = fc.color_budget(a.budget)
    ctx.metrics["color_fidelity"] = {**fid.to_json(), "budget": _budget_json(budget)}
    out = []
    for p in sorted(fid.over(budget), key=lambda p: -p.overall.p99):
        o = p.overall
        region = max(p.regions.items(), key=lambda kv: kv[1].p99, default=None)
        worst = f"; worst region {region[0]}: p99 {region[1].p99:.2f}" if region else ""
        out.append(
            make_issue(
                "WP-FID-008",
                f"pose {p.pose!r}: colour p99 {o.p99:.2f}, mean {o.mean:.2f}, max {o.max:.2f} "
                f"CIEDE2000 from the full-resolution source inside its active region "
                f"({o.texels} texels), over the colour budget ({budget.describe()}){worst}",
                ctx.inp.pointer("textures"),
                pose=p.pose,
                p99_delta_e=round(o.p99, 4),
                mean_delta_e=round(o.mean, 4),
            )
        )
    return out


def _factor(ctx: Context) -> tuple[float, float, float]:
    f = ctx.inp.extra.get("color_factor")
    return tuple(float(x) for x in f) if f else (1.0, 1.0, 1.0)  # type: ignore[return-value]


def _budget_json(b: Any) -> dict[str, float]:
    return {"max_mean_delta_e": b.mean, "max_p99_delta_e": b.p99}
