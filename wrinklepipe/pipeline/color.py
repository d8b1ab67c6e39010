"""The colour states' automatic choices, by CIEDE2000 inside each pose's active region: their
size, and the block format of the colour copies.

``choose_color_size`` is convert's colour stage, after the normals' choices (it measures with
the masks as they will ship): the colour states' size (``resolution.color``: a number, the
larger side; ``"auto"``, the smallest halving of the base colour's size whose colour fidelity
(:mod:`wrinklepipe.fidelity.color`) meets the colour budget; absent, the size they were painted
at). Smaller states are resampled in linear light (:func:`wrinklepipe.color.resample.
resize_texels`). The base colour always ships as it is.

``choose_color_format`` picks the colour copies' format after packaging (``formats.color``:
``auto``, the smaller of BC1 and BC7 within the colour budget; ``bc1``, ``bc7``; ``png8``: no
copies), measured on the blocks as decoded, the base colour over the face included.

Candidates are screened on every k-th active texel (about :data:`SCREEN_TEXELS` of them); the
size kept is then measured on every active texel, and that measure is what the report shows.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wrinklepipe.asset import ColorMaps, WrinkleAsset
from wrinklepipe.color.copies import FORMATS as COLOR_FORMATS
from wrinklepipe.color.copies import ColorCopy, color_copy
from wrinklepipe.color.resample import resize_texels
from wrinklepipe.fidelity import color as fc
from wrinklepipe.fidelity import footprint
from wrinklepipe.fidelity.reference import Pose
from wrinklepipe.fidelity.ship import mask_values
from wrinklepipe.metrics import Budget
from wrinklepipe.package import WrinklePackage

#: The smallest side the automatic size goes down to.
MIN_SIZE = 16
#: Active texels a candidate size is screened on.
SCREEN_TEXELS = 1 << 17


@dataclass
class ColorChoice:
    """The size chosen for the colour states, its fidelity, and every candidate screened."""

    size: tuple[int, int]
    source_size: tuple[int, int]
    how: str  # "auto" | "fixed" | "source"
    budget: Budget
    fidelity: fc.ColorFidelity
    tried: list[dict[str, Any]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "size": list(self.size),
            "source_size": list(self.source_size),
            "how": self.how,
            "budget": {"max_mean_delta_e": self.budget.mean, "max_p99_delta_e": self.budget.p99},
            "tried": self.tried,
            "fidelity": self.fidelity.to_json(),
        }

    def describe(self) -> str:
        """One line for the notes."""
        h, w = self.size
        return (
            f"colour states {w}x{h} ({self.how}; painted at {self.source_size[1]}x"
            f"{self.source_size[0]}): worst pose mean {self.fidelity.worst_mean():.2f}, p99 "
            f"{self.fidelity.worst_p99():.2f} CIEDE2000 inside the active regions; budget "
            f"{self.budget.describe()}"
        )


def color_reference(
    source: WrinkleAsset, poses: Sequence[Pose], face: bool = True
) -> fc.ColorReference:
    """The source's colour maps prepared for the measure (on the base colour's grid)."""
    c = source.color
    if c is None:
        raise ValueError("the asset has no colour states")
    base = c.base_linear()
    H, W = base.shape[:2]
    mesh = source.mesh
    fp = None
    if face and mesh is not None and mesh.uvs is not None and H == W:
        fp = footprint(mesh.uvs, mesh.indices, (H, W))
    return fc.prepare_color(
        base,
        c.states_linear(),
        source.masks,
        list(poses),
        source.region_names,
        source.policy,
        c.state_index,
        fp,
    )


def sizes_below(h: int, w: int, smallest: int = MIN_SIZE) -> list[tuple[int, int]]:
    """``(h, w)`` and its halvings while the larger side stays at least ``smallest``."""
    out = [(h, w)]
    while max(out[-1]) // 2 >= smallest and min(out[-1]) // 2 >= 1:
        a, b = out[-1]
        out.append((max(a // 2, 1), max(b // 2, 1)))
    return out


def fixed_size(h: int, w: int, side: int) -> tuple[int, int]:
    """The size whose larger side is ``side``, the base colour's aspect kept."""
    if h >= w:
        return side, max(1, round(w * side / h))
    return max(1, round(h * side / w)), side


def resized(color: ColorMaps, size: tuple[int, int]) -> ColorMaps:
    """The colour maps with the states at ``size`` (linear-light resampling)."""
    if color.states.shape[1:3] == tuple(size):
        return color
    states = np.stack([resize_texels(s, size) for s in color.states])
    return replace(color, states=states)


def _row(size: tuple[int, int], fid: fc.ColorFidelity, budget: Budget) -> dict[str, Any]:
    return {
        "size": list(size),
        "worst_mean_delta_e": round(fid.worst_mean(), 4),
        "worst_p99_delta_e": round(fid.worst_p99(), 4),
        "within": fid.inside(budget),
    }


def choose_color_size(
    source: WrinkleAsset,
    shipped: WrinkleAsset,
    poses: Sequence[Pose],
    ref: fc.ColorReference | None = None,
) -> tuple[WrinkleAsset, ColorChoice]:
    """``shipped`` with its colour states at the size the manifest asks for (see the module
    doc), and the choice. ``source``: the asset as read (full-resolution colour maps and
    masks); ``shipped``: after the normals' choices (its masks are what ships)."""
    c = source.color
    if c is None or shipped.color is None:
        raise ValueError("the asset has no colour states")
    ref = ref or color_reference(source, poses)
    budget = fc.color_budget(source.budget)
    masks = mask_values(shipped.masks)
    H, W = c.states.shape[1:3]
    factor = c.factor

    def measure(cm: ColorMaps, on: fc.ColorReference, full: bool) -> fc.ColorFidelity:
        return fc.measure_color(on, cm.base, list(cm.states), masks, factor, regions=full)

    auto = "color" in set(source.provenance.get("auto_resolution", ()))
    tried: list[dict[str, Any]] = []
    if auto and not ref.union.size:  # no pose shows a colour state: nothing to judge by
        size, how = (H, W), "source (no pose activates a colour state: nothing to judge by)"
    elif auto:
        screen = ref.coarse(SCREEN_TEXELS)
        size, how = (H, W), "auto"
        for cand in sizes_below(H, W):
            fid = measure(resized(c, cand), screen, False)
            tried.append(_row(cand, fid, budget))
            if not fid.inside(budget):
                break
            size = cand
    elif "color" in source.resolution:
        size, how = fixed_size(H, W, int(source.resolution["color"])), "fixed"
    else:
        size, how = (H, W), "source"
    chosen = resized(c, size)
    fid = measure(chosen, ref, True)
    choice = ColorChoice(size, (H, W), how, budget, fid, tried)
    return replace(shipped, color=chosen), choice


# ------------------------------------------------------------------------------------------------
# the block format of the colour copies


@dataclass
class ColorFormatChoice:
    """The block formats of the colour maps' copies, chosen per group as the normals' are: the
    colour states' (``format``, judged per pose in its active region) and the base colour's
    (``base_format``, judged over the face); None: PNG only. The copies made, the states'
    fidelity and every format tried."""

    format: str | None
    requested: str
    budget: Budget
    base_format: str | None = None
    copies: list[ColorCopy] = field(default_factory=list)
    fidelity: fc.ColorFidelity | None = None
    tried: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "requested": self.requested,
            "chosen": self.format or "png",
            "base": self.base_format or "png",
            "tried": self.tried,
            "fidelity": None if self.fidelity is None else self.fidelity.to_json(),
        }


def _color_textures(pkg: WrinklePackage) -> list[tuple[str, np.ndarray]]:
    """(name, sRGB texels) of the base colour and the colour states, in that order."""
    meta = pkg.meta
    names = [meta.base_color, *meta.color_textures] if meta.base_color else []
    return [(n, pkg.texture(n).pixels) for n in names]


def choose_color_format(
    source: WrinkleAsset,
    shipped: WrinkleAsset,
    poses: Sequence[Pose],
    pkg: WrinklePackage,
    want: str = "auto",
    ref: fc.ColorReference | None = None,
) -> ColorFormatChoice:
    """The colour copies' formats. ``auto``: for the base colour the smaller of BC1 and BC7
    whose copy stays inside the colour budget over the face; for the colour states the smaller
    whose copies keep every pose inside it (CIEDE2000 inside its active region, with the base
    colour as it ships: its copy when it has one). A named format is used as asked (a note
    when over the budget); ``png8`` makes none."""
    budget = fc.color_budget(source.budget)
    choice = ColorFormatChoice(None, want, budget)
    maps = _color_textures(pkg)
    if not maps or want == "png8":
        return choice
    if any(t.dtype != np.uint8 for _, t in maps):
        choice.notes.append("colour: 16-bit colour maps ship as PNG only (block formats are 8-bit)")
        return choice
    ref = ref or color_reference(source, poses)
    masks = mask_values(shipped.masks)
    factor = pkg.meta.color_factor
    (base_name, base_texels), states = maps[0], maps[1:]
    candidates = list(COLOR_FORMATS) if want == "auto" else [want]
    # the base colour over the face
    base_copies = {f: color_copy(base_name, base_texels, f, with_mips=False) for f in candidates}
    base_stats = {f: fc.base_color_fidelity(ref, c.decoded, factor) for f, c in base_copies.items()}
    base_fmt = next((f for f in candidates if budget.inside(base_stats[f])), None)
    if want != "auto":
        base_fmt = want
    shipped_base = base_copies[base_fmt].decoded if base_fmt is not None else base_texels
    # the colour states, with the base colour as it ships
    best = None
    for fmt in candidates:
        copies = [color_copy(n, t, fmt, with_mips=False) for n, t in states]
        fid = fc.measure_color(ref, shipped_base, [c.decoded for c in copies], masks, factor)
        inside = fid.inside(budget)
        choice.tried.append(
            {
                "format": fmt,
                "worst_mean_delta_e": round(fid.worst_mean(), 4),
                "worst_p99_delta_e": round(fid.worst_p99(), 4),
                "base_p99_delta_e": round(base_stats[fmt].p99, 4),
                "base_within": budget.inside(base_stats[fmt]),
                "within": inside,
            }
        )
        if inside or want != "auto":
            best = (fmt, fid)
            break
    if base_fmt is None:
        choice.notes.append(
            "colour: the base colour ships as PNG only (no block format keeps it inside the "
            "colour budget over the face: "
            + ", ".join(f"{f} p99 {base_stats[f].p99:.2f}" for f in candidates)
            + ")"
        )
    if best is None:
        choice.notes.append(
            "colour: no block format keeps the colour states inside the budget ("
            + ", ".join(f"{t['format']} p99 {t['worst_p99_delta_e']:.2f}" for t in choice.tried)
            + f"; budget {budget.describe()}): they ship as PNG only"
        )
    else:
        fmt, fid = best
        if not fid.inside(budget):
            choice.notes.append(f"colour: {fmt} as requested, over the colour budget")
        choice.format, choice.fidelity = fmt, fid
        choice.copies = [color_copy(n, t, fmt) for n, t in states]
    if base_fmt is not None:
        choice.base_format = base_fmt
        choice.copies.insert(0, color_copy(base_name, base_texels, base_fmt))
    return choice
