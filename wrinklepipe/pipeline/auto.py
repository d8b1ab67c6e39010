"""The automatic choices of convert, by fidelity (:mod:`wrinklepipe.fidelity.search`).

``auto_choices(asset, manifest_formats, auto_scale)`` runs the searches on the ingested source
(full resolution): each state's size (``resolution.wrinkle = "auto"``), the mask size
(``resolution.mask = "auto"``), the PD scale (``pd_scale = "auto"``) and the block formats of
the base and the states (``formats.base`` / ``formats.wrinkle``, ``auto`` by default). Choices
the manifest fixes are measured, not searched. The budget is the manifest's ``[budget]``
(inside each pose's active region), the compressed copies' the ``compressed_*`` keys (the same
budget when absent).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wrinklepipe import fidelity as fd
from wrinklepipe import model
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.fidelity import formats as ff
from wrinklepipe.fidelity import search as fs
from wrinklepipe.fidelity import ship
from wrinklepipe.fidelity.level import PdLevel
from wrinklepipe.metrics import Budget
from wrinklepipe.options import BudgetOptions, FormatOptions
from wrinklepipe.package import WrinklePackage
from wrinklepipe.pipeline.package import resize_normals_pd

#: Manifest format names that mean "no block-compressed copy".
_NOT_BLOCK = ("png8", "png16", "exr")


@dataclass
class Applied:
    """The asset with the choices applied, and the search's record."""

    asset: WrinkleAsset
    choice: fs.Choice
    formats: dict[str, str]  # for the compressed copies: {"base": fmt | "png8", "wrinkle": ...}
    notes: list[str]


def can_search(asset: WrinkleAsset, poses: Sequence[fd.Pose] | None = None) -> str:
    """Empty when the searches can run on this asset (judged on ``poses``, by default its
    expression table), else why not."""
    if asset.encoding != "pd":
        return f"encoding {asset.encoding!r} (the searches are for pd)"
    return can_measure(asset, poses)


def can_measure(asset: WrinkleAsset, poses: Sequence[fd.Pose] | None = None) -> str:
    """Empty when fidelity can judge this asset's choices (any encoding), else why not."""
    if asset.encoding not in model.ENCODINGS or asset.policy not in model.POLICIES:
        return f"encoding {asset.encoding!r} / policy {asset.policy!r}"
    if asset.policy == "signed" and len(asset.state_names) != 2:
        return "policy 'signed' needs two states"
    if not (asset.expressions if poses is None else poses):
        if poses is None or not asset.drivers:
            return "no poses to judge by (no expressions, no driver curve)"
        unplayed = (
            " (the expression table is not played while driver curves are)"
            if asset.expressions
            else ""
        )
        return f"no poses to judge by: no frame of the drivers' curves activates a region{unplayed}"
    k, h, w = asset.states.shape[:3]
    if h != w or asset.masks.shape[1] != asset.masks.shape[2]:
        return "maps that are not square"
    if asset.mesh is None or asset.mesh.uvs is None:
        return "no mesh with UVs"
    return ""


def budgets(budget: BudgetOptions) -> tuple[Budget, Budget]:
    """The PNG budget and the compressed copies' (:meth:`BudgetOptions.maps`,
    :meth:`BudgetOptions.copies`)."""
    return budget.maps(), budget.copies()


#: Formats the searches do not encode: the copy's own check measures them (UASTC: basisu).
_NOT_SEARCHED = ("uastc",)


def _fixed_format(want: str | None) -> str | None:
    if want in (None, "auto"):
        return None
    return "png" if want in _NOT_BLOCK or want in _NOT_SEARCHED else want


def _for_copies(want: str | None, chosen: str) -> str:
    """The format the compressed copies are made in: a format the searches do not encode as
    asked, else what they chose (``png``: no copy)."""
    if want in _NOT_SEARCHED:
        return str(want)
    return chosen if chosen != "png" else "png8"


def auto_choices(
    asset: WrinkleAsset,
    formats: FormatOptions | None = None,
    auto_scale: bool = True,
    compressed: bool = True,
    poses: Sequence[fd.Pose] | None = None,
) -> Applied:
    """Search, then apply: states at the chosen size (from the search's pyramid), masks at the
    chosen size, the chosen PD scale; the formats to pass to the compressed copies. ``poses``:
    what the searches judge (the poses the drivers produce, as validation measures them);
    by default every expression of the table at full amount."""
    formats = formats or FormatOptions()
    auto = set(asset.provenance.get("auto_resolution", ()))
    res = asset.resolution
    # PD slopes of the wrinkles alone, made where the searches read them (a band, or the
    # reference's texels: the same values, never the whole level)
    H = asset.states.shape[1]
    grid_base = resize_normals_pd(asset.base, H, H)
    slopes = PdLevel(grid_base, asset.states)
    if poses is None:
        poses = fd.expression_poses(
            asset.region_names, asset.region_state_matrix(), asset.expressions, asset.policy
        )
    mesh = asset.mesh
    src = fs.Source(
        base=asset.base,
        slopes=slopes,
        masks=asset.masks,
        poses=list(poses),
        region_names=asset.region_names,
        policy=asset.policy,
        footprint=fd.footprint(mesh.uvs, mesh.indices, (H, H)),
        source_base=grid_base,
    )
    fixed = fs.Fixed(
        wrinkle=None if "wrinkle" in auto else int(res.get("wrinkle", H)),
        mask=None if "mask" in auto else int(res.get("mask", asset.masks.shape[1])),
        scale=None if auto_scale else float(asset.pd_scale),
        base_format="png" if not compressed else _fixed_format(formats.base),
        state_format="png" if not compressed else _fixed_format(formats.wrinkle),
    )
    png_budget, comp_budget = budgets(asset.budget)
    choice = fs.search(src, png_budget, comp_budget, fixed)
    del src, slopes, grid_base
    notes = list(choice.notes)
    size, m = choice.wrinkle_size, choice.mask_size
    states = asset.states
    if size != H:
        base_s = resize_normals_pd(asset.base, size, size)  # what the package subtracts
        states = model.pd_to_normal(model.normal_to_pd(base_s)[None] + choice.states)
    masks = asset.masks
    if m != masks.shape[1]:
        masks = ship.mask_values(masks, m)
    out = replace(
        asset,
        states=states,
        masks=masks,
        pd_scale=choice.pd_scale,
        resolution={**res, "wrinkle": size, "mask": m},
    )
    notes.append(describe_choice(choice, auto, auto_scale, formats))
    return Applied(
        asset=out,
        choice=choice,
        formats={
            "base": _for_copies(formats.base, choice.base_format),
            "wrinkle": _for_copies(formats.wrinkle, choice.state_format),
        },
        notes=notes,
    )


def formats_by_fidelity(
    source: WrinkleAsset,
    shipped: WrinkleAsset,
    pkg: WrinklePackage,
    poses: Sequence[fd.Pose],
    formats: FormatOptions | None = None,
) -> tuple[dict[str, str], list[str], dict[str, Any] | None]:
    """The block formats of an asset the searches do not make (another encoding than pd: its
    maps ship at the manifest's sizes) chosen by fidelity (:func:`ff.choose_formats`), from the
    package's stored texels, against the source as read (``source``) inside each pose's active
    region: ``({"base": fmt | "png8", "wrinkle": ...}`` for the copies, notes, the record for
    report.json). Nothing is chosen (``{}``) when fidelity cannot be measured, or no format is
    automatic; the copies then choose as they do."""
    formats = formats or FormatOptions()
    want = {"base": formats.base, "wrinkle": formats.wrinkle}
    if all(w != "auto" for w in want.values()) or can_measure(source, poses):
        return {}, [], None
    base_tex = next((t for t in pkg.textures if t.role == "base_normal"), None)
    states = [pkg.texture(n) for n in pkg.meta.state_textures]
    if base_tex is None or not states or not poses:
        return {}, [], None
    if any(t.pixels.dtype != np.uint8 for t in [base_tex, *states]):
        return {}, [], None  # 16-bit maps ship as PNG only (the copies say so)
    H = source.states.shape[1]
    grid_base = resize_normals_pd(source.base, H, H)
    mesh = shipped.mesh
    ref = fd.prepare(
        grid_base,
        fd.source_states(grid_base, source.states, source.encoding),
        source.masks,
        list(poses),
        source.region_names,
        source.encoding,
        source.policy,
        fd.footprint(mesh.uvs, mesh.indices, (H, H)),
    )
    _, budget = budgets(shipped.budget)
    c = ff.choose_formats(
        ref,
        base_tex.pixels,
        [t.pixels for t in states],
        ship.mask_values(shipped.masks),
        pkg.meta.encoding,
        float(pkg.meta.scale),
        int(pkg.meta.mapping),
        budget,
        fixed_base=_fixed_format(want["base"]),
        fixed_states=_fixed_format(want["wrinkle"]),
    )
    chosen = {
        "base": _for_copies(want["base"], c.base_format),
        "wrinkle": _for_copies(want["wrinkle"], c.state_format),
    }
    notes = [*c.notes, describe_formats(c, source.encoding)]
    return chosen, notes, c.to_json()


def describe_formats(c: ff.FormatChoice, encoding: str) -> str:
    """One line for the notes: the block formats chosen by fidelity and what they give."""
    got = (
        f"; worst pose p99 {c.compressed.worst_p99():.2f} deg (compressed) inside the active "
        "regions"
        if c.compressed is not None
        else ""
    )
    return (
        f"block formats by fidelity ({encoding} maps at the manifest's sizes): base "
        f"{c.base_format}, states {c.state_format}{got}; budget {c.budget.describe()}"
    )


def describe_choice(c: fs.Choice, auto: set[str], auto_scale: bool, formats: FormatOptions) -> str:
    """One line for the notes: what was chosen (and how) and the fidelity it gives."""

    def how(flag: bool) -> str:
        return "auto" if flag else "fixed"

    return (
        f"fidelity choices: states {c.wrinkle_size}^2 ({how('wrinkle' in auto)}), masks "
        f"{c.mask_size}^2 ({how('mask' in auto)}), pd_scale {c.pd_scale:g} ({how(auto_scale)}), "
        f"base {c.base_format}, states {c.state_format}; worst pose p99 "
        f"{c.png.worst_p99():.2f} deg (png)"
        + (f", {c.compressed.worst_p99():.2f} deg (compressed)" if c.compressed else "")
        + f" inside the active regions; budget {c.budget.describe()}"
    )


def choice_report(c: fs.Choice) -> dict[str, Any]:
    """The search's record for report.json (its per-pose fidelity, every candidate tried)."""
    return c.to_json()


__all__ = [
    "Applied",
    "auto_choices",
    "budgets",
    "can_measure",
    "can_search",
    "choice_report",
    "formats_by_fidelity",
]
